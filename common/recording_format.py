"""Recording format version 1 (HDF5; docs/architecture.md "Recording format"): its constants, the
layout the writer creates and the reader that checks it, side by side.

Layout (format_version 1):

- root attributes ``format = "labtool.recording"``, ``format_version = 1``, ``sample_rate_hz``
  (the rate the device really runs at), ``start_time_utc`` (ISO 8601, UTC), ``complete`` (False
  while writing; True after a clean close), ``cam_speed_rpm`` (when known), plus anything the
  writer adds (labtool.common.recording_attrs names what labtool stores);
- dataset ``signals`` (n_samples, n_channels) float volts (float32 written; float64 read too),
  chunked, resizable along axis 0, with attributes ``channel_names``, ``ka_m_s2_per_v`` (NaN where
  no calibration) and ``units = "V"``;
- dataset ``events``: one-dimensional, resizable, compound dtype ``EVENT_DTYPE`` with fields
  ``index`` (int64, row of ``signals``), ``kind`` (fixed-length ASCII bytes, 16, one of
  ``EVENT_KINDS``) and ``detail`` (fixed-length UTF-8 bytes, 256, truncated). Fixed-length strings,
  not variable-length ones, because HDF5's SWMR mode does not support appending variable-length data.

Rows are the samples received, in order. Where a device lost samples the rows before and after are
not contiguous in time: a ``gap`` event at the first row after the loss says so, with
``missing_samples=N`` at the start of its detail. Files are written with HDF5 file-format bounds
``LIBVER`` (the oldest SWMR needs; HDF5 1.10+ tools read it).

The writer's state (buffering, flushing, crash safety, the lock) is labtool.acquisition.recorder's;
processing's reader (labtool.processing.readers.hdf5_v1) turns ``open_recording`` into its chunked
``Recording``.
"""
from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

import numpy as np

from labtool.common.errors import FileFormatError, InputError
from labtool.common.hdf5 import open_file

if TYPE_CHECKING:
    import h5py
# h5py is imported where a file is written or read: the readers of other formats share as_text and
# check_sample_rate and should not load it

FORMAT = "labtool.recording"
FORMAT_VERSION = 1
# HDF5 file-format bounds: v110 is the oldest that SWMR needs; anything newer (HDF5 2.0's "latest")
# writes datatype and attribute messages that HDF5 1.10-1.14 tools (HDFView, MATLAB, LabVIEW) cannot read
LIBVER = ("v110", "v110")
EVENT_KINDS = ("overrun", "gap", "clip", "start", "stop", "fault")
# events that mean the samples before and after the index are not contiguous in time
SPLITTING_KINDS = ("overrun", "gap")
DETAIL_BYTES = 256
EVENT_DTYPE = np.dtype([("index", "<i8"), ("kind", "S16"), ("detail", f"S{DETAIL_BYTES}")])
MAX_EVENTS_BASE = 100_000   # events beyond this plus two per sample: the dataset is damaged, not read


# ---------------------------------------------------------------------------------------- writing

def attr_value(value):
    """An attribute value h5py stores: lists as arrays, text arrays as UTF-8 strings."""
    import h5py
    if isinstance(value, (list, tuple)):
        value = np.asarray(value)
    if isinstance(value, np.ndarray) and value.dtype.kind in "UO":
        return np.array([str(v) for v in value.ravel()], dtype=h5py.string_dtype("utf-8")).reshape(value.shape)
    return value


