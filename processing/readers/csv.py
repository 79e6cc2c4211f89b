"""Reader of CSV recordings with a stated sample rate.

Layout: optional comment lines ``# key = value`` (``sample_rate_hz``, ``cam_speed_rpm``,
``ka_<channel>`` in m/s^2/V), then a header row of channel names, then one row per sample (volts).
A ``time`` column (s), if present, is not a channel; it gives the sample rate when no comment does.
Without either, the caller's ``sample_rate_hz`` is used, else InputError. The file is scanned
once on opening (bounded memory) and read in chunks by row.
"""
from __future__ import annotations

import io
import math

import numpy as np

from common.errors import FileFormatError, InputError
from processing.readers.base import Recording, check_finite, check_sample_rate


def _parse_float(text: str, src: str, what: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise InputError(f"{src}: {what} {text!r} is not a number") from None


def open_csv(path, sample_rate_hz: float | None = None) -> Recording:
    src = str(path)
    meta: dict[str, str] = {}
    header = None
    offsets: list[int] = []  # byte offset of every ~block of rows, for chunked reading
    block_rows = 65536
    n = 0
    t0 = t1 = None
    try:
        fh = open(path, "rb")
    except OSError as exc:
        raise InputError(f"cannot open {src}: {exc.strerror}") from None
    with fh:
        pos = 0
        for raw in fh:
            line = raw.decode("utf-8", errors="strict").strip() if raw.isascii() else _decode(raw, src)
            here, pos = pos, pos + len(raw)
            if not line:
                continue
            if line.startswith("#"):
                if header is None and "=" in line:
                    k, v = line[1:].split("=", 1)
                    meta[k.strip().lower()] = v.strip()
                continue
            if header is None:
                header = [h.strip() for h in line.split(",")]
                if not header or any(not h for h in header) or all(_is_number(h) for h in header):
                    raise FileFormatError(f"{src}: CSV needs a header row of channel names")
                continue
            if n % block_rows == 0:
                offsets.append(here)
            if n < 2:
                cells = line.split(",")
                if len(cells) != len(header):
                    raise FileFormatError(f"{src}: row {n + 1} has {len(cells)} values, header has {len(header)}")
                if "time" in [h.lower() for h in header]:
                    tval = _parse_float(cells[[h.lower() for h in header].index("time")], src, "time value")
                    t0, t1 = (tval, None) if n == 0 else (t0, tval)
            n += 1
    if header is None or n == 0:
        raise FileFormatError(f"{src}: CSV file holds no samples")
    lower = [h.lower() for h in header]
    time_col = lower.index("time") if "time" in lower else None
    names = [h for i, h in enumerate(header) if i != time_col]
    if not names:
        raise FileFormatError(f"{src}: CSV has no signal columns")
    fs = None
    if "sample_rate_hz" in meta:
        fs = _parse_float(meta["sample_rate_hz"], src, "sample_rate_hz")
    elif time_col is not None and t0 is not None and t1 is not None:
        if not t1 > t0:
            raise InputError(f"{src}: the time column does not increase")
        fs = 1.0 / (t1 - t0)
    elif sample_rate_hz is not None:
        fs = sample_rate_hz
    if fs is None:
        raise InputError(f"{src}: CSV states no sample rate ('# sample_rate_hz = ...' or a time column); "
                         "give it with --sample-rate")
    fs = check_sample_rate(fs, src)
    ka = np.array([_parse_float(meta[f"ka_{c.lower()}"], src, f"ka_{c}") if f"ka_{c.lower()}" in meta else math.nan
                   for c in names])
    rpm = _parse_float(meta["cam_speed_rpm"], src, "cam_speed_rpm") if "cam_speed_rpm" in meta else math.nan
    keep = [i for i in range(len(header)) if i != time_col]

    def read(start: int, stop: int) -> np.ndarray:
        out = []
        b0 = start // block_rows
        skip = start - b0 * block_rows
        with open(path, "rb") as fh:
            fh.seek(offsets[b0])
            need = stop - start + skip
            lines = []
            for raw in fh:
                if not raw.strip() or raw.lstrip().startswith(b"#"):
                    continue
                lines.append(raw)
                if len(lines) >= need:
                    break
        text = b"".join(lines[skip:]).decode("utf-8", errors="replace")
        try:
            arr = np.loadtxt(io.StringIO(text), delimiter=",", ndmin=2, dtype=np.float64)
        except ValueError as exc:
            raise FileFormatError(f"{src}: bad CSV value near row {start + 1}: {exc}") from None
        if arr.shape[1] != len(header) or arr.shape[0] != stop - start:
            raise FileFormatError(f"{src}: CSV rows {start + 1}..{stop} do not have {len(header)} values each")
        out = arr[:, keep]
        check_finite(out, start, names, src)
        return out

    return Recording(source=src, format="csv", sample_rate_hz=fs, channel_names=names, n_samples=n, read=read,
                     ka_m_s2_per_v=ka, cam_speed_rpm=rpm if rpm > 0 else math.nan, attrs=dict(meta))


def _is_number(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


def _decode(raw: bytes, src: str) -> str:
    try:
        return raw.decode("utf-8").strip()
    except UnicodeDecodeError:
        raise FileFormatError(f"{src}: not a text (CSV) file") from None
