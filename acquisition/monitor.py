"""What the stand looks like while it records: cam speed from the tacho, per-channel peak / RMS in
engineering units with the headroom left, losses, buffer fill, progress, the last revolution.

Device-independent (fed the same Blocks the recorder writes, for the simulated stand and NI-DAQmx
alike) and display-free: ``Monitor.update(block)`` after every block, ``Monitor.snapshot(...)``
when a display wants figures. Bounded work per block (a few numpy reductions) and bounded memory
(at most ``trace_window_s`` of two channels).

Cam speed: rising edges of the ``tacho`` channel through half its running peak (at least 0.5 V),
placed between samples by linear interpolation; rpm = 60 / (time between the last two edges). Time
is the device sample count, so an overrun between two edges does not distort the speed. Drift =
the last revolution's speed minus the first one's (rpm).
"""
from __future__ import annotations

import collections
import dataclasses
import math

import numpy as np

HEADROOM_WARN = 0.8  # peak above this fraction of the input range: warn (yellow)


@dataclasses.dataclass
class ChannelFigures:
    """One channel. Values in ``unit`` (m/s^2 where Ka is known, else V); fraction of the range
    from the volts. state: ok | warn (> 80 % of the range) | clip."""

    name: str
    unit: str
    peak: float
    peak_recent: float
    rms_recent: float
    peak_v: float
    range_v: float
    fraction: float
    state: str


@dataclasses.dataclass
class Snapshot:
    elapsed_wall_s: float
    data_s: float
    duration_s: float | None
    progress: float | None
    eta_s: float | None
    rpm: float | None
    rpm_drift: float | None
    revolutions: int
    channels: list[ChannelFigures]
    overruns: int
    gaps: int
    samples_lost: int
    buffer_fill: float | None
    trace: dict | None  # {"what": text, "x": phase or time, "x_unit": ..., name: values, "unit": ...}


