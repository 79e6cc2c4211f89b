"""Which recorded channel reads the tangential and which the normal acceleration, and their signs.

A recording from another stand may hold aE_t and aE_n swapped, or a sensor mounted the other way
round (one sign inverted). Processed as labelled, a swap gives omega2 from the normal acceleration
and an inversion gives -omega2 or a normal acceleration below zero: wrong answers that look like
answers. This module finds them from the data before processing starts.

Evidence: over a span of whole revolutions at the start of the longest segment, each channel's
reading is averaged per cam angle (BINS angles; the noise averages out) and kept to the first
HARMONICS harmonics of the cam frequency, where the motion law's acceleration lies (the impacts in
the groove's backlash and the follower's bending mode lie above: with them the tangential reading of
the simulated stand's twin correlates only 0.6-0.7 with the ideal one, without them 0.99), and
compared with what an ideal sensor at E reads at the measured speed, kept to the same harmonics
(docs/architecture.md's signs; labtool.models.mechanism.sensor_point):

    tangential  T(phi1) = psi'' DE omega1^2 + g cos(phi2),
    normal      N(phi1) = psi'^2 DE omega1^2 - g sin(phi2)     (>= -g sin(phi2): omega2^2 DE >= 0).

Pearson's r of each candidate channel with T and N (offset and gain free, sign kept) decides, for
the two arrangements (as labelled, swapped), which channel is which and with what sign. A correction
is made only on strong evidence (both |r| >= R_CONCLUSIVE, the other arrangement's fit poorer by
MARGIN); otherwise the channels are processed as labelled and the result says how well they fit.

What the data cannot tell:
- below ~30 rpm on the STB-216 gravity dominates both readings and T and N have nearly one shape
  (|r(T, N)| > TEMPLATES_ALIKE): neither a swap nor a sign can be told; said so;
- without a tacho, the cam angle comes from aE_t itself; on a cam whose return mirrors its rise
  (psi(phi1 + pi) = h - psi(phi1), the STB-216) an inverted aE_t equals the right one half a turn
  later, so the cam angle and aE_t's sign are known only together: the marks assume aE_t positive
  along the rise (``mirror_symmetric`` says when this holds; the pipeline states it).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from labtool.common.errors import InputError
from labtool.models.mechanism import sensor_point
from labtool.processing import cam_angle

BINS = 360                 # cam-angle bins of the averaged readings
HARMONICS = 20             # harmonics of the cam frequency compared: the motion law's band
R_CONCLUSIVE = 0.9         # |r| of both channels with their templates for a finding
MARGIN = 0.5               # the other arrangement's |r| sum must be this much lower for a swap
TEMPLATES_ALIKE = 0.5      # |r(T, N)| above which the readings cannot be told apart
R_FIT = 0.8                # below this, the channels as labelled do not read as the kinematics predicts
CHANNELS = ("aE_t", "aE_n")


@dataclasses.dataclass(frozen=True)
class Finding:
    """What the channel check found; ``swap`` and ``signs`` are what to apply to the channels as
    labelled (after any --channels and --invert): swap aE_t and aE_n, then multiply by signs."""
    verdict: str                  # "as labelled", "corrected", "inconclusive", "not checked"
    swap: bool
    signs: tuple                  # (tangential, normal): +1 or -1
    r: dict                       # "aE_t~T", "aE_t~N", "aE_n~T", "aE_n~N": Pearson's r (None if not computed)
    templates_r: float | None     # r(T, N) at the measured speed
    marks: str                    # where the span's cam angle came from: "tacho" or "correlation"
    revolutions: int              # whole revolutions averaged in the span
    text: str                     # the finding and its evidence, in words

    @property
    def changes(self) -> bool:
        return self.swap or self.signs != (1, 1)

    def what(self) -> str:
        """'aE_t and aE_n swapped, aE_n inverted' (the correction in words), '' if none."""
        parts = ["aE_t and aE_n swapped"] if self.swap else []
        parts += [f"{name} inverted" for name, s in zip(CHANNELS, self.signs) if s < 0]
        return ", ".join(parts)


def check(x_t: np.ndarray, x_n: np.ndarray, first: int, fs: float, mech, program, tacho_marks=None,
          search=None) -> Finding:
    """The channel check on a span of the recording.

    x_t, x_n: the channels labelled aE_t and aE_n over the span (m/s^2, Ka and any --invert applied),
    starting at sample ``first``; fs (Hz); tacho_marks: the tacho's revolution marks in the span
    (samples), None without a tacho; search: cam_angle.Search for the correlation's period.
    """
    x = {"aE_t": np.asarray(x_t, dtype=float), "aE_n": np.asarray(x_n, dtype=float)}
    arrangements = {False: ("aE_t", "aE_n"), True: ("aE_n", "aE_t")}    # swap -> (tangential, normal)
    fits, templates_r, how, revs = {}, None, "tacho" if tacho_marks is not None else "correlation", 0
    for swap, (tan, nor) in arrangements.items():
        marks = tacho_marks if tacho_marks is not None else _correlation_marks(x[tan], first, fs, mech, program, search)
        if marks is None or len(marks) < 2:
            continue
        per = float(np.median(np.diff(marks)))
        t_avg, n_avg = (_band(_averaged(x[c], first, marks, per)) for c in (tan, nor))
        T, N = (_band(v) for v in templates(mech, program, 2.0 * math.pi * fs / per, len(t_avg)))
        templates_r = _r(T, N)
        fits[swap] = (_r(t_avg, T), _r(n_avg, N))
        revs = max(revs, len(marks) - 1)
    r = {f"{c}~{k}": None for c in CHANNELS for k in "TN"}
    if False in fits:
        r["aE_t~T"], r["aE_n~N"] = fits[False]
    if True in fits:
        r["aE_n~T"], r["aE_t~N"] = fits[True]
    base = dict(r=r, templates_r=templates_r, marks=how, revolutions=revs)
    if not fits:
        return Finding("not checked", False, (1, 1), text="no whole revolution found in the span checked",
                       **base)
    evidence = _evidence(r, templates_r, how, revs)
    if templates_r is not None and abs(templates_r) > TEMPLATES_ALIKE:
        return Finding("not checked", False, (1, 1), text="at this speed gravity's reading dominates both channels "
                       f"and the two readings have nearly one shape (r(T, N) = {templates_r:+.2f}): which channel is "
                       f"which, and their signs, cannot be told ({evidence})", **base)
    score = {s: abs(f[0]) + abs(f[1]) for s, f in fits.items()}
    best = max(score, key=score.get)
    fit = fits[best]
    other = score.get(not best, 0.0)
    strong = min(abs(fit[0]), abs(fit[1])) >= R_CONCLUSIVE and (not best or score[best] - other >= MARGIN)
    signs = (int(math.copysign(1, fit[0])), int(math.copysign(1, fit[1])))
    if strong and not best and signs == (1, 1):
        return Finding("as labelled", False, (1, 1), text=f"the channels read as labelled ({evidence})", **base)
    if strong:
        found = Finding("corrected", best, signs, text="", **base)
        return dataclasses.replace(found, text=f"{found.what()}: corrected ({evidence})")
    straight = fits.get(False, (0.0, 0.0))
    if min(straight) >= R_FIT:
        return Finding("as labelled", False, (1, 1), text=f"the channels read as labelled, not conclusively "
                       f"({evidence})", **base)
    return Finding("inconclusive", False, (1, 1), text="the channels do not read as the kinematics predicts, nor "
                   f"as a swap or an inversion of them ({evidence}): processed as labelled", **base)


def templates(mech, program, omega1: float, n: int):
    """(T, N): the tangential and normal readings of an ideal sensor at E (m/s^2) at n cam angles
    2 pi (k + 1/2) / n (the bins' centres), at the cam speed omega1 (rad/s)."""
    phi1 = 2.0 * math.pi * (np.arange(n) + 0.5) / n
    psi, dpsi, ddpsi, _ = program(phi1)
    g_t, g_n = sensor_point.gravity_reading(mech.phiD + mech.psi0 + psi, mech.g)
    aE_t, aE_n = sensor_point.acceleration_at_E(mech.DE, dpsi * omega1, ddpsi * omega1**2)
    return aE_t + g_t, aE_n + g_n


def mirror_symmetric(program, n: int = 720) -> bool:
    """True when the cam's return mirrors its rise half a turn later (psi(phi1 + pi) = h - psi(phi1)):
    then an inverted aE_t reads as the right one half a turn on, and without a tacho the cam angle
    and aE_t's sign are known only together."""
    phi1 = 2.0 * math.pi * np.arange(n) / n
    psi = program(phi1)[0]
    later = program(np.mod(phi1 + math.pi, 2.0 * math.pi))[0]
    h = float(psi.max() - psi.min())
    return bool(h > 0 and np.max(np.abs(psi + later - psi.min() - later.min() - h)) < 1e-6 * h)


def _correlation_marks(x, first, fs, mech, program, search):
    """Revolution marks of the span by the matched filter (cam_angle.CorrelationEdges), None if none."""
    q = search.decimation(fs)
    try:
        per = cam_angle.estimate_period(cam_angle.block_mean(x, q), fs, (search.rpm_lo, search.rpm_hi), q)
    except InputError:
        return None
    return cam_angle.CorrelationEdges(mech, program, per, fs, q).feed(first, x, first, first + len(x))


def _averaged(x, first, marks, period) -> np.ndarray:
    """Mean of x per cam-angle bin over the whole revolutions between the first and last mark."""
    a, b = int(math.ceil(marks[0])) - first, int(math.floor(marks[-1])) - first
    n_bins = int(min(BINS, max(8, period // 4)))
    phi1, _ = cam_angle.phi1_from_marks(np.arange(a, b, dtype=float) + first, np.asarray(marks), period)
    k = np.minimum((phi1 * (n_bins / (2.0 * math.pi))).astype(np.int64), n_bins - 1)
    count = np.bincount(k, minlength=n_bins)
    return np.bincount(k, weights=x[a:b], minlength=n_bins) / np.maximum(count, 1)


def _band(v: np.ndarray) -> np.ndarray:
    """One revolution's readings kept to harmonics 1..HARMONICS of the cam frequency (circular)."""
    f = np.fft.rfft(v)
    f[0] = 0.0
    f[HARMONICS + 1:] = 0.0
    return np.fft.irfft(f, len(v))


def _r(a, b) -> float:
    a, b = a - a.mean(), b - b.mean()
    den = math.sqrt(float(np.dot(a, a)) * float(np.dot(b, b)))
    return float(np.dot(a, b) / den) if den > 0 else 0.0


def _evidence(r, templates_r, how, revs) -> str:
    """'r with the kinematics' readings over 6 revolutions (cam angle by tacho): aE_t~T +0.99, ...'"""
    shown = ", ".join(f"{k} {v:+.2f}" for k, v in r.items() if v is not None)
    return (f"correlation with an ideal sensor's tangential (T) and normal (N) readings over {revs} revolutions, "
            f"cam angle by {how}: {shown}")


MAX_SPAN = 1 << 22         # samples read for the check, at most


def check_recording(rec, segs, mech, program, rpm_hint, invert=(), tacho_channel: str = "tacho", warn=None):
    """The check on the start of ``rec``'s longest segment, a conclusive swap applied to ``rec`` (its
    channels renamed); returns the history step, whose ``signs`` (aE_t, aE_n) multiply the Ka:
    --invert's (``invert``: chain names) and the check's. ``warn`` hears a correction, a poor fit and
    a check that cannot be made, with the option that states it."""
    from labtool.common import history as H

    warn = warn or (lambda msg: None)
    fs = rec.sample_rate_hz
    user = {c: -1 if c in invert else 1 for c in CHANNELS}
    a0, b0 = max(segs, key=lambda s: s[1] - s[0])
    search = cam_angle.search_range(rpm_hint, mech)
    b = min(b0, a0 + search.window(fs), a0 + MAX_SPAN)
    block = rec.read(a0, b)
    col = {c: rec.channel_index(c) for c in CHANNELS}
    tacho = None
    if rec.has_channel(tacho_channel):
        tacho = cam_angle.TachoEdges().feed(a0, block[:, rec.channel_index(tacho_channel)])
        tacho = tacho if len(tacho) >= 2 else None
    found = check(block[:, col["aE_t"]] * user["aE_t"], block[:, col["aE_n"]] * user["aE_n"], a0, fs, mech, program,
                  tacho, search)
    if found.swap:
        names = list(rec.channel_names)
        rec.rename_channels({"aE_t": names[col["aE_n"]], "aE_n": names[col["aE_t"]]})
        user = {"aE_t": user["aE_n"], "aE_n": user["aE_t"]}
    signs = (user["aE_t"] * found.signs[0], user["aE_n"] * found.signs[1])
    inverted = [c for c, s in zip(CHANNELS, signs) if s < 0]
    src = rec.source
    if found.verdict == "corrected":
        label = {c: rec.file_names[rec.channel_index(c)] for c in CHANNELS}
        options = []
        if found.swap:
            options.append(f"--channels aE_t={label['aE_t']},aE_n={label['aE_n']}")
        if inverted:
            options.append(f"--invert {','.join(inverted)}")
        warn(f"{src}: {found.text}; processed as corrected (to state it yourself: {' '.join(options)})")
    elif found.verdict == "inconclusive":
        warn(f"{src}: {found.text}; check the law (--law), the mechanism (--mechanism), the channels (--channels) "
             "and the sensor's orientation (--invert)")
    elif found.verdict == "not checked" and found.templates_r is not None:
        warn(f"{src}: channels not checked: {found.text}")
    step = H.CheckChannels(verdict=found.verdict, swapped=found.swap, inverted=inverted,
                           inverted_by_option=[c for c in CHANNELS if c in invert], r=found.r,
                           templates_r=found.templates_r, marks=found.marks, revolutions=found.revolutions,
                           finding=found.text)
    return step, signs
