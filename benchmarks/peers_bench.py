"""labtool against the strongest peer solvers on the same equations and the same accuracy measure.

Peers (``benchmarks/peers/``, written from the paper's equations, not from labtool's kernels):
numbalsoda LSODA and DOP853 (compiled, called from numba; the optional ``bench`` extra), scipy
solve_ivp with a numba right-hand side (LSODA, DOP853, Radau), and, for continuity, scipy DOP853
with labtool's pure-Python right-hand side. Each runs a tolerance ladder; labtool runs its
``standard`` preset through the public ``simulate(scene, model)``.

Accuracy: ``labtool.models.dynamics.accuracy.compare`` against ``accuracy.reference_run`` (scipy DOP853,
rtol 1e-12): omega2 (relative, at the output instants both share) and the event times; a ladder
point that loses or adds an event is not "as accurate". Cost: the whole call (scene -> omega2 and
events at the output instants) and the integration loop alone, medians of interleaved repeats
(every solver once per round, so a busy machine slows all of them alike). ``--calls N`` (N > 1)
makes each round call every solver N times in a row and times calls 2..N only: the warm state of a
sweep, where one model runs operating point after operating point (``doe run``, the
identification's scans). With one call a round (the default) every call is cold: it follows a
dozen other solvers, whose code and data have left the caches; labtool's ~0.2-0.5 ms calls lose
more to that than the peers' ~2 ms ones. The peer's cost at
exactly labtool's achieved error is read off its work-precision curve (log-log interpolation
between the two ladder points that bracket it, ``work_precision.cost_at_error``); it must reach
both the omega2 and the event-time error, so the dearer of the two counts. The best compiled
peer's ratios are given for the medians and for each solver's fastest repeat ("min": a neighbour on
a shared VM slows some repeats by up to 1.5x, and the min is each solver's undisturbed cost).

Run: ``.venv/bin/python benchmarks/peers_bench.py [--runs 1,16] [--repeats 5] [--calls 1]``.
Writes ``benchmarks/results/peers.csv``, ``peers_summary.json`` and ``peers.png`` (with
``--calls`` > 1: ``peers_warm.csv``, ``peers_warm_summary.json``, ``peers_warm.png``).
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import pathlib
import statistics
import sys
import time
import types
import warnings

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from benchmarks.work_precision import RESULTS, SAME, cost_at_error, pin_one_core, scenes  # noqa: E402

LADDERS = {
    "numbalsoda-LSODA": [1e-7, 1e-8, 1e-9, 1e-10, 1e-11],
    "numbalsoda-DOP853": [1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12],
    "scipy+numba-LSODA": [1e-7, 1e-8, 1e-9, 1e-10],
    "scipy+numba-DOP853": [1e-7, 1e-8, 1e-9, 1e-10],
    "scipy+numba-Radau": [1e-6, 1e-7, 1e-8],
    "python-DOP853": [1e-7, 1e-8, 1e-9, 1e-10],
}


def labtool_call(scene, model):
    """labtool's standard preset: (result, loop_s, wall_s) through the public API."""
    from labtool.models.dynamics import accuracy
    stats = {}
    t0 = time.perf_counter()
    res = accuracy.run_model(scene, model, stats=stats)
    res.dataset                      # built at its first read (result.DatasetParts): part of the call
    return res, stats.get("loop_s", float("nan")), time.perf_counter() - t0


def labtool_indicators_call(scene, model):
    """labtool's Dataset-free indicator path (``labtool.models.dynamics.simulate.indicators``) at
    the standard preset: the same loop as ``labtool_call``, hence its accuracy; (indicators, loop_s,
    wall_s)."""
    from labtool.models.dynamics.simulate import indicators
    stats = {}
    t0 = time.perf_counter()
    ind = indicators(scene, model, stats=stats)
    return ind, stats.get("loop_s", float("nan")), time.perf_counter() - t0


