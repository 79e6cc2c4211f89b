"""Sweeps at scale: per-run cost of ``labtool doe run`` and its Dask scaling.

On a 4096-run design (Fu 16 levels x n1 16 x j 4 x Jt 4, sine law, omega1 variable, standard), or
with ``--design 100000`` on 10^5 runs (Fu 25 x n1 25 x j 10 x Jt 16), where a cluster pays:

* ``direct``: ``labtool.models.dynamics.simulate.indicators(scene, model)`` (the Dataset-free path that
  ``doe run`` calls) in a plain loop in this process (warm), per run: the floor that the
  runner's overhead is measured against; ``direct_dataset``: ``simulate(scene, model)`` on the same
  runs, interleaved (what a run cost before the indicator path);
* ``doe run --workers 1``: the whole command (a new process: imports, the runs, the CSV and
  NetCDF) divided by the number of runs, and the runner's own per-run cost it prints;
* Dask: ``doe run --scheduler`` against a LocalCluster of 1 and of 2 worker processes (one thread
  each, started and warmed before timing), interleaved repeats, medians; the ratio of their
  throughputs, for the whole command and for the runs alone (the runner's own wall, which leaves
  out the command's fixed cost: imports, the cluster connection, the output files). The Dask runs
  pass ``--scheduler-always``: without it a design whose measured work is under 10 s runs in
  the command's own process (labtool.execution.backends.OnDemand), which ``small`` shows: a
  1,024-run design given ``--scheduler``, its time and where it ran, as the command says.

Run: ``.venv/bin/python benchmarks/bench_doe.py [--models elastic,rigid] [--design 4096|100000] [--repeats 2]
[--no-dask] [--no-in-process]``. Writes ``benchmarks/results/doe_scaling.json`` (with --design 100000:
``doe_scaling_100000.json``). No assertion (speed is measured here, never in tests).
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import re
import statistics
import subprocess
import sys
import tempfile
import time
import warnings

ROOT = pathlib.Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
LABTOOL = [sys.executable, "-m", "labtool.cli"]
FACTORS_4096 = """factor,symbol,unit,level_1,level_2,level_3,level_4,level_5,level_6,level_7,level_8,level_9,level_10,level_11,level_12,level_13,level_14,level_15,level_16
A,Fu,N,0,5,10,15,20,25,30,35,40,45,50,55,60,65,70,75
B,n1,rpm,150,160,170,180,190,200,210,220,230,240,250,260,270,280,290,300
C,j,mm,0.016,0.05,0.09,0.128,,,,,,,,,,,,
D,Jt,factor_of_nominal,1,2,3,4,,,,,,,,,,,,
"""


def factors_100000() -> str:
    """Fu 25 levels x n1 25 x j 10 x Jt 16 = 10^5 runs, within Table 1's ranges."""
    levels = {"A,Fu,N": [3.0 * k for k in range(25)], "B,n1,rpm": [150.0 + 6.25 * k for k in range(25)],
              "C,j,mm": [0.016 + 0.0124 * k for k in range(10)], "D,Jt,factor_of_nominal": [1.0 + 0.2 * k for k in range(16)]}
    head = "factor,symbol,unit," + ",".join(f"level_{k + 1}" for k in range(25))
    rows = [name + "," + ",".join(f"{v:g}" for v in vals) + "," * (25 - len(vals)) for name, vals in levels.items()]
    return head + "\n" + "\n".join(rows) + "\n"


def runner_seconds(line: str) -> float:
    """The runner's own wall (s) in ``doe run``'s summary line ("(where, 2.93 s, ...)"): from the
    first chunk sent to the last result, without the command's imports, cluster connection and
    output files."""
    m = re.search(r", ([0-9.]+) s[,)]", line)
    return float(m.group(1)) if m else float("nan")


def doe_run(args: list[str], out: pathlib.Path) -> tuple[float, str]:
    for p in (out, out.with_suffix(".nc")):
        p.unlink(missing_ok=True)
    t0 = time.perf_counter()
    proc = subprocess.run(LABTOOL + ["doe", "run", *args, "-o", str(out)], capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"doe run failed: {proc.stderr.strip()}")
    return wall, proc.stdout.strip().splitlines()[-1 if "note:" not in proc.stdout else -2]


def direct_per_run(model: str, factors_csv: pathlib.Path, sample: int) -> tuple[float, float]:
    """(indicator path, dataset path) seconds per run over a random sample of the design's runs,
    interleaved run by run."""
    from labtool.models.study.paper import paper_scene
    from labtool.models.dynamics.simulate import indicators, simulate
    from labtool.models.study.doe import Design, read_factors
    design = Design(tuple(read_factors(factors_csv)), paper_scene(), model)
    # a random sample: every 16th run would always hit the same levels of the fastest factors
    import numpy as np
    idx = sorted(np.random.default_rng(0).choice(len(design), size=min(sample, len(design)), replace=False))
    simulate(design.scene(0), model)                     # compile / load the cache, build the tables
    indicators(design.scene(0), model)
    lean = full = 0.0
    for i in idx:
        scene = design.scene(int(i))
        t0 = time.perf_counter()
        indicators(scene, model)
        t1 = time.perf_counter()
        simulate(scene, model)
        lean, full = lean + t1 - t0, full + time.perf_counter() - t1
    return lean / len(idx), full / len(idx)


