"""The Python API reference (docs/reference/api.md) against the API itself: every public name of
``labtool`` has its entry, every parameter of every public function is documented, and each
number a caller passes states its unit. Sphinx's numpydoc validation checks the parameters again
when the docs build; this test says which name is missing without a build."""
from __future__ import annotations

import inspect
import re
from pathlib import Path

import pytest
from numpydoc.docscrape import FunctionDoc

import labtool

PAGE = Path(__file__).resolve().parents[1] / "docs" / "reference" / "api.md"
FUNCTIONS = [n for n in labtool.__all__ if inspect.isfunction(getattr(labtool, n))]
# a number's type in a numpydoc line: int, float, a sequence or tuple of them, (lo, hi, step)
NUMERIC = re.compile(r"^(int|float|sequence of (int|float)|\(lo, hi, step\))\b")
UNIT = re.compile(r"\[[^\]]+\]")


def test_every_public_name_has_its_entry_in_the_reference():
    text = PAGE.read_text(encoding="utf-8")
    directive = re.compile(r"^\.\. auto(function|class|data|module):: labtool\.(\w+)", re.M)
    entries = {m.group(2) for m in directive.finditer(text)}
    tabled = set(re.findall(r"\{(?:func|class|data)\}`labtool\.(\w+)`", text))
    missing = [n for n in labtool.__all__ if n not in entries and n not in tabled]
    assert not missing, f"docs/reference/api.md lacks {missing}"
    assert set(FUNCTIONS) <= entries, "every function has its autofunction entry"
    assert {"simulate", "process", "report", "fit", "suggest", "acquire", "kinematics", "run_design"} <= set(FUNCTIONS)


@pytest.mark.parametrize("name", FUNCTIONS)
def test_every_parameter_is_documented_and_every_number_has_its_unit(name):
    func = getattr(labtool, name)
    doc = FunctionDoc(func)
    documented = {p.name.lstrip("*"): p for p in doc["Parameters"]}
    params = list(inspect.signature(func).parameters.values())
    assert params, name
    for prm in params:
        assert prm.name in documented, f"labtool.{name}: parameter {prm.name!r} is not in its docstring"
    assert set(documented) <= {p.name for p in params}, f"labtool.{name} documents a parameter it lacks"
    for p in doc["Parameters"]:
        if NUMERIC.match(p.type):
            text = " ".join(p.desc)
            assert UNIT.search(text), f"labtool.{name}: {p.name} ({p.type}) states no unit in brackets: {text[:80]}"


def test_the_check_sees_a_number_without_a_unit():
    """The unit check is not vacuous: a docstring of a number without a unit fails it."""
    def f(speed=1.0):
        """Do.

        Parameters
        ----------
        speed : float
            The cam's speed.
        """
    p = FunctionDoc(f)["Parameters"][0]
    assert NUMERIC.match(p.type) and not UNIT.search(" ".join(p.desc))