def python_dop853_call(scene, model, rtol):
    """scipy DOP853 over the model's compiled equations (labtool's reference loop,
    labtool.models.dynamics.reference) at the standard preset's other settings."""
    from labtool.models.dynamics import accuracy, elastic, rigid
    mod = {"rigid": rigid, "elastic": elastic}[model]
    preset = accuracy.scaled_preset(mod.PRESETS["standard"], rtol=rtol)
    preset["method"] = "DOP853"
    stats = {}
    t0 = time.perf_counter()
    res = accuracy.run_model(scene, model, solver="scipy", preset=preset, stats=stats)
    return res, stats["loop_s"], time.perf_counter() - t0


def peer_call(scene, model, solver, rtol, ref):
    if model == "elastic":
        from benchmarks.peers import elastic_solvers as mod
        out, loop, wall = mod.solve(scene, solver, rtol)
    else:
        from benchmarks.peers import rigid_solvers as mod
        # the rigid output instants depend on the solution's end time: the peers sample every 4th
        # instant of the reference (as many as labtool's standard preset, 4000 per rise)
        t_ref = ref.dataset["time"].values
        out, loop, wall = mod.solve(scene, solver, rtol, t_out=t_ref[:-1:4])
    import xarray as xr

    from labtool.models.dynamics import events
    te = np.asarray(out["event_times"], dtype=float)
    z = np.zeros(te.size)      # the peers report their event instants only: what accuracy.compare reads
    record = events.record(te, z, z.astype(int), z.astype(int), z, z, z, z.astype(bool))
    ds = xr.Dataset({"omega2": ("time", out["omega2"]), "MR13D": ("time", out["MR13D"]), **record},
                    coords={"time": out["time"]})
    return types.SimpleNamespace(dataset=ds, indicators={}), loop, wall


def available_peers(model):
    if model == "elastic":
        from benchmarks.peers import elastic_solvers as mod
    else:
        try:
            from benchmarks.peers import rigid_solvers as mod
        except ImportError:
            return []
    return mod.available()


def measure(models, run_ids, repeats, log, calls=1):
    from labtool.models.dynamics import accuracy
    rows = []
    for model in models:
        for run, scene in scenes(run_ids):
            ref = accuracy.reference_run(scene, model)
            configs = [("labtool-standard", None), ("labtool-indicators", None)]
            for solver in available_peers(model) + ["python-DOP853"]:
                configs += [(solver, rtol) for rtol in LADDERS[solver]]

            def call(solver, rtol):
                if solver == "labtool-standard":
                    return labtool_call(scene, model)
                if solver == "labtool-indicators":
                    return labtool_indicators_call(scene, model)
                if solver == "python-DOP853":
                    return python_dop853_call(scene, model, rtol)
                return peer_call(scene, model, solver, rtol, ref)

            times = {c: ([], []) for c in configs}
            errors = {}
            for c in configs:                      # warm-up (compilation, tables), errors
                res, _, _ = call(*c)
                # the indicator path runs the standard preset's loop: its accuracy (and its
                # indicators are the dataset path's exactly: tests/test_indicators.py)
                errors[c] = (errors[("labtool-standard", None)] if c[0] == "labtool-indicators"
                             else accuracy.compare(res, ref))
            for rep in range(repeats):             # interleaved: every solver once per round
                for c in configs:
                    if c[0] in ("python-DOP853", "scipy+numba-Radau") and rep >= 1:
                        continue                   # 0.3-3 s each: one timed round is enough
                    for k in range(calls):         # calls > 1: the first, cold, is not timed
                        _, loop, wall = call(*c)
                        if calls == 1 or k > 0:
                            times[c][0].append(loop)
                            times[c][1].append(wall)
            for c in configs:
                e = errors[c]
                rows.append(dict(model=model, run=run, solver=c[0], rtol=c[1] if c[1] else "",
                                 loop_s=statistics.median(times[c][0]), wall_s=statistics.median(times[c][1]),
                                 wall_min_s=min(times[c][1]),
                                 repeats=len(times[c][0]), err_omega2=e["err_omega2"],
                                 err_event_time=e["err_event_time"], d_events=e["d_events"],
                                 n_events=e["n_events"], n_events_ref=e["n_events_ref"]))
                log(f"{model} run {run:2d} {c[0]:20s} {str(c[1] or ''):6s} loop {rows[-1]['loop_s'] * 1e3:9.3f} ms "
                    f"wall {rows[-1]['wall_s'] * 1e3:9.3f} ms  omega2 {e['err_omega2']:.2g}  "
                    f"t_ev {e['err_event_time']:.2g}  d_ev {e['d_events']}")
    return rows


