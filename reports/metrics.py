"""Comparison metrics between a measured and a simulated signal sampled on the same grid.

Pure functions on 1-D numpy arrays; ``measured`` is the reference (the paper's experiment, ISO's
"test" T), ``simulated`` the computed signal (ISO's "CAE" C). Both must have the same length and be
sampled on the same uniform grid (here the cam angle phi1; see reports/align.py). The metrics are
dimensionless unless a unit is named.

- Sprague & Geers (2004): magnitude M, phase P, comprehensive C.
- ISO/TS 18571:2014: corridor, phase, magnitude (after dynamic time warping), slope scores and the
  weighted overall rating with its grade. Simplifications are listed in docs/reports.md.
- NRMSE normalised by the measured signal's range (max - min).
- Peak errors and the timing (grid position) errors of the peaks.
"""
from __future__ import annotations

import math

import numpy as np

from labtool.common.errors import InputError
from labtool.models.dynamics.jit import jit

# ISO/TS 18571:2014 default parameters (section 6; docs/reports.md)
ISO_DEFAULTS = {
    "a0": 0.05,          # inner corridor half width, fraction of max |T|
    "b0": 0.5,           # outer corridor half width, fraction of max |T|
    "kz": 2.0,           # exponent of the corridor score between the corridors
    "max_shift": 0.2,    # eps_P*: largest allowed time shift, fraction of the signal length
    "kp": 1.0,
    "eps_mag": 0.5,      # eps_M*: magnitude error giving score 0
    "km": 1.0,
    "eps_slope": 2.0,    # eps_S*: slope error giving score 0
    "ks": 1.0,
    "dtw_window": 0.1,   # Sakoe-Chiba band of the DTW, fraction of the signal length
    "weights": (0.4, 0.2, 0.2, 0.2),  # corridor, phase, magnitude, slope
}

# ISO/TS 18571 grades of the overall rating R
ISO_GRADES = ((0.94, "excellent"), (0.8, "good"), (0.58, "fair"), (-math.inf, "poor"))


def _pair(measured, simulated, min_len: int = 2):
    m = np.asarray(measured, dtype=float)
    c = np.asarray(simulated, dtype=float)
    if m.ndim != 1 or c.ndim != 1:
        raise InputError("metrics need 1-D signals")
    if m.shape != c.shape:
        raise InputError(f"signals differ in length ({m.size} measured, {c.size} simulated); align them on one grid first")
    if m.size < min_len:
        raise InputError(f"signals too short for the metrics ({m.size} samples, at least {min_len} needed)")
    if not (np.all(np.isfinite(m)) and np.all(np.isfinite(c))):
        raise InputError("signals contain NaN or Inf samples")
    return m, c


def _rows(measured, simulated):
    """(R, N) measured rows and the simulation broadcast to them; InputError on a shape mismatch."""
    m = np.asarray(measured, dtype=float)
    c = np.asarray(simulated, dtype=float)
    if m.ndim != 2 or c.ndim not in (1, 2) or c.shape[-1] != m.shape[1] or (c.ndim == 2 and c.shape[0] != m.shape[0]):
        raise InputError(f"signals differ in shape ({m.shape} measured, {c.shape} simulated); align them on one grid first")
    return m, np.broadcast_to(c, m.shape)


# --------------------------------------------------------------------------- Sprague & Geers

def sprague_geers(measured, simulated) -> dict:
    """Sprague & Geers magnitude ``M``, phase ``P`` and comprehensive ``C`` error.

    With psi_mm = sum m^2, psi_cc = sum c^2, psi_mc = sum m c (uniform grid, so the integrals'
    common factor cancels):  M = sqrt(psi_cc/psi_mm) - 1,  P = arccos(psi_mc/sqrt(psi_mm psi_cc))/pi,
    C = sqrt(M^2 + P^2).  M > 0: the simulation is larger than the measurement.
    For sin(x) against a*sin(x + theta) over whole periods: M = |a| - 1 and P = |theta|/pi exactly.
    """
    m, c = _pair(measured, simulated)
    mm, cc, mc = float(m @ m), float(c @ c), float(m @ c)
    if mm == 0.0 or cc == 0.0:
        raise InputError("Sprague & Geers errors are undefined for an all-zero signal")
    M = math.sqrt(cc / mm) - 1.0
    P = math.acos(max(-1.0, min(1.0, mc / math.sqrt(mm * cc)))) / math.pi
    return {"sg_magnitude": M, "sg_phase": P, "sg_comprehensive": math.hypot(M, P)}


