"""Jumps and impacts, measured and predicted, with one definition (processing/impacts.py).

Measured: the velocity steps the detector finds in every whole revolution the report read.
Predicted: each model's own event record (``model_events``), seen as the chain would see it
(contacts closer than the detector's resolution merged, those below the recording's detectability
threshold dropped), over the model's steady revolutions. Both go through the same cycle
statistics (``processing.impacts.per_revolution``).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import xarray as xr

from processing import impacts

TWO_PI = 2.0 * math.pi
KEYS = ("impacts_per_rev", "jumps_per_rev", "first_impact_deg", "impact_angles_deg")   # summary JSON keys
IMPULSE_S = 1e-3     # elastic model: window over which a contact's impulse changes omega2 (s)


@dataclasses.dataclass
class EventRecord:
    """A simulation's contact events in the layout of EVENTS.md (SI): time (s), phi1 (rad,
    unwrapped), kind ("separation" | "contact"), d_omega2 (rad/s, change of omega2 caused by the
    contact; NaN for separations)."""

    time: np.ndarray
    phi1: np.ndarray
    kind: np.ndarray
    d_omega2: np.ndarray

    @property
    def contacts(self) -> np.ndarray:
        return self.kind == "contact"


def model_events(sim: xr.Dataset) -> EventRecord | None:
    """The one place that reads a model's events. Today: the rigid model's ``event`` dimension
    (``event_kind`` flags liftoff / impact_rebound / impact_settle, omega2 before and after) and
    the elastic model's attributes (``event_times_s``, ``event_kinds`` leave_* / land_*; the step of
    omega2 over each contact from the dataset's omega2). None for a simulation without events
    (the kinematic level). When models/dynamics/events.py lands, this reads its record instead."""
    if all(n in sim for n in ("event_time", "event_phi1", "event_kind", "event_domega2")) \
            and np.asarray(sim["event_kind"].values).dtype.kind in "USO":
        # the one record (EVENTS.md, models/dynamics/events.py): kinds by name, the step recorded
        kinds = np.asarray(sim["event_kind"].values, dtype=str).astype(object)
        d = np.where(kinds == "contact", np.asarray(sim["event_domega2"].values, float), np.nan)
        return EventRecord(np.asarray(sim["event_time"].values, float), np.asarray(sim["event_phi1"].values, float),
                           kinds, d)
    if "event_kind" in sim and "event_time" in sim and "event_phi1" in sim:
        meanings = str(sim["event_kind"].attrs.get("flag_meanings", "")).split()
        values = list(np.atleast_1d(sim["event_kind"].attrs.get("flag_values", range(1, len(meanings) + 1))))
        name = dict(zip(values, meanings))
        kinds = np.array(["contact" if "impact" in name.get(k, "") else "separation"
                          for k in np.asarray(sim["event_kind"].values)], dtype=object)
        d = np.full(kinds.size, np.nan)
        if "event_omega2_after" in sim and "event_omega2_before" in sim:
            d = np.asarray(sim["event_omega2_after"].values, float) - np.asarray(sim["event_omega2_before"].values, float)
        d = np.where(kinds == "contact", d, np.nan)
        return EventRecord(np.asarray(sim["event_time"].values, float), np.asarray(sim["event_phi1"].values, float),
                           kinds, d)
    if "event_times_s" in sim.attrs and "event_kinds" in sim.attrs and "time" in sim.variables:
        times = np.atleast_1d(np.asarray(sim.attrs["event_times_s"], dtype=float))
        labels = [k for k in str(sim.attrs["event_kinds"]).split(",") if k]
        if len(labels) != times.size:
            return None
        t = np.asarray(sim["time"].values, float)
        phi = np.interp(times, t, np.asarray(sim["phi1"].values, float))
        kinds = np.array(["contact" if k.startswith("land") else "separation" for k in labels], dtype=object)
        # the step the contact's impulse causes: omega2 less the cam law's over the impact (at most
        # IMPULSE_S; a persistent contact then follows the law and adds nothing)
        rel = np.asarray(sim["omega2"].values, float) - np.asarray(sim.get("omega2_kin", 0.0 * sim["omega2"]).values, float)
        d = np.full(times.size, np.nan)
        for i in np.flatnonzero(kinds == "contact"):
            end = min(times[i + 1] if i + 1 < times.size else t[-1], times[i] + IMPULSE_S)
            d[i] = np.interp(end, t, rel) - np.interp(times[i], t, rel)
        return EventRecord(times, phi, kinds, d)
    return None


def _by_revolution(t_ev, phi_ev, revs: range):
    """Split events (time, unwrapped phi1) into the revolutions ``revs`` (phi1 in [2 pi k, 2 pi (k+1)))."""
    out = []
    for k in revs:
        sel = (phi_ev >= TWO_PI * k) & (phi_ev < TWO_PI * (k + 1))
        out.append((t_ev[sel], phi_ev[sel] - TWO_PI * k))
    return out


def predicted(sim: xr.Dataset, steady: range, det: impacts.Detector, threshold: float) -> dict | None:
    """Predicted event statistics over the model's steady revolutions ``steady`` (indices k)."""
    rec = model_events(sim)
    if rec is None:
        return None
    c = rec.contacts
    per_rev_all = _by_revolution(rec.time[c], rec.phi1[c], steady)
    sep = ~c
    flights = _by_revolution(rec.time[sep], rec.phi1[sep], steady)
    t_vis, d_vis = impacts.visible_events(rec.time[c], rec.d_omega2[c], threshold, det.resolution_s)
    phi_vis = np.interp(t_vis, rec.time[c], rec.phi1[c]) if t_vis.size else t_vis
    jumps = impacts.jump_starts(t_vis, det.sequence_gap_s)
    angles, jump_angles = [], []
    for k in steady:
        sel = (phi_vis >= TWO_PI * k) & (phi_vis < TWO_PI * (k + 1))
        angles.append(np.sort(phi_vis[sel] - TWO_PI * k))
        jump_angles.append(np.sort(phi_vis[sel & jumps] - TWO_PI * k))
    out = impacts.per_revolution(angles, jump_angles)
    out["detectable_impacts_per_rev"] = out["impacts_per_rev"]
    out["impacts_per_rev"] = float(np.mean([len(t) for t, _ in per_rev_all])) if per_rev_all else None
    out["flights_per_rev"] = float(np.mean([len(t) for t, _ in flights])) if flights else None
    return out