def create_layout(f: h5py.File, channel_names, rate_hz: float, start_time_utc: str, ka_m_s2_per_v,
                  chunk_rows: int, attrs: dict | None = None) -> tuple[h5py.Dataset, h5py.Dataset]:
    """Write the format's root attributes and its two empty, resizable datasets into ``f``.

    Parameters
    ----------
    f : h5py.File
        A file just created for writing (with ``libver=LIBVER``).
    channel_names : sequence of str
        The columns of ``signals``.
    rate_hz : float
        Sample rate the device really runs at (Hz).
    start_time_utc : str
        ISO 8601 time of the first sample (UTC).
    ka_m_s2_per_v : array_like
        Per-channel calibration (m/s^2 per V), NaN where none.
    chunk_rows : int
        Rows per chunk of ``signals``.
    attrs : dict, optional
        Further root attributes; None values are left out.

    Returns
    -------
    signals, events : h5py.Dataset
    """
    import h5py
    nch = len(channel_names)
    f.attrs["format"] = FORMAT
    f.attrs["format_version"] = FORMAT_VERSION
    f.attrs["sample_rate_hz"] = float(rate_hz)
    f.attrs["start_time_utc"] = start_time_utc
    f.attrs["complete"] = False
    for k, v in (attrs or {}).items():
        if v is not None:
            f.attrs[k] = attr_value(v)
    sig = f.create_dataset("signals", shape=(0, nch), maxshape=(None, nch), dtype="f4", chunks=(chunk_rows, nch))
    sig.attrs["channel_names"] = np.array(list(channel_names), dtype=h5py.string_dtype("utf-8"))
    sig.attrs["ka_m_s2_per_v"] = np.asarray(ka_m_s2_per_v, dtype=float)
    sig.attrs["units"] = "V"
    ev = f.create_dataset("events", shape=(0,), maxshape=(None,), dtype=EVENT_DTYPE, chunks=(256,))
    ev.attrs["fields"] = "index: row of signals (int64); kind: ASCII; detail: UTF-8 (fixed-length bytes)"
    return sig, ev


def event_row(index: int, kind: str, detail: str) -> np.void:
    """One row of ``events``: the detail cut to DETAIL_BYTES of UTF-8."""
    if kind not in EVENT_KINDS:
        raise ValueError(f"unknown event kind {kind!r}")
    return np.array([(index, kind.encode("ascii"), detail.encode("utf-8")[:DETAIL_BYTES])], dtype=EVENT_DTYPE)[0]


# ---------------------------------------------------------------------------------------- reading

def as_text(value) -> str:
    """Decode bytes/numpy strings leniently (attributes and event fields come in many encodings)."""
    if isinstance(value, (bytes, np.bytes_)):
        return bytes(value).decode("utf-8", errors="replace").rstrip("\x00")
    if isinstance(value, np.ndarray) and value.shape == ():
        return as_text(value.item())
    return str(value)


def check_sample_rate(value, source: str) -> float:
    """A usable sample rate (Hz): one finite, positive, not absurd number; otherwise InputError."""
    if np.size(value) != 1:
        raise InputError(f"{source}: sample rate {np.asarray(value).tolist()!r} is not one number; give one rate in Hz")
    try:
        fs = float(np.asarray(value).reshape(-1)[0]) if np.ndim(value) else float(value)
    except (TypeError, ValueError, IndexError):
        raise InputError(f"{source}: sample rate {value!r} is not a number; give it in Hz") from None
    if not (math.isfinite(fs) and 1.0 <= fs <= 10e6):
        raise InputError(f"{source}: sample rate {fs!r} Hz is not usable (expected 1 Hz .. 10 MHz)")
    return fs