# --------------------------------------------------------------------------- NRMSE, peaks

def nrmse(measured, simulated) -> float:
    """RMS of (simulated - measured) divided by the measured range max(m) - min(m)."""
    m, c = _pair(measured, simulated)
    span = float(m.max() - m.min())
    if span == 0.0:
        raise InputError("NRMSE is undefined for a constant measured signal (zero range)")
    return float(np.sqrt(np.mean((c - m) ** 2)) / span)


def peak_errors(measured, simulated, grid, window: float | None = None) -> dict:
    """Errors of the largest and smallest values and of their positions on ``grid``.

    ``peak_max_error`` = (max c - max m)/max|m|, ``peak_min_error`` = (min c - min m)/max|m|
    (signed, relative to the measured peak magnitude). ``peak_max_shift``/``peak_min_shift`` =
    position of the simulated extreme minus that of the measured one, in the grid's unit (rad of cam
    angle here); the simulated extreme is searched within +-``window`` (grid units; default a tenth
    of the grid's span) of the measured one, so that a signal with several near-equal peaks (rise
    and return) pairs each peak with its own counterpart.
    """
    m, c = _pair(measured, simulated)
    x = np.asarray(grid, dtype=float)
    if x.shape != m.shape:
        raise InputError("grid and signals differ in length")
    scale = float(np.max(np.abs(m)))
    if scale == 0.0:
        raise InputError("peak errors are undefined for an all-zero measured signal")
    if window is None:
        window = 0.1 * float(x[-1] - x[0])

    def shift(sign):
        i = int(np.argmax(sign * m))
        near = np.flatnonzero(np.abs(x - x[i]) <= window)
        j = int(near[np.argmax(sign * c[near])])
        return float(x[j] - x[i])

    return {
        "measured_max": float(m.max()), "simulated_max": float(c.max()),
        "measured_min": float(m.min()), "simulated_min": float(c.min()),
        "peak_max_error": float((c.max() - m.max()) / scale),
        "peak_min_error": float((c.min() - m.min()) / scale),
        "peak_max_shift": shift(1.0),
        "peak_min_shift": shift(-1.0),
    }


# --------------------------------------------------------------------------- ISO/TS 18571

def iso_corridor(measured, simulated, a0: float = 0.05, b0: float = 0.5, kz: float = 2.0) -> float:
    """Corridor score Z in [0, 1]: inner/outer corridors of half width a0, b0 times max|T| around T;
    a point scores 1 inside the inner corridor, 0 outside the outer, ((d_o - |C-T|)/(d_o - d_i))^kz
    between them; Z is the mean over the points."""
    m, c = _pair(measured, simulated)
    tnorm = float(np.max(np.abs(m)))
    if tnorm == 0.0:
        raise InputError("the ISO corridor score is undefined for an all-zero measured signal")
    di, do = a0 * tnorm, b0 * tnorm
    d = np.abs(c - m)
    s = np.clip((do - d) / (do - di), 0.0, 1.0) ** kz
    return float(np.mean(s))



