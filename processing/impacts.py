"""Impacts and jumps of the follower, found in the measured signals (pure functions).

An impact of the roller on a flank of the groove changes the follower's angular velocity omega2 by
a step d_omega2 in a time (the contact, ~0.1-1 ms) shorter than the processing low-pass resolves.
Behind the processing's zero-phase low-pass (cutoff fc) the tangential acceleration shows it as the
filter's impulse response times d_omega2, centred on the impact. The detector:

1. residual r = epsilon2 - epsilon2_reference (rad/s^2): the measured acceleration less the one the
   cam law imposes at the measured cam angle and speed;
2. x = r band-limited to ``band_hz`` = min(fc, half the follower's first structural mode, 1.2 kHz:
   ``MODE_HZ``), so that the mode's ringing after an impact (the processing low-pass lets it through
   once fc nears it: 833 Hz at 500 rpm) is not taken for more impacts, less its own low-pass at
   band / 4 (zero-phase): what is left of the slow departures from the law (a flight through the
   backlash lasts several pulse widths) is small, an impact's pulse stays;
3. CLEAN (Hoegbom's deconvolution): the largest |x| is an impact; its step is x / h(0), with h the
   pulse of a unit step through the same two filters (``pulse_kernel``); the pulse is subtracted at
   its sub-sample position and the search repeats until |x| < ``k_sigma`` robust standard
   deviations of x. So rebounds that follow each other closer than one pulse width are still
   separated where they can be, and a pulse's side lobes are never counted as impacts.

The threshold in velocity-step units (rad/s) is the *detectability* of the recording: the
smallest step the chain shows above its noise. ``visible_events`` applies it, and the detector's
resolution, to a model's event record, so that measured and predicted counts mean the same thing.

Jumps (contact losses) are not seen directly: a flight through the backlash shows only by the
impact that ends it. A *jump* here is the start of a sequence of visible impacts: the first visible
impact after at least ``sequence_gap_s`` without one (a lift-off from persistent contact); the
impacts that follow it closer than that are its rebounds.

The normal channel checks the tangential finding: a step d_omega2 at omega2 changes the normal
acceleration DE omega2^2 by DE ((omega2 + d_omega2)^2 - omega2^2); ``normal_consistency`` compares
that with the measured change of aE_n across each impact.
"""
from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from labtool.models.mechanism import sensor_point

DEFAULT_K_SIGMA = 8.0          # detection threshold in robust standard deviations of x (as the spike detector)
DEFAULT_SEQUENCE_GAP_S = 5e-3  # a quiet time longer than this starts a new jump
FLOOR_FRACTION = 0.05          # smallest visible pulse, fraction of the cam law's peak |epsilon2|
SIDE_S = 2e-3                  # side windows of the normal channel's check (s)
# the follower's first bending mode (Hz): the chain's resonance of the simulated stand and the twin's
# mode (1.2 kHz clamped, 1.39 kHz in flight; docs/twin.md). The detector keeps below half of it, where
# an order-4 zero-phase low-pass leaves 1/257 of the ring (docs/reports.md)
MODE_HZ = 1200.0
MODE_BAND_FRACTION = 0.5
# dynamic range next to a large step: a step smaller than SHADOW_RATIO of a larger one closer than
# SHADOW_RESOLUTIONS resolutions is not told apart from that one's pulse, whose shape departs from
# the kernel's by ~10 % for a real impact sequence (contact durations, the flight's drift). 1.5 = the
# resolution plus the ~0.5 resolution by which CLEAN misplaces such a weak component: the rigid
# truth's rebounds, 0.77 resolution after the impact, came out at 1.3-1.4 as 7-14 % (docs/reports.md)
# where the cam law's |epsilon2| is below this fraction of its peak (the dwells, where it is 0) a
# flight does not depart from it: a component there is an impact whatever its sign. Small, for the
# law changes sign at the middle of a rise where the follower lifts off and its drift begins
LAW_QUIET = 1e-3
SHADOW_RATIO = 0.15
SHADOW_RESOLUTIONS = 1.5


