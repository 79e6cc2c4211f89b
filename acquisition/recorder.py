"""The recorder: writes recording format v1 (labtool.common.recording_format, which holds the layout
and its reader; docs/architecture.md) while acquiring, losing nothing.

What it adds to the format's root attributes: anything the device adds (scene, seed, chain
parameters), ``writer_lock``, and, on close, ``stop_time_utc``, ``n_samples``, ``samples_lost``,
``stop_reason``. Where a device lost samples (overrun, dropped block) a ``gap`` event at the first
row after the loss says so, with ``missing_samples=N`` at the start of its detail (an ``overrun``
event from the device sits at the same row). Without gaps, row i is the sample taken at
i / sample_rate_hz.

The file is switched to SWMR mode, so another process can read it while it grows; it is flushed at
least every ``flush_interval_s`` (0.5 s default) of wall time. A killed process leaves a file that
opens, with every sample up to the last flush and ``complete`` False. The closing attributes
(``complete``, ``stop_time_utc``, ``stop_reason``, ``n_samples``, ``samples_lost``, the headroom
figures) exist from the start and are modified in place at the close, still in SWMR mode, so a live
reader never blocks it. One writer at a time: ``writer_lock`` holds an exclusive lock on the file
while it is recorded. The disk's free space is checked before every write: below ``reserve_bytes``
the run stops with DiskFull and the file closes cleanly (``complete`` False, ``n_samples`` = the
rows in ``signals``), instead of HDF5 meeting ENOSPC.

Headroom (for reports): ``signals`` carries per-channel ``input_range_v`` (+-V the device really
has), ``peak_abs_v``, ``rms_v`` (V, over the whole recording), ``peak_fraction_of_range`` and
``clipped`` (int8, 1 if a clip event was seen); the root attribute ``headroom_summary`` says the
same in one line.
"""
from __future__ import annotations

import contextlib
import datetime as _dt
import errno
import os
import shutil
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

from labtool.acquisition.device import Block, Event
from labtool.acquisition.writer_lock import WriterLock
from labtool.common import recording_format as fmt
from labtool.common.hdf5 import open_file


class DiskFull(OSError):
    """Writing failed for lack of space (ENOSPC); the recording was stopped, data kept."""


def utc_now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="milliseconds")