def converges(points) -> bool:
    """Does a peer's error follow its tolerance? False when the omega2 error is the same (within 1 %)
    at every tolerance of a ladder of >= 3 (numbalsoda's DOP853 on the rigid model: 1.3e-9 on run
    1 from rtol 1e-7 to 1e-12, its event times too)."""
    errs = [p["err_omega2"] for p in points if p["d_events"] == 0 and p["rtol"] != ""]
    return len(errs) < 3 or max(errs) > 1.01 * min(errs)


def summarize(rows):
    """Per model and run: labtool's errors and costs, each peer's cost at those errors, ratios."""
    out = {}
    for model in sorted({r["model"] for r in rows}):
        for run in sorted({r["run"] for r in rows if r["model"] == model}):
            rr = [r for r in rows if r["model"] == model and r["run"] == run]
            lab = next(r for r in rr if r["solver"] == "labtool-standard")
            ind = next((r for r in rr if r["solver"] == "labtool-indicators"), None)
            entry = {"labtool": {k: lab[k] for k in ("loop_s", "wall_s", "err_omega2", "err_event_time", "d_events")},
                     "peers": {}}
            entry["labtool"]["wall_min_s"] = lab["wall_min_s"]
            if ind is not None:
                entry["labtool"]["indicators_wall_s"] = ind["wall_s"]
                entry["labtool"]["indicators_wall_min_s"] = ind["wall_min_s"]
            for solver in sorted({r["solver"] for r in rr} - {"labtool-standard", "labtool-indicators"}):
                pts = [r for r in rr if r["solver"] == solver and r["d_events"] == 0]
                res = {}
                for cost in ("loop_s", "wall_s", "wall_min_s"):
                    need = [cost_at_error([(p[key], p[cost]) for p in pts], max(lab[key], floor))
                            for key, floor in (("err_omega2", 1e-12), ("err_event_time", 1e-15))]
                    if all(n is not None for n in need):
                        res[cost] = max(need)
                        res[f"ratio_{cost}"] = max(need) / lab[cost]
                if res:
                    res["rule"] = "interpolated at labtool's errors"
                else:
                    # labtool's rigid errors sit at the comparison's floor (the reference's own error):
                    # as work_precision.py, errors within a factor SAME of each other are the same accuracy
                    ok = [p for p in pts if p["err_omega2"] <= SAME * lab["err_omega2"]
                          and p["err_event_time"] <= SAME * max(lab["err_event_time"], 1e-15)]
                    if ok:
                        best = min(ok, key=lambda p: p["loop_s"])
                        res = {"loop_s": best["loop_s"], "ratio_loop_s": best["loop_s"] / lab["loop_s"],
                               "wall_s": best["wall_s"], "ratio_wall_s": best["wall_s"] / lab["wall_s"],
                               "rule": f"cheapest rtol {best['rtol']} within a factor {SAME:g} of labtool's errors"}
                    else:
                        res["note"] = ("its ladder does not reach labtool's achieved accuracy, nor within a "
                                       f"factor {SAME:g} (no extrapolation)")
                if ind is not None and "wall_s" in res:
                    res["ratio_wall_s_indicators"] = res["wall_s"] / ind["wall_s"]
                entry["peers"][solver] = res
            for solver in entry["peers"]:
                if not converges([r for r in rr if r["solver"] == solver]):
                    entry["peers"][solver]["untrusted"] = ("its error does not change along its tolerance ladder: it "
                                                           "does not converge on this problem (not a peer here)")
            trusted = {k: v for k, v in entry["peers"].items() if "untrusted" not in v and "wall_s" in v}
            compiled = {k: v for k, v in trusted.items() if k.startswith("numbalsoda")}
            if not compiled:        # numbalsoda not installed or not as accurate: solve_ivp with a numba RHS
                compiled = {k: v for k, v in trusted.items() if k.startswith("scipy+numba")}
            if compiled:
                best = min(compiled, key=lambda k: compiled[k]["wall_s"])
                entry["best_compiled_peer"] = {"solver": best, "wall_s": compiled[best]["wall_s"],
                                               "whole_call_speedup": compiled[best]["wall_s"] / lab["wall_s"]}
                if ind is not None:
                    entry["best_compiled_peer"]["indicator_path_speedup"] = compiled[best]["wall_s"] / ind["wall_s"]
                # the same ratios of the fastest repeats: a noisy neighbour slows some repeats by
                # 1.5x; the min is each solver's undisturbed cost
                peer_min = compiled[best].get("wall_min_s", float("nan"))
                entry["best_compiled_peer"]["whole_call_speedup_min"] = peer_min / lab["wall_min_s"]
                if ind is not None:
                    entry["best_compiled_peer"]["indicator_path_speedup_min"] = peer_min / ind["wall_min_s"]
            out.setdefault(model, {})[f"run_{run}"] = entry
    return out


