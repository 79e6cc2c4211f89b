"""The verdict checked against a known truth, on the simulated stand:

* ``events``: measured vs true impacts (first impact angle, visible impacts per revolution) at 180,
  300 and 500 rpm, on the twin's default recordings and on model truths (rigid with k = 0.2 and
  elastic with 40 s/m). True = the truth's own event record (``truth_events``) with the measured
  side's visibility (``labtool.reports.events.truth_statistics``: the recording's detectability threshold,
  the detector's resolution). Goal: first impact within 1 deg, visible impacts within 25 %.
* ``self``: a recording whose truth is model X (its equations and parameters), reported against X
  (omega1 const, the same restitution or contact damping), fast and standard preset, 180 and 500
  rpm. Goal: ISO >= 0.94 (excellent) for omega2 and epsilon2.
* ``twin``: the twin's default recording (the demo's scene): each model's grades, the closest
  model, the robustness rows (both presets, both simulated lengths), with the groove's energy loss
  the recording states (as the demo) and with the paper's idealisations (k = 1, undamped).

    .venv/bin/python benchmarks/verdict_checks.py [events|self|twin ...] [--seconds 5] [--keep DIR]

Prints tables; no asserts (the tests hold the fast checks). Recordings: ``labtool acquire --device
sim --fast --seed 1`` and ``labtool process``, ``--seconds`` long (default 5).
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
LABTOOL = str(ROOT / ".venv" / "bin" / "labtool")
LOSS = {"rigid": {"restitution": 0.2}, "elastic": {"contact_damping": 40.0}}   # the truths' defaults (docs/twin.md)


STAND = {"seed": 1, "backlash_mm": 0.128}      # set from the command line


def record(d: Path, truth: str, rpm: float, seconds: float) -> tuple[Path, Path]:
    """(recording, measured file) of the simulated stand with ``truth`` at ``rpm``, made once."""
    tag = "" if STAND == {"seed": 1, "backlash_mm": 0.128} else f"_s{STAND['seed']}_j{STAND['backlash_mm']:g}"
    rec, nc = d / f"{truth}_{rpm:g}{tag}.h5", d / f"{truth}_{rpm:g}{tag}.nc"
    if not rec.exists():
        subprocess.run([LABTOOL, "acquire", "--device", "sim", "--truth", truth, "--rpm", f"{rpm:g}", "--duration",
                        f"{seconds:g}", "--fast", "--seed", str(STAND["seed"]), "--backlash-mm",
                        f"{STAND['backlash_mm']:g}", "-o", str(rec), "--force"], check=True, stdout=subprocess.DEVNULL)
    if not nc.exists():
        subprocess.run([LABTOOL, "process", str(rec), "-o", str(nc), "--force"], check=True, stdout=subprocess.DEVNULL)
    return rec, nc


def truth_record(rec: Path, duration: float) -> dict:
    """The recording's true events (labtool.models.dynamics.events arrays). The elastic model's record carries no
    event_domega2: its contacts' steps are taken as the report takes them from a model (labtool.reports.events.model_events: omega2 less the law's
    over the impact), from the truth's own simulation, its steady turn repeated as the stand does."""
    import h5py

    from labtool.acquisition.signal_chain import model_table, scene_from_attrs, truth_events
    from labtool.models.dynamics.simulate import simulate
    from labtool.reports import events

    with h5py.File(rec, "r") as f:
        scene = scene_from_attrs(dict(f.attrs))
    ev = truth_events(scene, duration)
    c = np.asarray(ev["event_kind"]).astype(str) == "contact"
    if scene.truth_model != "elastic" or np.isfinite(ev["event_domega2"][c]).any():
        return ev
    tab = model_table(scene)
    own = events.model_events(simulate(scene.model_scene(tab["revolutions"]), "elastic").dataset)
    T, R = tab["period"], tab["revolutions"]
    mc = own.contacts
    t_model = (R - 1) * T + np.mod(ev["event_time"][c], T) if tab["periodic"] else ev["event_time"][c]
    near = np.abs(own.time[mc][None, :] - t_model[:, None]).argmin(axis=1)
    d = ev["event_domega2"].copy()
    d[c] = own.d_omega2[mc][near]
    return {**ev, "event_domega2": d}


def measured_and_true(rec: Path, nc: Path) -> tuple[dict, dict]:
    from labtool.reports import align, events, pipeline

    ds = pipeline.load_measured(nc)
    cyc = align.read_measured(ds, pipeline.SIGNALS, align.Conditioning(), extra=("aE_n",))
    op = pipeline.operating_point(ds, cyc.cam_speed_rpm, {})
    det = pipeline.detector_for(align.processing_filter(ds), ds)
    m = pipeline._measured_events(cyc, det, op)
    tr = events.truth_statistics(truth_record(rec, float(cyc.time[-1, -1]) + 0.5), cyc, det, m["threshold_rad_s"],
                                 pipeline.cam_program(op))
    return m, tr


def _deg(v) -> str:
    return "-" if v is None else f"{v:6.2f}"