@dataclasses.dataclass
class RecordingFile:
    """An open, checked recording: its metadata read, its samples read on request (``read_rows``).

    ``n_samples`` counts the rows really written (an unwritten tail is cut off with a warning);
    ``events`` are (row, kind, detail) tuples; ``attrs`` the root attributes as plain Python (JSON
    friendly), without ``format`` and ``format_version``; ``close`` closes the file.
    """

    source: str
    file: h5py.File
    signals: h5py.Dataset
    sample_rate_hz: float
    channel_names: list[str]
    n_samples: int
    ka_m_s2_per_v: np.ndarray
    start_time_utc: str
    complete: bool
    cam_speed_rpm: float
    events: list[tuple[int, str, str]]
    attrs: dict
    warnings: list[str]
    # each channel's peak over its input range (the recorder's headroom), NaN where not stored
    peak_fraction_of_range: np.ndarray | None = None

    @property
    def format(self) -> str:
        return f"{FORMAT} v{FORMAT_VERSION}"

    @property
    def raw_dtype(self) -> type:
        """The dtype the samples are stored in (native byte order), the one ``read_rows`` fills with no conversion."""
        sig = self.signals
        return (np.dtype(sig.dtype).newbyteorder("=") if sig.dtype.itemsize in (4, 8) else np.dtype(np.float64)).type

    def read_rows(self, start: int, stop: int, out: np.ndarray | None = None) -> np.ndarray:
        """Rows start..stop of ``signals`` (volts), as float64, or into ``out[:stop - start]``."""
        try:
            if out is None:
                return np.asarray(self.signals[start:stop], dtype=np.float64)
            dest = out[:stop - start]
            self.signals.read_direct(dest, np.s_[start:stop], np.s_[0:stop - start])
            return dest
        except (OSError, ValueError, RuntimeError, TypeError) as exc:
            raise FileFormatError(f"{self.source}: cannot read samples {start}..{stop} (truncated or corrupt?): "
                                  f"{exc}") from None

    def close(self) -> None:
        self.file.close()


def open_recording(path) -> RecordingFile:
    """Open and check a recording of this format (the file stays open: ``close`` it).

    Raises FileFormatError for a file that is not one or is damaged, InputError for an unusable
    value (the sample rate); a file opened in SWMR mode or marked incomplete is read with a warning.
    """
    src = str(path)
    f, swmr_note = open_file(path)  # superblock and size checked first: a cut file never hangs
    try:
        rec = _checked(f, src)
        if swmr_note:
            rec.warnings.insert(0, swmr_note)
        return rec
    except (FileFormatError, InputError):
        f.close()
        raise
    except (OSError, KeyError, ValueError, TypeError, RuntimeError) as exc:
        f.close()
        raise FileFormatError(f"{src}: damaged labtool recording: {type(exc).__name__}: {exc}") from None


def load(path) -> dict:
    """A whole recording in memory, for tests and tools: ``attrs`` (with ``format`` and
    ``format_version``), ``signals`` (float64 volts), ``channel_names``, ``ka_m_s2_per_v``,
    ``events`` ((row, kind, detail) tuples) and the reader's ``warnings``."""
    rec = open_recording(path)
    try:
        return {"attrs": {"format": FORMAT, "format_version": FORMAT_VERSION, **rec.attrs},
                "signals": rec.read_rows(0, rec.n_samples), "channel_names": rec.channel_names,
                "ka_m_s2_per_v": rec.ka_m_s2_per_v, "events": rec.events, "warnings": rec.warnings}
    finally:
        rec.close()


