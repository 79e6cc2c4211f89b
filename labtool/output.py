"""The CLI's console (rich): tables and messages sized for a terminal, a pipe or a log."""
from __future__ import annotations

import os
import time


PIPE_WIDTH = 200   # columns of the tables written to a file or a pipe (a terminal keeps its own)


def console(stderr: bool = False):
    """A rich Console for the commands' tables and messages. Written to a file, a pipe or a CI log,
    rich would cut tables to 80 columns and elide the numbers; there it gets PIPE_WIDTH columns
    unless the user set COLUMNS."""
    from rich.console import Console

    con = Console(stderr=stderr)
    if not con.is_terminal and "COLUMNS" not in os.environ:
        con.width = PIPE_WIDTH
    return con


def terminal_console(stderr: bool = True):
    """``console(stderr)`` when rich would take the stream for a terminal, else None, without
    importing rich (~0.03 s of a command's start): rich's Console.is_terminal can be true only for
    a tty, TTY_COMPATIBLE=1 or a non-empty FORCE_COLOR, so off those it is false."""
    import sys

    stream = sys.stderr if stderr else sys.stdout
    try:
        tty = bool(stream.isatty())
    except (AttributeError, ValueError, OSError):      # no isatty, a closed stream
        tty = False
    if not (tty or os.environ.get("TTY_COMPATIBLE") == "1" or os.environ.get("FORCE_COLOR")):
        return None
    con = console(stderr=stderr)
    return con if con.is_terminal else None


def terminal_confirm():
    """``confirm(question) -> bool`` asking yes/no (default no) on stderr when a user sits at a
    terminal (stdin and stderr both are one); None otherwise, so a script gets the refusal line
    instead of a prompt it cannot answer (labtool.common.budget.check)."""
    import sys

    if not (sys.stdin.isatty() and sys.stderr.isatty()):
        return None
    import typer
    return lambda question: typer.confirm(question, default=False, err=True)


class ProgressLines:
    """Progress when stderr is not a terminal (a pipe, a CI log): the current step with the time
    since the start, at most every ``period`` s and not before ``quiet`` s, so a long command is
    never silent and a quick one (or one that ends in a bad-input line) prints nothing extra.
    Used like rich's status: ``with ... as status: status.update(msg)``."""

    def __init__(self, stream, name: str, quiet: float = 2.0, period: float = 5.0):
        self.stream, self.name = stream, name
        self.t0 = self.last = time.perf_counter()
        self.quiet, self.period = quiet, period
        self.printed = False

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def update(self, msg: str) -> None:
        now = time.perf_counter()
        if now - self.t0 >= self.quiet and (not self.printed or now - self.last >= self.period):
            print(f"{self.name}: {msg} ({now - self.t0:.0f} s)", file=self.stream, flush=True)
            self.last, self.printed = now, True
