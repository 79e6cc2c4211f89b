"""Measured and simulated signals on one cam-angle grid, over whole revolutions, filtered alike.

Both sides go through the same three steps (``condition``):
1. linear interpolation onto a fine uniform grid of ``FINE_FACTOR * n_grid`` points per revolution
   of the cam angle phi1 (rad, 0 at the start of the rise);
2. a zero-phase periodic low-pass: the revolution's Fourier series truncated after ``n_harmonics``
   harmonics of the cam frequency (the revolution is a period of the steady motion; phi1 = 0 lies in
   the dwell, where the follower rests, so the periodic extension is smooth);
3. decimation to the report grid of ``n_grid`` points (exact, the signal is band-limited).

A measured revolution is *whole* when its samples cover [2 pi k, 2 pi (k+1)] without a time gap;
partial revolutions at the ends of a recording, or around a gap, are left out and counted.
Simulations (``simulated_cycles``) are resampled uniformly in their own time, low-passed like the
measurement, and cut into whole revolutions the same way; their steady state is either periodic (the
last two revolutions agree within ``PERIODIC_TOL``: the last one is the model's cycle) or not (the
model's cycle statistics over its revolutions after the first are compared, as the measurement's).
A simulation that covers only part of a revolution (for instance the rise only) is compared over
that part only (``simulated_cycle``).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import xarray as xr

from labtool.common.errors import InputError
from labtool.common.history import History, Lowpass
from labtool.common.names import shown
from labtool.models.dynamics import periodicity
from labtool.processing.accumulators import LARGER_RANGE
from labtool.processing.cycles import cycle_statistics
from labtool.processing.filters import lowpass_sos, zero_phase

TWO_PI = 2.0 * math.pi
FINE_FACTOR = 4
DEFAULT_GRID = 720          # 0.5 deg of cam angle
DEFAULT_HARMONICS = 60      # 180 Hz at 180 rpm; about 10 harmonics of the 58 deg rise
# a model's motion is periodic when its last two revolutions differ by less than this fraction of
# the signal's rms, for omega2 and epsilon2 (after the common conditioning); docs/reports.md
PERIODIC_TOL = periodicity.STEADY_CYCLE_TOL
SIM_RATE_HZ = 10_000.0      # uniform resampling of a simulation when the measurement records no rate


@dataclasses.dataclass
class Conditioning:
    """The processing applied to both sides before any metric (recorded in the report)."""

    n_grid: int = DEFAULT_GRID
    n_harmonics: int = DEFAULT_HARMONICS

    def __post_init__(self):
        if not (isinstance(self.n_grid, int) and 16 <= self.n_grid <= 20000):
            raise InputError(f"grid points per revolution must be an integer in [16, 20000], got {self.n_grid}")
        if not (isinstance(self.n_harmonics, int) and 1 <= self.n_harmonics < self.n_grid // 2):
            raise InputError(f"harmonics must be an integer in [1, {self.n_grid // 2 - 1}], got {self.n_harmonics}")

    @property
    def grid(self) -> np.ndarray:
        """Report grid of cam angle phi1 (rad), [0, 2 pi) without the end point."""
        return np.arange(self.n_grid) * (TWO_PI / self.n_grid)

    @property
    def fine_grid(self) -> np.ndarray:
        n = self.n_grid * FINE_FACTOR
        return np.arange(n) * (TWO_PI / n)

    def describe(self) -> str:
        return (f"linear interpolation onto {self.n_grid * FINE_FACTOR} points per revolution, periodic zero-phase "
                f"low-pass keeping harmonics 0..{self.n_harmonics} of the cam frequency, decimation to "
                f"{self.n_grid} points ({360.0 / self.n_grid:g} deg)")


@dataclasses.dataclass(frozen=True)
class TimeFilter:
    """The time-domain low-pass ``labtool process`` applied to the measurement (Butterworth, SOS,
    zero-phase), re-applied to the simulations so that both sides see the same filter."""

    fs: float           # Hz, the recording's sample rate
    cutoff_hz: float
    order: int

    def describe(self) -> str:
        return (f"the processing's low-pass (Butterworth order {self.order}, {self.cutoff_hz:.1f} Hz, zero-phase, "
                f"at {self.fs:g} Hz) re-applied to the simulations")

    def apply_periodic(self, y: np.ndarray) -> np.ndarray:
        """Filter one period sampled uniformly in time, as a periodic signal (3 copies, middle kept)."""
        sos = lowpass_sos(self.fs, self.cutoff_hz, self.order)
        n = y.size
        return zero_phase(sos, np.concatenate([y, y, y]))[n:2 * n]


def processing_filter(ds: xr.Dataset) -> TimeFilter | None:
    """The low-pass recorded in the measured file's processing history (``lowpass`` step), else its
    ``lowpass_hz`` attribute (order 4); None when the file records none or processing is absent."""
    fs = ds.attrs.get("sample_rate_hz")
    cutoff, order = ds.attrs.get("lowpass_hz"), 4
    lp = History.parse(ds.attrs.get("processing_history", "[]")).find(Lowpass)
    if lp is not None:
        if lp.zero_phase is False or (lp.kind or "butterworth") != "butterworth":
            return None   # not a filter this re-implementation reproduces
        cutoff = lp.cutoff_hz if lp.cutoff_hz is not None else cutoff
        order = int(lp.order) if lp.order is not None else order
    if fs is None or cutoff is None:
        return None
    try:
        fs, cutoff = float(fs), float(cutoff)
    except (TypeError, ValueError):
        # a stated low-pass read as "none": the models went unfiltered, compared with a filtered measurement
        source = ds.encoding.get("source", "the measured file")
        raise InputError(f"{shown(str(source))}: the processing low-pass it states (cutoff {shown(str(cutoff))!r} Hz, "
                         f"sample rate {shown(str(fs))!r} Hz) is not a number; fix the file (lowpass_hz, "
                         "sample_rate_hz or the processing history), or process the recording again") from None
    if not (math.isfinite(fs) and math.isfinite(cutoff) and 0 < cutoff < fs / 2 and 1 <= order <= 12):
        return None
    return TimeFilter(fs, cutoff, order)


def harmonic_lowpass(y: np.ndarray, n_harmonics: int) -> np.ndarray:
    """Keep harmonics 0..n_harmonics of a periodic sample (last axis = one period)."""
    spec = np.fft.rfft(y, axis=-1)
    spec[..., n_harmonics + 1:] = 0.0
    return np.fft.irfft(spec, n=y.shape[-1], axis=-1)


def condition(fine: np.ndarray, cond: Conditioning) -> np.ndarray:
    """Steps 2-3 on signals already on ``cond.fine_grid`` (last axis)."""
    return harmonic_lowpass(fine, cond.n_harmonics)[..., ::FINE_FACTOR]



@dataclasses.dataclass
class MeasuredCycles:
    """Whole measured revolutions on the report grid."""

    grid: np.ndarray                       # phi1 (rad), (n_grid,)
    revolutions: np.ndarray                # revolution numbers k (phi1 in [2 pi k, 2 pi (k+1)])
    signals: dict                          # name -> (n_rev, n_grid), SI
    time: np.ndarray                       # (n_rev, n_grid) time of each grid point (s)
    partial: int                           # revolutions left out (partial or with a gap)
    cam_speed_rpm: float                   # mean measured cam speed over the whole revolutions
    in_file: int | None = None             # revolution marks in the file when only a sample is read
    blocks: list = dataclasses.field(default_factory=list)   # the measured data read (xr.Dataset each)

    def mean(self, name: str) -> np.ndarray:
        """Cycle average of ``name`` over the revolutions (labtool.processing.cycles)."""
        return cycle_statistics(self.signals[name]).mean

    def std(self, name: str) -> np.ndarray:
        """Standard deviation of ``name`` over the revolutions (population, ddof 0)."""
        return cycle_statistics(self.signals[name]).std


MAX_REVOLUTIONS = 160      # the report reads at most this many whole revolutions of a recording
BLOCK_REVOLUTIONS = 20     # ... in blocks of this many consecutive ones, evenly spread


def revolution_blocks(ds: xr.Dataset, max_revolutions: int = MAX_REVOLUTIONS,
                      per_block: int = BLOCK_REVOLUTIONS) -> tuple[list[tuple[slice, int]], int] | None:
    """Sample slices (of the ``time`` dimension, with the index of their first mark) of at most ``max_revolutions`` whole revolutions in
    blocks of ``per_block`` consecutive ones, evenly spread over the recording, and the number of
    revolution marks in the file; None when the file holds fewer (read it whole) or records no
    revolution marks (``revolution_start_time``, written by labtool process). So the report's cost
    does not grow with the recording's length; the page says how many revolutions were used."""
    if "revolution_start_time" not in ds.variables or "time" not in ds.coords:
        return None
    marks = np.asarray(ds["revolution_start_time"].values, dtype=float)
    marks = marks[np.isfinite(marks)]
    if marks.size <= max_revolutions + 2:
        return None
    n = ds.sizes["time"]
    n_blocks = max(1, max_revolutions // per_block)
    starts = np.linspace(0, marks.size - per_block - 1, n_blocks).round().astype(int)
    out = []
    for i in starts:
        a, b = lazy_searchsorted(ds["time"], [marks[i], marks[i + per_block]])
        # a few samples either side so the end marks' revolutions are whole in the slice
        out.append((slice(max(a - 4, 0), min(b + 5, n)), int(i)))
    return out, int(marks.size)


def lazy_searchsorted(var: xr.DataArray, values, window: int = 512) -> list[int]:
    """``numpy.searchsorted(var.values, v)`` for each v without reading ``var`` whole: an
    interpolation search on a lazily opened, increasing 1-D variable (a time axis, uniform between
    gaps, so one or two probes find the window), then the exact position within the window read.
    Falls back to bisection when interpolation does not shrink the bracket."""
    n = var.size

    def read(a, b):
        return np.asarray(var[a:b].values, dtype=float)

    out = []
    for v in values:
        lo, hi = 0, n                                # the answer lies in [lo, hi]
        for step in range(64):
            if hi - lo <= window:
                break
            t_lo, t_hi = read(lo, lo + 1)[0], read(hi - 1, hi)[0]
            if v <= t_lo or v > t_hi:
                lo = hi = lo if v <= t_lo else hi
                break
            g = lo + int((v - t_lo) / (t_hi - t_lo) * (hi - 1 - lo)) if step < 8 else (lo + hi) // 2
            # a window around the guess: the answer inside it is exact, else the bracket shrinks
            a, b = max(g - window // 2, lo), min(g + window // 2, hi)
            seg = read(a, b)
            if seg[0] < v <= seg[-1]:
                lo = hi = a + int(np.searchsorted(seg, v, side="left"))
                break
            lo, hi = (b, hi) if seg[-1] < v else (lo, a + 1)
        if hi > lo:
            lo += int(np.searchsorted(read(lo, hi), v, side="left"))
        out.append(lo)
    return out


def read_measured(ds: xr.Dataset, names, cond: Conditioning, extra=(),
                  max_revolutions: int = MAX_REVOLUTIONS) -> MeasuredCycles:
    """``measured_cycles`` of a (lazily opened) measured file, reading only a bounded sample of
    whole revolutions (``revolution_blocks``) when it is long. ``extra`` names further variables
    over time to read with them (kept in ``blocks`` for the event detection)."""
    want = [n for n in dict.fromkeys(["phi1", *names, *extra]) if n in ds]
    sel = revolution_blocks(ds, max_revolutions)
    if sel is None:
        block = ds[want].load()
        cyc = measured_cycles(block, names, cond)
        cyc.blocks = [block]
        return cyc
    slices, in_file = sel
    parts, revs = [], []
    for sl, first_mark in slices:
        block = ds[want].isel(time=sl).load()
        c = measured_cycles(block, names, cond)
        parts.append((block, c))
        revs.append(c.revolutions - c.revolutions.min() + first_mark)   # numbered as the file's marks
    first = parts[0][1]
    signals = {n: np.concatenate([c.signals[n] for _, c in parts]) for n in names}
    times = np.concatenate([c.time for _, c in parts])
    rpm = float(np.mean([c.cam_speed_rpm for _, c in parts]))
    return MeasuredCycles(first.grid, np.concatenate(revs), signals, times, 0, rpm, in_file, [b for b, _ in parts])


MAX_MEASURED = 1e12   # rad/s, rad/s^2: a measured omega2 or epsilon2 past it is no motion (its square must stay finite)


def _unwrapped_angle(phi1: np.ndarray) -> np.ndarray:
    """Cam angle that keeps growing over the recording (rad); accepts wrapped or unwrapped phi1."""
    return np.unwrap(phi1)


def measured_cycles(ds: xr.Dataset, names, cond: Conditioning) -> MeasuredCycles:
    """Whole revolutions of the measured signals ``names`` (variables over ``time``) on the grid."""
    if "phi1" not in ds or "time" not in ds["phi1"].dims:
        raise InputError("the measured file has no cam angle phi1 over time; run 'labtool process' on a "
                         "recording with a tacho channel (or with the kinematics' correlation)")
    t = np.asarray(ds["time"].values, dtype=float)
    if np.issubdtype(ds["time"].dtype, np.datetime64) or np.issubdtype(ds["time"].dtype, np.timedelta64):
        t = (ds["time"].values - ds["time"].values[0]) / np.timedelta64(1, "s")
    phi = np.asarray(ds["phi1"].values, dtype=float)
    data = {n: np.asarray(ds[n].values, dtype=float) for n in names}
    ok = np.isfinite(phi) & np.isfinite(t)
    for y in data.values():
        ok &= np.isfinite(y)
    if ok.sum() < 16:
        raise InputError("the measured file has fewer than 16 usable samples of phi1 and the signals")
    for n, y in data.items():   # 1e300 rad/s overflowed the impact check (OverflowError) as a bug
        big = np.flatnonzero(ok & (np.abs(y) > MAX_MEASURED))
        if big.size:
            raise InputError(f"the measured file's {n} reaches {y[big[0]]:g}, past any follower's motion "
                             f"(|{n}| <= {MAX_MEASURED:g} in SI units); the file is damaged: process the recording again")
    t, phi = t[ok], phi[ok]
    data = {n: y[ok] for n, y in data.items()}
    if np.any(np.diff(t) <= 0):
        raise InputError("the measured file's time does not increase sample by sample")
    theta = _unwrapped_angle(phi)
    if theta[-1] < theta[0]:
        raise InputError("the measured cam angle phi1 decreases over the recording; expected the cam to turn forwards")
    dt = np.diff(t)
    step = float(np.median(dt)) if dt.size else 0.0
    gap_at = np.flatnonzero(dt > 1.5 * step) if step > 0 else np.array([], int)
    gap_times = t[gap_at]
    # samples dropped as non-finite also make a gap
    k_first = int(math.ceil(theta[0] / TWO_PI - 1e-9))
    k_last = int(math.floor(theta[-1] / TWO_PI + 1e-9)) - 1
    fine = cond.fine_grid
    revs, out, times = [], {n: [] for n in names}, []
    partial = 0
    tol = 2.0 * float(np.median(np.abs(np.diff(theta)))) if theta.size > 1 else 0.0
    for k in range(k_first, k_last + 1):
        a, b = TWO_PI * k, TWO_PI * (k + 1)
        i0 = int(np.searchsorted(theta, a - tol, side="left"))
        i1 = int(np.searchsorted(theta, b + tol, side="right"))
        seg = slice(max(i0 - 1, 0), min(i1 + 1, theta.size))
        th, tt = theta[seg], t[seg]
        if th.size < 8 or th[0] > a + tol or th[-1] < b - tol or np.any((gap_times >= tt[0]) & (gap_times < tt[-1])):
            partial += 1
            continue
        if np.any(np.diff(th) <= 0):       # jitter in phi1: keep it monotonic for interpolation
            order = np.argsort(th, kind="stable")
            th, tt = th[order], tt[order]
            sel = {n: y[seg][order] for n, y in data.items()}
        else:
            sel = {n: y[seg] for n, y in data.items()}
        revs.append(k)
        times.append(np.interp(a + cond.grid, th, tt))
        for n in names:
            out[n].append(np.interp(a + fine, th, sel[n]))
    # the partial revolutions before the first and after the last whole one
    partial += int(theta[0] < TWO_PI * k_first - tol) + int(theta[-1] > TWO_PI * (k_last + 1) + tol)
    if not revs:
        turns = max(k_last - k_first + 1, 0)
        dropped = int(ok.size - ok.sum())
        why = (f": each of its {turns} revolutions holds a gap, {dropped} samples are not finite (clipped at the ADC's "
               f"rails, most likely at the impacts): {LARGER_RANGE} and process it again" if turns and dropped else "")
        src = ds.encoding.get("source")
        raise InputError(f"{shown(src) + ': it' if src else 'the measured file'} holds no whole cam revolution (need phi1 to cover 0..360 deg without gaps){why}")
    signals = {n: condition(np.array(v), cond) for n, v in out.items()}
    times = np.array(times)
    period = float(np.mean(times[:, -1] - times[:, 0])) * cond.n_grid / (cond.n_grid - 1)
    return MeasuredCycles(cond.grid, np.array(revs), signals, times, partial, 60.0 / period)


@dataclasses.dataclass
class SimulatedCycle:
    """One simulated revolution on the report grid; ``covered`` marks the grid points the
    simulation reached (False outside a partial simulation)."""

    grid: np.ndarray
    signals: dict
    covered: np.ndarray
    note: str
    periodic: bool = True      # one revolution (the kinematics, a partial run): nothing to average
    change: float = 0.0
    n_used: int = 1

    @property
    def std(self) -> dict:
        return {n: np.zeros_like(v) for n, v in self.signals.items()}


def _sim_time(sim: xr.Dataset, ok: np.ndarray, order: np.ndarray) -> np.ndarray | None:
    """The simulation's time (s) on the same axis as phi1, strictly increasing, or None."""
    if "time" not in sim.variables or sim["time"].shape != sim["phi1"].shape:
        return None
    t = np.asarray(sim["time"].values, dtype=float)[ok][order]
    # an impact may repeat a time stamp (the states before and after it): non-decreasing is enough
    if not (np.all(np.isfinite(t)) and np.all(np.diff(t) >= 0) and t[-1] > t[0]):
        return None
    return t


def _sim_angle(sim: xr.Dataset, names) -> tuple[np.ndarray, dict]:
    if "phi1" not in sim.variables:
        raise InputError("the simulation has no cam angle phi1")
    phi = np.asarray(sim["phi1"].values, dtype=float)
    data = {}
    for n in names:
        if n not in sim:
            raise InputError(f"the simulation ({sim.attrs.get('model', '?')}) has no {n}")
        y = np.asarray(sim[n].values, dtype=float)
        if y.shape != phi.shape:
            raise InputError(f"the simulation's {n} is not on the same axis as its phi1")
        data[n] = y
    return phi, data


def derivative_in_time(omega2_fine: np.ndarray, omega1_fine: np.ndarray, cond: Conditioning) -> np.ndarray:
    """d omega2/dt (rad/s^2) of a revolution on the fine grid: the band-limited derivative with
    respect to phi1 (harmonic k times i k), times the cam speed omega1(phi1) (rad/s)."""
    spec = np.fft.rfft(omega2_fine)
    spec[cond.n_harmonics + 1:] = 0.0
    k = np.arange(spec.size)
    d_dphi = np.fft.irfft(1j * k * spec, n=omega2_fine.size)
    return d_dphi * omega1_fine


def _time_filtered_revolution(theta, t, data, a, fine, tf: TimeFilter) -> dict:
    """Signals of the revolution [a, a + 2 pi] resampled uniformly in the simulation's own time at
    the recording's rate, low-passed like the measurement (periodically), then put on ``a + fine``."""
    ta, tb = np.interp([a, a + TWO_PI], theta, t)
    n = max(int(round((tb - ta) * tf.fs)), 16)
    tt = ta + (tb - ta) * np.arange(n) / n
    th = np.interp(tt, t, theta)
    th_ext = np.append(th, a + TWO_PI)          # periodic closure for the interpolation
    out = {}
    for name, y in data.items():
        yf = tf.apply_periodic(np.interp(tt, t, y))
        out[name] = np.interp(a + fine, th_ext, np.append(yf, yf[0]))
    return out


def simulated_cycle(sim: xr.Dataset, names, cond: Conditioning, epsilon2_from_omega2: bool = False,
                    time_filter: TimeFilter | None = None) -> SimulatedCycle:
    """The last whole revolution of a simulation (or the part it covers), conditioned like the
    measurement. ``sim`` holds ``phi1`` (rad, from the start of the rise) and the signals on one axis
    (``phi1`` itself for the kinematic level, ``time`` for the dynamic models).

    ``epsilon2_from_omega2``: for a model whose epsilon2 leaves out the impulses of its impacts (the
    rigid model's velocity jumps), epsilon2 is taken as the time derivative of the band-limited
    omega2 instead, which is what an accelerometer behind the same filter sees (filtering and
    differentiation commute).

    ``time_filter``: the measurement's processing low-pass, applied to the simulation in its own
    time before the common conditioning (whole revolutions only)."""
    names = list(names)
    if epsilon2_from_omega2 and "omega1" in sim and "omega1" not in names:
        names.append("omega1")
    phi, data = _sim_angle(sim, names)
    ok = np.isfinite(phi)
    for y in data.values():
        ok &= np.isfinite(y)
    phi = phi[ok]
    data = {n: y[ok] for n, y in data.items()}
    if phi.size < 4:
        raise InputError(f"the simulation ({sim.attrs.get('model', '?')}) has fewer than 4 finite samples")
    theta = np.unwrap(phi) if np.any(np.diff(phi) < -math.pi) else phi
    order = np.argsort(theta, kind="stable")
    theta = theta[order]
    data = {n: y[order] for n, y in data.items()}
    fine = cond.fine_grid
    # a simulation that stops within half a fine-grid step of a revolution's end covers it
    # (interpolation holds the end value over that sliver)
    slack = 0.5 * TWO_PI / fine.size
    k_last = int(math.floor((theta[-1] + slack) / TWO_PI)) - 1
    t = _sim_time(sim, ok, order)
    if k_last >= 0 and theta[0] <= TWO_PI * k_last + slack:
        a = TWO_PI * k_last
        covered = np.ones(cond.n_grid, bool)
        note = f"revolution {k_last + 1} of {k_last + 1} simulated (steady state)"
        if time_filter is not None and t is not None:
            fine_vals = _time_filtered_revolution(theta, t, data, a, fine, time_filter)
            note += "; processing low-pass applied"
        else:
            fine_vals = {n: np.interp(a + fine, theta, y) for n, y in data.items()}
    else:
        # partial revolution: compare on the covered angles only; the rest is the dwell, at rest
        lo, hi = theta[0] % TWO_PI, theta[0] % TWO_PI + (theta[-1] - theta[0])
        base = theta[0] - lo
        x = base + fine
        inside = (x >= theta[0]) & (x <= theta[-1])
        fine_vals = {n: np.where(inside, np.interp(x, theta, y), 0.0) for n, y in data.items()}
        g = cond.grid + base
        covered = (g >= theta[0]) & (g <= theta[-1])
        note = (f"the simulation covers cam angles {math.degrees(lo):.1f}..{math.degrees(hi):.1f} deg only; "
                "metrics use that range, the figures show the rest of the revolution as rest (zero)")
    if epsilon2_from_omega2:
        w1 = fine_vals.pop("omega1", None)
        if w1 is None:
            w1 = np.full(fine.size, float(sim.attrs.get("omega1_rad_s", np.nan)))
        if not np.all(np.isfinite(w1)):
            raise InputError("the simulation has no cam speed omega1 to differentiate omega2 in time")
        fine_vals["epsilon2"] = derivative_in_time(fine_vals["omega2"], w1, cond)
        note += "; epsilon2 = d(omega2)/dt of the filtered omega2 (impact impulses included)"
    signals = {n: condition(v, cond) for n, v in fine_vals.items()}
    return SimulatedCycle(cond.grid, signals, covered, note)


@dataclasses.dataclass
class SimulatedCycles:
    """Every whole revolution of a simulation on the report grid, and the model's cycle.

    ``revolutions[name]``: (K, n_grid), revolution 0 first. ``periodic``: the last two revolutions
    agree within ``PERIODIC_TOL`` (``change`` is the larger relative rms difference of the two
    signals). ``signals``: the model's cycle, the last revolution when periodic, else the mean over
    the revolutions after the first (``n_used`` of them); ``std``: their scatter (0 when periodic)."""

    grid: np.ndarray
    revolutions: dict
    periodic: bool
    change: float
    signals: dict
    std: dict
    n_used: int
    covered: np.ndarray
    note: str

    def upto(self, k: int, tol: float = PERIODIC_TOL) -> "SimulatedCycles":
        """The same simulation stopped after its first ``k`` revolutions (a causal simulation of k
        revolutions is the first k revolutions of a longer one)."""
        return steady_cycles({n: v[:k] for n, v in self.revolutions.items()}, self.grid, tol)


def _uniform_in_time(sim: xr.Dataset, names, fs: float):
    """(theta (rad, unwrapped), time, {name: values}) resampled uniformly at ``fs`` over the
    simulation, or None when it has no usable time axis. At repeated time stamps (the states
    before and after a rigid impact) the later state is kept, so omega2 steps across them."""
    if "time" not in sim.variables or "phi1" not in sim.variables or sim["time"].shape != sim["phi1"].shape:
        return None
    t = np.asarray(sim["time"].values, dtype=float)
    cols = {n: np.asarray(sim[n].values, dtype=float) for n in names if n in sim and sim[n].shape == t.shape}
    phi = np.asarray(sim["phi1"].values, dtype=float)
    ok = np.isfinite(t) & np.isfinite(phi)
    for y in cols.values():
        ok &= np.isfinite(y)
    t, phi = t[ok], phi[ok]
    if t.size < 4 or np.any(np.diff(t) < 0):
        return None
    keep = np.append(np.diff(t) > 0, True)
    t, phi = t[keep], phi[keep]
    tu = t[0] + np.arange(int(math.floor((t[-1] - t[0]) * fs)) + 1) / fs
    return np.interp(tu, t, phi), tu, {n: np.interp(tu, t, y[ok][keep]) for n, y in cols.items()}


def _periodic_tail_filter(y: np.ndarray, period_n: int, tf: "TimeFilter") -> np.ndarray:
    """Zero-phase low-pass of a record whose end continues periodically (the steady state): one
    more period is appended before filtering so the last revolution has no edge transient."""
    n = y.size
    ext = np.concatenate([y, y[n - period_n:]]) if 0 < period_n < n else y
    return zero_phase(lowpass_sos(tf.fs, tf.cutoff_hz, tf.order), ext)[:n]


def simulated_cycles(sim: xr.Dataset, names, cond: Conditioning, epsilon2_from_omega2: bool = False,
                     time_filter: "TimeFilter | None" = None, tol: float = PERIODIC_TOL) -> SimulatedCycles | None:
    """Whole revolutions of a dynamic simulation conditioned like the measurement, and its steady
    cycle; None when the simulation has no time axis or no whole revolution (use simulated_cycle).

    The simulation is resampled uniformly in its own time (at the recording's rate when the
    measurement's low-pass is known), low-passed with ``time_filter`` (zero-phase, as the
    processing), then every revolution [2 pi k, 2 pi (k+1)] goes through ``condition`` on the
    fine grid. ``epsilon2_from_omega2`` (rigid model: its epsilon2 leaves out the impulses of its
    velocity jumps): epsilon2 = d(omega2)/dt of the filtered omega2, which is what an accelerometer
    behind the same filter sees (filtering and differentiation commute)."""
    names = list(names)
    fs = time_filter.fs if time_filter is not None else SIM_RATE_HZ
    u = _uniform_in_time(sim, names, fs)
    if u is None:
        return None
    theta, tu, data = u
    if any(n not in data for n in names if not (n == "epsilon2" and epsilon2_from_omega2)):
        return None
    # a run that stops within 1.5 resampling steps of a revolution's end covers it (the uniform
    # resampling ends up to one step before the run; the rigid model stops 3e-9 of a turn short)
    slack = 1.5 * float(theta[-1] - theta[-2]) if theta.size > 1 else 0.0
    K = int(math.floor((theta[-1] + slack) / TWO_PI))
    if K < 1 or theta[0] > 1e-6:
        return None
    period_n = int(round(TWO_PI / max(float(np.median(np.diff(theta))), 1e-12)))   # samples per revolution
    if time_filter is not None:
        data = {n: _periodic_tail_filter(y, period_n, time_filter) for n, y in data.items()}
    if epsilon2_from_omega2:
        data["epsilon2"] = np.gradient(data["omega2"], 1.0 / fs)
    fine = cond.fine_grid
    revs = {n: condition(np.array([np.interp(TWO_PI * k + fine, theta, data[n]) for k in range(K)]), cond)
            for n in names}
    out = steady_cycles(revs, cond.grid, tol)
    if time_filter is not None:
        out.note += "; processing low-pass applied"
    if epsilon2_from_omega2:
        out.note += "; epsilon2 = d(omega2)/dt of the filtered omega2 (impact impulses included)"
    return out


def steady_cycles(revs: dict, grid: np.ndarray, tol: float = PERIODIC_TOL) -> SimulatedCycles:
    """The model's cycle from its conditioned revolutions ``revs[name]`` (K, n_grid)."""
    K = next(iter(revs.values())).shape[0]
    change = 0.0
    if K >= 2:
        change = max(periodicity.revolution_change(v[-1], v[-2]) for v in revs.values())
    periodic = K >= 2 and change < tol
    if periodic or K < 3:
        cyc = {n: v[-1].copy() for n, v in revs.items()}
        std = {n: np.zeros(v.shape[1]) for n, v in revs.items()}
        n_used = 1
        note = (f"periodic: revolution {K} of {K} (steady state; it differs from revolution {K - 1} by "
                f"{100 * change:.2g} % rms)" if periodic else
                f"revolution {K} of {K}" + ("" if K < 2 else f"; NOT periodic ({100 * change:.2g} % rms change "
                                              "from the revolution before), too few revolutions for statistics"))
    else:
        stats = {n: cycle_statistics(v[1:]) for n, v in revs.items()}
        cyc = {n: st.mean for n, st in stats.items()}
        std = {n: st.std for n, st in stats.items()}
        n_used = K - 1
        note = (f"NOT periodic ({100 * change:.2g} % rms change between its last two revolutions): the model's "
                f"cycle average over revolutions 2..{K} is compared, with its scatter")
    return SimulatedCycles(grid, revs, periodic, change, cyc, std, n_used, np.ones(grid.size, bool), note)


def as_measured(signals: dict, ka_gain: float = 1.0, delay_rad: float = 0.0) -> dict:
    """Conditioned revolutions (last axis = one period of phi1) as a chain with a Ka error and a
    delay would show them: divided by ``ka_gain`` (true Ka / the Ka the processing used: the
    measured accelerations, and omega2 integrated from them, are the truth over it) and delayed by
    ``delay_rad`` of cam angle (omega1 times the channels' delay behind the tacho; > 0 late), i.e.
    y(phi1 - delay_rad). The shift is exact for the band-limited conditioned signals (a phase
    ramp on their harmonics)."""
    out = {}
    for name, y in signals.items():
        y = np.asarray(y, float)
        if delay_rad:
            spec = np.fft.rfft(y, axis=-1)
            spec *= np.exp(-1j * np.arange(spec.shape[-1]) * delay_rad)
            y = np.fft.irfft(spec, n=y.shape[-1], axis=-1)
        out[name] = y / ka_gain
    return out


def cycle_as_measured(cycle, ka_gain: float = 1.0, delay_rad: float = 0.0):
    """A simulated cycle (``SimulatedCycles`` or ``SimulatedCycle``: its cycle, scatter and
    revolutions) as a chain with a Ka error and a delay shows it (``as_measured``)."""
    if ka_gain == 1.0 and delay_rad == 0.0:
        return cycle
    rep = {"signals": as_measured(cycle.signals, ka_gain, delay_rad)}
    if isinstance(cycle, SimulatedCycles):
        rep["std"] = as_measured(cycle.std, ka_gain, delay_rad)
        rep["revolutions"] = as_measured(cycle.revolutions, ka_gain, delay_rad)
    return dataclasses.replace(cycle, **rep)
