"""Speed of the simulated stand + recorder: --fast vs real time, and a --realtime run's overruns.

Run: ``.venv/bin/python benchmarks/bench_acquire.py [--fast-seconds 60] [--realtime-seconds 60]``.
Prints ratios (data seconds per wall second), no assertion (speed is measured here, never in tests).
Goal: --fast >= 50x real time; --realtime 60 s with zero overruns on this 2-core machine.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path
from labtool.common.units import RPM

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--fast-seconds", type=float, default=60.0, help="seconds of data for the --fast runs")
    ap.add_argument("--realtime-seconds", type=float, default=0.0, help="seconds of a --realtime run (0: skip)")
    ap.add_argument("--rpm", type=float, default=180.0)
    args = ap.parse_args()

    from labtool.acquisition import session
    from labtool.acquisition import signal_chain as sc
    from labtool.acquisition.sim_stand import SimStand

    with tempfile.TemporaryDirectory() as tmp:
        # generation alone (no file), then the whole chain to HDF5
        dev = SimStand(sc.StandScene(cam_speed=args.rpm * RPM), seed=1, duration_s=args.fast_seconds, realtime=False)
        dev.configure(10000)
        dev.start()
        t0 = time.perf_counter()
        while dev.read_block() is not None:
            pass
        gen = time.perf_counter() - t0
        print(f"stand generation only : {args.fast_seconds:g} s of data in {gen:.2f} s wall -> {args.fast_seconds / gen:6.1f}x real time")
        for rpm in (180.0, 500.0):
            dev = SimStand(sc.StandScene(cam_speed=rpm * RPM), seed=1, duration_s=args.fast_seconds, realtime=False)
            res = session.run(dev, Path(tmp) / f"fast{rpm:g}.h5", 10000, args.fast_seconds)
            size = os.path.getsize(Path(tmp) / f"fast{rpm:g}.h5") / 1e6
            print(f"--fast {rpm:3g} rpm to HDF5: {args.fast_seconds:g} s of data in {res.wall_s:.2f} s wall -> "
                  f"{args.fast_seconds / res.wall_s:6.1f}x real time (goal >= 50x), {size:.1f} MB, overruns {res.overruns}")
        if args.realtime_seconds > 0:
            dev = SimStand(sc.StandScene(cam_speed=args.rpm * RPM), seed=1, duration_s=args.realtime_seconds, realtime=True)
            cpu0 = time.process_time()
            res = session.run(dev, Path(tmp) / "rt.h5", 10000, args.realtime_seconds)
            cpu = time.process_time() - cpu0
            print(f"--realtime {args.realtime_seconds:g} s: wall {res.wall_s:.2f} s (ratio {args.realtime_seconds / res.wall_s:.3f}), "
                  f"overruns {res.overruns}, gaps {res.gaps}, samples {res.n_samples}, CPU {100 * cpu / res.wall_s:.1f} % of one core")


if __name__ == "__main__":
    main()
