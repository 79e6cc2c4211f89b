"""Progress of a long computation: a bar with an ETA on a terminal, a line now and then in a pipe.

On a terminal (rich) the bar shows items done, elapsed time and the time remaining; written to a
pipe, a file or a CI log it prints one line every ``interval_s`` seconds (and none at all for work
that ends sooner), so a log shows that the work goes on and when it should end. The ETA is the
items left over the rate of this run (items resumed from an earlier run do not count).
"""
from __future__ import annotations

import time

from labtool.execution.chunked import format_duration


class LineProgress:
    """callable(done, total): a line on ``write`` every ``interval_s`` (s)."""

    def __init__(self, label: str, write, interval_s: float = 15.0, clock=time.monotonic):
        self.label, self.write, self.interval_s, self.clock = label, write, interval_s, clock
        self.t0 = self.last = None
        self.done0 = 0

    def __call__(self, done: int, total: int) -> None:
        now = self.clock()
        if self.t0 is None:
            self.t0 = self.last = now
            self.done0 = done
            return
        if now - self.last < self.interval_s:
            return
        self.last = now
        self.write(f"{self.label}: {done}/{total} ({100.0 * done / max(total, 1):.1f} %), "
                   f"{format_duration(now - self.t0)} elapsed, ETA {format_duration(eta(self, done, total, now))}")


def eta(p, done: int, total: int, now: float) -> float:
    rate = (done - p.done0) / max(now - p.t0, 1e-9)
    return (total - done) / rate if rate > 0 else float("inf")


class BarProgress:
    """A rich progress bar with the time remaining; a context manager, callable(done, total)."""

    def __init__(self, label: str, console, total: int):
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, \
            TimeRemainingColumn
        self._bar = Progress(TextColumn(label), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                             TextColumn("ETA"), TimeRemainingColumn(), console=console, transient=True)
        self._task = self._bar.add_task(label, total=total)

    def __enter__(self):
        self._bar.__enter__()
        return self

    def __exit__(self, *exc):
        return self._bar.__exit__(*exc)

    def __call__(self, done: int, total: int) -> None:
        self._bar.update(self._task, completed=done, total=total)
