"""The recorder: writes DESIGN.md's recording format v1 (HDF5) while acquiring, losing nothing.

Layout written (format_version 1):

- root attributes ``format = "labtool.recording"``, ``format_version = 1``, ``sample_rate_hz``
  (the rate the device really runs at), ``start_time_utc`` (ISO 8601, UTC), ``complete`` (False
  while writing; True after a clean close), ``cam_speed_rpm`` (when known), plus anything the
  device adds (scene, seed, chain parameters) and, on close, ``stop_time_utc``, ``n_samples``,
  ``stop_reason``;
- dataset ``signals`` (n_samples, n_channels) float32 volts, chunked, resizable along axis 0, with
  attributes ``channel_names`` and ``ka_m_s2_per_v`` (NaN where no calibration);
- dataset ``events``: one-dimensional, resizable, compound dtype with fields ``index`` (int64,
  row of ``signals``), ``kind`` (fixed-length ASCII bytes, 16) and ``detail`` (fixed-length UTF-8
  bytes, 256, truncated). Fixed-length strings, not variable-length ones, because HDF5's SWMR mode
  does not support appending variable-length data.

Rows are the samples received, in order. Where a device lost samples (overrun, dropped block) the
rows before and after are NOT contiguous in time: a ``gap`` event at the first row after the loss
says so, with ``missing_samples=N`` at the start of its detail (an ``overrun`` event from the device
sits at the same row). Readers split the data at these events; nothing is joined silently. Without
gaps, row i is the sample taken at i / sample_rate_hz.

The file is opened with ``libver="latest"`` and switched to SWMR mode, so another process can
read it while it grows; it is flushed at least every ``flush_interval_s`` (0.5 s default) of wall
time. A killed process leaves a file that opens, with every sample up to the last flush and
``complete`` False. ``complete`` is set after the SWMR session is closed, by reopening the file.
"""
from __future__ import annotations

import datetime as _dt
import errno
import os
import time
from pathlib import Path

import h5py
import numpy as np

from acquisition.device import Block, Event

FORMAT = "labtool.recording"
FORMAT_VERSION = 1
EVENT_DTYPE = np.dtype([("index", "<i8"), ("kind", "S16"), ("detail", "S256")])


class DiskFull(OSError):
    """Writing failed for lack of space (ENOSPC); the recording was stopped, data kept."""


def utc_now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="milliseconds")


def _attr(value):
    """h5py-friendly attribute value (None -> skipped by the caller)."""
    if isinstance(value, (list, tuple)):
        return np.asarray(value)
    return value


