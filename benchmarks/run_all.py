"""``make bench``: every benchmark of the repository, then the headline speed figures.

1. compile time of the numba kernels with an empty cache (a fresh NUMBA_CACHE_DIR), and the time
   to load them from that cache in a new process (cache=True: compiled once, reused by every run);
2. the 16 runs of Table 1 for both models at the ``standard`` preset on one core, after compilation
   (``table1_timing``), through ``labtool.models.dynamics.simulate.simulate``;
3. the work-precision benchmark (benchmarks/work_precision.py: CSV, PNG, JSON summary);
4. the other ``benchmarks/bench_*.py`` scripts, each in its own process.

Run: ``.venv/bin/python benchmarks/run_all.py [--quick]`` (--quick: work-precision on 2 runs only,
the other bench scripts skipped). Machine facts (nproc, lscpu) are printed first. Nothing here
asserts a speed: the figures are reported (docs/performance.md quotes them).
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
HERE = pathlib.Path(__file__).resolve().parent
RESULTS = HERE / "results"

_WARM = """
import time, warnings
warnings.simplefilter('ignore')
t0 = time.perf_counter()
from labtool.models.study.paper import paper_scene
from labtool.models.dynamics.simulate import simulate
from labtool.models.dynamics import accuracy
from labtool.common.units import RPM
t1 = time.perf_counter()
for model in ('rigid', 'elastic'):
    accuracy.run_model(paper_scene(accuracy='standard'), model)
print(t1 - t0, time.perf_counter() - t1)
"""


def machine() -> dict:
    def sh(cmd):
        try:
            return subprocess.run(cmd, shell=True, capture_output=True, text=True, timeout=20).stdout.strip()
        except Exception as exc:  # noqa: BLE001 - a fact we could not read is reported, not fatal
            return f"({exc})"
    return dict(nproc=sh("nproc"), lscpu=sh("lscpu | head -20"), load=sh("cat /proc/loadavg"),
                python=sys.version.split()[0])


def compile_times() -> dict:
    """Cold compile (empty cache dir) and warm load (same dir, new process) of both kernels,
    each including one small simulation of each model (s)."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONPATH=str(ROOT))
        out = {}
        for label in ("cold_compile", "warm_cached"):
            t0 = time.perf_counter()
            p = subprocess.run([sys.executable, "-c", _WARM], cwd=ROOT, env=env, capture_output=True, text=True)
            if p.returncode:
                raise SystemExit(p.stderr)
            imp, first = (float(x) for x in p.stdout.split())
            out[label] = dict(process_s=time.perf_counter() - t0, import_s=imp, first_runs_s=first)
        return out


def table1_timing(repeat: int = 3) -> dict:
    """Wall time of the 16 runs of Table 1 (omega1 variable) for both models at 'standard', one
    core, after compilation: best of ``repeat``; per model and total (s)."""
    try:
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    except (AttributeError, OSError):
        pass
    sys.path.insert(0, str(ROOT))
    from labtool.models.mechanism import memo
    from labtool.models.study.paper import table1_runs
    from labtool.models.study.paper import paper_scene
    from labtool.models.dynamics.simulate import simulate
    scenes = [paper_scene(cam_speed=r.n1_rpm * RPM, Fu=r.Fu_N, backlash=r.j_mm * 1e-3, jt_factor=r.Jt_factor,
                    omega1_mode="var", accuracy="standard") for r in table1_runs().itertuples()]
    for model in ("rigid", "elastic"):            # load the compiled kernels from the cache
        simulate(scenes[0], model)
    out = {}
    for model in ("rigid", "elastic"):
        best = float("inf")
        for _ in range(repeat):
            memo.clear_cache()      # the sweep computes its cam-angle table once, inside the timing
            t0 = time.perf_counter()
            for sc in scenes:
                simulate(sc, model).dataset     # the Dataset built (at its first read)
            best = min(best, time.perf_counter() - t0)
        out[model] = best
    out["total"] = out["rigid"] + out["elastic"]
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description="all benchmarks")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--models-only", action="store_true", help="skip the other bench_*.py scripts")
    args = ap.parse_args(argv)
    RESULTS.mkdir(exist_ok=True)
    report = {"machine": machine()}
    print(f"nproc {report['machine']['nproc']}, load {report['machine']['load']}\n{report['machine']['lscpu']}\n")
    report["compile"] = compile_times()
    print("numba kernels:", json.dumps(report["compile"]))
    report["table1_standard_one_core_s"] = table1_timing()
    print("Table 1, 16 runs, standard, one core (s):", json.dumps(report["table1_standard_one_core_s"]))
    wp = [sys.executable, str(HERE / "work_precision.py")]
    if args.quick:
        wp += ["--runs", "1,12", "--ladder-runs", "1"]
    t0 = time.perf_counter()
    subprocess.run(wp, cwd=ROOT, check=True)
    report["work_precision_s"] = time.perf_counter() - t0
    if not (args.quick or args.models_only):
        for script in sorted(HERE.glob("bench_*.py")):
            print(f"\n== {script.name}", flush=True)
            t0 = time.perf_counter()
            p = subprocess.run([sys.executable, str(script)], cwd=ROOT, timeout=1800)
            report[script.stem] = dict(returncode=p.returncode, wall_s=time.perf_counter() - t0)
    (RESULTS / "run_all.json").write_text(json.dumps(report, indent=1))
    print(f"\nwritten {RESULTS / 'run_all.json'}")


if __name__ == "__main__":
    main()
