"""Snapshot of every indicator of Table 1's 16 runs, both models, every preset, and their errors.

A before/after check for changes that must not move the physics: run it on two
commits and compare the JSON files.

    .venv/bin/python benchmarks/table1_snapshot.py -o before.json [--errors]
    .venv/bin/python benchmarks/table1_snapshot.py --compare before.json after.json

Per (model, preset, run): every numeric indicator and the event times (s). The elastic model runs
twice: the default physical gap and the closed gap of the paper's Table 3. ``--errors`` adds each
preset's errors against the reference solution (labtool.models.dynamics.accuracy.compare against
reference_run: DOP853 at rtol 1e-12), the figures of accuracy.MEASURED (a few minutes).
The compare mode prints, per model and preset, the largest change of each indicator against the
preset's measured indicator error (accuracy.bound(..., "err_indicators"): the worst error of the
Table 1 indicators against the reference solution, times 3; relative as in accuracy.compare); counts
and event numbers must be equal.
"""
from __future__ import annotations

import argparse
import json
import math
import pathlib
import sys
import time
from labtool.common.units import RPM
from labtool.models.study.paper import paper_scene

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

CASES = (("rigid", "physical"), ("elastic", "physical"), ("elastic", "closed"))
PRESETS = ("fast", "standard", "reference")
COUNTS = ("jumps", "impacts", "liftoffs", "settles", "separations", "n_events")


def _event_times(ds):
    try:                                             # the one event record
        from labtool.models.dynamics import events
        return [float(t) for t in events.read(ds)["event_time"].values]
    except ImportError:                              # before it: two formats
        from labtool.models.dynamics import accuracy
        return [float(t) for t in accuracy.event_times(ds)]


def _scene(run, gap, preset):
        return paper_scene(cam_speed=run.n1_rpm * RPM, Fu=run.Fu_N, backlash=run.j_mm * 1e-3, jt_factor=run.Jt_factor,
                 omega1_mode="var", accuracy=preset, elastic_gap=gap)


def snapshot(errors: bool, models=("rigid", "elastic")) -> dict:
    from labtool.models.dynamics import accuracy
    from labtool.models.dynamics.simulate import simulate
    from labtool.models.study.paper import table1_runs

    out = {}
    for model, gap in CASES:
        if model not in models:
            continue
        refs = {}
        for preset in PRESETS:
            rows = []
            for run in table1_runs().itertuples():
                scene = _scene(run, gap, preset)
                t0 = time.perf_counter()
                res = simulate(scene, model)
                wall = time.perf_counter() - t0
                ind = {k: (float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else v)
                       for k, v in res.indicators.items() if isinstance(v, (int, float, type(None)))}
                row = dict(run=int(run.run), wall_s=wall, indicators=ind, event_times=_event_times(res.dataset))
                if errors and model == "rigid" or errors and gap == "physical":
                    if run.run not in refs:
                        refs[run.run] = accuracy.reference_run(scene, model)
                    row["errors"] = accuracy.compare(res, refs[run.run])
                rows.append(row)
                print(f"{model}/{gap}/{preset} run {run.run}: {wall:.3f} s", file=sys.stderr)
            out[f"{model}/{gap}/{preset}"] = rows
    return out


def _rel(a, b, scale):
    if a is None or b is None:
        return 0.0 if a is b else math.inf
    return abs(a - b) / max(abs(scale), 1e-12)


def _scale(ind: dict, key: str, value: float) -> float:
    """What an indicator's change is relative to (as labtool.models.dynamics.accuracy.compare): MR13D and
    xel extremes by the larger of their max and min (a minimum near zero has no relative error)."""
    for prefix in ("MR13D_contact", "MR13D", "xel"):
        if key.startswith(prefix):
            unit = "_Nm" if prefix.startswith("MR13D") else "_mm"
            return max(abs(ind.get(f"{prefix}_max{unit}") or 0.0), abs(ind.get(f"{prefix}_min{unit}") or 0.0))
    return value if value else 1.0


def _distinct(times):
    """Event instants, each once (a rebound is two rows at one instant in the event record)."""
    out = []
    for t in times:
        if not out or t != out[-1]:
            out.append(t)
    return out


def compare(before: dict, after: dict) -> None:
    from labtool.models.dynamics import accuracy

    print(f"{'case':28s} {'indicator':22s} {'max change':>12s} {'bound':>8s}  verdict")
    for case, rows_a in before.items():
        rows_b = after.get(case)
        if rows_b is None:
            print(f"{case:28s} missing after")
            continue
        model, _, preset = case.split("/")
        stated = accuracy.bound(model, preset, "err_indicators")   # the preset's measured indicator error x 3
        keys = sorted(set(rows_a[0]["indicators"]) & set(rows_b[0]["indicators"]))
        new = sorted(set(rows_b[0]["indicators"]) - set(rows_a[0]["indicators"]))
        if new:
            print(f"{case:28s} {'new: ' + ', '.join(new)}")
        for key in keys:
            worst, diff_counts = 0.0, 0
            for ra, rb in zip(rows_a, rows_b):
                a, b = ra["indicators"].get(key), rb["indicators"].get(key)
                if not isinstance(a, (int, float, type(None))) or not isinstance(b, (int, float, type(None))):
                    continue
                if key in COUNTS:
                    diff_counts += int(a != b)
                    continue
                worst = max(worst, _rel(a, b, _scale(ra["indicators"], key, a)))
            if key in COUNTS:
                print(f"{case:28s} {key:22s} {diff_counts:>9d} runs {'':>8s}  {'same' if diff_counts == 0 else 'DIFFERENT'}")
            elif worst > 0 or True:
                verdict = "identical" if worst == 0 else ("within" if worst <= stated else "OUTSIDE")
                print(f"{case:28s} {key:22s} {worst:12.2e} {stated:8.0e}  {verdict}")
        pairs = [(_distinct(ra["event_times"]), _distinct(rb["event_times"])) for ra, rb in zip(rows_a, rows_b)]
        n_ev = sum(len(a) != len(b) for a, b in pairs)
        dt = max((abs(x - y) for a, b in pairs if len(a) == len(b) for x, y in zip(a, b)), default=0.0)
        print(f"{case:28s} {'event times':22s} {dt:12.2e} {'s':>8s}  {n_ev} runs with another event count")
        if "errors" in rows_a[0] and "errors" in rows_b[0]:
            for key in ("err_omega2", "err_MR13D", "err_event_time", "d_events", "err_indicators"):
                ea = max(r["errors"][key] for r in rows_a)
                eb = max(r["errors"][key] for r in rows_b)
                print(f"{case:28s} {'preset ' + key:22s} {ea:12.2e} -> {eb:.2e}")
        wa = sum(r["wall_s"] for r in rows_a)
        wb = sum(r["wall_s"] for r in rows_b)
        print(f"{case:28s} {'wall, 16 runs':22s} {wa:10.3f} s -> {wb:.3f} s (noisy: same-run ratios only)")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--output", type=pathlib.Path)
    ap.add_argument("--errors", action="store_true", help="also the presets' errors against the reference")
    ap.add_argument("--compare", nargs=2, type=pathlib.Path, metavar=("BEFORE", "AFTER"))
    ap.add_argument("--models", default="rigid,elastic", help="comma-separated: rigid, elastic")
    args = ap.parse_args(argv)
    if args.compare:
        compare(*(json.loads(p.read_text()) for p in args.compare))
        return 0
    data = snapshot(args.errors, tuple(args.models.split(",")))
    text = json.dumps(data, indent=1)
    if args.output:
        args.output.write_text(text)
    else:
        print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