@dataclasses.dataclass(frozen=True)
class Detector:
    """Detector settings for one recording: sample rate (Hz), the processing low-pass (Hz, order)."""

    fs: float
    cutoff_hz: float
    order: int = 4
    k_sigma: float = DEFAULT_K_SIGMA
    sequence_gap_s: float = DEFAULT_SEQUENCE_GAP_S
    mode_hz: float = MODE_HZ

    @property
    def band_hz(self) -> float:
        """The detector's band (Hz): the processing low-pass, at most half the structural mode."""
        return min(self.cutoff_hz, MODE_BAND_FRACTION * self.mode_hz)

    @property
    def resolution_s(self) -> float:
        """Impacts closer than this (s) are one visible impact: half a pulse width, 1 / (2 band)."""
        return 0.5 / self.band_hz

    def describe(self, threshold: float | None = None) -> str:
        thr = "" if threshold is None or not math.isfinite(threshold) else f"; visible: |d omega2| >= {threshold:.3g} rad/s"
        return (f"CLEAN deconvolution of the measured epsilon2 minus the kinematic epsilon2 by the pulse of a velocity "
                f"step through the processing low-pass ({self.cutoff_hz:.0f} Hz){self._band_text()}, threshold {self.k_sigma:g} robust "
                f"sigma{thr}; impacts closer than {1e3 * self.resolution_s:.2f} ms are one; a jump = the first visible "
                f"impact after {1e3 * self.sequence_gap_s:g} ms without one")

    def _band_text(self) -> str:
        if self.band_hz >= self.cutoff_hz:
            return ""
        return f" and the detector's own at {self.band_hz:.0f} Hz (half the {self.mode_hz:.0f} Hz structural mode)"

    def kernel(self) -> np.ndarray:
        return pulse_kernel(self.fs, self.cutoff_hz, self.order, self.mode_hz)


def _band(x: np.ndarray, det: Detector) -> np.ndarray:
    """x limited to the detector's band (zero-phase low-pass at ``band_hz`` when it is below the
    processing's), less its zero-phase low-pass at band / 4 (the slow departures from the cam law)."""
    from labtool.processing.filters import lowpass_sos, zero_phase
    if det.band_hz < det.cutoff_hz:
        x = zero_phase(lowpass_sos(det.fs, det.band_hz, det.order), x)
    return x - zero_phase(lowpass_sos(det.fs, 0.25 * det.band_hz, det.order), x)


@functools.lru_cache(maxsize=16)
def pulse_kernel(fs: float, cutoff_hz: float, order: int = 4, mode_hz: float = MODE_HZ) -> np.ndarray:
    """What a velocity step of 1 rad/s at sample 0 looks like in the detector's x (rad/s^2), on
    samples -L..L (odd length, centre = the step): an impulse of area 1 through the processing
    low-pass and the detector's band (``_band``), all zero-phase."""
    from labtool.processing.filters import lowpass_sos, zero_phase
    det = Detector(fs, cutoff_hz, order, mode_hz=mode_hz)
    half = int(math.ceil(6.0 * fs / det.band_hz))
    imp = np.zeros(8 * half + 1)
    imp[4 * half] = fs                               # area 1 (rad/s) over one sample
    y = zero_phase(lowpass_sos(fs, cutoff_hz, order), imp)
    y = _band(y, det)
    out = y[3 * half: 5 * half + 1].copy()
    out.setflags(write=False)
    return out


