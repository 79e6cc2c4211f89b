"""From the accelerations at E to the follower's epsilon2 and omega2 (pure functions).

Sign conventions (docs/architecture.md): aE_t positive along increasing psi (rise), aE_n positive towards D,
epsilon2 = aE_t / DE (rad/s^2), omega2 positive in the rise; the relation between the accelerations
at E, the follower's motion and gravity's reading is labtool.models.mechanism.sensor_point.

Gravity: an accelerometer reads the specific force a - g, so the sensor reads
    tangential: aE_t + g cos(phi2),      normal: aE_n - g sin(phi2).
These terms change by about 2.5 and 0.25 m/s^2 over the 15 deg stroke (2-3 % of the aE_t peak at
180 rpm); they are removed with phi2 from the kinematics at the measured cam angle.

Offset and drift: the sensor chain is AC-coupled and the conditioner has an offset, so the zero of
the acceleration is unknown. The follower rests in the dwells (omega2 = 0, epsilon2 = 0, aE_n = 0
there), so each channel is referenced to the mean of the middle DWELL_MIDDLE (60 %) of every dwell, interpolated
linearly between dwells. omega2 is the integral of epsilon2 over each motion interval (rise or
return, plus a margin into the dwells), started at 0 and corrected by a linear ramp so that it
ends at 0 in the next dwell: the integration drift cannot accumulate beyond one motion interval.
"""
from __future__ import annotations

import numpy as np

DWELL_MIDDLE = 0.6    # fraction of each dwell, centred, whose mean is the reference
DWELL_MIN_LEN = 8     # samples: shorter dwells are not used as a reference


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of every run of True in a boolean array."""
    m = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    d = np.flatnonzero(np.diff(m.astype(np.int8)))
    return list(zip(d[0::2].tolist(), d[1::2].tolist()))


def dwell_baseline(x: np.ndarray, dwell: np.ndarray, middle: float = DWELL_MIDDLE, min_len: int = DWELL_MIN_LEN) -> np.ndarray:
    """Baseline (same unit as x) through the mean of the middle part of every complete dwell.

    x: (n,) or (n, nch); dwell: (n,) bool. The middle ``middle`` fraction keeps the impacts and the
    settling at the dwell's ends out. Dwells touching the ends of the array are incomplete (their
    centre is unknown) and are used only when no complete dwell exists. Constant extrapolation
    beyond the first and last dwell centre.
    """
    x2 = x[:, None] if x.ndim == 1 else x
    n = len(x2)
    rr = runs(dwell)
    full = [(a, b) for a, b in rr if a > 0 and b < n and b - a >= min_len]
    use = full or [(a, b) for a, b in rr if b - a >= min_len]
    if not use:
        out = np.repeat(np.mean(x2, axis=0, keepdims=True), n, axis=0)
        return out[:, 0] if x.ndim == 1 else out
    ab = np.asarray(use)
    cut = ((ab[:, 1] - ab[:, 0]) * (1 - middle) / 2).astype(int)
    lo, hi = ab[:, 0] + cut, ab[:, 1] - cut
    centres = 0.5 * (ab[:, 0] + ab[:, 1] - 1)
    idx = np.arange(n, dtype=float)
    cols = []
    for j in range(x2.shape[1]):
        cs = np.concatenate([[0.0], np.cumsum(x2[:, j])])
        levels = (cs[hi] - cs[lo]) / (hi - lo)
        cols.append(np.interp(idx, centres, levels))
    out = np.column_stack(cols)
    return out[:, 0] if x.ndim == 1 else out


def integrate_motion(epsilon2: np.ndarray, moving: np.ndarray, fs: float, margin: int,
                     bad: np.ndarray | None = None) -> np.ndarray:
    """omega2 (rad/s) from epsilon2 (rad/s^2) sampled at fs (Hz), zero in the dwells.

    Each motion run (``moving`` True) widened by ``margin`` samples into the dwells on both sides is
    integrated with the trapezoidal rule from 0, and a linear ramp is subtracted so it ends at 0.
    Runs that touch an end of the array are incomplete (NaN), as are runs holding a ``bad``
    (clipped) sample: their drift cannot be controlled.
    """
    n = len(epsilon2)
    out = np.zeros(n)
    rr = runs(moving)
    if not rr:
        return out
    ab = np.asarray(rr)
    a0 = np.maximum(ab[:, 0] - margin, 0)
    b0 = np.minimum(ab[:, 1] + margin, n)
    # widened runs may meet: each keeps its own samples up to the midpoint between them
    if len(ab) > 1:
        mid = (ab[:-1, 1] + ab[1:, 0]) // 2
        b0[:-1] = np.minimum(b0[:-1], mid)
        a0[1:] = np.maximum(a0[1:], mid)
    ok = (ab[:, 0] > 0) & (ab[:, 1] < n) & (a0 > 0) & (b0 < n)
    if bad is not None:
        bc = np.concatenate([[0], np.cumsum(bad)])
        ok &= (bc[b0] - bc[a0]) == 0
    # one cumulative trapezoid over the window; each run takes differences from its first sample
    c = np.empty(n)
    c[0] = 0.0
    np.cumsum(0.5 * (epsilon2[1:] + epsilon2[:-1]) / fs, out=c[1:])
    lengths = b0 - a0
    run_of = np.repeat(np.arange(len(ab)), lengths)
    pos = np.repeat(a0 - np.cumsum(np.concatenate([[0], lengths[:-1]])), lengths) + np.arange(lengths.sum())
    start, last = a0[run_of], b0[run_of] - 1
    w = c[pos] - c[start]
    end_val = c[last] - c[start]
    frac = (pos - start) / np.maximum(last - start, 1)
    vals = w - frac * end_val
    vals[~ok[run_of]] = np.nan
    out[pos] = vals
    return out