def _shift_correlations(m: np.ndarray, c: np.ndarray, n_max: int) -> np.ndarray:
    """Pearson correlation of the overlapping parts for every lag k in [-n_max, n_max], rows at once.

    ``m``, ``c``: (R, N). Returns (R, 2 n_max + 1); column n_max + k holds lag k (k > 0: pairs
    m[:N-k] with c[k:], the simulation is late). Cross sums from one zero-padded FFT, the sums of
    the overlaps from prefix sums: O(N log N) per row instead of O(N n_max)."""
    R, N = m.shape
    m = m - m.mean(axis=1, keepdims=True)      # Pearson ignores constants; this keeps the sums small
    c = c - c.mean(axis=1, keepdims=True)
    nfft = 1 << int(math.ceil(math.log2(2 * N)))
    xc = np.fft.irfft(np.conj(np.fft.rfft(m, nfft)) * np.fft.rfft(c, nfft), nfft)
    k = np.arange(-n_max, n_max + 1)
    smc = xc[:, k % nfft]                      # sum_i m[i] c[i + k] over the overlap
    z = np.zeros((R, 1))
    pm, pc = np.hstack([z, np.cumsum(m, 1)]), np.hstack([z, np.cumsum(c, 1)])
    pmm, pcc = np.hstack([z, np.cumsum(m * m, 1)]), np.hstack([z, np.cumsum(c * c, 1)])
    kp = np.maximum(k, 0)
    kn = np.maximum(-k, 0)
    L = N - np.abs(k)
    # overlap: m[kn : N - kp], c[kp : N - kn]
    sm, smm = pm[:, N - kp] - pm[:, kn], pmm[:, N - kp] - pmm[:, kn]
    sc, scc = pc[:, N - kn] - pc[:, kp], pcc[:, N - kn] - pcc[:, kp]
    num = L * smc - sm * sc
    den = np.sqrt(np.maximum(L * smm - sm * sm, 0.0) * np.maximum(L * scc - sc * sc, 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)
    return rho


def _pick_shift(rho: np.ndarray, n_max: int) -> tuple[np.ndarray, np.ndarray]:
    """ISO's choice among the lags: the largest correlation, the smallest |n| on a tie, the
    positive lag before the negative one (as ISO/TS 18571 and objective-rating-metrics scan)."""
    best_n = np.zeros(rho.shape[0], dtype=np.int64)
    best = rho[:, n_max].copy()
    for n in range(1, n_max + 1):
        for k in (n, -n):
            r = rho[:, n_max + k]
            better = r > best + 1e-12
            best = np.where(better, r, best)
            best_n = np.where(better, k, best_n)
    return best_n, best



def _shifted(m, c, n):
    """Overlapping parts of T and C after removing the simulation's lag n."""
    if n > 0:
        return m[:-n], c[n:]
    if n < 0:
        return m[-n:], c[:n]
    return m, c


@jit
def _dtw_fill(x, y, window):
    """Cumulative cost D (n+1, m+1) of DTW, squared-difference cost, steps (1,0), (0,1), (1,1) of
    weight 1, band |i - j| <= window (1-based i, j). Self-contained (no module globals), so
    numba's file-keyed cache cannot keep a stale copy of anything it calls."""
    n, m = x.size, y.size
    D = np.full((n + 1, m + 1), np.inf)
    D[0, 0] = 0.0
    for i in range(1, n + 1):
        lo = max(1, i - window)
        hi = min(m, i + window)
        for j in range(lo, hi + 1):
            prev = D[i - 1, j - 1]
            if D[i - 1, j] < prev:
                prev = D[i - 1, j]
            if D[i, j - 1] < prev:
                prev = D[i, j - 1]
            d = x[i - 1] - y[j - 1]
            D[i, j] = d * d + prev
    return D


@jit
def _dtw_backtrack(D):
    """Warping path (0-based index arrays) from the end. On a tie the step (i-1, j) first, then
    (i, j-1), then the diagonal: dtwalign's order for the ISO step pattern (objective-rating-metrics),
    so that equal-cost paths resolve the same way as in the independent implementation."""
    i, j = D.shape[0] - 1, D.shape[1] - 1
    pi = np.empty(i + j, dtype=np.int64)
    pj = np.empty(i + j, dtype=np.int64)
    k = 0
    pi[0], pj[0] = i - 1, j - 1
    while i > 1 or j > 1:
        up, left, diag = D[i - 1, j], D[i, j - 1], D[i - 1, j - 1]
        if up <= left and up <= diag:
            i = i - 1
        elif left <= diag:
            j = j - 1
        else:
            i, j = i - 1, j - 1
        k += 1
        pi[k], pj[k] = i - 1, j - 1
    return pi[:k + 1][::-1].copy(), pj[:k + 1][::-1].copy()


def dtw_path(x, y, window: int) -> tuple[np.ndarray, np.ndarray]:
    """Dynamic time warping of x against y (squared-difference cost, steps (1,0), (0,1), (1,1)
    with weight 1, Sakoe-Chiba band |i - j| <= window). Returns the index arrays of the warping
    path. Compiled (numba): O(n window)."""
    x = np.ascontiguousarray(x, dtype=float)
    y = np.ascontiguousarray(y, dtype=float)
    window = max(int(window), abs(x.size - y.size))
    return _dtw_backtrack(_dtw_fill(x, y, window))


def dtw_window(n: int, fraction: float) -> int:
    """ISO's DTW band for n samples: ceil(fraction n) - 1 samples either side, as
    objective-rating-metrics passes it to dtwalign's Sakoe-Chiba window (|i - j| <= size)."""
    return max(int(math.ceil(fraction * n)) - 1, 0)


def _moving_average_9(d):
    """ISO's smoothing of the derivative: centred 9-point mean, shrinking windows (1, 3, 5, 7) at
    the ends (as objective-rating-metrics); one convolution."""
    d = np.asarray(d, dtype=float)
    n = d.size
    if n < 9:
        return np.array([d[max(0, k - min(4, k, n - 1 - k)):k + min(4, k, n - 1 - k) + 1].mean() for k in range(n)])
    out = np.empty_like(d)
    out[4:-4] = np.convolve(d, np.ones(9) / 9.0, mode="valid")
    c = np.cumsum(d)
    for h in range(4):               # windows of 2h + 1 points centred on h and on n - 1 - h
        out[h] = c[2 * h] / (2 * h + 1)
        out[n - 1 - h] = (c[-1] - (c[n - 2 - 2 * h] if n - 2 - 2 * h >= 0 else 0.0)) / (2 * h + 1)
    return out


def _iso_from_shift(m, c, n_eps, rho, p) -> dict:
    """The ISO scores of one pair once its lag ``n_eps`` (samples) is known."""
    N = m.size
    Z = iso_corridor(m, c, p["a0"], p["b0"], p["kz"])
    limit = p["max_shift"] * N
    E_P = 1.0 if n_eps == 0 else max(0.0, (limit - abs(n_eps)) / limit) ** p["kp"]
    ms, cs = _shifted(m, c, n_eps)
    pi, pj = dtw_path(cs, ms, dtw_window(ms.size, p["dtw_window"]))
    cw, mw = cs[pi], ms[pj]
    den = float(np.sum(np.abs(mw)))
    e_mag = float(np.sum(np.abs(cw - mw)) / den) if den > 0 else math.inf
    E_M = max(0.0, (p["eps_mag"] - e_mag) / p["eps_mag"]) ** p["km"]
    # slope: central differences (the grid step cancels in the ratio), smoothed, on the shifted signals
    dm = _moving_average_9(np.gradient(ms))
    dc = _moving_average_9(np.gradient(cs))
    den = float(np.sum(np.abs(dm)))
    e_slope = float(np.sum(np.abs(dc - dm)) / den) if den > 0 else math.inf
    E_S = max(0.0, (p["eps_slope"] - e_slope) / p["eps_slope"]) ** p["ks"]
    wz, wp, wm, ws = p["weights"]
    R = wz * Z + wp * E_P + wm * E_M + ws * E_S
    return {
        "iso_corridor": Z, "iso_phase": E_P, "iso_magnitude": E_M, "iso_slope": E_S,
        "iso_rating": R, "iso_grade": iso_grade(R),
        "iso_shift_samples": int(n_eps), "iso_rho": float(rho),
        "iso_magnitude_error": e_mag, "iso_slope_error": e_slope,
    }


def _iso_params(params: dict) -> dict:
    unknown = set(params) - set(ISO_DEFAULTS)
    if unknown:
        raise InputError(f"unknown ISO/TS 18571 parameter(s): {', '.join(sorted(unknown))}")
    return {**ISO_DEFAULTS, **params}


def iso18571(measured, simulated, **params) -> dict:
    """ISO/TS 18571 scores of ``simulated`` against the reference ``measured`` (same uniform grid).

    Returns corridor, phase, magnitude and slope scores, the overall rating R (weights
    0.4/0.2/0.2/0.2), its grade, and the intermediate errors (shift in samples, magnitude and slope
    errors). Parameters: see ``ISO_DEFAULTS``.
    """
    return iso18571_rows(np.asarray(measured, dtype=float)[None], simulated, **params)[0]


def iso18571_rows(measured, simulated, **params) -> list[dict]:
    """``iso18571`` of every row of ``measured`` (R, N) against ``simulated`` ((N,) or (R, N)):
    the lag search of all rows in one FFT pass, DTW compiled."""
    p = _iso_params(params)
    m, c = _rows(measured, simulated)
    rows = [_pair(a, b, min_len=10) for a, b in zip(m, c)]
    N = m.shape[1]
    n_max = min(int(math.floor(p["max_shift"] * N)), N - 2)
    n_eps, rho = _pick_shift(_shift_correlations(m, np.array(c), n_max), n_max)
    return [_iso_from_shift(a, b, int(n), r, p) for (a, b), n, r in zip(rows, n_eps, rho)]


def iso_grade(rating: float) -> str:
    """ISO/TS 18571 grade: excellent (R > 0.94), good (> 0.8), fair (> 0.58), poor."""
    for bound, name in ISO_GRADES:
        if rating > bound:
            return name
    return "poor"


# --------------------------------------------------------------------------- all together

# metric name -> (better when, signed); thresholds (reports/thresholds.py) use this table
METRICS = {
    "sg_magnitude": ("low", True),
    "sg_phase": ("low", False),
    "sg_comprehensive": ("low", False),
    "iso_corridor": ("high", False),
    "iso_phase": ("high", False),
    "iso_magnitude": ("high", False),
    "iso_slope": ("high", False),
    "iso_rating": ("high", False),
    "nrmse": ("low", False),
    "peak_max_error": ("low", True),
    "peak_min_error": ("low", True),
    "peak_max_shift_deg": ("low", True),
    "peak_min_shift_deg": ("low", True),
    "lag_deg": ("low", True),
    "band_overlap": ("high", False),    # labtool.reports.pipeline.band_statistics
}


def compare(measured, simulated, grid_rad, iso_params: dict | None = None) -> dict:
    """Every metric of this module for one pair of signals on the cam-angle grid ``grid_rad`` (rad).
    Peak shifts are reported in degrees of cam angle (``*_shift_deg``)."""
    return compare_rows(np.asarray(measured, dtype=float)[None], simulated, grid_rad, iso_params)[0]


def compare_rows(measured, simulated, grid_rad, iso_params: dict | None = None) -> list[dict]:
    """``compare`` for every row of ``measured`` (R, N) against ``simulated`` ((N,) or (R, N)),
    e.g. every measured revolution against one simulated cycle."""
    m, c = _rows(measured, simulated)
    iso = iso18571_rows(m, c, **(iso_params or {}))
    step = float(np.mean(np.diff(np.asarray(grid_rad, dtype=float))))
    out = []
    for a, b, s in zip(m, c, iso):
        row = {**sprague_geers(a, b), **s, "nrmse": nrmse(a, b)}
        pk = peak_errors(a, b, grid_rad)
        row.update({k: v for k, v in pk.items() if not k.endswith("_shift")})
        row["peak_max_shift_deg"] = math.degrees(pk["peak_max_shift"])
        row["peak_min_shift_deg"] = math.degrees(pk["peak_min_shift"])
        # the lag of best correlation (ISO phase step) as a cam angle: the timing error of the whole curve
        row["lag_deg"] = math.degrees(row["iso_shift_samples"] * step)
        out.append(row)
    return out
