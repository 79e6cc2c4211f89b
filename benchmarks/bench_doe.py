"""Wall time of ``run_design`` for the 16 runs of Table 1: in-process, local processes, Dask.

Run: ``.venv/bin/python benchmarks/bench_doe.py [--model kinematic|rigid|elastic] [--accuracy fast]``.
Prints one line per executor; no assertion (speed is measured here, never in tests).
"""
from __future__ import annotations

import argparse
import os
import time
import warnings


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--model", default="kinematic")
    ap.add_argument("--accuracy", default="fast")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    args = ap.parse_args()
    warnings.simplefilter("ignore", RuntimeWarning)

    from distributed import LocalCluster

    from models.study.doe import run_design, table1_factors
    from models.dynamics.scene import Scene

    factors, base = table1_factors(), Scene(accuracy=args.accuracy)
    runs = [("in-process", dict(workers=1)), (f"{args.workers} processes", dict(workers=args.workers))]
    for name, kw in runs:
        t0 = time.perf_counter()
        res = run_design(factors, base, args.model, **kw)
        print(f"{args.model:9s} {name:22s} {time.perf_counter() - t0:7.2f} s wall, "
              f"sum of run times {res.frame.wall_s.sum():7.2f} s, failures {len(res.failures)}")
    with LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as cluster:
        t0 = time.perf_counter()
        res = run_design(factors, base, args.model, scheduler=cluster.scheduler_address)
        print(f"{args.model:9s} {'Dask ' + str(args.workers) + ' workers':22s} {time.perf_counter() - t0:7.2f} s wall, "
              f"sum of run times {res.frame.wall_s.sum():7.2f} s, failures {len(res.failures)}")


if __name__ == "__main__":
    main()
