"""Benchmark of ``labtool fit``: a fit of two parameters at ``--accuracy fast`` and ``standard`` on one
core, beside the unit it is made of, one model run of the same scene through the report's path
(labtool.reports.pipeline.run_simulation: the simulation, resampled, filtered and conditioned like the
measurement) measured in the same run. The goals: the whole fit under 60 s, under 10 s at
fast. Prints, no asserts.

    .venv/bin/python benchmarks/bench_fit.py [--quick]

The recording: the simulated stand with the rigid model's truth (j = 0.2 mm, k = 0.5, 180 rpm, 4 s,
``labtool acquire --fast`` then ``labtool process``), and with the elastic truth at 500 rpm
(j = 0.128 mm, 40 s/m). The process is pinned to one core and BLAS to one thread; the fit is timed
in-process after a warm-up (imports and numba's cache loaded once, as a lab's second fit would
be), and once end to end through the CLI. ``--quick``: the rigid case only.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(var, "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("MPLBACKEND", "Agg")
LABTOOL = str(ROOT / ".venv" / "bin" / "labtool")

CASES = {
    "rigid": (["--truth", "rigid", "--backlash-mm", "0.2", "--restitution", "0.5", "--rpm", "180"],
              "backlash,restitution"),
    "elastic": (["--truth", "elastic", "--backlash-mm", "0.128", "--contact-damping", "40", "--rpm", "500"],
                "backlash,contact_damping"),
}


def record(folder: Path, model: str) -> Path:
    h5, nc = folder / f"{model}.h5", folder / f"{model}.nc"
    opts, _ = CASES[model]
    for args in (["acquire", "--device", "sim", "--fast", "--duration", "4", *opts, "-o", str(h5)],
                 ["process", str(h5), "-o", str(nc)]):
        subprocess.run([LABTOOL, *args], check=True, capture_output=True)
    return nc


def one_run_s(measured: Path, model: str, preset: str, revolutions: int, reps: int = 5) -> float:
    """Median wall time of one model run through the report's path at the fit's scene."""
    from labtool.identification.objective import load_target
    from labtool.reports import pipeline

    target = load_target(measured)
    op = {**target.op, "backlash_mm": 0.2, "restitution": 0.5, "contact_damping": 40.0}
    times = []
    for _ in range(reps + 1):
        t = time.perf_counter()
        pipeline.run_simulation(op, model, "const", preset, revolutions, target.cond, target.time_filter)
        times.append(time.perf_counter() - t)
    return sorted(times[1:])[len(times[1:]) // 2]


def bench(measured: Path, model: str, free: str) -> None:
    from labtool.identification.fit import FitRequest, identify

    identify(FitRequest(measured, model, free.split(",")[0], accuracy="fast", max_runs=8))    # warm-up
    unit = {p: one_run_s(measured, model, p, 3) for p in ("fast", "standard")}
    print(f"{model}: one model run (3 revolutions, the report's path): fast {unit['fast'] * 1e3:.0f} ms, "
          f"standard {unit['standard'] * 1e3:.0f} ms")
    for accuracy in ("fast", "standard"):
        cpu, t = time.process_time(), time.perf_counter()
        s = identify(FitRequest(measured, model, free, accuracy=accuracy)).summary
        wall, cpu = time.perf_counter() - t, time.process_time() - cpu
        goal = 10.0 if accuracy == "fast" else 60.0
        print(f"  fit {free} --accuracy {accuracy}: {wall:.1f} s wall, {cpu:.1f} s CPU (goal {goal:g} s), "
              f"{s['evaluations']} model runs ({s['model_time_s']:.1f} s, {100 * s['model_time_s'] / wall:.0f} % of "
              f"the wall), = {wall / unit['fast']:.0f} fast runs' time; "
              + ", ".join(f"{k} {p['value']:.4g} [{p['ci95'][0]:.4g}, {p['ci95'][1]:.4g}]"
                          for k, p in s["parameters"].items()))
    t = time.perf_counter()
    subprocess.run([LABTOOL, "fit", str(measured), "--model", model, "--free", free, "--accuracy", "fast",
                    "--json"], check=True, capture_output=True)
    print(f"  labtool fit --accuracy fast end to end (imports, reading, the fit, JSON): {time.perf_counter() - t:.1f} s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the rigid case only")
    args = ap.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    with tempfile.TemporaryDirectory() as tmp:
        for model in ("rigid",) if args.quick else tuple(CASES):
            bench(record(Path(tmp), model), model, CASES[model][1])


if __name__ == "__main__":
    main()
