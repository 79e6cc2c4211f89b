"""The cam angle phi1 (rad) of every sample: from a tacho, or by correlation with the kinematics.

phi1 = 0 at the start of the rise (docs/architecture.md); the tacho gives one pulse per revolution there.
Between two revolution marks phi1 grows linearly (the cam speed is taken constant within one
revolution, which follows the motor's slow speed variation revolution by revolution).
Without a tacho the revolution marks come from a matched filter: the measured aE_t correlated
with the ideal aE_t of one revolution at the estimated period (a "software tacho").
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import scipy.fft as sfft

from labtool.common.errors import InputError
from labtool.common.names import shown
from labtool.models.mechanism import sensor_point
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
    t = sensor_point.acceleration_at_E(mech.DE, 0.0, ddpsi)[0]
    return t - t.mean()


def template_reading(mech, program, n_per_rev: int, omega1: float) -> np.ndarray:
    """What the tangential sensor reads over one revolution (m/s^2, mean removed) at the cam speed
    omega1 (rad/s): d2psi/dphi1^2 DE omega1^2 plus gravity's g cos(phi2) (sensor_point.gravity_reading).

    At a few rpm gravity's reading changes by 2.5 m/s^2 over the stroke while the motion's peak is
    0.08 m/s^2 (5 rpm): a template of the motion alone then matches nothing."""
    phi1 = TWO_PI * np.arange(n_per_rev) / n_per_rev
    psi, _, ddpsi, _ = program(phi1)
    g_t, _ = sensor_point.gravity_reading(mech.phiD + mech.psi0 + psi, mech.g)
    t = sensor_point.acceleration_at_E(mech.DE, 0.0, ddpsi * omega1**2)[0] + g_t
    return t - t.mean()


@dataclasses.dataclass(frozen=True)
class Search:
    """Where the cam speed is looked for without a tacho: rpm_lo..rpm_hi (rpm), and why there."""
    rpm_lo: float
    rpm_hi: float
    why: str

    def window(self, fs: float) -> int:
        """Samples to read for the period estimate (Hz -> samples): MIN_WINDOW_S, or WINDOW_REVOLUTIONS
        of the slowest speed searched if longer (the autocorrelation must see two periods)."""
        return int(max(MIN_WINDOW_S, WINDOW_REVOLUTIONS * 60.0 / self.rpm_lo) * fs)

    def decimation(self, fs: float) -> int:
        """Samples averaged into one for the search (1 at the stand's usual speeds): the fastest
        revolution searched keeps >= SAMPLES_PER_REVOLUTION; slow searches get the noise averaged
        and a bounded FFT."""
        return max(1, int(fs * 60.0 / self.rpm_hi / SAMPLES_PER_REVOLUTION))


DEFAULT_RPM_RANGE = (20.0, 1500.0)   # rpm: searched when no speed is stated
STATED_FACTOR = 1.5                  # a stated speed is searched within /1.5 .. x1.5 (speed.REFUSE_RATIO)
MIN_WINDOW_S = 20.0                  # s of aE_t read for the period estimate, at least
WINDOW_REVOLUTIONS = 4               # ... or this many revolutions at the slowest speed searched
SAMPLES_PER_REVOLUTION = 2000        # samples a revolution keeps after the search's averaging, at least
GRAVITY_IN_TEMPLATE = 0.1            # gravity's reading over the motion's peak above which the template holds it


def search_range(rpm_hint, mech) -> Search:
    """The stated speed's neighbourhood (/STATED_FACTOR .. x STATED_FACTOR), else DEFAULT_RPM_RANGE
    within what the mechanism's drive can turn (its speed range, widened by STATED_FACTOR)."""
    if rpm_hint is not None and math.isfinite(rpm_hint) and rpm_hint > 0:
        return Search(rpm_hint / STATED_FACTOR, rpm_hint * STATED_FACTOR,
                      f"the stated {rpm_hint:g} rpm within a factor {STATED_FACTOR:g}")
    lo = max(DEFAULT_RPM_RANGE[0], mech.min_cam_speed_rpm / STATED_FACTOR)
    hi = min(DEFAULT_RPM_RANGE[1], mech.max_cam_speed_rpm * STATED_FACTOR)
    return Search(lo, max(hi, 2 * lo), f"{lo:g} to {max(hi, 2 * lo):g} rpm, no speed being stated")


def block_mean(x: np.ndarray, q: int) -> np.ndarray:
    """Means of q consecutive samples (the last partial block dropped); x itself when q == 1."""
    if q == 1:
        return x
    m = len(x) // q
    return x[:m * q].reshape(m, q).mean(axis=1)


def estimate_period(x: np.ndarray, fs: float, rpm_range=DEFAULT_RPM_RANGE, averaged: int = 1) -> float:
    """Cam revolution period (samples at fs, Hz) of aE_t samples ``x`` by autocorrelation.

    The first local maximum reaching 80 % of the largest autocorrelation in the allowed range of
    speeds (rpm): the revolution, not a multiple of it (rise and return are of opposite sign, so
    T/2 is negative). Each sample of ``x`` may be the mean of ``averaged`` samples at fs
    (block_mean: a slow cam's search). InputError when the range holds no periodic motion (no
    local maximum, or one below 0.3).
    """
    q = int(averaged)
    x = np.asarray(x, dtype=float)
    x = x - np.mean(x)
    n = len(x)
    lo = int(fs / q * 60.0 / rpm_range[1])
    hi = min(int(fs / q * 60.0 / rpm_range[0]), n // 2)
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
    if not len(peaks):
        # the autocorrelation only falls (or only rises) across the range: its period lies outside
        raise InputError(f"aE_t repeats at no period between {rpm_range[0]:g} and {rpm_range[1]:g} rpm")
    k = int(peaks[0]) + lo
    # parabolic refinement
    if 1 <= k < len(ac) - 1:
        y0, y1, y2 = ac[k - 1], ac[k], ac[k + 1]
        den = y0 - 2 * y1 + y2
        if den < 0:
            return q * (k + 0.5 * (y0 - y2) / den)
    return float(q * k)


def period_by_correlation(rec, segs, col, rpm_hint, mech, chunk):
    """(cam period in samples, samples averaged into one, the Search that found it) from the
    autocorrelation of column ``col`` (aE_t) of ``rec`` (a Recording) over the start of the longest of
    its segments ``segs``: searched around the stated speed ``rpm_hint`` (rpm), else (or when nothing
    repeats there) over DEFAULT_RPM_RANGE; InputError naming what was searched and what to give."""
    fs = rec.sample_rate_hz
    a0, b0 = max(segs, key=lambda s: s[1] - s[0])
    searches = [search_range(rpm_hint, mech)]
    if rpm_hint and math.isfinite(rpm_hint) and rpm_hint > 0:
        # a stated speed that is wrong by more than the factor is found and refused as such (speed.py)
        searches.append(search_range(None, mech))
    for search in searches:
        q = search.decimation(fs)
        x = averaged_column(rec, a0, min(b0, a0 + search.window(fs)), col, q, chunk)
        try:
            return estimate_period(x, fs, (search.rpm_lo, search.rpm_hi), q), q, search
        except InputError as exc:
            failure = exc
    where = f"searched {searches[0].why}" + (f", then {searches[1].why}" if len(searches) > 1 else "")
    if len(searches) > 1:
        raise InputError(f"{shown(rec.source)}: no cam revolution found in aE_t by correlation ({failure}; {where}) and "
                         "no tacho recorded: is aE_t the tangential accelerometer (--channels aE_t=<channel>)?")
    raise InputError(f"{shown(rec.source)}: no cam revolution found in aE_t by correlation ({failure}; {where}) and no "
                     "tacho recorded: give the speed the cam turned at with --rpm (rpm; it is then searched within a "
                     f"factor {STATED_FACTOR:g} of it)")


def averaged_column(rec, a: int, b: int, col: int, q: int, chunk: int) -> np.ndarray:
    """Column ``col`` of samples [a, b), means of q samples (block_mean), read chunk by
    chunk: a slow cam's window (minutes at tens of kHz) is never held whole."""
    step = max(q, chunk // q * q)
    return np.concatenate([block_mean(rec.read(s, min(s + step, b))[:, col], q)
                           for s in range(a, b, step)])


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

    Feed windows of aE_t (m/s^2 when ``fs`` is given, else any unit) with ``feed(start, x,
    core_start, core_stop)``; marks whose position lies in [core_start, core_stop) are returned,
    so overlapping windows count each once. ``span`` is how many samples past a core a window
    must reach. With ``fs`` (Hz) the template is the sensor's reading at the period's speed, gravity
    included where it is more than GRAVITY_IN_TEMPLATE of the motion's peak (slow cams); without,
    the motion alone. ``decimation`` samples are averaged into one first (slow cams: noise).
    ``retune(marks)`` follows a drifting speed: the template takes the period of the latest marks.
    """

    def __init__(self, mech, program, period_samples: float, fs: float | None = None, decimation: int = 1):
        self.mech, self.program, self.fs, self.q = mech, program, fs, int(decimation)
        self.gravity = False
        self._build(float(period_samples))

    def _build(self, period: float) -> None:
        self.period = period
        self.n = int(round(period / self.q))
        if self.fs:
            omega1 = TWO_PI * self.fs / period
            motion = float(np.max(np.abs(template_aE_t(self.mech, self.program, 720)))) * omega1**2
            grav = np.ptp(sensor_point.gravity_reading(self.mech.phiD + self.mech.psi0 +
                                                   self.program(TWO_PI * np.arange(720) / 720)[0], self.mech.g)[0])
            self.gravity = bool(grav > GRAVITY_IN_TEMPLATE * motion)
        self.template = self._template(self.n, period)
        # past its core a window holds a whole revolution and the widest refinement (_refine)
        self.span = (self.n + int(0.1 * self.n) + 6) * self.q

    def _template(self, n: int, period: float) -> np.ndarray:
        """The template of n (averaged) samples for a revolution of ``period`` samples at fs."""
        if self.gravity:
            return template_reading(self.mech, self.program, n, TWO_PI * self.fs / period)
        return template_aE_t(self.mech, self.program, n)

    def retune(self, marks) -> None:
        """Template at the median of the last RETUNE_REVOLUTIONS periods of ``marks`` (samples)."""
        if len(marks) >= 3:
            self._follow(float(np.median(np.diff(np.asarray(marks[-(RETUNE_REVOLUTIONS + 1):], dtype=float)))))

    def _follow(self, period: float) -> bool:
        """Rebuild the template at ``period`` (samples) when that changes its length; True if it did."""
        if int(round(period / self.q)) != self.n and abs(period / self.period - 1) < 0.2:
            self._build(period)
            return True
        return False

    def feed(self, start: int, x: np.ndarray, core_start: int, core_stop: int) -> np.ndarray:
        x = block_mean(np.asarray(x, dtype=float), self.q)
        if len(x) < self.n + 2:
            return np.empty(0)
        x = x - x.mean()
        pos = self._marks(x)
        # the autocorrelation's period is off by a sample or more (a window of few revolutions, a
        # drift since): once, the template takes the period of the marks themselves
        if len(pos) >= 2 and self._follow(float(np.median(np.diff(pos)))):
            pos = self._marks(x)
        pos = self._refine(x, pos)
        # an averaged sample stands at the middle of the samples it averages
        g = start + pos + 0.5 * (self.q - 1)
        return g[(g >= core_start) & (g < core_stop)]

    def _refine(self, x: np.ndarray, pos: np.ndarray) -> np.ndarray:
        """Each mark matched again with a template of its own revolution's length, where that length
        (from its neighbours in x) differs from the template's: a drifting speed. A template too long
        or too short by a fraction d of a revolution places its match early or late by about d / 3 of a
        revolution (the template's energy lies a third of a turn from its start), which this removes."""
        if len(pos) < 2:
            return pos
        d = np.diff(pos)
        local = np.concatenate([[d[0]], 0.5 * (d[:-1] + d[1:]), [d[-1]]]) if len(pos) > 2 else np.repeat(d, 2)
        out = pos.copy()
        keep = np.ones(len(pos), dtype=bool)
        for i, (p, per) in enumerate(zip(pos, local)):
            n = int(round(per / self.q))
            if abs(n - self.n) < REFINE_MIN_SAMPLES or abs(per / self.period - 1) >= 0.2:
                continue            # its match would move by under a sample
            k, w = int(round(p / self.q)), int(math.ceil(0.4 * abs(n - self.n))) + 3
            if k - w < 0 or k + w + n > len(x):
                keep[i] = False     # at the data's edge (windows reach span past their core): cannot be placed
                continue
            t = self._template(n, per)
            seg = x[k - w:k + w + n]
            c = correlate_valid(seg, t)
            cs = np.concatenate([[0.0], np.cumsum(seg**2)])
            rho = c / (np.sqrt(np.maximum(cs[n:] - cs[:-n], 1e-300))[:len(c)] * float(np.sqrt(np.sum(t**2))))
            j = int(np.argmax(rho))
            if not 0 < j < len(rho) - 1:
                keep[i] = False     # no maximum inside the search: no trustworthy place
                continue
            y0, y1, y2 = rho[j - 1], rho[j], rho[j + 1]
            den = y0 - 2 * y1 + y2
            out[i] = (k - w + j + (0.5 * (y0 - y2) / den if den < 0 else 0.0)) * self.q
        return out[keep]

    def _marks(self, x: np.ndarray) -> np.ndarray:
        """Positions (samples at the full rate from x's start) of the template's matches in x (averaged)."""
        c = correlate_valid(x, self.template)
        norm = float(np.sqrt(np.sum(self.template**2)))
        # energy of x over each template-long window, for a normalised correlation coefficient
        cs = np.concatenate([[0.0], np.cumsum(x**2)])
        energy = np.sqrt(np.maximum(cs[self.n:] - cs[:-self.n], 1e-300))[:len(c)]
        rho = c / (energy * norm)
        peaks = kernels.find_peaks(rho, 0.5, float(max(1, int(0.7 * self.period / self.q))))
        out = []
        for k in peaks:
            pos = float(k)
            if 1 <= k < len(rho) - 1:
                y0, y1, y2 = rho[k - 1], rho[k], rho[k + 1]
                den = y0 - 2 * y1 + y2
                if den < 0:
                    pos = k + 0.5 * (y0 - y2) / den
            out.append(pos * self.q)
        return np.asarray(out, dtype=float)


RETUNE_REVOLUTIONS = 8   # revolutions whose median period a retuned template takes
REFINE_MIN_SAMPLES = 3   # a revolution this many (averaged) samples off the template's length is matched again


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