def _checked(f: h5py.File, src: str) -> RecordingFile:
    import h5py
    a = f.attrs
    fmt = as_text(a.get("format", ""))
    if fmt != FORMAT:
        raise FileFormatError(f"{src}: HDF5 file is not a labtool recording (format attribute {fmt!r})")
    try:
        version = int(np.asarray(a.get("format_version", -1)).reshape(-1)[0])
    except (TypeError, ValueError):
        version = -1
    if version != FORMAT_VERSION:
        raise FileFormatError(f"{src}: recording format_version {a.get('format_version')!r} is not supported "
                              f"(this labtool reads version {FORMAT_VERSION})")
    if "sample_rate_hz" not in a:
        raise InputError(f"{src}: the recording has no sample_rate_hz attribute")
    fs = check_sample_rate(a["sample_rate_hz"], src)
    if "signals" not in f or not isinstance(f["signals"], h5py.Dataset):
        raise FileFormatError(f"{src}: the recording has no 'signals' dataset")
    sig = f["signals"]
    if sig.ndim != 2 or sig.dtype.kind != "f":
        raise FileFormatError(f"{src}: 'signals' must be a 2-D float array, found shape {sig.shape} {sig.dtype}")
    n, nch = sig.shape
    names_raw = sig.attrs.get("channel_names", None)
    if names_raw is None:
        raise FileFormatError(f"{src}: 'signals' has no channel_names attribute")
    names = [as_text(x) for x in np.atleast_1d(names_raw)]
    if len(names) != nch:
        raise FileFormatError(f"{src}: {len(names)} channel names for {nch} signal columns")
    if len(set(names)) != len(names):
        raise FileFormatError(f"{src}: duplicate channel names {names}")
    ka = np.full(nch, np.nan)
    if "ka_m_s2_per_v" in sig.attrs:
        raw = np.atleast_1d(np.asarray(sig.attrs["ka_m_s2_per_v"], dtype=float))
        if raw.size != nch:
            raise FileFormatError(f"{src}: ka_m_s2_per_v has {raw.size} values for {nch} channels")
        ka = raw.astype(float)
    frac = np.full(nch, np.nan)
    if "peak_fraction_of_range" in sig.attrs:
        try:
            raw = np.atleast_1d(np.asarray(sig.attrs["peak_fraction_of_range"], dtype=float))
        except (TypeError, ValueError):
            raw = np.empty(0)
        if raw.size == nch:          # a headroom that does not fit the channels is no headroom
            frac = np.where(np.isfinite(raw) & (raw >= 0), raw, np.nan)
    complete = _complete_flag(a.get("complete", False), src)
    warns = []
    if not complete:
        reason = a.get("stop_reason", "")
        reason = reason.decode("utf-8", "replace") if isinstance(reason, bytes) else str(reason)
        # "recording (not closed)" is what the recorder writes first: it never reached its close
        why = (f"stopped short: {reason}" if reason and reason != "recording (not closed)"
               else "its recorder did not close cleanly")
        warns.append(f"{src}: recording is marked incomplete ({why}); processing the samples that were written")
    rpm = math.nan
    if "cam_speed_rpm" in a:
        try:
            rpm = float(np.asarray(a["cam_speed_rpm"]).reshape(-1)[0])
        except (TypeError, ValueError):
            rpm = math.nan
        if not (math.isfinite(rpm) and rpm > 0):
            warns.append(f"{src}: ignoring unusable cam_speed_rpm {a['cam_speed_rpm']!r}")
            rpm = math.nan
    events = _events(f, src, warns, max_events=MAX_EVENTS_BASE + 2 * n)
    n = _written_rows(sig, src, warns)
    extra = {k: _plain(v) for k, v in a.items() if k not in ("format", "format_version")}
    return RecordingFile(source=src, file=f, signals=sig, sample_rate_hz=fs, channel_names=names, n_samples=int(n),
                         ka_m_s2_per_v=ka, start_time_utc=as_text(a.get("start_time_utc", "")), complete=complete,
                         cam_speed_rpm=rpm, events=events, attrs=extra, warnings=warns, peak_fraction_of_range=frac)


def _complete_flag(value, src: str) -> bool:
    """The ``complete`` attribute: one boolean (h5py gives numpy.bool_); 0 and 1 are taken too.
    A string such as "no" is refused: bool("no") is True and would pass a killed recording for a
    clean one."""
    arr = np.asarray(value)
    if arr.size == 1 and (arr.dtype.kind == "b" or (arr.dtype.kind in "iu" and int(arr.reshape(-1)[0]) in (0, 1))):
        return bool(arr.reshape(-1)[0])
    raise FileFormatError(f"{src}: attribute complete = {_plain(value)!r} is not a boolean; expected true or false "
                          "(false: the recorder did not close cleanly)")


