"""State carried across the chunks of one run: spikes found, the normal-axis check, clipped samples.

Each accumulator is fed the core (the samples a chunk owns, without its overlap) of every window
and gives its result at the end; memory does not grow with the recording beyond ``MAX_SPIKES``.
"""
from __future__ import annotations

import math

import numpy as np

from labtool.processing import events, kernels

MAX_SPIKES = 100_000  # stored spike records (a noisy hour could otherwise hold millions)


class SpikeCollector:
    """Spikes of aE_t and aE_n (events.detect_spikes on the content above the processing band)."""

    def __init__(self, fs: float, k_sigma: float, max_stored: int | None = None):
        self.fs, self.k_sigma = fs, k_sigma
        self.max_stored = MAX_SPIKES if max_stored is None else max_stored
        self.index: list[int] = []
        self.channel: list[str] = []
        self.amplitude: list[float] = []
        self.threshold: list[float] = []
        self.seen = 0

    def feed(self, phys, lowpassed, clipped, wa: int, c0: int, c1: int, scratch=None) -> None:
        """phys, lowpassed: (n, 2) over the window starting at sample ``wa``; core [c0, c1);
        scratch: a reusable float array of >= n samples."""
        scratch = np.empty(len(phys)) if scratch is None else scratch
        distance = float(max(1, int(events.DEFAULT_REFRACTORY_S * self.fs)))
        for j, name in enumerate(("aE_t", "aE_n")):
            # events.detect_spikes on the residual, compiled (tests/test_proc_kernels.py)
            pk, amp, thr = kernels.spikes(phys, lowpassed, clipped, j, self.k_sigma, events.DEFAULT_FLOOR_FRACTION,
                                          distance, scratch)
            if not len(pk):
                continue
            keep = (pk >= c0) & (pk < c1)
            self.seen += int(keep.sum())
            room = self.max_stored - len(self.index)
            if keep.sum() > room:  # bounded memory: keep the first max_stored, count the rest
                keep &= np.cumsum(keep) <= room
            k = int(keep.sum())
            self.index.extend((pk[keep] + wa).tolist())
            self.channel.extend([name] * k)
            self.amplitude.extend(amp[keep].tolist())
            self.threshold.extend([thr] * k)

    @property
    def stored(self) -> int:
        return len(self.index)

    def sorted(self):
        """(sample index, channel, amplitude, threshold) arrays in time order."""
        si = np.asarray(self.index, dtype=np.int64)
        order = np.argsort(si, kind="stable")
        ch = np.asarray(self.channel, dtype=str)[order] if len(si) else np.array([], dtype=str)
        return (si[order], ch, np.asarray(self.amplitude, dtype=float)[order],
                np.asarray(self.threshold, dtype=float)[order])


class NormalCheck:
    """rms(|omega2| - sqrt(aE_n/DE)) / max|omega2| over the motion samples: two independent axes.

    ``sums`` (sum of squares, count, peak) is what kernels.core_outputs adds to in the pipeline;
    ``feed`` is the same in numpy.
    """

    def __init__(self):
        self.sums = np.zeros(3)

    def feed(self, omega2, absn, moving) -> None:
        mv = moving & np.isfinite(omega2)
        if mv.any():
            d = np.abs(omega2[mv]) - absn[mv]
            self.sums[0] += float(np.sum(d * d))
            self.sums[1] += int(mv.sum())
            self.sums[2] = max(self.sums[2], float(np.max(np.abs(omega2[mv]))))

    @property
    def value(self) -> float:
        sq, n, peak = self.sums
        return math.sqrt(sq / n) / peak if n and peak > 0 else math.nan


# what to do about a recording clipped at every impact: the advice process and report give alike
# (tests/test_hostile_advice.py follows it)
LARGER_RANGE = ("record with a larger range in m/s^2 (the ADC's range x Ka: a less sensitive conditioner setting; "
                "on the simulated stand acquire --ka 8643)")


class ClipCounter:
    """Samples flagged as clipped (events, rails, runs at a channel's extreme)."""

    MIN_RUN = 3  # samples in a row at a channel's extreme value that make a clip
    MIN_DROP_LEVELS = 3  # ... entered or left by a step of at least this many ADC levels (when known)

    def __init__(self, rail_v: float | None, recorder_events: np.ndarray, lsb_v: float | None = None):
        self.rail_v = rail_v
        self.min_drop_v = self.MIN_DROP_LEVELS * lsb_v if lsb_v else 0.0
        self.events = recorder_events
        self.flagged = 0

    def mask(self, block, cols, lo, hi, wa: int, wb: int, out=None) -> np.ndarray:
        """Clip flags of a window's samples [wa, wb) (into ``out`` if given): columns ``cols`` of
        ``block`` (volts, as read), per-channel extremes lo, hi of those columns."""
        out = np.empty(wb - wa, dtype=np.bool_) if out is None else out
        kernels.clip_mask(block, cols, lo, hi, self.rail_v or 0.0, self.MIN_RUN, self.min_drop_v, out)
        sel = self.events[(self.events >= wa) & (self.events < wb)]
        out[sel - wa] = True
        return out

    def count(self, core_mask) -> None:
        self.flagged += int(core_mask.sum())
