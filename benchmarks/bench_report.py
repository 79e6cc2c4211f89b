"""Benchmark of the report: one ISO/TS 18571 evaluation per grid size, and the whole report
(build, figures, HTML) on a synthetic 180 rpm measurement, per model set. Prints, no asserts.

    .venv/bin/python benchmarks/bench_report.py [--demo]

``--demo`` also times ``labtool demo`` end to end (must stay under 2 minutes on the lab machine).
"""
from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("MPLBACKEND", "Agg")


def bench_metrics() -> None:
    import numpy as np

    from reports import metrics
    rng = np.random.default_rng(0)
    for n in (360, 720, 1440, 2880):
        x = np.linspace(0, 2 * math.pi, n, endpoint=False)
        m = np.sin(x) * np.exp(-x)
        c = 1.1 * np.sin(x - 0.05) * np.exp(-x) + 0.01 * rng.standard_normal(n)
        reps = 5
        t = time.perf_counter()
        for _ in range(reps):
            metrics.compare(m, c, x)
        print(f"metrics.compare, {n:5d} points: {(time.perf_counter() - t) / reps * 1e3:7.1f} ms")


def bench_report() -> None:
    from common.files import write_netcdf
    from reports.figures import all_figures
    from reports.html import render_html
    from reports.pipeline import build_report
    from reports.synthetic import synthetic_measured

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "m.nc"
        write_netcdf(synthetic_measured(noise=0.02, revolutions=6.3), path)
        for models, acc in ((("kinematic",), "standard"), (("rigid", "elastic"), "fast"), (("rigid", "elastic"), "standard")):
            t = time.perf_counter()
            rep = build_report(path, models, ("const", "var"), accuracy=acc, revolutions=1.0)
            t_build = time.perf_counter() - t
            sims = sum(r.wall_s for r in rep.sims)
            t = time.perf_counter()
            html = render_html(rep, all_figures(rep))
            t_html = time.perf_counter() - t
            print(f"report {'+'.join(models):15s} {acc:8s}: build {t_build:5.1f} s (simulations {sims:5.1f} s, "
                  f"{len(rep.cycles.revolutions)} revolutions), figures + HTML {t_html:4.1f} s, {len(html) / 1e6:.2f} MB")


def bench_demo() -> None:
    with tempfile.TemporaryDirectory() as d:
        t = time.perf_counter()
        subprocess.run([str(ROOT / ".venv" / "bin" / "labtool"), "demo", "-o", d], check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        print(f"labtool demo: {time.perf_counter() - t:.1f} s wall")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--demo", action="store_true")
    a = ap.parse_args()
    bench_metrics()
    bench_report()
    if a.demo:
        bench_demo()