def _written_rows(sig: h5py.Dataset, src: str, warns: list[str]) -> int:
    """Rows of ``signals`` that hold written data.

    HDF5 returns the fill value (0) for chunks that were never written, so a dataset resized but
    not filled (a recorder killed between the two) or a damaged shape would read as silent zeros.
    Unwritten chunks at the end are cut off with a warning; unwritten chunks inside, or a
    contiguous dataset shorter than its shape, make the file corrupt.
    """
    n, nch = sig.shape
    if n == 0:
        return 0
    if sig.chunks is None:
        if sig.compression is None and sig.id.get_storage_size() < n * nch * sig.dtype.itemsize:
            raise FileFormatError(f"{src}: 'signals' holds fewer bytes than its shape {sig.shape} needs (truncated)")
        return n
    crow, ccol = sig.chunks
    row_chunks = -(-n // crow)
    expected = row_chunks * -(-nch // ccol)
    have = sig.id.get_num_chunks()
    if have >= expected:
        return n
    if have > 100_000:
        raise FileFormatError(f"{src}: 'signals' has {expected - have} unwritten chunks; the file is damaged")
    written = {sig.id.get_chunk_info(i).chunk_offset[0] // crow for i in range(have)}
    last = max(written) if written else -1
    missing_inside = [k for k in range(last + 1) if k not in written]
    if missing_inside:
        a = missing_inside[0] * crow
        raise FileFormatError(f"{src}: samples from row {a} on were never written although later ones were; "
                              "the file is damaged")
    rows = min(n, (last + 1) * crow)
    if rows == 0:
        raise FileFormatError(f"{src}: 'signals' has a shape of {n} rows but none was written")
    warns.append(f"{src}: rows {rows}..{n} of 'signals' were never written (recorder killed?); "
                 f"reading the first {rows}")
    return rows


def _events(f: h5py.File, src: str, warns: list[str], max_events: int) -> list[tuple[int, str, str]]:
    import h5py
    if "events" not in f:
        return []
    node = f["events"]
    rows = node["index"].shape[0] if isinstance(node, h5py.Group) and "index" in node else \
        (node.shape[0] if isinstance(node, h5py.Dataset) and node.ndim else 0)
    if rows > max_events:   # read whole, 1e9 rows filled the memory before any check
        raise FileFormatError(f"{src}: 'events' holds {rows} rows, more than a recorder writes for its samples "
                              f"(at most {max_events}); the file is damaged")
    try:
        if isinstance(node, h5py.Group):  # lenient: a group of parallel datasets
            idx = np.asarray(node["index"][()]).reshape(-1)
            kind = np.asarray(node["kind"][()]).reshape(-1)
            detail = np.asarray(node["detail"][()]).reshape(-1) if "detail" in node else np.array([""] * idx.size)
        else:
            data = node[()]
            fields = data.dtype.names or ()
            if not fields:
                if data.size == 0:
                    return []
                raise FileFormatError(f"{src}: 'events' must be a compound dataset with fields index, kind, detail")
            lower = {n.lower(): n for n in fields}
            key_i = next((lower[k] for k in ("index", "sample_index", "sample") if k in lower), None)
            key_k = lower.get("kind")
            if key_i is None or key_k is None:
                raise FileFormatError(f"{src}: 'events' needs fields index and kind, found {list(fields)}")
            data = np.atleast_1d(data)
            idx, kind = data[key_i], data[key_k]
            detail = data[lower["detail"]] if "detail" in lower else np.array([""] * len(data))
        out = [(int(i), as_text(k).strip().lower(), as_text(d)) for i, k, d in zip(idx, kind, detail)]
        unknown = sorted({k for _, k, _ in out} - set(EVENT_KINDS))
        if unknown:
            warns.append(f"{src}: ignoring unknown event kinds {unknown}")
        return out
    except FileFormatError:
        raise
    except (KeyError, ValueError, TypeError, OSError) as exc:
        raise FileFormatError(f"{src}: unreadable 'events' dataset: {exc}") from None


def _plain(v):
    """Attribute value as JSON-friendly Python."""
    if isinstance(v, (bytes, np.bytes_, str)):
        return as_text(v)
    arr = np.asarray(v)
    if arr.dtype.kind in "SUO":
        return [as_text(x) for x in arr.reshape(-1)] if arr.ndim else as_text(arr.item())
    return arr.tolist()