def kinematic_epsilon2(phi1: np.ndarray, omega1: np.ndarray, mech, program) -> np.ndarray:
    """epsilon2 (rad/s^2) the cam law imposes at cam angle phi1 (rad) and speed omega1 (rad/s)."""
    from models.mechanism.kinematics import follower_motion
    _, _, eps2, _ = follower_motion(program, mech, phi1, omega1, np.zeros_like(phi1))
    return eps2


def _pieces(t: np.ndarray, *arrays):
    """Contiguous pieces (no time gap, all finite) of a block's samples."""
    ok = np.isfinite(t)
    for a in arrays:
        ok &= np.isfinite(a)
    dt = np.diff(t)
    step = float(np.median(dt)) if dt.size else 0.0
    cut = np.flatnonzero((np.diff(ok.astype(int)) != 0) | (dt > 1.5 * step)) + 1
    for sl in np.split(np.arange(t.size), cut):
        if sl.size >= 64 and ok[sl[0]]:
            yield sl


def measured(cycles, det: impacts.Detector, mech, program) -> dict:
    """Visible impacts and jumps in every whole revolution of ``cycles`` (align.MeasuredCycles with
    its ``blocks``), their cycle statistics, the detectability threshold (rad/s) and the normal
    channel's check. Needs epsilon2, omega2, phi1 (and aE_n for the check) over time."""
    found, noise, peak = [], [], 0.0
    for block in cycles.blocks:
        if "epsilon2" not in block or "phi1" not in block:
            continue
        t = np.asarray(block["time"].values, float)
        e2 = np.asarray(block["epsilon2"].values, float)
        th = np.asarray(block["phi1"].values, float)
        for sl in _pieces(t, e2, th):
            theta = np.unwrap(th[sl])
            w1 = np.gradient(theta, t[sl])
            n_avg = max(int(0.05 * TWO_PI / max(float(np.median(np.abs(np.diff(theta)))), 1e-9)), 1)
            w1 = np.convolve(w1, np.ones(n_avg) / n_avg, mode="same")
            ref = kinematic_epsilon2(np.mod(theta, TWO_PI), w1, mech, program)
            r = e2[sl] - ref
            peak = max(peak, float(np.max(np.abs(ref))))
            noise.append(impacts.prepare(r, det)[:: max(1, r.size // 5000)])
            found.append((block, sl, r))
    threshold = impacts.threshold_step(np.concatenate(noise), peak, det) if noise else math.nan
    times, steps, checks, jump_t = [], [], [], []
    for block, sl, r in found:
        t = np.asarray(block["time"].values, float)[sl]
        tt, dd, jj = impacts.detect_impacts(r, det, threshold)
        times.append(t[0] + tt)
        jump_t.append(t[0] + jj)
        steps.append(dd)
        if "aE_n" in block and "omega2" in block:
            checks.append(impacts.normal_consistency(t[0] + tt, dd, t, np.asarray(block["omega2"].values, float)[sl],
                                                     np.asarray(block["aE_n"].values, float)[sl], mech.DE, det))
    t_all = np.concatenate(times) if times else np.empty(0)
    j_all = np.concatenate(jump_t) if jump_t else np.empty(0)
    angles, jump_angles = [], []
    for row in cycles.time:
        period_end = row[-1] + (row[-1] - row[0]) / (row.size - 1)
        sel = (t_all >= row[0]) & (t_all < period_end)
        grid = np.append(cycles.grid, TWO_PI)
        ang = np.interp(t_all[sel], np.append(row, period_end), grid)
        order = np.argsort(ang)
        angles.append(ang[order])
        jsel = (j_all >= row[0]) & (j_all < period_end)
        jump_angles.append(np.sort(np.interp(j_all[jsel], np.append(row, period_end), grid)))
    out = impacts.per_revolution(angles, jump_angles)
    chk = np.concatenate(checks) if checks else np.empty(0)
    chk = chk[np.isfinite(chk)]
    out.update(threshold_rad_s=threshold, threshold_m_s=threshold * mech.DE if math.isfinite(threshold) else None,
               normal_check_median=float(np.median(chk)) if chk.size else None, normal_check_n=int(chk.size),
               detector=det.describe(threshold))
    return out
