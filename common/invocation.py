"""The command line that is running, as the user typed it: what a file's ``history`` records.

``labtool.cli`` sets it around each command (a command run inside another, as ``labtool demo``'s
steps, sees its own line); a library call outside the CLI has none.
"""
from __future__ import annotations

import contextlib
import contextvars
import shlex

from labtool.common.names import shown

_LINE: contextvars.ContextVar[tuple[str, ...] | None] = contextvars.ContextVar("labtool_command_line", default=None)


@contextlib.contextmanager
def running(args):
    token = _LINE.set(("labtool", *map(str, args)))
    try:
        yield
    finally:
        _LINE.reset(token)


def command_line(default: str = "") -> str:
    """``labtool <args>`` quoted for a shell (file names that are not UTF-8 escaped), or ``default``
    outside a command."""
    line = _LINE.get()
    return shown(shlex.join(line)) if line is not None else default


def named(param: str) -> str:
    """A parameter's name as the caller wrote it: ``--ka-gain`` inside a command, ``ka_gain`` from
    Python. The API's checks word their refusals with it, so that a command needs no copy of them."""
    return "--" + param.replace("_", "-") if _LINE.get() is not None else param
