"""Command-line options of the operating point, made from its owner
(:mod:`labtool.common.operating_point`): the same name, unit, default and reason in every command's
``--help``, and the values given turned into SI once.

An option's default is None (not given), so that a command can say where each value came from:
the option, a file, or the owner's default that the help names.
"""
from __future__ import annotations

from typing import Any

import typer

from labtool.common.operating_point import FIELD


def op_option(name: str, help_extra: str = "", default_note: str | None = None, file_first: bool = False) -> Any:
    """The typer option of operating-point field ``name`` (its owner's option name, unit and help).
    ``default_note`` replaces the help's "(default ...)" where a command takes the value from
    elsewhere first; ``file_first``: the input file's attribute, else the owner's default."""
    f = FIELD[name]
    text = f.help()
    if file_first:
        text = text.replace(" (default ", " (default: the file's, else ", 1)
    if default_note is not None:
        text = text[: text.rindex(" (default")] + f" ({default_note})"
    return typer.Option(None, f.option, help=text + (f"; {help_extra}" if help_extra else ""), show_default=False)


def given(**edge_values) -> dict:
    """Option values (edge units, keyed by field name; None = not given) as SI values, checked."""
    return {name: FIELD[name].check_edge(v) for name, v in edge_values.items() if v is not None}