class Recorder:
    """Append-only writer of one recording. Use as a context manager or call ``close``.

    path            output file; an existing one is replaced only if ``replace`` and no other
                    process is recording into it (writer_lock); while this recorder is open,
                    every other writer is refused
    channel_names   names of the columns of ``signals``
    rate_hz         sample rate the device really runs at (Hz)
    attrs           extra root attributes (scene, seed, operating point, ...)
    ka_m_s2_per_v   per-channel Ka (m/s^2 per V), NaN where none (tacho)
    input_range_v   per-channel +-input range the device really has (V), NaN where unknown
    on_flush        callback(n_samples_flushed) after every flush (tests, progress)
    reserve_bytes   disk space held back (an unnamed, preallocated file) for closing the recording:
                    the run stops (DiskFull) before HDF5 would meet ENOSPC, and if it meets it
                    anyway (another program filled the disk) the reserve is released so HDF5 can
                    still write its metadata and close the file with every row it claims
    """

    def __init__(self, path, channel_names, rate_hz: float, attrs: dict | None = None, ka_m_s2_per_v=None,
                 input_range_v=None, chunk_rows: int = 4096, flush_interval_s: float = 0.5, on_flush=None,
                 clock=time.monotonic, replace: bool = True, reserve_bytes: int | None = None):
        self.path = Path(path)
        self.channel_names = tuple(channel_names)
        self.rate_hz = float(rate_hz)
        self.flush_interval_s = flush_interval_s
        self.on_flush = on_flush
        self._clock = clock
        nch = len(self.channel_names)
        ka = _per_channel(ka_m_s2_per_v, nch, "ka_m_s2_per_v")
        self.input_range_v = _per_channel(input_range_v, nch, "input_range_v")
        self.reserve_bytes = int(reserve_bytes if reserve_bytes is not None else max(512_000, 8 * chunk_rows * nch * 4))
        self._chunk_bytes = chunk_rows * nch * 4
        self._pending_bytes = 0  # appended since the last flush: HDF5's chunk cache writes them at the flush
        self.n_samples = 0  # rows written
        self.device_index = 0  # device sample count seen so far (rows + samples lost)
        self.n_flushed = 0
        self.overruns = 0
        self.gaps = 0
        self.samples_lost = 0
        self.clipped = set()
        self.peak_v = np.zeros(nch)
        self._sum_sq = np.zeros(nch)
        self.events: list[Event] = []
        self.closed = False
        self.healthy = True  # False once HDF5 itself failed a write: the file is then left as it is
        self._lock = WriterLock.create(self.path, replace)
        try:
            self._reserve = _DiskReserve(self.path.parent, self.reserve_bytes)
            self._f = _create_hdf5(self.path)
        except OSError as exc:
            self.path.unlink(missing_ok=True)
            self._lock.release()
            raise _classify(exc) from None
        try:
            self._create_layout(attrs or {}, ka, nch, chunk_rows)
        except BaseException:
            self._f.close()
            self.path.unlink(missing_ok=True)
            self._reserve.release()
            self._lock.release()
            raise
        self._last_flush = self._clock()
        self.add_event(Event(0, "start", f"recording started at {self._f.attrs['start_time_utc']}"))
        self.flush()

    def _create_layout(self, attrs: dict, ka, nch: int, chunk_rows: int) -> None:
        f = self._f
        self._sig, self._ev = fmt.create_layout(f, self.channel_names, self.rate_hz, utc_now(), ka, chunk_rows, attrs)
        f.attrs["writer_lock"] = "exclusive while recording" if self._lock.held else f"none: {self._lock.reason}"
        # everything the close sets exists from the start: SWMR forbids new objects later, and the
        # close modifies values in place (no reopen, so a live SWMR reader cannot block it)
        f.attrs["stop_time_utc"] = ""
        f.attrs["n_samples"] = 0
        f.attrs["samples_lost"] = 0
        f.attrs["stop_reason"] = "recording (not closed)"
        f.attrs["headroom_summary"] = ""
        sa = self._sig.attrs
        sa["input_range_v"] = self.input_range_v
        for name in HEADROOM_ATTRS:
            sa[name] = np.full(nch, np.nan)
        sa["clipped"] = np.zeros(nch, np.int8)
        f.swmr_mode = True

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
                self._sum_sq += np.nansum(np.square(data, dtype=np.float64), axis=0)
        if self._clock() - self._last_flush >= self.flush_interval_s:
            self.flush()

    @property
    def rms_v(self) -> np.ndarray:
        """RMS of every channel over the rows written so far (V, mean included)."""
        return np.sqrt(self._sum_sq / self.n_samples) if self.n_samples else np.full(len(self.channel_names), np.nan)

    def add_event(self, ev: Event) -> None:
        self.events.append(ev)
        if ev.kind == "overrun":
            self.overruns += 1
        if ev.kind == "clip":
            self.clipped.add(ev.detail.split(":")[0])
        # events are not held to the reserve: it is there so that the stop and fault events fit
        row = fmt.event_row(ev.index, ev.kind, ev.detail)
        try:
            n = self._ev.shape[0]
            self._ev.resize((n + 1,))
            self._ev[n] = row
        except (OSError, RuntimeError) as exc:
            raise self._failed(exc) from exc

    def _failed(self, exc) -> OSError:
        """HDF5 failed a write: mark the file unhealthy, free the reserve so the close can work."""
        self.healthy = False
        self._reserve.release()
        return _classify(exc)

    def _guard_space(self, nbytes: int) -> None:
        """DiskFull before HDF5 is asked to write more than the disk holds (it crashes on ENOSPC).
        What the next flush writes counts: the rows still in HDF5's chunk cache, two partial chunks."""
        try:
            free = shutil.disk_usage(self.path.parent).free
        except OSError:
            return
        need = nbytes + self._pending_bytes + 2 * self._chunk_bytes + 64_000
        if free < need:
            raise DiskFull(errno.ENOSPC, f"{free / 1e3:.0f} kB left on the disk, {need / 1e3:.0f} kB needed "
                                         "for the next rows")

    def _append_rows(self, rows: np.ndarray) -> None:
        """The one place samples reach the file (tests replace it to simulate a full disk)."""
        self._guard_space(rows.nbytes)
        n = self._sig.shape[0]
        try:
            self._sig.resize((n + rows.shape[0], rows.shape[1]))
            self._sig[n:] = rows
        except (OSError, RuntimeError) as exc:
            err = self._failed(exc)
            with contextlib.suppress(Exception):  # claim only the rows really written
                self._sig.resize((n, rows.shape[1]))
            raise err from exc
        self.n_samples += rows.shape[0]
        self._pending_bytes += rows.nbytes

    def flush(self) -> None:
        try:
            self._f.flush()
        except (OSError, RuntimeError) as exc:
            raise self._failed(exc) from exc
        self._pending_bytes = 0
        self.n_flushed = self.n_samples
        self._last_flush = self._clock()
        if self.on_flush is not None:
            self.on_flush(self.n_flushed)

    # -- closing
    def close(self, complete: bool = True, reason: str = "stopped") -> None:
        """Write the stop event and the closing attributes, flush, close, release the lock.

        complete=False keeps the file marked incomplete (e.g. disk full). Never raises on a second
        call. The attributes are modified in place in SWMR mode: a reader holding the file open does
        not stop the close (reopening it for writing would fail on the reader's lock).
        """
        if self.closed:
            return
        self.closed = True
        try:
            if reason and len(reason) > 250:
                reason = reason[:250]
            self.add_event(Event(self.n_samples, "stop", reason))
            self._write_closing_attrs(complete, reason)
            self._f.flush()
            self.n_flushed = self.n_samples
        finally:
            try:
                self._f.close()
            finally:
                self._reserve.release()
                self._lock.release()

    def _write_closing_attrs(self, complete: bool, reason: str) -> None:
        a, sa = self._f.attrs, self._sig.attrs
        peak, rms = self.peak_v.astype(float), self.rms_v.astype(float)
        with np.errstate(invalid="ignore", divide="ignore"):
            frac = peak / self.input_range_v
        sa.modify("peak_abs_v", peak)
        sa.modify("rms_v", rms)
        sa.modify("peak_fraction_of_range", frac)
        sa.modify("clipped", np.array([n in self.clipped for n in self.channel_names], np.int8))
        a.modify("headroom_summary", headroom_summary(self.channel_names, peak, self.input_range_v, self.clipped))
        a.modify("n_samples", int(self.n_samples))
        a.modify("samples_lost", int(self.samples_lost))
        a.modify("stop_reason", reason)
        a.modify("stop_time_utc", utc_now())
        a.modify("complete", bool(complete))

    def abandon(self, reason: str) -> None:
        """Close after HDF5 itself failed a write: keep whatever reached the file, ``complete``
        stays False, ``n_samples`` says how many rows are real. Does what still works."""
        if self.closed:
            return
        self.closed = True
        self._reserve.release()
        steps = [lambda: self._sig.resize((self.n_samples, self._sig.shape[1])),
                 lambda: self._f.attrs.modify("n_samples", int(self.n_samples)),
                 lambda: self._f.attrs.modify("stop_reason", reason[:250]),
                 lambda: self._f.flush(), lambda: self._f.close()]
        for step in steps:
            try:
                step()
            except Exception:  # the disk is full: do what still works
                pass
        self._lock.release()
        try:  # what really reached the file
            with h5py.File(self.path, "r", swmr=True) as f:
                self.n_samples = min(self.n_samples, int(f["signals"].shape[0]))
        except Exception:
            pass

    def discard(self) -> None:
        """Close and delete a recording that holds no sample (a run that failed before its first block)."""
        if not self.closed:
            self.closed = True
            with contextlib.suppress(Exception):
                self._f.close()
        self._reserve.release()
        if self.n_samples == 0:
            self.path.unlink(missing_ok=True)
        self._lock.release()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close(True, "stopped")
        else:
            self.abandon(f"stopped by {exc_type.__name__}: {exc}")
        return False