def _warm(model: str) -> int:
    """Load in a worker what its runs will use: the model's compiled code, of the Dataset path and of
    the indicator path that ``doe run`` calls."""
    from labtool.models.study.paper import paper_scene
    from labtool.models.dynamics.simulate import indicators, simulate
    simulate(paper_scene(), model)
    indicators(paper_scene(), model)
    return os.getpid()


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", default="elastic,rigid")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--sample", type=int, default=256, help="runs of the direct loop")
    ap.add_argument("--no-dask", action="store_true", help="only the direct loop and doe run --workers 1")
    ap.add_argument("--design", type=int, choices=(4096, 100000), default=4096, help="runs of the design")
    ap.add_argument("--no-in-process", action="store_true", help="skip doe run --workers 1 (the Dask runs only)")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)
    from distributed import Client, LocalCluster

    tmp = pathlib.Path(tempfile.mkdtemp(prefix="bench_doe_"))
    factors = tmp / f"factors_{args.design}.csv"
    factors.write_text(FACTORS_4096 if args.design == 4096 else factors_100000())
    n_runs = args.design
    out: dict = {"runs": n_runs, "machine": {"nproc": os.cpu_count(), "loadavg_start": os.getloadavg()},
                 "models": {}}
    models = args.models.split(",")
    # the direct loop first, before any cluster's processes share the machine with it
    directs = {model: direct_per_run(model, factors, args.sample) for model in models}
    clusters = {} if args.no_dask else {
        n: LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None)
        for n in (1, 2)}
    try:
        for model in models:
            for c in clusters.values():
                with Client(c.scheduler_address) as client:
                    client.run(_warm, model)
            direct, direct_dataset = directs[model]
            rec = {"direct_ms_per_run": direct * 1e3, "direct_dataset_ms_per_run": direct_dataset * 1e3,
                   "in_process": [], "dask_1": [], "dask_2": [],
                   "runner_in_process": [], "runner_dask_1": [], "runner_dask_2": []}
            base = ["--model", model, "--factors", str(factors), "--yes"]
            if clusters:                 # a small design given a scheduler: where it runs, and why
                small = tmp / "small.csv"
                small.write_text("factor,symbol,unit,level_1,level_2,level_3,level_4,level_5,level_6,level_7,level_8\n"
                                 "A,Fu,N,0,10,20,30,40,50,60,70\nB,n1,rpm,150,170,190,210,230,250,270,300\n"
                                 "C,j,mm,0.016,0.05,0.09,0.128,,,,\nD,Jt,factor_of_nominal,1,2,3,4,,,,\n")
                wall, line = doe_run(["--model", model, "--factors", str(small), "--scheduler",
                                      clusters[2].scheduler_address], tmp / "s.csv")
                rec["small_1024_with_scheduler"] = {"wall_s": wall, "summary": line}
                print(f"{model} 1024 runs, --scheduler given: {wall:.2f} s | {line}", flush=True)
            for rep in range(args.repeats):
                if not args.no_in_process:
                    wall, line = doe_run(base + ["--workers", "1"], tmp / "w1.csv")
                    rec["in_process"].append(wall)
                    rec["runner_in_process"].append(runner_seconds(line))
                    print(f"{model} in-process     {wall:7.2f} s  {wall / n_runs * 1e3:6.2f} ms/run  | {line}", flush=True)
                for n in clusters:
                    wall, line = doe_run(base + ["--scheduler", clusters[n].scheduler_address, "--scheduler-always"],
                                         tmp / f"d{n}.csv")
                    rec[f"dask_{n}"].append(wall)
                    rec[f"runner_dask_{n}"].append(runner_seconds(line))
                    print(f"{model} Dask {n} worker(s) {wall:7.2f} s  {wall / n_runs * 1e3:6.2f} ms/run  | {line}",
                          flush=True)
            med = {k: statistics.median(rec[k]) for k in ("in_process", "dask_1", "dask_2", "runner_in_process",
                                                           "runner_dask_1", "runner_dask_2") if rec[k]}
            if "in_process" in med:
                rec.update(doe_run_ms_per_run=med["in_process"] / n_runs * 1e3,
                           overhead_ms_per_run=(med["in_process"] / n_runs - direct) * 1e3)
            if clusters:
                rec.update(dask_1_ms_per_run=med["dask_1"] / n_runs * 1e3, dask_2_ms_per_run=med["dask_2"] / n_runs * 1e3,
                           dask_2_over_1_throughput=med["dask_1"] / med["dask_2"],
                           # the runs alone, as the runner times them (the command's fixed cost left out)
                           dask_2_over_1_runner_throughput=med["runner_dask_1"] / med["runner_dask_2"])
            out["models"][model] = rec
            print(f"{model}: direct {direct * 1e3:.2f} ms/run (dataset path {direct_dataset * 1e3:.2f})"
                  + (f", whole doe run {rec['doe_run_ms_per_run']:.2f} ms/run (overhead {rec['overhead_ms_per_run']:+.2f} ms)"
                     if "doe_run_ms_per_run" in rec else "")
                  + (f", Dask 2 workers / 1 worker throughput {rec['dask_2_over_1_throughput']:.2f}x (the runner's "
                     f"own {rec['dask_2_over_1_runner_throughput']:.2f}x)" if clusters else ""),
                  flush=True)
    finally:
        for c in clusters.values():
            c.close()
    out["machine"]["loadavg_end"] = os.getloadavg()
    RESULTS.mkdir(exist_ok=True)
    name = "doe_scaling.json" if n_runs == 4096 else f"doe_scaling_{n_runs}.json"
    (RESULTS / name).write_text(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()
