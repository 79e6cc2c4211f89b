"""Map a pure function over a large list of items, in chunks sized from its measured cost.

``map_chunked(fn, items, store, backend)`` calls ``fn(items[i])`` (a dict of column values, one row)
for every item that ``store`` (a :class:`labtool.execution.parts.PartStore`) does not hold yet, groups the
rows of consecutive items into chunks, runs the chunks on ``backend`` (``labtool.execution.backends``) and
writes each finished chunk to the store at once. So a run holds in memory only the chunks in
flight, a kill loses only those, and the same call again finishes the rest.

Chunk sizes. A task costs the backend a few milliseconds (Dask: 2-3 ms, as much as an elastic run),
so one item per task would double the cost; one huge chunk per worker would leave workers idle at
the end and lose much on a kill. The first chunks are small probes (``PROBE_ITEMS`` items); every
result reports the time of each of its items, and from their median (the first item of a cold
worker, which loads and compiles the code, is not the work's cost) the next chunks are sized to
take ``target_task_s`` each, never more than the remaining items over ``2 x workers`` (guided
self-scheduling: the last chunks shrink so that the workers finish together), nor less than
``MIN_TASK_S`` of work (a task's own cost would then dominate: the workers finish within that).

Before most of the work runs, ``on_estimate(cost_s, n_items_left, workers)`` is called once with
the measured per-item cost (it may refuse by raising); no part is written before it returns.
"""
from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Sequence

import numpy as np

from labtool.common.errors import interrupt_cause
from labtool.common.files import check_interrupted
from labtool.execution.backends import InProcess, LocalProcesses, OnDemand, TaskFailed
from labtool.execution.parts import DiskFull, PartStore

PROBE_ITEMS = 4          # items in each first chunk, before any cost is known
TARGET_TASK_S = 1.0      # wanted duration of a chunk (s): task overhead << 1 %, a kill loses ~1 s per worker
MAX_CHUNK = 20_000       # items per chunk at most (a part's rows in memory)
MIN_TASK_S = 0.05         # the shrinking last chunks stop at this much work (s): a task's round trip costs
                          # 5-10 ms on Dask, and 1-item chunks made the last 2 % of a 4096-run design take 10 %
POOL_WORTH_S = 3.0       # auto: below this much work (s) the worker processes' start-up is not worth it


class Chunk:
    """A task: ``fn`` over ``items[start:stop]``; returns :class:`ChunkResult`. Picklable when
    ``fn`` and ``items`` are (a top-level function or a bound method of a picklable object, a range)."""

    def __init__(self, fn: Callable, items: Sequence, start: int, stop: int):
        self.fn, self.items, self.start, self.stop = fn, items, start, stop

    def __call__(self) -> "ChunkResult":
        rows, times = [], np.empty(self.stop - self.start)
        for k, i in enumerate(range(self.start, self.stop)):
            t0 = time.perf_counter()
            try:
                rows.append(self.fn(self.items[i]))
            except Exception as exc:  # noqa: BLE001 - a failing item must not lose its chunk
                stop = interrupt_cause(exc)
                if stop is not None:      # a signal in compiled code: the run was stopped, not failed
                    raise stop from None
                rows.append({"error": f"{type(exc).__name__}: {exc}"})
            times[k] = time.perf_counter() - t0
        return ChunkResult(self.start, self.stop, rows, times, os.getpid())


class ChunkResult:
    """A finished chunk: its items' rows (dicts, ``fn``'s return values), their times (s), the pid."""

    def __init__(self, start, stop, rows, item_s, pid):
        self.start, self.stop, self.rows, self.item_s, self.pid = start, stop, rows, item_s, pid


