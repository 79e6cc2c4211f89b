"""Where chunks run: this process, local worker processes, or a Dask distributed cluster.

Every backend has the same narrow interface: ``workers`` (how many chunks run at once), ``warm``
(True once the workers have loaded the code: measured costs are then the work's own) and
``run(tasks, on_result, window)``: call each task (a picklable zero-argument callable), at most
``window`` of them queued at a time, and ``on_result(task, result)`` in the calling thread as each
finishes (so results are written by one process, in the order they complete). A task that raises
is reported as a :class:`TaskFailed` result, never lost silently; Ctrl-C and errors in
``on_result`` cancel what is still queued.
"""
from __future__ import annotations

import os
import re
import signal
import threading
import time
from collections.abc import Callable, Iterable

from labtool.common.errors import InputError


class TaskFailed:
    """The result of a task that raised (or whose worker died): ``message`` says why."""

    def __init__(self, message: str):
        self.message = message


class InProcess:
    """Chunks run one after the other in this process."""

    workers = 1
    where = "in-process"

    def run(self, tasks: Iterable[Callable], on_result, window: int = 1) -> None:
        for task in tasks:
            try:
                res = task()
            except Exception as exc:   # noqa: BLE001 - reported per task, the others go on
                res = TaskFailed(f"{type(exc).__name__}: {exc}")
            if on_result(task, res) is False:
                return

    def close(self) -> None:
        pass


def die_with_parent(parent_pid: int) -> None:
    """In a worker process: end when ``parent_pid`` ends, even by SIGKILL (which leaves the pool no
    chance to stop its workers: they would go on computing chunks nobody writes). Linux: the
    kernel's parent-death signal; elsewhere a thread that watches the parent's pid."""
    try:
        import ctypes
        libc = ctypes.CDLL(None, use_errno=True)
        PR_SET_PDEATHSIG = 1
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):
        pass
    if os.getppid() != parent_pid:      # the parent died before the signal was armed
        os._exit(1)

    def watch():
        while True:
            time.sleep(1.0)
            if os.getppid() != parent_pid:
                os._exit(1)
    threading.Thread(target=watch, daemon=True).start()


class LocalProcesses:
    """Chunks run on ``n`` local worker processes (spawned: a forked child could inherit a lock
    held by another thread of this one)."""

    def __init__(self, n: int):
        if n < 1:
            raise InputError(f"--workers must be >= 1, got {n}")
        import concurrent.futures as cf
        import multiprocessing as mp
        self.workers = n
        self.where = f"{n} local processes"
        self._pool = cf.ProcessPoolExecutor(max_workers=n, mp_context=mp.get_context("spawn"),
                                            initializer=die_with_parent, initargs=(os.getpid(),))

    def run(self, tasks, on_result, window: int | None = None) -> None:
        import concurrent.futures as cf
        from concurrent.futures.process import BrokenProcessPool
        window = window or 2 * self.workers
        it = iter(tasks)
        pending = {}
        try:
            while True:
                while len(pending) < window:
                    task = next(it, None)
                    if task is None:
                        break
                    pending[self._pool.submit(task)] = task
                if not pending:
                    return
                done, _ = cf.wait(pending, return_when=cf.FIRST_COMPLETED)
                for fut in done:
                    task = pending.pop(fut)
                    try:
                        res = fut.result()
                    except BrokenProcessPool as exc:
                        raise InputError(f"a worker process died ({exc}); the finished chunks are kept, "
                                         "rerun the same command to resume") from None
                    except Exception as exc:  # noqa: BLE001
                        res = TaskFailed(f"{type(exc).__name__}: {exc}")
                    if on_result(task, res) is False:
                        return
        finally:
            for fut in pending:
                fut.cancel()

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)


_SCHEMES = ("tcp", "tls", "ucx", "ws", "wss")
_ADDRESS_RE = re.compile(r"^(?:(?P<scheme>[a-z]+)://)?(?P<host>\[[0-9a-fA-F:]+\]|[A-Za-z0-9_.\-]+)(?::(?P<port>\d{1,5}))?/?$")