def noise_level(x: np.ndarray) -> float:
    """Robust standard deviation (1.4826 MAD) of x, on at most ~50k samples."""
    sub = x[:: max(1, x.size // 50_000)]
    sub = sub[np.isfinite(sub)]
    if sub.size == 0:
        return math.nan
    return float(1.4826 * np.median(np.abs(sub - np.median(sub))))


def prepare(residual: np.ndarray, det: Detector) -> np.ndarray:
    """The detector's x from the residual r (rad/s^2)."""
    return _band(np.asarray(residual, dtype=float), det)


def threshold_step(x: np.ndarray, reference_peak: float, det: Detector) -> float:
    """The visible velocity step (rad/s) of a record: ``k_sigma`` robust sigma of x, and at least
    the step whose pulse peaks at ``FLOOR_FRACTION`` of the cam law's peak |epsilon2|
    ``reference_peak`` (rad/s^2): below that a pulse is lost among the law's own shape and the
    departures of a real follower from it (as the processing's spike detector's floor)."""
    h = det.kernel()
    h0 = abs(float(h[h.size // 2]))
    return max(det.k_sigma * noise_level(x), FLOOR_FRACTION * abs(reference_peak)) / h0


def detect_impacts(residual: np.ndarray, det: Detector, threshold: float, gain: float = 0.5,
                   max_iterations: int = 20_000, law: np.ndarray | None = None):
    """Impacts in one contiguous record of the residual r (rad/s^2, sampled at det.fs) whose
    velocity step is at least ``threshold`` (rad/s; ``threshold_step``). ``law``: the cam law's
    epsilon2 (rad/s^2) at the same samples, which tells a flight's drift from an impact.

    CLEAN with loop gain ``gain``: each iteration removes that fraction of the largest pulse; the
    components closer than ``det.resolution_s`` are then one impact (steps added, time their
    step-weighted mean). Returns (times in s from the record's first sample, d_omega2 in rad/s,
    times of the jumps in s; ``split_flights``)."""
    x = prepare(residual, det).copy()
    h = det.kernel()
    L = h.size // 2
    h0 = float(h[L])
    n = x.size
    if n < 16 or not (math.isfinite(threshold) and threshold > 0):
        return np.empty(0), np.empty(0), np.empty(0)
    lim = threshold * abs(h0)
    grid = np.arange(-L, L + 1, dtype=float)
    pos, amp = [], []
    for _ in range(max_iterations):
        i = int(np.argmax(np.abs(x)))
        # components are removed at gain < 1, so stop at half the limit: what is left is below it
        if abs(x[i]) < 0.5 * lim:
            break
        frac = 0.0
        if 0 < i < n - 1:              # sub-sample position of the peak (parabola through three samples)
            y0, y1, y2 = x[i - 1], x[i], x[i + 1]
            den = y0 - 2 * y1 + y2
            frac = float(np.clip(0.5 * (y0 - y2) / den, -0.5, 0.5)) if den != 0 else 0.0
        step = gain * float(x[i] / np.interp(-frac, grid, h))
        a, b = max(i - L, 0), min(i + L + 1, n)
        x[a:b] -= step * np.interp(np.arange(a, b) - i - frac, grid, h)
        pos.append(i + frac)
        amp.append(step)
    law_t = None if law is None else (np.arange(n) / det.fs, np.asarray(law, dtype=float))
    t_i, d_i, t_j = split_flights(np.asarray(pos) / det.fs, np.asarray(amp), threshold, det, law_t)
    # CLEAN stops with up to half the limit of a step left in x: each impact's size gets what is left
    # at it (a 0.25 rad/s step at a 0.1 rad/s threshold came out 0.19). Which impacts are visible was
    # decided before, on the components alone, as for a model's record
    return t_i, d_i + np.interp(t_i * det.fs, np.arange(n), x) / h0, t_j


def split_flights(times: np.ndarray, steps: np.ndarray, threshold: float, det: Detector, law=None):
    """Impacts from CLEAN's components (time s, step rad/s).

    A flight through the backlash shows as a gradual change of omega2 away from the cam law (the
    follower keeps its speed while the law's changes: the departure has the sign of -epsilon2 of
    the law), the impact that ends it as an abrupt step back, of the law's sign. Behind the
    low-pass both look like steps. With ``law`` (the cam law's epsilon2 at each component, rad/s^2)
    a component is an impact when it has the law's sign, or where the law hardly accelerates (below
    ``LAW_QUIET`` of its peak, the dwells: a flight there shows no drift), else it is drift. Without it, in
    each sequence (``sequence_gap_s`` apart) the first visible component is the drift when visible
    components of the opposite sign follow, those being the impacts. The first visible component
    of a sequence with an impact starts the jump. Impacts are merged within ``resolution_s`` and
    into a larger neighbour's shadow (``merge_shadowed``). Returns (impact times, impact steps,
    jump times)."""
    t, d = merge_close(times, steps, 0.25 * det.resolution_s)
    law_at = None
    if law is not None and t.size:
        law_at = np.interp(t, np.asarray(law[0], float), np.asarray(law[1], float))
        quiet = np.abs(law_at) < LAW_QUIET * float(np.max(np.abs(law[1])))
    imp_t, imp_d, jumps = [], [], []
    for seq in np.split(np.arange(t.size), np.flatnonzero(np.diff(t) > det.sequence_gap_s) + 1):
        visible = seq[np.abs(d[seq]) >= threshold]
        if visible.size == 0:
            continue
        if law_at is not None:
            imp = visible[quiet[visible] | (np.sign(d[visible]) == np.sign(law_at[visible]))]
        else:
            first = visible[0]
            opp = visible[(visible > first) & (np.sign(d[visible]) == -np.sign(d[first]))]
            # a first component followed by steps back is the flight's drift; without them (a flight
            # in a dwell, where the law does not accelerate, shows nothing) it is an impact itself
            imp = opp if opp.size else visible
        mt, md = merge_shadowed(*merge_close(t[imp], d[imp], det.resolution_s), det.resolution_s)
        keep = np.abs(md) >= threshold
        if keep.any():
            jumps.append(t[visible[0]])
        imp_t.extend(mt[keep])
        imp_d.extend(md[keep])
    return np.asarray(imp_t), np.asarray(imp_d), np.asarray(jumps)


def merge_close(times: np.ndarray, steps: np.ndarray, resolution_s: float):
    """Events closer than ``resolution_s`` (chained) as one: steps added, time the |step|-weighted
    mean. Returns sorted (times, steps)."""
    t = np.asarray(times, dtype=float)
    d = np.asarray(steps, dtype=float)
    ok = np.isfinite(t) & np.isfinite(d)
    t, d = t[ok], d[ok]
    order = np.argsort(t, kind="stable")
    t, d = t[order], d[order]
    if t.size == 0:
        return t, d
    groups = np.concatenate([[0], np.cumsum(np.diff(t) >= resolution_s)])
    n = groups[-1] + 1
    w = np.abs(d)
    tw = np.bincount(groups, weights=t * w, minlength=n)
    ws = np.bincount(groups, weights=w, minlength=n)
    ds = np.bincount(groups, weights=d, minlength=n)
    first = t[np.searchsorted(groups, np.arange(n))]
    return np.where(ws > 0, tw / np.where(ws > 0, ws, 1.0), first), ds


def merge_shadowed(times: np.ndarray, steps: np.ndarray, resolution_s: float, ratio: float = SHADOW_RATIO,
                   resolutions: float = SHADOW_RESOLUTIONS):
    """Steps (sorted times s, rad/s) with those in a larger one's shadow merged into it: a step
    smaller than ``ratio`` x a neighbour closer than ``resolutions`` x ``resolution_s`` is added to
    the largest such neighbour (its time kept), smallest first. Returns (times, steps)."""
    t, d = np.asarray(times, dtype=float).copy(), np.asarray(steps, dtype=float).copy()
    alive = np.ones(t.size, bool)
    for i in np.argsort(np.abs(d), kind="stable"):
        near = alive & (np.abs(t - t[i]) < resolutions * resolution_s) & (np.abs(d) * ratio > abs(d[i]))
        near[i] = False
        if near.any():
            j = np.flatnonzero(near)[np.argmax(np.abs(d[near]))]
            d[j] += d[i]
            alive[i] = False
    return t[alive], d[alive]


def visible_events(times: np.ndarray, d_omega2: np.ndarray, threshold: float, resolution_s: float):
    """A model's impacts as the chain would show them: contacts closer than ``resolution_s`` merged
    (``merge_close``), those in a larger one's shadow merged into it (``merge_shadowed``), then
    those with |d_omega2| >= threshold. Returns (times, d_omega2)."""
    t, d = merge_shadowed(*merge_close(times, d_omega2, resolution_s), resolution_s)
    keep = np.abs(d) >= threshold
    return t[keep], d[keep]


def jump_starts(times: np.ndarray, gap_s: float = DEFAULT_SEQUENCE_GAP_S) -> np.ndarray:
    """Mask of the visible impacts that start a jump: the first one, and each one after more than
    ``gap_s`` without a visible impact (``times`` sorted, s)."""
    t = np.asarray(times, dtype=float)
    if t.size == 0:
        return np.zeros(0, bool)
    return np.concatenate([[True], np.diff(t) > gap_s])


def normal_consistency(t_impact: np.ndarray, d_omega2: np.ndarray, time: np.ndarray, omega2: np.ndarray,
                       aE_n: np.ndarray, DE: float, det: Detector) -> np.ndarray:
    """Measured over predicted change of the normal acceleration across each impact (1 = the
    normal channel confirms the tangential step; NaN where the predicted change is below 5 % of
    the record's aE_n range, e.g. in a dwell where omega2 ~ 0)."""
    out = np.full(np.size(t_impact), np.nan)
    time = np.asarray(time, float)
    span = float(np.nanmax(aE_n) - np.nanmin(aE_n)) if np.size(aE_n) else 0.0
    w1, w2 = 2 * det.resolution_s, 2 * det.resolution_s + SIDE_S
    for k, (t0, d) in enumerate(zip(np.atleast_1d(t_impact), np.atleast_1d(d_omega2))):
        left = (time >= t0 - w2) & (time <= t0 - w1)
        right = (time >= t0 + w1) & (time <= t0 + w2)
        if not (left.any() and right.any()):
            continue
        w = float(np.mean(omega2[left]))
        pred = float(np.diff(sensor_point.acceleration_at_E(DE, [w, w + d], 0.0)[1])[0])
        if abs(pred) < 0.05 * span or span == 0:
            continue
        out[k] = (float(np.mean(aE_n[right])) - float(np.mean(aE_n[left]))) / pred
    return out


def per_revolution(angles_by_rev: list, jumps_by_rev: list) -> dict:
    """Cycle statistics of events given, for each whole revolution, the cam angles (rad, in
    [0, 2 pi), sorted) of its visible impacts and of its jumps.

    Returns impacts_per_rev and jumps_per_rev (means over the revolutions), first_impact_deg (median
    over the revolutions with an impact of the first one's angle), impact_angles_deg (the angles at
    which an impact recurs: clusters of the pooled angles, gaps > 2 deg apart, present in at least
    half of the revolutions, each as its median angle), and the per-revolution counts."""
    n = len(angles_by_rev)
    if n == 0:
        return {"impacts_per_rev": None, "jumps_per_rev": None, "first_impact_deg": None, "impact_angles_deg": [],
                "revolutions": 0, "impacts_each_rev": [], "jumps_each_rev": []}
    counts = [int(np.size(a)) for a in angles_by_rev]
    jumps = [int(np.size(j)) for j in jumps_by_rev]
    firsts = [math.degrees(float(a[0])) for a in angles_by_rev if np.size(a)]
    pooled = np.sort(np.degrees(np.concatenate([np.asarray(a, float) for a in angles_by_rev]))) if sum(counts) else np.empty(0)
    clusters = []
    if pooled.size:
        cut = np.flatnonzero(np.diff(pooled) > 2.0) + 1
        for grp in np.split(pooled, cut):
            revs_with = sum(1 for a in angles_by_rev if np.any((np.degrees(np.asarray(a, float)) >= grp[0])
                                                                & (np.degrees(np.asarray(a, float)) <= grp[-1])))
            if revs_with >= 0.5 * n:
                clusters.append(float(np.median(grp)))
    return {"impacts_per_rev": float(np.mean(counts)), "jumps_per_rev": float(np.mean(jumps)),
            "first_impact_deg": float(np.median(firsts)) if firsts else None, "impact_angles_deg": clusters,
            "revolutions": n, "impacts_each_rev": counts, "jumps_each_rev": jumps}
