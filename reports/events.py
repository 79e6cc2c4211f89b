"""Jumps and impacts, measured and predicted, with one definition (processing/impacts.py).

Measured: the velocity steps the detector finds in every whole revolution the report read.
Predicted: each model's own event record (``model_events``), seen as the chain would see it
(contacts closer than the detector's resolution merged, those below the recording's detectability
threshold dropped), over the model's steady revolutions. Both go through the same cycle
statistics (``labtool.processing.impacts.per_revolution``).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import xarray as xr

from labtool.processing import impacts

TWO_PI = 2.0 * math.pi
KEYS = ("impacts_per_rev", "jumps_per_rev", "first_impact_deg", "impact_angles_deg")   # summary JSON keys


@dataclasses.dataclass
class EventRecord:
    """A simulation's contact events in the layout of labtool.models.dynamics.events (SI): time (s), phi1 (rad,
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
    """The one place the report reads a model's events: the dataset's event record
    (labtool.models.dynamics.events, the same for every model). None for a simulation without
    one (the kinematic level)."""
    from labtool.common.errors import FileFormatError
    from labtool.models.dynamics import events

    try:
        ev = events.read(sim)
    except FileFormatError:
        return None
    kinds = np.where(events.is_impact(ev), "contact", "separation").astype(object)
    d = np.where(events.is_impact(ev), np.asarray(ev["event_domega2"].values, float), np.nan)
    return EventRecord(np.asarray(ev["event_time"].values, float), np.asarray(ev["event_phi1"].values, float), kinds, d)


def _by_revolution(t_ev, phi_ev, revs: range):
    """Split events (time, unwrapped phi1) into the revolutions ``revs`` (phi1 in [2 pi k, 2 pi (k+1)))."""
    out = []
    for k in revs:
        sel = (phi_ev >= TWO_PI * k) & (phi_ev < TWO_PI * (k + 1))
        out.append((t_ev[sel], phi_ev[sel] - TWO_PI * k))
    return out


def motion_starts(program) -> np.ndarray:
    """Cam angles (rad) where the law's motion begins: the start of every rise and return."""
    out, a = [], 0.0
    for seg in program.segments:
        if seg.kind in ("rise", "return"):
            out.append(a)
        a += seg.beta
    return np.asarray(out)


def hidden_pickups(t, phi1, flight_start, starts, omega1: float, resolution_s: float) -> np.ndarray:
    """Mask of the contacts a detector cannot see although their step is large: a follower resting
    in the gap (its flight began before the law's motion did) picked up by the moving flank less
    than ``resolution_s`` after the law began to move. The motion it missed and the step that
    catches it up lie inside one pulse and cancel in the band (twin, 500 rpm: 0.34 rad/s at 2.2 deg,
    0.73 ms after the rise began, shows as two components of 0.15 and 0.10 rad/s of opposite sign).
    t, flight_start in s; phi1, starts in rad; omega1 the cam speed (rad/s)."""
    t, phi1 = np.asarray(t, float), np.asarray(phi1, float)
    if t.size == 0 or len(starts) == 0 or not omega1 > 0:
        return np.zeros(t.size, bool)
    since = np.min(np.mod(np.mod(phi1, TWO_PI)[:, None] - np.asarray(starts)[None, :], TWO_PI), axis=1) / omega1
    return (since < resolution_s) & (np.asarray(flight_start, float) < t - since)


def flight_starts(t_contact, t_separation) -> np.ndarray:
    """For each contact (s), the time of the separation that began its flight (-inf without one)."""
    ts = np.sort(np.asarray(t_separation, float))
    i = np.searchsorted(ts, np.asarray(t_contact, float), side="left") - 1
    return np.where(i >= 0, ts[np.maximum(i, 0)] if ts.size else -np.inf, -np.inf)


def visible_statistics(t: np.ndarray, phi1: np.ndarray, d_omega2: np.ndarray, det: impacts.Detector,
                       threshold: float, spans, by: str = "phi1", hidden=None) -> dict:
    """Cycle statistics of the contacts (time s, unwrapped cam angle rad, d_omega2 rad/s) the chain
    could see: merged within the detector's resolution and into a larger neighbour's shadow,
    |d_omega2| >= ``threshold`` (``impacts.visible_events``), none of the ``hidden`` ones (mask,
    ``hidden_pickups``), jumps as the starts of their sequences; per revolution for each span (lo,
    hi) of ``by`` ("phi1": unwrapped cam angle, rad; "time": s), the angle of an event being its cam
    angle modulo a turn. The one definition of a visible impact for the models' predictions and for
    a known truth (``truth_statistics``)."""
    t, phi1, d = (np.asarray(a, dtype=float) for a in (t, phi1, d_omega2))
    if hidden is not None:
        d = np.where(hidden, 0.0, d)
    t_vis, _ = impacts.visible_events(t, d, threshold, det.resolution_s)
    phi_vis = np.interp(t_vis, t, phi1) if t_vis.size else t_vis
    jumps = impacts.jump_starts(t_vis, det.sequence_gap_s)
    key = phi_vis if by == "phi1" else t_vis
    angles, jump_angles = [], []
    for lo, hi in spans:
        sel = (key >= lo) & (key < hi)
        angles.append(np.sort(np.mod(phi_vis[sel], TWO_PI)))
        jump_angles.append(np.sort(np.mod(phi_vis[sel & jumps], TWO_PI)))
    return impacts.per_revolution(angles, jump_angles)