def load_rows(path):
    rows = []
    with open(path) as fh:
        for r in csv.DictReader(fh):
            for k in ("loop_s", "wall_s", "err_omega2", "err_event_time"):
                r[k] = float(r[k])
            r["wall_min_s"] = float(r.get("wall_min_s") or "nan")        # older files: medians only
            for k in ("run", "d_events", "n_events", "n_events_ref", "repeats"):
                r[k] = int(r[k])
            r["rtol"] = float(r["rtol"]) if r["rtol"] else ""
            rows.append(r)
    return rows


def markdown(summary) -> str:
    """The docs' table: per model and run, each peer's cost over labtool's at equal accuracy."""
    lines = ["| model, run | labtool standard: err omega2 / event time; loop / whole call / indicator path | peer | "
             "peer / labtool, loop | peer / labtool, whole call | peer / labtool, indicator path |",
             "|---|---|---|---|---|---|"]
    for model in ("elastic", "rigid"):
        for run, e in sorted((summary.get(model) or {}).items()):
            lab = e["labtool"]
            head = (f"{lab['err_omega2']:.2g} / {lab['err_event_time']:.2g} s; "
                    f"{lab['loop_s'] * 1e3:.3g} / {lab['wall_s'] * 1e3:.3g} / "
                    f"{lab.get('indicators_wall_s', float('nan')) * 1e3:.3g} ms")
            label = f"{model} {run.replace('_', ' ')}"
            for solver, r in sorted(e["peers"].items()):
                if "untrusted" in r:
                    lines.append(f"| {label} | {head} | {solver} | does not converge (error independent of rtol) | | |")
                elif "note" in r:
                    lines.append(f"| {label} | {head} | {solver} | not as accurate on its ladder | | |")
                else:
                    mark = "" if r["rule"].startswith("interpolated") else " (factor 3)"
                    ri = r.get("ratio_wall_s_indicators")
                    lines.append(f"| {label} | {head} | {solver} | {r['ratio_loop_s']:.2f}{mark} | "
                                 f"{r['ratio_wall_s']:.2f}{mark} | {'' if ri is None else f'{ri:.2f}{mark}'} |")
                head = label = ""
            b = e.get("best_compiled_peer")
            if b:
                lines.append(f"| {model} {run.replace('_', ' ')} | **best compiled peer: {b['solver']}** | | | "
                             f"**{b['whole_call_speedup']:.2f}** (min {b.get('whole_call_speedup_min', float('nan')):.2f}) | "
                             f"**{b.get('indicator_path_speedup', float('nan')):.2f}** "
                             f"(min {b.get('indicator_path_speedup_min', float('nan')):.2f}) |")
    return "\n".join(lines)


