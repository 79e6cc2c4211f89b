"""The extremes suite's figures as a table: for every case of tests/test_extremes.py, the events,
the RHS evaluations, the wall time and the step-halving differences (the 'standard' preset's error
estimate) against the preset's error measured on Table 1.

Run: ``.venv/bin/python benchmarks/extremes_table.py`` -> benchmarks/results/extremes.csv (+ stdout).
"""
from __future__ import annotations

import csv
import pathlib
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))


def main():
    from labtool.models.dynamics import accuracy
    from labtool.common.errors import LabtoolError
    from labtool.models.study.paper import paper_scene
    from test_extremes import BASE, ELASTIC_CASES, RIGID_CASES

    rows = []
    for model, cases in (("rigid", RIGID_CASES), ("elastic", ELASTIC_CASES)):
        for kw in cases:
            scene = paper_scene(**{**BASE, **kw})
            stats = {}
            t0 = time.perf_counter()
            try:
                res = accuracy.run_model(scene, model, stats=stats)
            except LabtoolError as exc:
                rows.append(dict(model=model, case=str(kw), error=str(exc)))
                continue
            wall = time.perf_counter() - t0
            half = accuracy.run_model(scene, model, preset=accuracy.halved(model, "standard"))
            err = accuracy.compare(res, half)
            worst = max(err[k] / accuracy.MEASURED[model]["standard"][k]
                        for k in ("err_omega2", "err_MR13D", "err_event_time", "err_indicators")
                        if accuracy.MEASURED[model]["standard"][k])
            rows.append(dict(model=model, case=";".join(f"{k}={v}" for k, v in kw.items()), error="",
                             jumps=res.indicators["jumps"], impacts=res.indicators["impacts"],
                             nfev=stats.get("nfev"), wall_s=round(wall, 4),
                             **{k: f"{err[k]:.2e}" for k in ("err_omega2", "err_MR13D", "err_event_time", "err_indicators")},
                             d_events=err["d_events"], worst_ratio_to_table1=round(worst, 2)))
            print(rows[-1], flush=True)
    out = ROOT / "benchmarks" / "results" / "extremes.csv"
    out.parent.mkdir(exist_ok=True)
    keys = sorted({k for r in rows for k in r}, key=lambda k: list(rows[0]).index(k) if k in rows[0] else 99)
    with open(out, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    print(f"written {out}")


if __name__ == "__main__":
    main()