class Cost:
    """Running estimate of the cost of one item (s) from the chunks' item times."""

    def __init__(self):
        self.weighted, self.n = 0.0, 0
        self.seen_pids: set = set()

    def add(self, res: ChunkResult) -> None:
        t = res.item_s
        if res.pid not in self.seen_pids and t.size > 1:
            t = t[1:]                 # a worker's first item loads and compiles the code
        self.seen_pids.add(res.pid)
        if t.size:
            self.weighted += float(np.median(t)) * t.size
            self.n += t.size

    @property
    def per_item(self) -> float | None:
        return self.weighted / self.n if self.n else None


def plan(ranges: list[tuple[int, int]], cost: Cost, workers: int, target_task_s: float,
         chunk_items: int | None):
    """Yield (start, stop) chunks over ``ranges`` ([start, stop) of items still to do), each sized
    when it is asked for (so later chunks use the cost measured on the earlier ones)."""
    left = sum(b - a for a, b in ranges)
    for a, b in ranges:
        pos = a
        while pos < b:
            if chunk_items:
                size = chunk_items
            elif cost.per_item is None:
                size = PROBE_ITEMS
            else:
                per = max(cost.per_item, 1e-6)
                size = max(1, min(MAX_CHUNK, round(target_task_s / per),
                                  max(math.ceil(left / (2 * workers)), round(MIN_TASK_S / per))))
            size = min(size, b - pos)
            yield pos, pos + size
            pos += size
            left -= size


class Outcome:
    """What a map_chunked call did: items done before (resumed) and now, failures, timing."""

    def __init__(self, n_items, resumed, where):
        self.n_items, self.resumed, self.where = n_items, resumed, where
        self.done_now = 0
        self.failed_chunks: list[tuple[int, int, str]] = []
        self.cost_s: float | None = None
        self.wall_s = 0.0


def map_chunked(fn: Callable, items: Sequence, store: PartStore, backend=None, *,
                chunk_items: int | None = None, target_task_s: float = TARGET_TASK_S,
                on_estimate: Callable | None = None, progress: Callable | None = None,
                auto_workers: int | None = None, unit: str = "items") -> Outcome:
    """Compute ``fn(item)`` for every item not yet in ``store``; see the module docstring.

    backend       an ``labtool.execution.backends`` backend; None = decide from the measured cost: this
                  process for work under POOL_WORTH_S, else ``auto_workers`` (default: the cores)
                  local processes; an ``OnDemand`` (a Dask scheduler): the same, its backend made
                  for work over its ``worth_s`` (``Outcome.where`` says which ran, and why)
    chunk_items   items per chunk (None: sized from the measured cost)
    progress      callable(done_items, total_items) after every chunk
    """
    t_start = time.perf_counter()
    n = len(items)
    todo = store.missing(n)
    resumed = n - sum(b - a for a, b in todo)
    cost = Cost()
    demand = backend if isinstance(backend, OnDemand) else None
    auto = backend is None or demand is not None
    active = InProcess() if auto else backend
    out = Outcome(n, resumed, active.where)
    state = {"accepted": on_estimate is None, "buffer": [], "done": resumed, "decided": not auto}
    if progress:
        progress(resumed, n)

    def accept() -> None:
        if not state["accepted"]:
            left = n - state["done"] - sum(r.stop - r.start for r in state["buffer"])
            on_estimate(cost.per_item, left + sum(r.stop - r.start for r in state["buffer"]),
                        _workers_for(auto, active, auto_workers, cost, left))
            state["accepted"] = True
        for r in state["buffer"]:
            write(r)
        state["buffer"].clear()

    def write(r: ChunkResult) -> None:
        try:
            store.write(r.start, r.stop, r.rows)
        except DiskFull as exc:
            kept = state["done"]
            raise DiskFull(f"disk full ({exc}): {kept} of {n} {unit} are finished and kept in "
                           f"{store.folder}; free space and rerun the same command to resume") from None
        state["done"] += r.stop - r.start
        out.done_now += r.stop - r.start
        if progress:
            progress(state["done"], n)
        check_interrupted()          # a stop signal whose exception Python dropped ends the run here

    def on_result(task: Chunk, res) -> bool | None:
        if isinstance(res, TaskFailed):
            out.failed_chunks.append((task.start, task.stop, res.message))
            return None
        cost.add(res)
        if not state["accepted"]:
            state["buffer"].append(res)
            if cost.per_item is not None:
                accept()
        else:
            write(res)
        if auto and not state["decided"] and cost.per_item is not None:
            return False          # probe done in this process: choose the backend for the rest
        return None

    try:
        workers = active.workers
        tasks = (Chunk(fn, items, a, b) for a, b in plan(todo, cost, workers, target_task_s, chunk_items))
        active.run(tasks, on_result)
        if auto:
            state["decided"] = True
            todo = store.missing(n)
            left = sum(b - a for a, b in todo)
            if left:
                if demand is not None:
                    active, out.where = _on_demand(demand, cost, left, n - left - resumed, unit)
                else:
                    nw = _workers_for(True, active, auto_workers, cost, left)
                    if nw > 1:
                        active = LocalProcesses(nw)
                        out.where = f"{active.where} (after {n - left - resumed} items in this process)"
                tasks = (Chunk(fn, items, a, b) for a, b in plan(todo, cost, active.workers, target_task_s, chunk_items))
                active.run(tasks, on_result)
        if state["buffer"]:
            accept()
        if demand is not None and isinstance(active, InProcess):
            out.where = _stayed(demand, cost, n - resumed, unit)
    except KeyboardInterrupt as exc:    # Ctrl-C, SIGTERM, SIGHUP: the command ends 128 + signal (labtool.cli)
        if state["done"]:
            exc.add_note(f"{state['done']} of {n} {unit} are finished and kept in {store.folder}; "
                         "the same command resumes")
        raise
    finally:
        active.close()
    out.cost_s = cost.per_item
    out.wall_s = time.perf_counter() - t_start
    return out