HEADROOM_ATTRS = ("peak_abs_v", "rms_v", "peak_fraction_of_range")
HEADROOM_WARN = 0.8  # peak above this fraction of the input range: little headroom left


def headroom_summary(names, peak_v, range_v, clipped=()) -> str:
    """One line per recording: each channel's peak as % of its input range, flagged above 80 %."""
    parts = []
    for name, p, r in zip(names, peak_v, range_v):
        if not (np.isfinite(p) and np.isfinite(r) and r > 0):
            parts.append(f"{name} peak {p:.3g} V (range unknown)")
            continue
        flag = " CLIPPED" if name in clipped else (" LOW HEADROOM" if p / r > HEADROOM_WARN else "")
        parts.append(f"{name} {100 * p / r:.1f} % of +-{r:g} V{flag}")
    return "; ".join(parts)


def _per_channel(values, nch: int, what: str) -> np.ndarray:
    out = np.full(nch, np.nan) if values is None else np.asarray(values, dtype=float)
    if out.shape != (nch,):
        raise ValueError(f"{what} needs one value per channel")
    return out


class _DiskReserve:
    """Disk space held by an unnamed, preallocated file in the recording's folder; ``release``
    gives it back. Unnamed (O_TMPFILE where the system has it, else unlinked at once), so a killed
    run leaves nothing behind: the kernel frees the space with the process."""

    def __init__(self, folder: Path, nbytes: int):
        self._f = None
        if nbytes <= 0:
            return
        f = tempfile.TemporaryFile(dir=folder if str(folder) else ".")
        try:
            if hasattr(os, "posix_fallocate"):
                os.posix_fallocate(f.fileno(), 0, nbytes)
            else:  # pragma: no cover - no fallocate: write the bytes
                f.write(b"\0" * nbytes)
                f.flush()
        except OSError as exc:
            f.close()
            if exc.errno == errno.ENOSPC:
                raise DiskFull(errno.ENOSPC, f"less than {nbytes / 1e3:.0f} kB free: not enough to start a recording") from None
            raise
        self._f = f

    def release(self) -> None:
        if self._f is not None:
            f, self._f = self._f, None
            f.close()