def check_scheduler_address(address: str) -> str:
    """``address`` as a Dask scheduler address (scheme://host:port), or InputError in one line.

    Checked before anything connects: the distributed client would otherwise wait for its whole
    timeout on a string that cannot be an address.
    """
    m = _ADDRESS_RE.match(address.strip())
    if m is None or (m.group("scheme") or "tcp") not in _SCHEMES:
        raise InputError(f"--scheduler {address!r} is not a Dask scheduler address; give "
                         "tcp://HOST:PORT, e.g. tcp://127.0.0.1:8786")
    scheme, port = m.group("scheme") or "tcp", m.group("port")
    if port is None or not 0 < int(port) < 65536:
        raise InputError(f"--scheduler {address!r} needs a port 1-65535, e.g. tcp://{m.group('host')}:8786")
    return f"{scheme}://{m.group('host')}:{int(port)}"


class DaskCluster:
    """Chunks run on the workers of a Dask distributed scheduler at ``address``."""

    def __init__(self, address: str, connect_timeout_s: float = 10.0):
        address = check_scheduler_address(address)
        try:
            from distributed import Client
        except ImportError:  # pragma: no cover - distributed is a dependency
            raise InputError("--scheduler needs the 'distributed' package") from None
        try:
            self._client = Client(address, timeout=connect_timeout_s, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(f"cannot reach the Dask scheduler at {address} within {connect_timeout_s:g} s "
                             f"({type(exc).__name__}); check the address and that the scheduler runs") from None
        threads = self._client.nthreads()
        self.workers = max(1, sum(threads.values()))
        self.where = f"Dask cluster at {address} ({len(threads)} workers, {self.workers} threads)"

    def run(self, tasks, on_result, window: int | None = None) -> None:
        from distributed import as_completed
        window = window or 2 * self.workers
        it = iter(tasks)
        pending = {}
        ac = as_completed(loop=self._client.loop)

        def submit() -> bool:
            task = next(it, None)
            if task is None:
                return False
            fut = self._client.submit(task, pure=False)
            pending[fut.key] = (fut, task)
            ac.add(fut)
            return True

        try:
            while len(pending) < window and submit():
                pass
            for fut in ac:
                _, task = pending.pop(fut.key)
                try:
                    res = fut.result()
                except Exception as exc:  # noqa: BLE001 - the worker died or could not import the code
                    res = TaskFailed(f"Dask worker failed: {type(exc).__name__}: {exc}")
                fut.release()
                if on_result(task, res) is False:
                    return
                while len(pending) < window and submit():
                    pass
        finally:
            if pending:   # Ctrl-C or an error: do not leave queued chunks on the cluster
                self._client.cancel([f for f, _ in pending.values()])
            ac.clear()

    def close(self) -> None:
        self._client.close()


class OnDemand:
    """A backend made only if the work is worth it: the first chunks run in this process and
    measure the cost of an item; ``labtool.execution.chunked.map_chunked`` then calls ``make()``
    when the work left is over ``worth_s`` seconds, else finishes here and says why. ``name``: what
    ``make`` would start, for that sentence."""

    def __init__(self, make: Callable, worth_s: float, name: str):
        self.make, self.worth_s, self.name = make, worth_s, name

    def close(self) -> None:
        pass                     # what ``make`` made is closed by its user (map_chunked)


# below this much work (s) a Dask cluster does not pay: the tasks' round trips, the workers' first
# task (labtool's import and its compiled code loaded, ~1 s) and the client's start cost ~1-2 s,
# which the design would have finished in (1,024 elastic runs: 1.5 s on 2 workers, 1.2 s here)
DASK_WORTH_S = 10.0


def backend_for(workers: int | None, scheduler: str | None, connect_timeout_s: float = 10.0,
                scheduler_always: bool = False):
    """The backend of ``--workers`` / ``--scheduler`` (None workers: decided later from the cost).
    A scheduler is connected to when the measured work is worth it (``OnDemand``, DASK_WORTH_S),
    or at once with ``scheduler_always``."""
    if scheduler and scheduler_always:
        return DaskCluster(scheduler, connect_timeout_s)
    if scheduler:
        address = check_scheduler_address(scheduler)
        return OnDemand(lambda: DaskCluster(address, connect_timeout_s), DASK_WORTH_S,
                        f"the Dask cluster at {address}")
    if workers is not None and workers < 1:
        raise InputError(f"--workers must be >= 1, got {workers}")
    if workers == 1:
        return InProcess()
    return LocalProcesses(workers) if workers else None
