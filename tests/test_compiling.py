"""A compilation of labtool's code is announced once, with progress when it lasts
(labtool.models.dynamics.compiling); a real compile fires it, a quiet scope and other code do not.

The real first command against an empty cache (the notice, then none from the cache) is checked in
tests/test_kernel_cache.py, where the models compile anyway.
"""
import itertools
import time
import types

import pytest
from numba import njit

from labtool.models.dynamics import compiling

_names = itertools.count()


@pytest.fixture(autouse=True)
def notices_on(monkeypatch):
    """The suite runs with LABTOOL_COMPILE_NOTICES=0 (tests/conftest.py): on here."""
    monkeypatch.setitem(compiling._state, "quiet", 0)


def _fresh(module: str):
    """A function never compiled before, which numba's event reports as defined in ``module``."""
    k = next(_names)
    ns = {}
    exec(f"def f_{k}(x):\n    return x * {k + 2}.0 + 1.0\n", ns)
    fn = ns[f"f_{k}"]
    fn.__module__ = module
    return njit(cache=False)(fn)


def _what() -> str:
    return f"the test model {next(_names)}"


def test_the_first_compilation_in_a_scope_says_what_how_long_and_once(capsys):
    what = _what()
    compiling.ESTIMATES_S[what] = 7.0
    with compiling.announce(what):
        assert _fresh("labtool.models.dynamics.fake")(1.0) > 0
        _fresh("labtool.models.dynamics.fake")(1.0)            # the same scope: no second line
    with compiling.announce(what):
        _fresh("labtool.models.dynamics.fake")(1.0)            # announced once a process
    lines = capsys.readouterr().err.splitlines()
    assert lines == [f"labtool: compiling {what} for this machine (about 7 s, once: later runs load it "
                     "from numba's cache)"]


def test_a_compiled_function_called_again_and_code_not_labtools_say_nothing(capsys):
    f = _fresh("labtool.models.dynamics.fake")
    f(1.0)
    capsys.readouterr()
    with compiling.announce(_what()):
        f(2.0)                                                 # compiled already: no event
        _fresh("someone_elses_module")(1.0)                    # compiles, but not labtool's code
    assert capsys.readouterr().err == ""


def test_outside_every_scope_a_compilation_is_named_by_its_package(capsys):
    compiling._state["announced"].discard("the processing kernels")
    _fresh("labtool.processing.kernels")(1.0)
    err = capsys.readouterr().err
    assert err.startswith("labtool: compiling the processing kernels for this machine (about ")


def test_quiet_silences_the_notice_but_counts_the_compilation(capsys):
    n0, s0 = compiling.totals()
    with compiling.quiet(), compiling.announce(_what()):
        _fresh("labtool.models.dynamics.fake")(1.0)
    n1, s1 = compiling.totals()
    assert capsys.readouterr().err == ""
    assert n1 == n0 + 1 and s1 > s0


class _Fake:
    """numba's compile event data for a labtool function (to drive a long compilation)."""

    def __init__(self):
        self.data = {"dispatcher": types.SimpleNamespace(py_func=types.SimpleNamespace(__module__="labtool.x"))}


@pytest.fixture
def fast_progress(monkeypatch):
    monkeypatch.setattr(compiling, "PROGRESS_AFTER_S", 0.02)
    monkeypatch.setattr(compiling, "TICK_S", 0.01)
    monkeypatch.setattr(compiling, "STATUS_EVERY_S", 0.06)


def _long_compilation(what: str, capsys, until) -> str:
    """A compilation in scope ``what`` that lasts until ``until(stderr so far)`` (at most 30 s: a
    loaded machine runs the progress thread late), then the scope's end; returns stderr."""
    err = ""
    with compiling.announce(what):
        compiling._compile_started(_Fake().data)
        deadline = time.monotonic() + 30.0
        while not until(err) and time.monotonic() < deadline:
            time.sleep(0.01)
            err += capsys.readouterr().err
        compiling._compile_ended(_Fake().data)
    return err + capsys.readouterr().err


def test_a_long_compilation_writes_status_lines_when_stderr_is_not_a_terminal(capsys, fast_progress):
    what = _what()
    compiling.ESTIMATES_S[what] = 1.0
    status = f"labtool: still compiling {what}: "
    lines = _long_compilation(what, capsys, lambda err: err.count(status) >= 2).splitlines()
    assert lines[0].startswith(f"labtool: compiling {what} for this machine")
    shown = [line for line in lines if line.startswith(status)]
    assert len(shown) >= 2 and all(line.endswith("(about 1 s in all)") for line in shown)
    assert lines[-1].startswith(f"labtool: compiled {what} in ")


def test_on_a_terminal_the_progress_line_is_redrawn_in_place_then_replaced(capsys, fast_progress, monkeypatch):
    monkeypatch.setattr(compiling, "_terminal", lambda: True)
    what = _what()
    compiling.ESTIMATES_S[what] = 1.0
    bar = f"\rlabtool: compiling {what} ["
    err = _long_compilation(what, capsys, lambda err: err.count(bar) >= 2)
    first, rest = err.split("\n", 1)
    assert first.startswith(f"labtool: compiling {what} for this machine")
    assert rest.count(bar) >= 2 and "\n" not in rest.rstrip("\n")
    assert rest.endswith("\033[K\n") and f"\rlabtool: compiled {what} in " in rest