def predicted(sim: xr.Dataset, steady: range, det: impacts.Detector, threshold: float,
              program=None) -> dict | None:
    """Predicted event statistics over the model's steady revolutions ``steady`` (indices k);
    ``program``: the cam program, whose motion starts ``hidden_pickups`` needs."""
    rec = model_events(sim)
    if rec is None:
        return None
    c = rec.contacts
    per_rev_all = _by_revolution(rec.time[c], rec.phi1[c], steady)
    sep = ~c
    flights = _by_revolution(rec.time[sep], rec.phi1[sep], steady)
    starts = motion_starts(program) if program is not None else ()
    hidden = hidden_pickups(rec.time[c], rec.phi1[c], flight_starts(rec.time[c], rec.time[sep]), starts,
                            _mean_speed(rec.time, rec.phi1), det.resolution_s)
    out = visible_statistics(rec.time[c], rec.phi1[c], rec.d_omega2[c], det, threshold,
                             [(TWO_PI * k, TWO_PI * (k + 1)) for k in steady], hidden=hidden)
    out["detectable_impacts_per_rev"] = out["impacts_per_rev"]
    out["impacts_per_rev"] = float(np.mean([len(t) for t, _ in per_rev_all])) if per_rev_all else None
    out["flights_per_rev"] = float(np.mean([len(t) for t, _ in flights])) if flights else None
    return out


def _mean_speed(t, phi1) -> float:
    """Mean cam speed (rad/s) of an event record, from its first and last rows."""
    t, phi1 = np.asarray(t, float), np.asarray(phi1, float)
    return float((phi1[-1] - phi1[0]) / (t[-1] - t[0])) if t.size > 1 and t[-1] > t[0] else math.nan


def truth_statistics(record: dict, cycles, det: impacts.Detector, threshold: float, program=None) -> dict:
    """A known truth's events (the arrays of labtool.models.dynamics.events, e.g. the simulated stand's
    ``labtool.acquisition.signal_chain.truth_events``; times from the recording's first sample) over the
    measured whole revolutions of ``cycles`` (by time), with the same visibility as the measured and
    predicted ones: what the detector should find. ``program`` as for ``predicted``."""
    t_all, phi_all = np.asarray(record["event_time"], float), np.asarray(record["event_phi1"], float)
    c = np.asarray(record["event_kind"]).astype(str) == "contact"
    spans = [(row[0], row[-1] + (row[-1] - row[0]) / (row.size - 1)) for row in cycles.time]
    starts = motion_starts(program) if program is not None else ()
    hidden = hidden_pickups(t_all[c], phi_all[c], flight_starts(t_all[c], t_all[~c]), starts,
                            _mean_speed(t_all, phi_all), det.resolution_s)
    out = visible_statistics(t_all[c], phi_all[c], record["event_domega2"][c], det, threshold, spans, by="time",
                             hidden=hidden)
    t = t_all[c]
    out["contacts_per_rev"] = float(np.mean([np.sum((t >= a) & (t < b)) for a, b in spans])) if spans else None
    return out


def kinematic_epsilon2(phi1: np.ndarray, omega1: np.ndarray, mech, program) -> np.ndarray:
    """epsilon2 (rad/s^2) the cam law imposes at cam angle phi1 (rad) and speed omega1 (rad/s)."""
    from labtool.models.mechanism.kinematics import follower_motion
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
            n_avg = min(max(int(0.05 * TWO_PI / max(float(np.median(np.abs(np.diff(theta)))), 1e-9)), 1), sl.size)
            w1 = np.convolve(w1, np.ones(n_avg) / n_avg, mode="same")
            ref = kinematic_epsilon2(np.mod(theta, TWO_PI), w1, mech, program)
            r = e2[sl] - ref
            peak = max(peak, float(np.max(np.abs(ref))))
            noise.append(impacts.prepare(r, det)[:: max(1, r.size // 5000)])
            found.append((block, sl, r, ref))
    threshold = impacts.threshold_step(np.concatenate(noise), peak, det) if noise else math.nan
    times, steps, checks, jump_t = [], [], [], []
    for block, sl, r, law in found:
        t = np.asarray(block["time"].values, float)[sl]
        tt, dd, jj = impacts.detect_impacts(r, det, threshold, law=law)
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