class Monitor:
    """Running figures of one acquisition (see the module docstring).

    channel_names, rate_hz   as the device delivers them
    ka_m_s2_per_v            per channel (NaN: shown in V)
    range_v                  per channel +-input range (V; NaN: unknown)
    duration_s               planned data duration (None: until stopped)
    """

    def __init__(self, channel_names, rate_hz: float, ka_m_s2_per_v=None, range_v=None, duration_s=None,
                 recent_s: float = 1.0, trace_window_s: float = 4.0, trace_points: int = 200):
        self.names = tuple(channel_names)
        n = len(self.names)
        self.rate = float(rate_hz)
        self.ka = np.full(n, np.nan) if ka_m_s2_per_v is None else np.asarray(ka_m_s2_per_v, float)
        self.range_v = np.full(n, np.nan) if range_v is None else np.asarray(range_v, float)
        self.duration_s = duration_s
        self.recent_n = max(1, int(recent_s * self.rate))
        self.trace_points = trace_points
        self._tacho = self.names.index("tacho") if "tacho" in self.names else None
        self._accel = [i for i, nm in enumerate(self.names) if nm in ("aE_t", "aE_n")]
        self.peak_v = np.zeros(n)
        self._recent = collections.deque()  # (n_samples, max|v| per channel, sum v^2 per channel)
        self._recent_count = 0
        self._tacho_peak = 0.0
        self._prev_tacho = None  # (device index, value) of the last tacho sample
        self.edges: collections.deque = collections.deque(maxlen=64)  # device sample positions of edges
        self.first_rpm = None
        self.revolutions = 0
        self._cap = max(1, int(trace_window_s * self.rate))
        self._trace_blocks = collections.deque()  # (first device index, (n, k) volts of the accel channels)
        self._trace_n = 0
        self.end_index = 0
        self._last_trace = None

    # -- feeding
    def update(self, block) -> None:
        data = np.asarray(block.data, float)
        self.end_index = block.end_index
        if data.shape[0] == 0:
            return
        with np.errstate(invalid="ignore"):
            pk = np.nanmax(np.abs(data), axis=0)
            sq = np.nansum(data * data, axis=0)
        self.peak_v = np.fmax(self.peak_v, pk)
        self._recent.append((data.shape[0], pk, sq))
        self._recent_count += data.shape[0]
        while len(self._recent) > 1 and self._recent_count - self._recent[0][0] >= self.recent_n:
            self._recent_count -= self._recent.popleft()[0]
        if self._accel:
            self._trace_blocks.append((block.first_index, data[:, self._accel]))
            self._trace_n += data.shape[0]
            while len(self._trace_blocks) > 1 and self._trace_n - self._trace_blocks[0][1].shape[0] >= self._cap:
                self._trace_n -= self._trace_blocks.popleft()[1].shape[0]
        if self._tacho is not None:
            self._find_edges(block.first_index, data[:, self._tacho])

    def _find_edges(self, first: int, x: np.ndarray) -> None:
        finite = x[np.isfinite(x)]
        if finite.size:
            self._tacho_peak = max(self._tacho_peak, float(finite.max()))
        level = max(0.5, 0.5 * self._tacho_peak)
        n = x.size
        idx = first + np.arange(n, dtype=float)
        if self._prev_tacho is not None and self._prev_tacho[0] == first - 1:  # an edge across two blocks
            idx = np.concatenate([[first - 1.0], idx])
            x_prev = self._prev_tacho[1]
            self._prev_tacho = (first + n - 1, float(x[-1]))
            x = np.concatenate([[x_prev], x])
        else:
            self._prev_tacho = (first + n - 1, float(x[-1]))
        up = np.flatnonzero((x[:-1] < level) & (x[1:] >= level))
        for i in up:
            pos = idx[i] + (level - x[i]) / (x[i + 1] - x[i])
            self.edges.append(float(pos))
            if len(self.edges) >= 2:
                self.revolutions += 1
                if self.first_rpm is None:
                    self.first_rpm = self._rpm(-1)
                self._last_trace = self._trace_between(self.edges[-2], self.edges[-1])

    def _rpm(self, k: int) -> float | None:
        if len(self.edges) < 2:
            return None
        dt = (self.edges[k] - self.edges[k - 1]) / self.rate
        return 60.0 / dt if dt > 0 else None

    # -- the last revolution
    def _window(self):
        if not self._trace_blocks:
            return None, None
        firsts = [f for f, _ in self._trace_blocks]
        arrays = [a for _, a in self._trace_blocks]
        # the window is contiguous only after its last gap
        start = 0
        for k in range(1, len(firsts)):
            if firsts[k] != firsts[k - 1] + arrays[k - 1].shape[0]:
                start = k
        return firsts[start], np.concatenate(arrays[start:])

    def _trace_between(self, a: float, b: float) -> dict | None:
        first, v = self._window()
        if v is None:
            return None
        lo, hi = int(math.ceil(a)) - first, int(math.floor(b)) - first
        if lo < 0 or hi > v.shape[0] or hi - lo < 8:
            return None
        return self._binned(v[lo:hi], "last revolution", "phi1 from the tacho [deg]", 360.0)

    def _binned(self, v: np.ndarray, what: str, x_unit: str, x_span: float) -> dict:
        npts = min(self.trace_points, v.shape[0])
        edges = np.linspace(0, v.shape[0], npts + 1).astype(int)
        # each bin shows its extreme sample (signed), so an impact of one sample stays visible
        hi, lo = np.maximum.reduceat(v, edges[:-1], axis=0), np.minimum.reduceat(v, edges[:-1], axis=0)
        means = np.where(np.abs(hi) >= np.abs(lo), hi, lo)
        ka = self.ka[self._accel]
        scaled = np.all(np.isfinite(ka))
        out = {"what": what, "x": (edges[:-1] + np.diff(edges) / 2) / v.shape[0] * x_span, "x_unit": x_unit,
               "unit": "m/s^2" if scaled else "V"}
        for j, i in enumerate(self._accel):
            out[self.names[i]] = means[:, j] * (ka[j] if scaled else 1.0)
        return out

    # -- figures
    def snapshot(self, elapsed_wall_s: float, overruns: int = 0, gaps: int = 0, samples_lost: int = 0,
                 clipped=(), buffer_fill=None, rows: int | None = None) -> Snapshot:
        data_s = (self.end_index if rows is None else rows) / self.rate
        dur = self.duration_s
        progress = eta = None
        if dur:
            progress = min(1.0, self.end_index / (dur * self.rate))
            pace = self.end_index / self.rate / elapsed_wall_s if elapsed_wall_s > 0 else 0.0
            eta = (dur - self.end_index / self.rate) / pace if pace > 0 else None
        rpm = self._rpm(-1)
        drift = None if rpm is None or self.first_rpm is None else rpm - self.first_rpm
        chans = self._channels(set(clipped))
        trace = self._last_trace
        if trace is None and self._accel and self._tacho is None:
            first, v = self._window()
            if v is not None:
                n = min(v.shape[0], max(8, int(0.05 * self.rate)))
                trace = self._binned(v[-n:], "last 50 ms (no tacho)", "time [ms]", 1e3 * n / self.rate)
        return Snapshot(elapsed_wall_s, data_s, dur, progress, eta, rpm, drift, self.revolutions, chans,
                        overruns, gaps, samples_lost, buffer_fill, trace)

    def _channels(self, clipped: set) -> list[ChannelFigures]:
        if self._recent:
            pk_recent = np.max(np.array([p for _, p, _ in self._recent]), axis=0)
            rms_recent = np.sqrt(np.sum(np.array([s for _, _, s in self._recent]), axis=0) / self._recent_count)
        else:
            pk_recent = rms_recent = np.zeros(len(self.names))
        out = []
        for i, name in enumerate(self.names):
            k = self.ka[i]
            scale, unit = (k, "m/s^2") if math.isfinite(k) else (1.0, "V")
            r = self.range_v[i]
            frac = self.peak_v[i] / r if math.isfinite(r) and r > 0 else math.nan
            # at the rails: within 2 LSB of a 16-bit converter
            state = "clip" if (name in clipped or (math.isfinite(frac) and frac >= 1 - 2 / 2**15)) else \
                ("warn" if math.isfinite(frac) and frac > HEADROOM_WARN else "ok")
            out.append(ChannelFigures(name, unit, self.peak_v[i] * scale, pk_recent[i] * scale, rms_recent[i] * scale,
                                      float(self.peak_v[i]), float(r), float(frac), state))
        return out