class Recorder:
    """Append-only writer of one recording. Use as a context manager or call ``close``.

    path            output file (replaced if it exists: the caller checks --force first)
    channel_names   names of the columns of ``signals``
    rate_hz         sample rate the device really runs at (Hz)
    attrs           extra root attributes (scene, seed, ...)
    ka_m_s2_per_v   per-channel Ka (m/s^2 per V), NaN where none (tacho)
    on_flush        callback(n_samples_flushed) after every flush (tests, progress)
    """

    def __init__(self, path, channel_names, rate_hz: float, attrs: dict | None = None, ka_m_s2_per_v=None,
                 chunk_rows: int = 4096, flush_interval_s: float = 0.5, on_flush=None, clock=time.monotonic):
        self.path = Path(path)
        self.channel_names = tuple(channel_names)
        self.rate_hz = float(rate_hz)
        self.flush_interval_s = flush_interval_s
        self.on_flush = on_flush
        self._clock = clock
        nch = len(self.channel_names)
        ka = np.full(nch, np.nan) if ka_m_s2_per_v is None else np.asarray(ka_m_s2_per_v, dtype=float)
        if ka.shape != (nch,):
            raise ValueError("ka_m_s2_per_v needs one value per channel")
        self.n_samples = 0  # rows written
        self.device_index = 0  # device sample count seen so far (rows + samples lost)
        self.n_flushed = 0
        self.overruns = 0
        self.gaps = 0
        self.samples_lost = 0
        self.clipped = set()
        self.peak_v = np.zeros(nch)
        self.events: list[Event] = []
        self.closed = False
        if self.path.exists():
            self.path.unlink()
        try:
            self._f = h5py.File(self.path, "w", libver="latest")
        except OSError as exc:
            raise _classify(exc) from None
        f = self._f
        f.attrs["format"] = FORMAT
        f.attrs["format_version"] = FORMAT_VERSION
        f.attrs["sample_rate_hz"] = self.rate_hz
        f.attrs["start_time_utc"] = utc_now()
        f.attrs["complete"] = False
        for k, v in (attrs or {}).items():
            if v is not None:
                f.attrs[k] = _attr(v)
        # the attributes set on close exist from the start: SWMR forbids new objects later
        f.attrs["stop_time_utc"] = ""
        f.attrs["n_samples"] = 0
        f.attrs["stop_reason"] = "recording (not closed)"
        self._sig = f.create_dataset("signals", shape=(0, nch), maxshape=(None, nch), dtype="f4",
                                     chunks=(chunk_rows, nch))
        self._sig.attrs["channel_names"] = np.array(self.channel_names, dtype=h5py.string_dtype("utf-8"))
        self._sig.attrs["ka_m_s2_per_v"] = ka
        self._sig.attrs["units"] = "V"
        self._ev = f.create_dataset("events", shape=(0,), maxshape=(None,), dtype=EVENT_DTYPE, chunks=(256,))
        self._ev.attrs["fields"] = "index: row of signals (int64); kind: ASCII; detail: UTF-8 (fixed-length bytes)"
        f.swmr_mode = True
        self._last_flush = self._clock()
        self.add_event(Event(0, "start", f"recording started at {f.attrs['start_time_utc']}"))
        self.flush()

    # -- writing
    def write_block(self, block: Block) -> None:
        """Append a device block; a jump in first_index becomes a ``gap`` event at the joint row."""
        if block.first_index < self.device_index:
            raise ValueError(f"block starts at device sample {block.first_index}, before {self.device_index} already seen")
        missing = block.first_index - self.device_index
        if missing:
            self.gaps += 1
            self.samples_lost += missing
        joint = self.n_samples
        # device events carry device sample numbers; the file's index is the row
        for ev in block.events:
            self.add_event(Event(max(joint, ev.index - self.samples_lost), ev.kind, ev.detail))
        if missing:
            # rows stay contiguous; the event at the joint says how much time is missing
            self.add_event(Event(joint, "gap", f"missing_samples={missing} ({missing / self.rate_hz:.4f} s) "
                                               f"lost before this row; device sample {block.first_index}"))
        self.device_index = block.end_index
        if block.n:
            data = np.asarray(block.data, dtype=np.float32)
            self._append_rows(data)
            with np.errstate(invalid="ignore"):
                self.peak_v = np.fmax(self.peak_v, np.nanmax(np.abs(data), axis=0))
        if self._clock() - self._last_flush >= self.flush_interval_s:
            self.flush()

    def add_event(self, ev: Event) -> None:
        self.events.append(ev)
        if ev.kind == "overrun":
            self.overruns += 1
        if ev.kind == "clip":
            self.clipped.add(ev.detail.split(":")[0])
        row = np.array([(ev.index, ev.kind.encode("ascii"), ev.detail.encode("utf-8")[:256])], dtype=EVENT_DTYPE)
        try:
            n = self._ev.shape[0]
            self._ev.resize((n + 1,))
            self._ev[n] = row[0]
        except OSError as exc:
            raise _classify(exc) from exc

    def _append_rows(self, rows: np.ndarray) -> None:
        """The one place samples reach the file (tests replace it to simulate a full disk)."""
        try:
            n = self._sig.shape[0]
            self._sig.resize((n + rows.shape[0], rows.shape[1]))
            self._sig[n:] = rows
        except OSError as exc:
            raise _classify(exc) from exc
        self.n_samples += rows.shape[0]

    def flush(self) -> None:
        try:
            self._f.flush()
        except OSError as exc:
            raise _classify(exc) from exc
        self.n_flushed = self.n_samples
        self._last_flush = self._clock()
        if self.on_flush is not None:
            self.on_flush(self.n_flushed)

    # -- closing
    def close(self, complete: bool = True, reason: str = "stopped") -> None:
        """Write the stop event, flush, close; then mark ``complete`` (reopening outside SWMR).

        complete=False keeps the file marked incomplete (e.g. disk full). Never raises on a second call.
        """
        if self.closed:
            return
        self.closed = True
        try:
            self.add_event(Event(self.n_samples, "stop", reason))
            self._f.attrs["n_samples"] = self.n_samples
            self._f.flush()
            self.n_flushed = self.n_samples
        finally:
            self._f.close()
        with h5py.File(self.path, "r+", libver="latest") as f:
            f.attrs["stop_time_utc"] = utc_now()
            f.attrs["stop_reason"] = reason
            f.attrs["complete"] = bool(complete)
            f.attrs["samples_lost"] = int(self.samples_lost)

    def abandon(self, reason: str) -> None:
        """Close after a write failure: keep whatever reached the file, ``complete`` stays False."""
        if self.closed:
            return
        self.closed = True
        for step in (lambda: self.add_event(Event(self.n_samples, "fault", reason)),
                     lambda: self._f.flush(), lambda: self._f.close()):
            try:
                step()
            except Exception:  # the disk is full: do what still works
                pass
        try:
            with h5py.File(self.path, "r+", libver="latest") as f:
                f.attrs["stop_reason"] = reason
                f.attrs["n_samples"] = f["signals"].shape[0]
        except Exception:
            pass

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close(True, "stopped")
        else:
            self.abandon(f"stopped by {exc_type.__name__}: {exc}")
        return False


def _classify(exc: OSError) -> OSError:
    """ENOSPC (also when h5py wraps it in its message) -> DiskFull; other OSErrors unchanged."""
    if getattr(exc, "errno", None) == errno.ENOSPC or "No space left" in str(exc):
        return DiskFull(errno.ENOSPC, os.strerror(errno.ENOSPC))
    return exc


def read_recording(path) -> dict:
    """Minimal reader for tests and calibration: attrs, signals (float64), channel names, Ka, events.

    (The full reader, with checks and warnings, is processing's job.)
    """
    with h5py.File(path, "r", libver="latest", swmr=True) as f:
        if f.attrs.get("format") != FORMAT:
            from common.errors import FileFormatError
            raise FileFormatError(f"{path} is not a labtool recording (format attribute missing)")
        names = [n.decode() if isinstance(n, bytes) else str(n) for n in f["signals"].attrs["channel_names"]]
        ev = f["events"][...]
        return {
            "attrs": {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()},
            "signals": f["signals"][...].astype(np.float64),
            "channel_names": names,
            "ka_m_s2_per_v": np.asarray(f["signals"].attrs["ka_m_s2_per_v"], float),
            "events": [(int(e["index"]), e["kind"].decode(), e["detail"].decode("utf-8", "replace")) for e in ev],
        }