def check_events(d: Path, seconds: float) -> None:
    print("measured vs true events (true: the truth's record, visible as measured: |d omega2| >= threshold, "
          "merged within the detector's resolution)")
    print(f"{'truth':8s} {'rpm':>4s} {'thr rad/s':>9s} {'first meas':>10s} {'first true':>10s} {'diff':>6s} "
          f"{'imp/rev meas':>12s} {'true':>6s} {'diff':>6s}  angles measured | true (deg)")
    for truth in ("twin", "rigid", "elastic"):
        for rpm in (180.0, 300.0, 500.0):
            m, t = measured_and_true(*record(d, truth, rpm, seconds))
            fm, ft = m["first_impact_deg"], t["first_impact_deg"]
            dfirst = "-" if fm is None or ft is None else f"{fm - ft:+6.2f}"
            im, it = m["impacts_per_rev"], t["impacts_per_rev"]
            dcount = f"{100 * (im / it - 1):+5.0f}%" if it else "-"
            ok = fm is not None and ft is not None and abs(fm - ft) <= 1.0 and it and abs(im / it - 1) <= 0.25
            print(f"{truth:8s} {rpm:4.0f} {m['threshold_rad_s']:9.3f} {_deg(fm):>10s} {_deg(ft):>10s} {dfirst:>6s} "
                  f"{im:12.2f} {it:6.2f} {dcount:>6s}  {', '.join(f'{a:.1f}' for a in m['impact_angles_deg'])} | "
                  f"{', '.join(f'{a:.1f}' for a in t['impact_angles_deg'])}  {'ok' if ok else 'NOT MET'}")


def check_self(d: Path, seconds: float) -> None:
    from labtool.reports import pipeline
    print("self-consistency: truth = model X, reported against X (omega1 const, the truth's k or damping)")
    print(f"{'model':8s} {'rpm':>4s} {'preset':9s} {'w2 ISO':>7s} {'e2 ISO':>7s}  grades              motion")
    for model in ("rigid", "elastic"):
        for rpm in (180.0, 500.0):
            _, nc = record(d, model, rpm, seconds)
            for acc in ("fast", "standard"):
                rep = pipeline.build_report(nc, (model,), ("const",), overrides=LOSS[model], accuracy=acc,
                                            robustness=False)
                h = pipeline.headline(rep)[0]
                ok = min(h["omega2_iso_rating"], h["epsilon2_iso_rating"]) >= 0.94
                print(f"{model:8s} {rpm:4.0f} {acc:9s} {h['omega2_iso_rating']:7.3f} {h['epsilon2_iso_rating']:7.3f}  "
                      f"{h['omega2_iso_grade']:9s} {h['epsilon2_iso_grade']:9s}  {h['motion']}  {'ok' if ok else 'NOT MET'}")


def check_twin(d: Path, seconds: float) -> None:
    from labtool.reports import pipeline
    for rpm in (180.0, 500.0):
        _, nc = record(d, "twin", rpm, seconds)
        for name, loss in (("the recording's energy loss (k 0.2, 40 s/m), as the demo", {**LOSS["rigid"], **LOSS["elastic"]}),
                           ("the paper's idealisations (k 1, undamped)", {})):
            rep = pipeline.build_report(nc, overrides=loss, accuracy="fast")
            print(f"twin, {rpm:g} rpm, models with {name}; simulated at {rep.scene['cam_speed_rpm']:.2f} rpm "
                  f"({rep.scene['cam_speed_source']}), stated {rep.scene['cam_speed_rpm_stated']:g}")
            for h in pipeline.headline(rep):
                print(f"  {h['label']:22s} omega2 ISO {h['omega2_iso_rating']:.3f} ({h['omega2_iso_grade']}), epsilon2 ISO "
                      f"{h['epsilon2_iso_rating']:.3f} ({h['epsilon2_iso_grade']}); {h['motion']}")
            for r in rep.robustness:
                grades = "; ".join(f"{m['label']}: {m['omega2_iso_rating']:.2f}/{m['epsilon2_iso_rating']:.2f}"
                                   for m in r["models"])
                print(f"  robustness {r['accuracy']:8s} {r['revolutions']:g} rev: closest {r['closest']}  ({grades})")
            for line in pipeline.verdict_lines(rep):
                print("  " + line)


CHECKS = {"events": check_events, "self": check_self, "twin": check_twin}

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checks", nargs="*", choices=list(CHECKS), help="which checks (default: all)")
    ap.add_argument("--seconds", type=float, default=5.0, help="recording length [s]")
    ap.add_argument("--keep", type=Path, default=None, help="folder to keep (and reuse) the recordings in")
    ap.add_argument("--seed", type=int, default=1, help="noise seed of the simulated stand")
    ap.add_argument("--backlash-mm", type=float, default=0.128, help="groove backlash j [mm]")
    args = ap.parse_args()
    STAND.update(seed=args.seed, backlash_mm=args.backlash_mm)
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        for name in args.checks or CHECKS:
            CHECKS[name](folder, args.seconds)
            print()
