"""The tutorial (docs/tutorial.md) run as a reader runs it: its shell commands, in order, in a fresh
folder beside a copy of sample_data/, on the simulated stand.

The page is the test's input. Each ```console block holds commands (``$ `` lines; a line ending
in ``\\`` goes on on the next) and what they print. A command must exit 0, unless the next command
is ``echo $?`` and the page shows another status. Every line the page shows under a command must
come out of it, in that order (``...`` stands for lines left out); numbers are compared by their
shape only, since timings and the last digits of a fit differ between machines. A
``{code-block}`` with a ``:caption:`` naming a file in the working folder is written there, as a
reader would save it.
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "tutorial.md"

_CONSOLE = re.compile(r"^```console\n(.*?)^```", re.S | re.M)
_FILE = re.compile(r"^```\{code-block\} \w+\n:caption: (\S+)\n\n(.*?)^```", re.S | re.M)
_NUMBER = re.compile(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?")


@dataclass
class Step:
    command: str = ""                               # a shell command, or a file to write
    output: list[str] = field(default_factory=list)
    file: str | None = None
    content: str = ""


def steps(text: str) -> list[Step]:
    """The page's commands and files, in the order they appear."""
    found = [(m.start(), "console", m) for m in _CONSOLE.finditer(text)]
    found += [(m.start(), "file", m) for m in _FILE.finditer(text)]
    out: list[Step] = []
    for _, kind, m in sorted(found, key=lambda f: f[0]):
        if kind == "file":
            out.append(Step(file=m.group(1), content=m.group(2)))
            continue
        lines = m.group(1).splitlines()
        i = 0
        while i < len(lines):
            line = lines[i]
            i += 1
            if not line.startswith("$ "):
                assert out and out[-1].file is None, f"output before any command: {line!r}"
                out[-1].output.append(line)
                continue
            command = line[2:]
            while command.endswith("\\") and i < len(lines):
                command = command[:-1] + " " + lines[i].strip()
                i += 1
            out.append(Step(command=command))
    return out


def shape(line: str) -> str:
    """A line with every number as '#' and runs of blanks as one."""
    return " ".join(_NUMBER.sub("#", line).split())


def shown_in_order(shown: list[str], printed: str) -> str | None:
    """None if the page's lines come out of the command in order, else the first that does not."""
    lines = [shape(x) for x in printed.splitlines()]
    at = 0
    for want in shown:
        if want.strip() in ("", "..."):
            continue
        key = shape(want)
        while at < len(lines) and lines[at] != key:
            at += 1
        if at == len(lines):
            return want
        at += 1
    return None


def test_the_page_has_the_day_in_order():
    """The parser finds the whole day: a test that found no commands would pass on nothing."""
    commands = [s.command.split()[:2] for s in steps(PAGE.read_text()) if s.file is None]
    firsts = [c[1] for c in commands if c and c[0] == "labtool"]
    order = ["acquire", "calibrate", "process", "simulate", "report", "fit", "campaign"]
    assert [c for c in dict.fromkeys(firsts) if c in order] == order


def test_shape_and_order_checks_can_fail():
    printed = "wrote a.h5: 40000 samples\nKa: 864.39 m/s^2/V\n"
    assert shown_in_order(["wrote a.h5: 4 samples", "...", "Ka: 1 m/s^2/V"], printed) is None
    assert shown_in_order(["Ka: 1 m/s^2/V", "wrote a.h5: 4 samples"], printed) == "wrote a.h5: 4 samples"
    assert shown_in_order(["wrote b.h5: 4 samples"], printed) == "wrote b.h5: 4 samples"


@pytest.mark.slow
def test_the_tutorial_runs_as_the_page_says(tmp_path):
    shutil.copytree(ROOT / "sample_data", tmp_path / "sample_data")
    bin_dir = Path(sys.executable).parent
    env = dict(os.environ, COLUMNS="120", MPLBACKEND="Agg", PATH=f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    env.pop("NO_COLOR", None)
    (tmp_path / ".venv" / "bin").mkdir(parents=True)       # `source .venv/bin/activate` finds one
    (tmp_path / ".venv" / "bin" / "activate").write_text(f'export PATH="{bin_dir}:$PATH"\n')

    last_status = None
    for step in steps(PAGE.read_text()):
        if step.file is not None:
            path = tmp_path / step.file
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(step.content)
            continue
        if step.command.strip() == "echo $?":
            assert step.output == [str(last_status)], f"the page says {step.output}, the command exited {last_status}"
            last_status = 0
            continue
        assert last_status in (None, 0), f"{previous!r} exited {last_status}:\n{printed}"
        run = subprocess.run(["bash", "-c", step.command], cwd=tmp_path, env=env, stdin=subprocess.DEVNULL,
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=600)
        previous, printed, last_status = step.command, run.stdout, run.returncode
        missing = shown_in_order(step.output, printed)
        assert missing is None, f"{step.command!r} did not print {missing!r}; it printed:\n{printed}"
    assert last_status == 0, f"{previous!r} exited {last_status}:\n{printed}"
    assert (tmp_path / "day" / "campaign" / "campaign.html").is_file()
