"""What a second busy core costs a run on this machine (the Dask goal).

Two Dask workers on a 2-core machine can give at most 2 / (1 + c) times one worker's throughput,
c being how much slower a run gets while the other core computes too. This script measures c for
two kinds of work, each pinned to core 0, first alone and then with a copy of itself pinned to
core 1 (the same work, started together, timed over the same window):

* ``arith``: a compiled loop of scalar floating-point arithmetic on a few registers (no memory
  traffic): what the cores themselves do when both run (frequency, the hypervisor's scheduling);
* ``stream``: a compiled sum over a 64 MB array, memory traffic only (the shared last-level cache
  and memory bandwidth);
* ``elastic``: ``indicators(scene, "elastic")`` on Table 1 run 1 in a loop, what each Dask worker
  runs in ``doe run``.

Run: ``.venv/bin/python benchmarks/core_contention.py [--seconds 6]``. Prints each kind's time per
call alone and beside its twin, and the ratio; no file is written.
"""
from __future__ import annotations

import argparse
import os
import pathlib
import statistics
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _arith_kernel():
    import numba as nb

    @nb.njit(cache=False)
    def spin(n):
        a, b, c = 1.0, 0.5, 0.25
        for _ in range(n):
            a = a * 0.999999 + b
            b = b * 0.999998 + c
            c = c * 0.999997 + a * 1e-9
        return a + b + c
    spin(10)
    return lambda: spin(200_000)


def _stream_kernel():
    import numba as nb
    import numpy as np

    @nb.njit(cache=False, fastmath=True)      # vectorised: bandwidth-bound, not add-latency-bound
    def total(a):
        acc = 0.0
        for i in range(a.size):
            acc += a[i]
        return acc
    data = np.ones(8 * 1024 * 1024)
    total(data)
    return lambda: total(data)


def _elastic_call():
    sys.path.insert(0, str(ROOT))
    from benchmarks.work_precision import scenes
    from labtool.models.dynamics.simulate import indicators
    scene = scenes({1})[0][1]
    for _ in range(20):
        indicators(scene, "elastic")
    return lambda: indicators(scene, "elastic")


def worker(kind: str, cpu: int, start_at: float, seconds: float) -> None:
    """Pinned to ``cpu``, warm, then calls in a loop from ``start_at`` (time.time()) for ``seconds``;
    prints the median time per call (s)."""
    os.sched_setaffinity(0, {cpu})
    call = {"arith": _arith_kernel, "stream": _stream_kernel, "elastic": _elastic_call}[kind]()
    while time.time() < start_at:
        time.sleep(0.001)
    times = []
    end = start_at + seconds
    while time.time() < end:
        t0 = time.perf_counter()
        call()
        times.append(time.perf_counter() - t0)
    print(statistics.median(times), flush=True)


def _launch(kind, cpu, start_at, seconds):
    return subprocess.Popen([sys.executable, __file__, "--worker", kind, str(cpu), repr(start_at), repr(seconds)],
                            stdout=subprocess.PIPE, text=True, cwd=ROOT)


def measure(kind: str, seconds: float) -> tuple[float, float]:
    """(median s per call alone on core 0, the same beside a twin on core 1)."""
    alone = _launch(kind, 0, time.time() + 4.0, seconds)
    t_alone = float(alone.communicate()[0].split()[-1])
    start = time.time() + 4.0
    pair = [_launch(kind, cpu, start, seconds) for cpu in (0, 1)]
    t_pair = float(pair[0].communicate()[0].split()[-1])
    pair[1].communicate()
    return t_alone, t_pair


def main(argv=None):
    if argv is None and len(sys.argv) > 1 and sys.argv[1] == "--worker":
        worker(sys.argv[2], int(sys.argv[3]), float(sys.argv[4]), float(sys.argv[5]))
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=6.0)
    args = ap.parse_args(argv)
    if len(os.sched_getaffinity(0)) < 2:
        print("needs two cores")
        return
    for kind in ("arith", "stream", "elastic"):
        alone, pair = measure(kind, args.seconds)
        print(f"{kind:8s} alone {alone * 1e6:8.1f} us/call  beside its twin {pair * 1e6:8.1f} us/call  "
              f"slower by {100 * (pair / alone - 1):5.1f} %  -> 2 workers at most {2 * alone / pair:.2f}x one",
              flush=True)


if __name__ == "__main__":
    main()
