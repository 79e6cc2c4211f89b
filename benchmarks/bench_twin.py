"""The stand's twin (the simulated stand's default truth): what it records and what it costs.

Run: ``.venv/bin/python benchmarks/bench_twin.py [--seconds 60] [--rpm 180 300 500]``.

Per cam speed, for the default stand (sine law, Fu = 0, j = 0.128 mm, the 480C02 at gain x1):
the true events per revolution (labtool.models.dynamics.twin's event record: contacts, visible impacts
with |event_domega2| > 0.05 rad/s, impacts faster than 1 mm/s, lift-offs), the first impact on the
exterior flank in the rise, the peak recorded volts against the +-10 V range and the clip events;
then the cost of ``--seconds`` of data to HDF5 (``--fast``) against its peer measured in the same
run, the same stand with the kinematic truth, and the twin integration alone. The 1-hour figure is
the measured one scaled by 3600 / seconds (the twin streams in bounded memory, its cost is linear
in the duration). Timing is wall and CPU of this process; no assertion (speed is measured here,
never in tests).
"""
from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from labtool.common.units import RPM

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

VISIBLE_DOMEGA2 = 0.05   # rad/s
IMPACT_SPEED = 1e-3      # m/s


def record(scene, seconds, path):
    """(wall s, CPU s, peak volts per channel, clip events) of a --fast recording to HDF5."""
    from labtool.acquisition import session
    from labtool.acquisition import signal_chain as sc
    from labtool.common import recording_format
    from labtool.acquisition.sim_stand import SimStand

    params = sc.ChainParams(resonance_hz=scene.twin.mode_hz, resonance_zeta=scene.twin.mode_zeta)
    dev = SimStand(scene, params, seed=1, duration_s=seconds, realtime=False)
    cpu0, wall0 = time.process_time(), time.perf_counter()
    session.run(dev, path, 10000, seconds)
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    rec = recording_format.load(path)
    clips = [e for e in rec["events"] if e[1] == "clip"]
    return wall, cpu, np.abs(rec["signals"][:, :2]).max(axis=0), clips


def event_figures(ev, T, seconds):
    revs = seconds / T
    ang = np.degrees(ev["event_phi1"]) % 360.0
    contact = ev["event_kind"] == "contact"
    lift = (ev["event_kind"] == "separation") & ev["event_persistent"]
    visible = contact & (np.abs(ev["event_domega2"]) > VISIBLE_DOMEGA2)
    fast = contact & (ev["event_v_rel"] > IMPACT_SPEED)
    rise_ext = contact & (ev["event_side"] == "exterior") & (ang < 58.0) & (ang > 20.0)
    lift_rise = lift & (ang < 58.0)
    return dict(contacts=contact.sum() / revs, visible=visible.sum() / revs, impacts=fast.sum() / revs,
                lift_offs=lift.sum() / revs,
                lift_off_deg=float(np.median(ang[lift_rise])) if lift_rise.any() else math.nan,
                first_impact_deg=float(np.median([ang[rise_ext & (np.floor(ev["event_time"] / T) == k)].min()
                                                  for k in range(int(revs)) if (rise_ext & (np.floor(ev["event_time"] / T) == k)).any()]))
                if rise_ext.any() else math.nan)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=60.0, help="seconds of data per recording")
    ap.add_argument("--rpm", type=float, nargs="+", default=[180.0, 300.0, 500.0])
    args = ap.parse_args()

    from labtool.acquisition import signal_chain as sc
    from labtool.models.dynamics.twin import TwinRun

    TwinRun(sc.StandScene().model_scene())   # compile (or load the cached kernels) before timing
    print(f"default twin stand, {args.seconds:g} s per recording, 10 kHz, Ka = {sc.DEFAULT_KA:g} m/s^2/V (gain x1), range +-10 V")
    with tempfile.TemporaryDirectory() as tmp:
        for rpm in args.rpm:
            scene = sc.StandScene(cam_speed=rpm * RPM)
            T = 60.0 / rpm
            c0, w0 = time.process_time(), time.perf_counter()
            ev = sc.truth_events(scene, args.seconds)
            twin_wall, twin_cpu = time.perf_counter() - w0, time.process_time() - c0
            f = event_figures(ev, T, args.seconds)
            wall, cpu, peak, clips = record(scene, args.seconds, Path(tmp) / f"twin{rpm:g}.h5")
            kin_wall, kin_cpu, kin_peak, _ = record(sc.StandScene(cam_speed=rpm * RPM, truth_model="kinematic"),
                                                    args.seconds, Path(tmp) / f"kin{rpm:g}.h5")
            print(f"\n{rpm:g} rpm ({args.seconds / T:.0f} revolutions)")
            print(f"  true events per revolution: {f['contacts']:.1f} contacts, {f['visible']:.1f} visible impacts "
                  f"(|domega2| > {VISIBLE_DOMEGA2} rad/s), {f['impacts']:.1f} faster than {IMPACT_SPEED * 1e3:g} mm/s, "
                  f"{f['lift_offs']:.1f} lift-offs")
            print(f"  rise: lift-off at {f['lift_off_deg']:.2f} deg, first exterior impact at {f['first_impact_deg']:.2f} deg (median over turns)")
            print(f"  peak volts: aE_t {peak[0]:.3f} V, aE_n {peak[1]:.3f} V of +-10 V ({100 * peak[0] / 10:.0f} %); "
                  f"clip events {len(clips)} (kinematic truth: aE_t {kin_peak[0]:.3f} V)")
            print(f"  cost of {args.seconds:g} s to HDF5: twin stand {wall:.1f} s wall / {cpu:.1f} s CPU; "
                  f"kinematic stand (peer, same run) {kin_wall:.1f} s wall / {kin_cpu:.1f} s CPU; ratio {cpu / kin_cpu:.1f}x CPU; "
                  f"the twin alone {twin_cpu:.1f} s CPU")
            scale = 3600.0 / args.seconds
            print(f"  extrapolated 1 h: twin stand {wall * scale / 60:.1f} min wall / {cpu * scale / 60:.1f} min CPU "
                  f"(kinematic {kin_cpu * scale / 60:.1f} min CPU)")


if __name__ == "__main__":
    main()
