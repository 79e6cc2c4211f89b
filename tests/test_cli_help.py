"""Every option of every command keeps its name, its units and its whole help text at 80 columns."""
import re

import pytest
import typer
from typer.testing import CliRunner

from labtool.cli import app

WIDTH = 80


def _commands(cmd, path=()):
    yield path, cmd
    for name, sub in sorted(getattr(cmd, "commands", {}).items()):
        yield from _commands(sub, path + (name,))


COMMANDS = list(_commands(typer.main.get_command(app)))


def _help(path):
    res = CliRunner().invoke(app, [*path, "--help"], terminal_width=WIDTH, env={"COLUMNS": str(WIDTH)})
    assert res.exit_code == 0, res.output
    return res.output


def _flat(text):
    """Whitespace collapsed; a word click broke after its hyphen ("in-\n  process") joined again."""
    return " ".join(re.sub(r"-\n\s+", "-", text).split())


@pytest.mark.parametrize("path,cmd", COMMANDS, ids=[" ".join(p) or "labtool" for p, _ in COMMANDS])
def test_help_keeps_every_option_and_unit_at_80_columns(path, cmd):
    out = _help(path)
    assert max(len(line) for line in out.splitlines()) <= WIDTH, out
    flat = _flat(out)
    for param in cmd.params:
        for opt in list(param.opts) + list(param.secondary_opts):
            assert re.search(rf"(?<![\w-]){re.escape(opt)}(?![\w-])", out), f"{opt} missing from {' '.join(path)} --help"
        text = getattr(param, "help", None)
        if text:
            # the whole help text, brackets ([mm], [s/m], ...) included, in reading order
            assert _flat(text) in flat, f"{' '.join(path)} {param.opts}: help text altered: {text!r}"


def test_a_unit_in_brackets_survives():
    out = _flat(_help(("report",)))
    assert "[mm]" in out and "[rpm]" in out


@pytest.mark.slow
def test_a_command_group_loads_only_its_own_module_and_help_still_lists_every_command():
    """``labtool doe ...`` registers the doe group alone (the other commands' modules are not
    imported: a shorter start); ``--help`` afterwards, in the same process, lists every command in
    the usual order; a lone command (not a group) gets the whole app, so its name is not read as
    an extra argument."""
    import subprocess
    import sys
    import textwrap
    from pathlib import Path

    code = textwrap.dedent("""
        import contextlib, io, sys
        import labtool.cli as cli
        with contextlib.redirect_stdout(io.StringIO()):
            assert cli.main(["doe", "run", "--help"]) == 0
        others = sorted(m for m in cli.COMMAND_MODULES if m in sys.modules and not m.endswith(".doe"))
        print("others:", others)
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            assert cli.main(["--help"]) == 0
        names = [line.split()[0] for line in out.getvalue().split("Commands:")[1].splitlines() if line.strip()]
        print("listed:", names)
        with contextlib.redirect_stdout(io.StringIO()):
            code = cli.main(["kinematics", "--help"])
        print("kinematics:", code)
        """)
    proc = subprocess.run([sys.executable, "-c", code], cwd=Path(__file__).resolve().parents[1],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    lines = dict(line.split(": ", 1) for line in proc.stdout.splitlines())
    assert lines["others"] == "[]"
    whole = _help(())              # the app with every command registered at once
    expected = [line.split()[0] for line in whole.split("Commands:")[1].splitlines() if line.strip()]
    assert len(expected) == 15 and lines["listed"] == repr(expected)
    assert lines["kinematics"] == "0"
