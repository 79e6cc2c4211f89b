"""The CLI's console (rich): tables and messages sized for a terminal, a pipe or a log."""
from __future__ import annotations

import os


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