def _on_demand(demand: OnDemand, cost: Cost, left: int, done_here: int, unit: str):
    """(backend, where) for the ``left`` items after the probe: ``demand``'s backend when their
    measured work is over its ``worth_s``, else this process (``_stayed`` says why, at the end)."""
    if (cost.per_item or 0.0) * left > demand.worth_s:
        active = demand.make()
        return active, f"{active.where} (after {done_here} {unit} in this process)"
    return InProcess(), None


def _stayed(demand: OnDemand, cost: Cost, n_here: int, unit: str) -> str:
    """Why the ``n_here`` items ran in this process, not on ``demand``'s backend."""
    per = cost.per_item or 0.0
    return (f"in-process, not {demand.name}: {n_here} {unit} x {per * 1e3:.3g} ms measured = about "
            f"{format_duration(per * n_here)} of work, under the {demand.worth_s:g} s a cluster needs to pay for its start")


def _workers_for(auto: bool, active, auto_workers, cost: Cost, left: int) -> int:
    if not auto:
        return active.workers
    cores = auto_workers or os.cpu_count() or 1
    work = (cost.per_item or 0.0) * left
    return cores if cores > 1 and work > POOL_WORTH_S else 1


def estimate_text(cost_s: float, n_items: int, workers: int, what: str = "runs") -> str:
    """'1000000 runs x 2.4 ms / 2 workers = about 20 min'."""
    total = cost_s * n_items / max(workers, 1)
    return (f"{n_items} {what} x {cost_s * 1e3:.3g} ms (measured) / {workers} worker{'s' if workers > 1 else ''}"
            f" = about {format_duration(total)}")


def format_duration(s: float) -> str:
    if not math.isfinite(s):
        return "?"
    if s < 60:
        return f"{s:.0f} s" if s >= 10 else f"{s:.1f} s"
    if s < 3600:
        return f"{s / 60:.0f} min"
    if s < 86400 * 2:
        return f"{s / 3600:.1f} h"
    return f"{s / 86400:.1f} days"

