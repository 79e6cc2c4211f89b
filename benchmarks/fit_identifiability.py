"""Where j, k and the contact damping are visible: the sensitivity of the fit's residuals to each
parameter over operating points (docs/identification.md, "identifiability per operating point").

For each model, speed n1 and load Fu the model's cycle (the report's path: steady state, the
processing low-pass at 100 x the cam frequency, 60 harmonics) is computed at a reference point
and with one parameter changed (j x 1.25, k + 0.1, damping x 1.5), at the paper's two backlashes
(0.016 and 0.128 mm, Table 1) with k = 0.5 and 40 s/m; the visibility of that change is
the rms difference of omega2 and epsilon2 over the revolution, each in units of the fit's floor
(1 % of the signal's rms, objective.MODEL_FLOOR): > 1 means the change shows above what a model
cycle reproduces, so a measurement at that point can identify the parameter; < 1 it cannot. The
jumps per revolution of the rigid model say whether the follower leaves the flank at all.

    .venv/bin/python benchmarks/fit_identifiability.py [--accuracy fast]
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

REFERENCE = {"law": "sine", "backlash_mm": 0.128, "jt_factor": 1.0, "restitution": 0.5, "contact_damping": 40.0,
             "contact_length_mm": 6.0, "elastic_gap": "physical"}
CHANGES = {"rigid": {"backlash_mm": lambda v: 1.25 * v, "restitution": lambda v: v + 0.1},
           "elastic": {"backlash_mm": lambda v: 1.25 * v, "contact_damping": lambda v: 1.5 * v}}


def cycle(op, model, accuracy):
    from labtool.reports import align, pipeline
    cond = align.Conditioning()
    tf = align.TimeFilter(10_000.0, 100.0 * op["cam_speed_rpm"] / 60.0, 4)
    run = pipeline.run_simulation(op, model, "const", accuracy, 3, cond, tf)
    return run.cycle.signals, run.indicators


def visibility(base, changed) -> float:
    """rms change over the fit's floor (1 % rms), the larger of omega2 and epsilon2."""
    from labtool.identification.objective import MODEL_FLOOR
    out = 0.0
    for s in ("omega2", "epsilon2"):
        rms = math.sqrt(float(np.mean(base[s] ** 2)))
        out = max(out, math.sqrt(float(np.mean((changed[s] - base[s]) ** 2))) / (MODEL_FLOOR * rms))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--accuracy", default="fast", choices=("fast", "standard"))
    args = ap.parse_args()
    print("model    j mm    n1 rpm  Fu N  jumps/rev  " + "  ".join(f"{k:>22s}" for k in ("change 1", "change 2")))
    points = [(j, rpm, fu) for j in (0.016, 0.128) for rpm in (180.0, 300.0, 500.0) for fu in (0.0, 65.0)]
    for model, changes in CHANGES.items():
        for j, rpm, fu in points:
            op = {**REFERENCE, "backlash_mm": j, "cam_speed_rpm": rpm, "Fu": fu}
            base, ind = cycle(op, model, args.accuracy)
            cells = []
            for key, change in changes.items():
                sig, _ = cycle({**op, key: change(op[key])}, model, args.accuracy)
                cells.append(f"{key} {visibility(base, sig):8.1f}")
            jumps = ind.get("jumps")
            jumps = "-" if jumps is None else f"{jumps / 3:.1f}"
            print(f"{model:8s} {j:6.3f} {rpm:6.0f} {fu:5.0f}  {jumps:>9s}  " + "  ".join(f"{c:>22s}" for c in cells),
                  flush=True)

if __name__ == "__main__":
    main()