CREATE_TRIES, CREATE_WAIT_S = 40, 0.025


def _create_hdf5(path: Path):
    """h5py.File(path, "w") on the file the writer lock just created. A reader that opens it in the
    same instant (a monitor polling for it, a file indexer) holds HDF5's shared file lock for the
    moment its open fails, and HDF5's create then fails with EAGAIN ("unable to lock file"): the
    create is tried again for up to 1 s instead of failing the recording."""
    for attempt in range(CREATE_TRIES):
        try:
            return h5py.File(path, "w", libver=fmt.LIBVER)
        except OSError as exc:
            busy = exc.errno == errno.EAGAIN or "unable to lock file" in str(exc)
            if not busy or attempt == CREATE_TRIES - 1:
                raise
            time.sleep(CREATE_WAIT_S)


def _classify(exc: Exception) -> OSError:
    """ENOSPC (also when h5py wraps it in a RuntimeError's message) -> DiskFull; other OSErrors
    unchanged; any other HDF5 failure -> OSError with its first line."""
    if isinstance(exc, DiskFull):
        return exc
    if getattr(exc, "errno", None) == errno.ENOSPC or "No space left" in str(exc) or "errno = 28" in str(exc):
        return DiskFull(errno.ENOSPC, os.strerror(errno.ENOSPC))
    if isinstance(exc, OSError):
        return exc
    return OSError(errno.EIO, " ".join(str(exc).split())[:200])


def unfinished(path) -> str | None:
    """What ``path`` holds when a rerun may record over it without ``--force``: an empty file (a run
    killed as it created it) or a labtool recording that did not finish (``complete`` false: stopped
    short of its duration, killed, a full disk); None for anything else (a finished recording, another
    file, one that cannot be read: those are replaced only when asked). The text names the samples kept."""
    from labtool.common.errors import LabtoolError

    p = Path(path)
    try:
        if not p.is_file():
            return None
        if p.stat().st_size == 0:
            return "an empty file left by a run killed as it started"
        f, _note = open_file(p)
    except (OSError, LabtoolError):
        return None
    try:
        with f:
            if f.attrs.get("format") != fmt.FORMAT or "signals" not in f:
                return None
            if f.attrs.get("complete") not in (False, 0):
                return None
            reason = f.attrs.get("stop_reason", "")
            reason = reason.decode("utf-8", "replace") if isinstance(reason, bytes) else str(reason)
            n = int(f["signals"].shape[0])
    except Exception:      # noqa: BLE001 - h5py raises many types for a damaged file: not replaced unasked
        return None
    why = "killed while recording" if reason in ("", "recording (not closed)") else reason
    return f"an unfinished recording ({n} samples; {why})"
