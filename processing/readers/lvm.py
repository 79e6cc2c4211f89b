"""Reader of LabVIEW measurement files (.lvm, "Write To Measurement File" text format).

Layout (NI's LVM specification): a file header from ``LabVIEW Measurement`` to
``***End_of_Header***`` (``Separator`` Tab/Comma/Semicolon, ``Decimal_Separator``, ``Date``,
``Time``, ``X_Columns``), then a channel header to a second ``***End_of_Header***`` (``Channels``,
``Samples``, ``X0`` and ``Delta_X`` per channel, ``Unit_Label`` if any), then the column names
(``X_Value``, the channel names, ``Comment``) and the data. One segment per file: a second header
(several segments) is refused. Delta_X (s) of every channel must be the same; the X_Value column,
when written, is checked row by row against it (text.py).
"""
from __future__ import annotations

import math

from labtool.common.errors import FileFormatError, InputError
from labtool.common.names import shown
from labtool.processing.readers.csv import read_head
from labtool.processing.readers.text import Layout, open_table

END = "***End_of_Header***"
SEPARATORS = {"tab": "\t", "comma": ",", "semicolon": ";", "space": " "}


def open_lvm(path, sample_rate_hz: float | None = None, time_unit_s: float | None = None):
    text, bom = read_head(path, 1 << 18)
    lines = text.splitlines(keepends=True)
    body = [ln.rstrip("\r\n") for ln in lines]
    ends = [i for i, ln in enumerate(body) if ln.strip().startswith(END)]
    if not body or not body[0].startswith("LabVIEW Measurement") or len(ends) < 2:
        raise FileFormatError(f"{path}: not a complete LabVIEW measurement file (its two headers end with {END})")
    file_head = _pairs(body[1:ends[0]])
    sep = SEPARATORS.get(file_head.get("separator", "tab").lower())
    if sep is None:
        raise FileFormatError(f"{path}: LVM separator {file_head.get('separator')!r} is not known")
    dec = file_head.get("decimal_separator", ".") or "."
    chan = _fields(body[ends[0] + 1:ends[1]], sep)
    names_i = next((i for i in range(ends[1] + 1, len(body)) if body[i].strip()), None)
    if names_i is None:
        raise FileFormatError(f"{path}: the LVM file holds no data")
    columns = [c.strip() for c in body[names_i].split(sep)]
    if columns and columns[-1].lower() == "comment":
        raise FileFormatError(f"{path}: LVM files with a Comment column are not read; save without comments")
    if len(ends) > 2:
        raise FileFormatError(f"{path}: the LVM file holds {len(ends) - 1} segments; labtool reads one per file "
                              "(save the measurement as one segment)")
    try:
        deltas = {float(x.strip().replace(dec, ".")) for x in chan.get("delta_x", []) if x.strip()}
    except ValueError:
        deltas = {math.nan}
    if len(deltas) > 1 and not all(math.isfinite(d) and d > 0 for d in deltas):
        deltas = {math.nan}
    if len(deltas) > 1:
        raise InputError(f"{path}: the channels have different Delta_X {sorted(deltas)} s; labtool needs one rate")
    delta = deltas.pop() if deltas else None
    if delta is not None and not (math.isfinite(delta) and delta > 0):   # 0 was a ZeroDivisionError
        said = shown(", ".join(x.strip() for x in chan.get("delta_x", [])))
        raise InputError(f"{path}: Delta_X {said!r} is not a usable sample interval (a number of seconds > 0); "
                         "fix the LVM channel header")
    rate = 1.0 / delta if delta is not None else None
    time_col = 0 if columns and columns[0].lower() == "x_value" else None
    units = {}
    labels = [u for u in chan.get("unit_label", []) if u.strip()]
    sig_cols = [c for i, c in enumerate(columns) if i != time_col]
    if labels and len(labels) == len(sig_cols):
        units = dict(zip(sig_cols, labels))
    offset = bom + sum(len(ln.encode("utf-8")) for ln in lines[:names_i + 1])
    lay = Layout(data_start=offset, delimiter=sep, decimal=dec, columns=columns, time_col=time_col,
                 time_unit_s=1.0 if time_col is not None else None, units=units, rate_hz=rate,
                 assumptions=[])
    meta = {"lvm_" + k: v for k, v in file_head.items()}
    date, time = file_head.get("date"), file_head.get("time")
    if date and time:
        meta["start_time_utc"] = f"{date.replace('/', '-')}T{time[:15]}+00:00"
        lay.assumptions.append("the LVM Date/Time taken as UTC")
    return open_table(path, lay, "lvm", meta, sample_rate_hz, time_unit_s, [])


def _pairs(lines) -> dict:
    """Key/value lines of the file header, in whichever separator the file uses."""
    out = {}
    for ln in lines:
        cut = [i for i in (ln.find("\t"), ln.find(";"), ln.find(",")) if i > 0]
        if not cut:
            continue
        i = min(cut)
        value = ln[i + 1:].split(ln[i])[0] if ln[i + 1:] else ""
        out[ln[:i].strip().lower()] = value.strip() or value
    return out


def _fields(lines, sep) -> dict:
    out = {}
    for ln in lines:
        parts = ln.split(sep)
        if parts and parts[0].strip():
            out[parts[0].strip().lower()] = parts[1:]
    return out