def plot(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    groups = sorted({(r["model"], r["run"]) for r in rows})
    fig, axes = plt.subplots(len(groups), 2, figsize=(11, 3.8 * len(groups)), squeeze=False)
    styles = {"labtool-standard": ("*", "k"), "labtool-indicators": ("P", "k"), "numbalsoda-LSODA": ("o-", "C0"), "numbalsoda-DOP853": ("s-", "C1"),
              "scipy+numba-LSODA": ("o--", "C2"), "scipy+numba-DOP853": ("s--", "C3"),
              "scipy+numba-Radau": ("d--", "C4"), "python-DOP853": ("^:", "C5")}
    for i, (model, run) in enumerate(groups):
        for j, (key, label) in enumerate((("err_omega2", "error in omega2 (rel.)"),
                                          ("err_event_time", "error in event times (s)"))):
            ax = axes[i, j]
            for solver, (marker, color) in styles.items():
                pts = sorted((r["wall_s"], max(float(r[key]), 1e-16)) for r in rows
                             if r["model"] == model and r["run"] == run and r["solver"] == solver)
                if pts:
                    ax.plot(*zip(*pts), marker, color=color, ms=12 if solver.startswith("labtool") else 4,
                            label=solver)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel("whole call, median wall time (s)", fontsize=8)
            ax.set_title(f"{model}, Table 1 run {run}: {label}", fontsize=9)
            ax.grid(True, which="both", alpha=0.3)
            if i == 0 and j == 0:
                ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", default="elastic,rigid")
    ap.add_argument("--runs", default="1,16")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--calls", type=int, default=1,
                    help="calls of each solver in a row per round; > 1 times calls 2..N (warm, as in a sweep)")
    ap.add_argument("--out", default=str(RESULTS))
    ap.add_argument("--all-cores", action="store_true")
    ap.add_argument("--from-csv", action="store_true", help="only re-summarize and re-plot peers.csv in --out")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)
    stem = "peers" if args.calls <= 1 else "peers_warm"
    if args.from_csv:
        out = pathlib.Path(args.out)
        rows = load_rows(out / f"{stem}.csv")
        summary = summarize(rows)
        summary["machine"] = json.loads((out / f"{stem}_summary.json").read_text()).get("machine", {})
        (out / f"{stem}_summary.json").write_text(json.dumps(summary, indent=1, default=float))
        plot(rows, out / f"{stem}.png")
        print(markdown(summary))
        return summary
    cpu = None if args.all_cores else pin_one_core()
    from benchmarks.peers.elastic_solvers import HAVE_NUMBALSODA
    if not HAVE_NUMBALSODA:
        print("numbalsoda is not installed: its peers are skipped (pip install -e '.[bench]'; it builds from "
              "source and needs gfortran and cmake: apt-get install -y gfortran cmake)", flush=True)
    t0 = time.perf_counter()
    load0 = os.getloadavg()
    rows = measure(args.models.split(","), {int(x) for x in args.runs.split(",")}, args.repeats,
                   lambda s: print(s, flush=True), max(1, args.calls))
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / f"{stem}.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    summary = summarize(rows)
    summary["machine"] = dict(cpu_pinned=cpu, nproc=os.cpu_count(), repeats=args.repeats, calls=max(1, args.calls),
                              total_s=time.perf_counter() - t0, loadavg_start=load0, loadavg=os.getloadavg())
    (out / f"{stem}_summary.json").write_text(json.dumps(summary, indent=1, default=float))
    plot(rows, out / f"{stem}.png")
    print(markdown(summary))
    return summary


if __name__ == "__main__":
    main()
