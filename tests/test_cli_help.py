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
