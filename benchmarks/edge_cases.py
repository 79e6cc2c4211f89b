"""The models' edge cases at every preset: each must end finite and plausible, or in one line.

    .venv/bin/python benchmarks/edge_cases.py [--presets fast,standard,reference] [--cases NAME,...]

Prints a table: case, model, preset, outcome (the indicators that matter, the validity warnings,
or the one-line error) and the wall time. The verdict of a case (ran / ran with warnings / refused)
must be the same at every preset.
"""
from __future__ import annotations

import argparse
import math
import pathlib
import sys
import time
from labtool.common.units import RPM
from labtool.models.study.paper import paper_scene

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))


def cases():
    from labtool.models.mechanism import Mechanism
    
    steep = Mechanism.default().replace(program={"law": "sine", "rise_deg": 5.0})
    return {
        "rise 5 deg": ("rigid", paper_scene(mechanism=steep)),
        "random point k=1": ("rigid", paper_scene(omega1_mode="var", Fu=83.08451831611706, backlash=0.16261007916261438e-3,
                                            cam_speed=263.4775377785051 * RPM, jt_factor=1.3244428636474361,
                                            restitution=1.0)),
        "cosine law": ("elastic", paper_scene(law="cosine")),
        "Kc x1e-6": ("elastic", paper_scene(kc_factor=1e-6)),
        "Fu 1e5 N rigid": ("rigid", paper_scene(Fu=1e5)),
        "Fu 1e5 N elastic": ("elastic", paper_scene(Fu=1e5)),
        "j 5 mm rigid": ("rigid", paper_scene(backlash=5e-3)),
        "j 5 mm elastic": ("elastic", paper_scene(backlash=5e-3)),
    }


def outcome(model: str, scene) -> tuple[str, str, float]:
    from labtool.common.errors import LabtoolError
    from labtool.models.dynamics.simulate import simulate

    t0 = time.perf_counter()
    try:
        res = simulate(scene, model)
    except LabtoolError as exc:
        return "refused", f"{type(exc).__name__}: {exc}", time.perf_counter() - t0
    ind = res.indicators
    keys = ("jumps", "impacts", "percussion_max_Ns", "xel_max_mm", "xel_min_mm", "MR13D_max_Nm", "energy_error")
    text = ", ".join(f"{k}={ind[k]:.4g}" for k in keys if isinstance(ind.get(k), (int, float)))
    finite = all(math.isfinite(v) for v in ind.values() if isinstance(v, (int, float)) and not isinstance(v, bool))
    warnings = list(getattr(res, "warnings", []))
    verdict = ("ran" if not warnings else "ran, warned") + ("" if finite else " NON-FINITE")
    if warnings:
        text += " | " + " | ".join(warnings)
    return verdict, text, time.perf_counter() - t0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--presets", default="fast,standard,reference")
    ap.add_argument("--cases", default="")
    args = ap.parse_args(argv)
    wanted = [c for c in args.cases.split(",") if c]
    verdicts = {}
    print("| case | model | preset | outcome | details | wall s |")
    print("|---|---|---|---|---|---|")
    for name, (model, scene) in cases().items():
        if wanted and name not in wanted:
            continue
        for preset in args.presets.split(","):
            verdict, text, wall = outcome(model, scene.replace(accuracy=preset))
            verdicts.setdefault(name, set()).add(verdict)
            print(f"| {name} | {model} | {preset} | {verdict} | {text} | {wall:.2f} |", flush=True)
    same = all(len(v) == 1 for v in verdicts.values())
    print(f"\nsame verdict at every preset: {'yes' if same else 'NO: ' + str(verdicts)}")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
