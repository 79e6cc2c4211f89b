"""The common shape of every reader: a lazily read recording in volts plus its metadata.

A reader validates everything it can cheaply (format, sample rate, channel names, shape) when the
file is opened, and reads the samples chunk by chunk so that a recording of any length is
processed in bounded memory. Samples are volts as recorded (no calibration applied).
"""
from __future__ import annotations

import dataclasses
import math
import re
from typing import Callable, Iterator

import numpy as np

from labtool.common.errors import FileFormatError, InputError
from labtool.common.names import shown
# the format's event kinds and the text and rate checks every reader shares
from labtool.common.recording_format import EVENT_KINDS, SPLITTING_KINDS, as_text, check_sample_rate  # noqa: F401



@dataclasses.dataclass
class Event:
    """One recorder event: ``index`` (sample index, 0-based), ``kind``, free-text ``detail``."""
    index: int
    kind: str
    detail: str = ""


@dataclasses.dataclass
class Recording:
    """A recording opened for chunked reading.

    sample_rate_hz: the rate the device really ran at (Hz); channel_names: one per column;
    ka_m_s2_per_v: per-channel calibration (m/s^2/V, NaN where none); channel_units: "V" (read()
    gives volts) or "m/s^2" (the file gave an acceleration, read() gives m/s^2); complete: False for a
    recording whose writer did not close cleanly; cam_speed_rpm: nominal, NaN when unknown.
    ``read(start, stop)`` returns float64 of shape (stop - start, n_channels) in channel_units,
    checked for NaN/Inf. A reader that can fill a buffer straight from the file also gives
    ``read_raw(start, stop, out)``: the samples as stored (``raw_dtype``), not checked (see
    ``read_unchecked``).
    """
    source: str
    format: str
    sample_rate_hz: float
    channel_names: list[str]
    n_samples: int
    read: Callable[[int, int], np.ndarray]
    ka_m_s2_per_v: np.ndarray
    start_time_utc: str = ""
    complete: bool = True
    cam_speed_rpm: float = math.nan
    events: list[Event] = dataclasses.field(default_factory=list)
    attrs: dict = dataclasses.field(default_factory=dict)
    warnings: list[str] = dataclasses.field(default_factory=list)
    close: Callable[[], None] = lambda: None
    channel_units: list[str] = dataclasses.field(default_factory=list)   # "V" or "m/s^2" per channel
    unit_sources: list[str] = dataclasses.field(default_factory=list)    # where each unit was read
    assumptions: list[str] = dataclasses.field(default_factory=list)     # what the reader assumed, in words
    read_raw: Callable[[int, int, np.ndarray], np.ndarray] | None = None
    raw_dtype: type = np.float64                                         # the dtype read_raw fills
    left_out: list[str] = dataclasses.field(default_factory=list)        # the file's channels not read (side channels)
    file_names: list[str] = dataclasses.field(default_factory=list)      # the channels' names in the file (before renaming)

    def __post_init__(self):
        n = len(self.channel_names)
        if not self.file_names:
            self.file_names = list(self.channel_names)
        if not self.channel_units:
            self.channel_units = ["V"] * n
        if not self.unit_sources:
            self.unit_sources = ["format (volts)"] * n
        outside = [e for e in self.events if not 0 <= e.index <= self.n_samples]
        if outside:          # segments(), lost_samples() and clip_indices() leave them out: say so
            first = outside[0]
            self.warnings.append(f"{self.source}: ignoring {len(outside)} recorder event(s) outside its samples "
                                 f"0..{self.n_samples} (the first: {first.kind} at sample {first.index}); "
                                 "they mark no sample of this recording")

    def __enter__(self) -> "Recording":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def n_channels(self) -> int:
        return len(self.channel_names)

    @property
    def duration_s(self) -> float:
        return self.n_samples / self.sample_rate_hz

    def channel_index(self, name: str) -> int:
        """Column of channel ``name`` (exact, then case-insensitive); FileFormatError if absent."""
        if name in self.channel_names:
            return self.channel_names.index(name)
        low = [c.lower() for c in self.channel_names]
        if name.lower() in low:
            return low.index(name.lower())
        aside = f"; left out at another rate or length: {', '.join(self.left_out)}" if self.left_out else ""
        raise FileFormatError(
            f"{self.source}: channel '{name}' is missing (channels: {', '.join(self.channel_names) or 'none'}{aside}); "
            f"name the file's channels with --channels {name}=<channel>")

    def rename_channels(self, mapping: dict[str, str]) -> None:
        """Give source channels the names the chain uses, e.g. {"aE_t": "aE180t"} (new: old), all at
        once: {"aE_t": "aE_n", "aE_n": "aE_t"} swaps two channels."""
        names = list(self.channel_names)
        cols = {new: self.channel_index(old) for new, old in mapping.items()}
        twice = [new for new in cols if list(cols.values()).count(cols[new]) > 1]
        if twice:
            raise InputError(f"{self.source}: channel '{mapping[twice[0]]}' is named twice "
                             f"({', '.join(sorted(twice))}); name each of the file's channels once")
        for new, j in cols.items():
            names[j] = new
        for new, j in cols.items():
            if [k for k, n in enumerate(names) if n.lower() == new.lower()] != [j]:
                raise InputError(f"{self.source}: cannot name channel '{mapping[new]}' '{new}': another channel has "
                                 "that name (name that one too, e.g. --channels aE_t=<a>,aE_n=<b> swaps two)")
        self.channel_names = names

    def has_channel(self, name: str) -> bool:
        return name.lower() in [c.lower() for c in self.channel_names]

    def chunks(self, chunk_samples: int, start: int = 0, stop: int | None = None) -> Iterator[tuple[int, np.ndarray]]:
        """Yield (first sample index, volts[n, n_channels]) over [start, stop)."""
        stop = self.n_samples if stop is None else stop
        for a in range(start, stop, chunk_samples):
            b = min(a + chunk_samples, stop)
            yield a, self.read(a, b)

    def read_unchecked(self, start: int, stop: int, out: np.ndarray | None = None) -> np.ndarray:
        """Samples [start, stop) as the file stores them (``raw_dtype``), **not checked** for NaN/Inf.

        For a caller that checks every sample itself (the pipeline's first pass, kernels.scan_block,
        before any result is made); ``out`` a reusable buffer of (>= stop - start, n_channels) and
        ``raw_dtype`` (no allocation, no conversion: the HDF5 reader fills it with read_direct).
        Readers without ``read_raw`` give ``read()``'s float64 (checked anyway).
        """
        if self.read_raw is None:
            return self.read(start, stop)
        if out is None or out.shape[0] < stop - start:
            out = np.empty((stop - start, self.n_channels), dtype=self.raw_dtype)
        return self.read_raw(start, stop, out)

    def segments(self) -> list[tuple[int, int]]:
        """Contiguous sample ranges [a, b): gaps and overruns split the data, never interpolated."""
        cuts = sorted({e.index for e in self.events if e.kind in SPLITTING_KINDS and 0 < e.index < self.n_samples})
        bounds = [0, *cuts, self.n_samples]
        return [(a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]

    def lost_samples(self) -> tuple[np.ndarray, np.ndarray, int]:
        """(row indices, samples lost before each, events whose loss is unknown) from the gap events.

        The recorder writes ``missing_samples=N`` at the start of a gap event's detail (samples the
        device lost before that row). Overrun events at the same row are not counted twice.
        """
        rows, lost, unknown = [], [], 0
        gap_rows = set()
        for e in self.events:
            if e.kind != "gap" or not (0 < e.index < self.n_samples):
                continue
            gap_rows.add(e.index)
            m = re.search(r"missing_samples\s*=\s*(\d+)", e.detail)
            if m:
                rows.append(e.index)
                lost.append(int(m.group(1)))
            else:
                unknown += 1
        unknown += len({e.index for e in self.events if e.kind == "overrun" and 0 < e.index < self.n_samples}
                       - gap_rows)
        order = np.argsort(rows, kind="stable")
        rows_a, lost_a = np.asarray(rows, dtype=np.int64)[order], np.asarray([min(x, 2**62) for x in lost],
                                                                              dtype=np.int64)[order]
        self._check_lost(rows_a, lost_a)
        return rows_a, lost_a, unknown

    def _check_lost(self, rows: np.ndarray, lost: np.ndarray) -> None:
        """Samples lost at gaps that no run allows are refused: 9e17 lost samples wrote a time axis
        of 9e13 s that xarray cannot decode, with exit 0. The bound: MAX_LOST_S in all (a device
        lost for longer than that is a new run, not a gap). The wall clock (start_time_utc to
        stop_time_utc) is no bound: the simulated stand records faster than real time."""
        if not len(lost):
            return
        fs = self.sample_rate_hz
        total = float(lost.sum(dtype=np.float64))
        if total / fs > MAX_LOST_S:
            k = int(np.argmax(lost))
            raise FileFormatError(
                f"{self.source}: its gap events claim {total:.0f} lost samples ({total / fs:.4g} s at {fs:g} Hz), "
                f"more than one run can lose ({MAX_LOST_S:g} s); the events are damaged (the largest: "
                f"missing_samples={int(lost[k])} at sample {int(rows[k])})")

    def clip_indices(self) -> np.ndarray:
        """Sample indices the recorder reported as clipped."""
        return np.array(sorted(e.index for e in self.events if e.kind == "clip" and 0 <= e.index < self.n_samples),
                        dtype=np.int64)


MAX_LOST_S = 86400.0   # s: the most a run's gaps may lose in all (a device lost longer is a new run)


MAX_SAMPLE = 1e12   # V or m/s^2: past any ADC or accelerometer; x Ka (<= 1e6) and squared it stays finite


def check_finite(block: np.ndarray, start: int, names: list[str], source: str) -> None:
    """NaN or Inf volts are not a measurement: InputError naming the first bad sample. Nor is a
    sample past MAX_SAMPLE: 1e300 V in a CSV cell made the chain's omega2 inf with exit 0."""
    bad = ~np.isfinite(block)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise InputError(f"{source}: sample {start + i} of channel '{names[j]}' is {block[i, j]} (NaN/Inf); "
                         "the recording is damaged")
    big = np.abs(block) > MAX_SAMPLE
    if big.any():
        i, j = np.argwhere(big)[0]
        raise InputError(f"{source}: sample {start + i} of channel '{names[j]}' is {block[i, j]:g}, past any ADC or "
                         f"accelerometer (|sample| <= {MAX_SAMPLE:g} V or m/s^2); the recording is damaged")


def stated_number(attrs, name: str, source, option: str | None = None) -> float | None:
    """The attribute ``name`` of ``attrs`` (a file's attributes) as one number, None when the file
    has none; one that is not one number is InputError naming ``source`` and the option ``option``
    that gives the value instead, if there is one. (Read loosely, such an attribute was taken for
    "not stated": a default replaced what the file meant.)"""
    raw = attrs.get(name)
    if raw is None:
        return None
    try:
        if np.size(raw) != 1:
            raise ValueError
        return float(np.asarray(raw).ravel()[0])
    except (TypeError, ValueError):
        raise InputError(f"{shown(source)}: attribute {name} = {shown(as_text(raw))!r} is not a number; fix the file"
                         + (f" or give {option}" if option else "")) from None
