"""Reader of the labtool recording format version 1 (HDF5, docs/architecture.md "Recording format").

Root attributes format="labtool.recording", format_version=1, sample_rate_hz, start_time_utc,
complete, optional cam_speed_rpm; dataset ``signals`` (n_samples, n_channels) float32/64 volts
with attributes ``channel_names`` and ``ka_m_s2_per_v`` (m/s^2/V, NaN where none); dataset
``events`` (compound: index, kind, detail). A recording with complete=false (its recorder was
killed) is read with a warning.
"""
from __future__ import annotations

import math

import h5py
import numpy as np

from labtool.common.errors import FileFormatError, InputError
from labtool.common.hdf5 import open_file
from labtool.processing.readers.base import Event, Recording, as_text, check_finite, check_sample_rate

FORMAT = "labtool.recording"
VERSION = 1


def open_hdf5_v1(path) -> Recording:
    src = str(path)
    f, swmr_note = open_file(path)  # superblock and size checked first: a cut file never hangs
    try:
        rec = _build(f, src)
        if swmr_note:
            rec.warnings.insert(0, swmr_note)
        return rec
    except (FileFormatError, InputError):
        f.close()
        raise
    except (OSError, KeyError, ValueError, TypeError, RuntimeError) as exc:
        f.close()
        raise FileFormatError(f"{src}: damaged labtool recording: {type(exc).__name__}: {exc}") from None


def _build(f: h5py.File, src: str) -> Recording:
    a = f.attrs
    fmt = as_text(a.get("format", ""))
    if fmt != FORMAT:
        raise FileFormatError(f"{src}: HDF5 file is not a labtool recording (format attribute {fmt!r})")
    try:
        version = int(np.asarray(a.get("format_version", -1)).reshape(-1)[0])
    except (TypeError, ValueError):
        version = -1
    if version != VERSION:
        raise FileFormatError(f"{src}: recording format_version {a.get('format_version')!r} is not supported "
                              f"(this labtool reads version {VERSION})")
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

    def read(start: int, stop: int) -> np.ndarray:
        try:
            block = np.asarray(sig[start:stop], dtype=np.float64)
        except (OSError, ValueError, RuntimeError) as exc:
            raise FileFormatError(f"{src}: cannot read samples {start}..{stop} (truncated or corrupt?): {exc}") from None
        check_finite(block, start, names, src)
        return block

    raw_dtype = np.dtype(sig.dtype).newbyteorder("=") if sig.dtype.itemsize in (4, 8) else np.dtype(np.float64)

    def read_raw(start: int, stop: int, out: np.ndarray) -> np.ndarray:
        """Fill out[:stop - start] from the file (HDF5 converts nothing when the dtypes agree)."""
        dest = out[:stop - start]
        try:
            sig.read_direct(dest, np.s_[start:stop], np.s_[0:stop - start])
        except (OSError, ValueError, RuntimeError, TypeError) as exc:
            raise FileFormatError(f"{src}: cannot read samples {start}..{stop} (truncated or corrupt?): {exc}") from None
        return dest

    extra = {k: _plain(v) for k, v in a.items() if k not in ("format", "format_version")}
    return Recording(source=src, format=f"{FORMAT} v{VERSION}", sample_rate_hz=fs, channel_names=names,
                     n_samples=int(n), read=read, ka_m_s2_per_v=ka, start_time_utc=as_text(a.get("start_time_utc", "")),
                     complete=complete, cam_speed_rpm=rpm, events=events, attrs=extra, warnings=warns, close=f.close,
                     read_raw=read_raw, raw_dtype=raw_dtype.type)


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


MAX_EVENTS_BASE = 100_000   # events beyond this plus two per sample: the dataset is damaged, not read


def _events(f: h5py.File, src: str, warns: list[str], max_events: int) -> list[Event]:
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
        out = []
        for i, k, d in zip(idx, kind, detail):
            out.append(Event(int(i), as_text(k).strip().lower(), as_text(d)))
        unknown = sorted({e.kind for e in out} - {"overrun", "gap", "clip", "start", "stop", "fault"})
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
