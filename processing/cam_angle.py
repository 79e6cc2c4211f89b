"""The cam angle phi1 (rad) of every sample: from a tacho, or by correlation with the kinematics.

phi1 = 0 at the start of the rise (docs/architecture.md); the tacho gives one pulse per revolution there.
Between two revolution marks phi1 grows linearly (the cam speed is taken constant within one
revolution, which follows the motor's slow speed variation revolution by revolution).
Without a tacho the revolution marks come from a matched filter: the measured aE_t correlated
with the ideal aE_t of one revolution at the estimated period (a "software tacho").
"""
from __future__ import annotations

import math

import numpy as np
import scipy.fft as sfft

from labtool.common.errors import InputError
from labtool.processing import kernels

TWO_PI = 2.0 * math.pi


class TachoEdges:
    """Rising edges of a pulse channel, fed block by block; sub-sample positions (sample units).

    The threshold is the middle of the range seen so far, with a hysteresis of 20 % of the range;
    nothing is detected until the range exceeds ``min_range`` (V), so that a silent start is not
    taken for pulses.
    """

    def __init__(self, min_range: float = 0.1):
        self.min_range = min_range
        self.lo = math.inf
        self.hi = -math.inf
        self.armed = False  # below the lower hysteresis level: next upward crossing is an edge
        self.prev = None  # (index, value) of the last sample seen

    def feed(self, start: int, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if x.size == 0:
            return np.empty(0)
        self.lo = min(self.lo, float(x.min()))
        self.hi = max(self.hi, float(x.max()))
        rng = self.hi - self.lo
        if rng < self.min_range:
            self.prev = (start + len(x) - 1, float(x[-1]))
            return np.empty(0)
        mid = 0.5 * (self.hi + self.lo)
        low_level, high_level = mid - 0.1 * rng, mid + 0.1 * rng
        # states: -1 below low, +1 above high, 0 between; an edge is a -1 -> +1 passage
        state = np.where(x <= low_level, -1, np.where(x >= high_level, 1, 0))
        edges = []
        armed = self.armed
        # only samples outside the hysteresis band matter: find their -1 -> +1 passages
        nz = np.flatnonzero(state)
        s = state[nz]
        if armed and len(s) and s[0] == 1:
            first_up = True
        else:
            first_up = False
        trans = np.flatnonzero((s[1:] == 1) & (s[:-1] == -1)) + 1
        ups = list(nz[trans])
        if first_up:
            ups = [nz[0]] + ups
        if len(s):
            self.armed = bool(s[-1] == -1)
        for i in ups:
            # sub-sample crossing of the mid level between the last sample below mid and the next
            j = i
            while j > 0 and x[j - 1] >= mid:
                j -= 1
            if j == 0:
                x0 = self.prev[1] if self.prev is not None else x[0]
                i0, x1 = -1, x[0]
            else:
                i0, x0, x1 = j - 1, x[j - 1], x[j]
            frac = (mid - x0) / (x1 - x0) if x1 != x0 else 0.0
            edges.append(start + i0 + min(max(frac, 0.0), 1.0))
        self.prev = (start + len(x) - 1, float(x[-1]))
        return np.asarray(edges, dtype=float)


class CompiledTachoEdges(TachoEdges):
    """TachoEdges with ``feed`` compiled (kernels.tacho_edges; tests/test_proc_kernels.py checks
    that both find the same edges over any split into blocks)."""

    def __init__(self, min_range: float = 0.1):
        super().__init__(min_range)
        self._state = np.array([math.inf, -math.inf, 0.0, 0.0, 0.0])

    def feed(self, start: int, x: np.ndarray) -> np.ndarray:
        return kernels.tacho_edges(x, start, self._state, self.min_range)


def template_aE_t(mech, program, n_per_rev: int) -> np.ndarray:
    """Ideal aE_t (m/s^2 at 1 rad/s cam speed, i.e. d2psi/dphi1^2 * DE) over one revolution, phi1 = 2 pi k / n."""
    phi1 = TWO_PI * np.arange(n_per_rev) / n_per_rev
    _, _, ddpsi, _ = program(phi1)
    t = ddpsi * mech.DE
    return t - t.mean()


def estimate_period(x: np.ndarray, fs: float, rpm_range=(20.0, 1500.0)) -> float:
    """Cam revolution period (samples) of aE_t samples ``x`` by autocorrelation.

    The first lag whose autocorrelation reaches 80 % of the largest one in the allowed range: the
    revolution, not a multiple of it (rise and return are of opposite sign, so T/2 is negative).
    """
    x = np.asarray(x, dtype=float) - np.mean(x)
    n = len(x)
    lo = int(fs * 60.0 / rpm_range[1])
    hi = min(int(fs * 60.0 / rpm_range[0]), n // 2)
    if hi <= lo + 2:
        raise InputError("the recording is too short to find the cam speed by correlation; "
                         "record at least two revolutions or state cam_speed_rpm")
    nfft = 1 << int(math.ceil(math.log2(2 * n)))
    spec = np.fft.rfft(x, nfft)
    ac = np.fft.irfft(spec * np.conj(spec), nfft)[:hi + 2]
    if ac[0] <= 0:
        raise InputError("aE_t is constant: the cam speed cannot be found")
    ac = ac / ac[0]
    seg = ac[lo:hi]
    best = float(seg.max())
    if best < 0.3:
        raise InputError("aE_t shows no periodic cam motion; cannot find the cam angle without a tacho")
    peaks = kernels.find_peaks(np.ascontiguousarray(seg), 0.8 * best, 1.0)
    k = int(peaks[0]) + lo if len(peaks) else int(np.argmax(seg)) + lo
    # parabolic refinement
    if 1 <= k < len(ac) - 1:
        y0, y1, y2 = ac[k - 1], ac[k], ac[k + 1]
        den = y0 - 2 * y1 + y2
        if den < 0:
            return k + 0.5 * (y0 - y2) / den
    return float(k)


def correlate_valid(x: np.ndarray, t: np.ndarray) -> np.ndarray:
    """c[k] = sum_j x[k + j] t[j] for k = 0 .. len(x) - len(t): scipy.signal.correlate(x, t,
    mode="valid", method="fft"), by one real FFT of a length >= len(x) (no circular wrap-around)."""
    m = len(x) - len(t) + 1
    if m <= 0:
        return np.empty(0)
    L = sfft.next_fast_len(len(x), real=True)
    return sfft.irfft(sfft.rfft(x, L) * np.conj(sfft.rfft(t, L)), L)[:m]


class CorrelationEdges:
    """Revolution marks (phi1 = 0) by matched filtering of aE_t with the kinematic template.

    Feed windows of aE_t (any unit) with ``feed(start, x, core_start, core_stop)``; marks whose
    position lies in [core_start, core_stop) are returned, so overlapping windows count each once.
    """

    def __init__(self, mech, program, period_samples: float):
        self.period = float(period_samples)
        n = int(round(period_samples))
        self.template = template_aE_t(mech, program, n)
        self.n = n

    def feed(self, start: int, x: np.ndarray, core_start: int, core_stop: int) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if len(x) < self.n + 2:
            return np.empty(0)
        x = x - x.mean()
        c = correlate_valid(x, self.template)
        norm = float(np.sqrt(np.sum(self.template**2)))
        # energy of x over each template-long window, for a normalised correlation coefficient
        cs = np.concatenate([[0.0], np.cumsum(x**2)])
        energy = np.sqrt(np.maximum(cs[self.n:] - cs[:-self.n], 1e-300))[:len(c)]
        rho = c / (energy * norm)
        peaks = kernels.find_peaks(rho, 0.5, float(max(1, int(0.7 * self.period))))
        out = []
        for k in peaks:
            pos = float(k)
            if 1 <= k < len(rho) - 1:
                y0, y1, y2 = rho[k - 1], rho[k], rho[k + 1]
                den = y0 - 2 * y1 + y2
                if den < 0:
                    pos = k + 0.5 * (y0 - y2) / den
            g = start + pos
            if core_start <= g < core_stop:
                out.append(g)
        return np.asarray(out)


def phi1_from_marks(index: np.ndarray, marks: np.ndarray, fallback_period: float):
    """(phi1 in [0, 2 pi) rad, revolution index) of samples ``index`` given revolution marks.

    Revolution k runs from marks[k] to marks[k+1]; before the first mark the revolution is -1 and
    phi1 is extrapolated with the first period, after the last with the last period.
    """
    index = np.asarray(index, dtype=float)
    marks = np.asarray(marks, dtype=float)
    if len(marks) == 0:
        raise InputError("no revolution mark found (no tacho pulse and no match with the kinematics)")
    if len(marks) >= 2:
        periods = np.diff(marks)
        first, last = periods[0], periods[-1]
    else:
        periods = np.empty(0)
        first = last = float(fallback_period)
    # per interval (before the first mark, between marks, after the last): origin and period
    origin = np.concatenate([[marks[0]], marks])
    per = np.concatenate([[first], periods, [last]])
    if index.ndim == 1 and len(index) > 1 and np.all(np.diff(index[:2]) > 0) and _is_arange(index):
        # contiguous samples: interval of each sample by counting, not by a search per sample
        counts = np.diff(np.concatenate([[0], np.searchsorted(index, marks, side="right"), [len(index)]]))
        k = np.repeat(np.arange(-1, len(marks)), counts)
    else:
        k = np.searchsorted(marks, index, side="right") - 1
    scale = TWO_PI / per[k + 1]
    phi1 = np.mod((index - origin[k + 1]) * scale, TWO_PI)
    return phi1, k.astype(np.int64)


def _is_arange(index: np.ndarray) -> bool:
    return bool(index[-1] - index[0] == len(index) - 1 and index[1] - index[0] == 1)
