"""Reader of LabVIEW measurement files (.lvm, "Write To Measurement File" text format), as LabVIEW
writes them.

Layout (NI's LVM specification): a file header from ``LabVIEW Measurement`` to
``***End_of_Header***`` (``Separator`` Tab/Comma/Semicolon/Space, ``Decimal_Separator``, ``Date``,
``Time``, ``X_Columns`` No/One/Multi), then a channel header to a second ``***End_of_Header***``
(``Channels``, ``Samples``, ``Date``, ``Time``, ``Y_Unit_Label``, ``X0``, ``Delta_X`` per channel,
perhaps a ``Notes`` line), then the column names (``X_Value`` columns, the channel names, a
``Comment`` column) and the data. One segment per file (several are refused).

What LabVIEW writes and this reader takes as it comes:

- a ``Comment`` column: read past (its text is not a sample; rows without one are as good);
- side channels (a channel of 5 samples, or at another Delta_X, beside the accelerometers): only
  the channels asked for (``--channels``), else those named like the chain's (aE_t, aE_n, tacho),
  else those of the longest channels' rate and length, must share one rate; the others are left out
  and named;
- the X_Value column printed with a few decimals: the header's ``Delta_X`` (exact) stands where the
  column agrees with X0 + i Delta_X within its printed precision; which was used is said;
- X0 other than 0, old or odd dates and times (``09:51:39,1970510124996275989``);
- ``Y_Unit_Label`` per channel: volts, or an acceleration (m/s^2, g) used as stated and said.
"""
from __future__ import annotations

import datetime as dt
import math
import re

from labtool.common.errors import FileFormatError, InputError
from labtool.common.names import shown
from labtool.processing.readers.csv import read_head
from labtool.processing.readers.text import Layout, open_table
from labtool.processing.readers.units import signal_unit

END = "***End_of_Header***"
SEPARATORS = {"tab": "\t", "comma": ",", "semicolon": ";", "space": " "}
CHAIN = ("aE_t", "aE_n", "tacho")


def open_lvm(path, sample_rate_hz: float | None = None, time_unit_s: float | None = None,
             wanted: list[str] | None = None):
    """A Recording of the LVM file ``path``; ``wanted``: the file's channel names to read (the
    sources named by ``--channels``), None to choose as the module says."""
    src = shown(str(path))
    text, bom = read_head(path, 1 << 18)
    lines = text.splitlines(keepends=True)
    body = [ln.rstrip("\r\n") for ln in lines]
    ends = [i for i, ln in enumerate(body) if ln.strip().startswith(END)]
    if not body or not body[0].startswith("LabVIEW Measurement") or len(ends) < 2:
        raise FileFormatError(f"{src}: not a complete LabVIEW measurement file (its two headers end with {END})")
    if len(ends) > 2:
        raise FileFormatError(f"{src}: the LVM file holds {len(ends) - 1} segments; labtool reads one per file "
                              "(save the measurement as one segment)")
    file_head = _pairs(body[1:ends[0]])
    sep = SEPARATORS.get(file_head.get("separator", "tab").lower())
    if sep is None:
        raise FileFormatError(f"{src}: LVM separator {file_head.get('separator')!r} is not known")
    dec = file_head.get("decimal_separator", ".") or "."
    chan = _fields(body[ends[0] + 1:ends[1]], sep)
    names_i = next((i for i in range(ends[1] + 1, len(body)) if body[i].strip()), None)
    if names_i is None:
        raise FileFormatError(f"{src}: the LVM file holds no data")
    columns = [c.strip() for c in body[names_i].split(sep)]
    x_cols = [i for i, c in enumerate(columns) if c.lower() == "x_value"]
    comment = [i for i, c in enumerate(columns) if c.lower() == "comment" and i == len(columns) - 1]
    chans = [i for i in range(len(columns)) if i not in x_cols and i not in comment]
    if not chans:
        raise FileFormatError(f"{src}: the LVM file names no channel columns")
    # channel header cells: one per channel, except with X_Columns Multi, where they stand under
    # the data columns (an empty cell under each X_Value)
    multi = file_head.get("x_columns", "one").lower() == "multi"
    info = {j: _channel(chan, j - 1 if multi else k, len(chans), dec) for k, j in enumerate(chans)}
    picked, left_out, why = _pick(src, columns, chans, info, wanted)
    delta = info[picked[0]]["delta"]
    if delta is not None and not (math.isfinite(delta) and delta > 0):
        said = shown(", ".join(x.strip() for x in chan.get("delta_x", [])))
        raise InputError(f"{src}: Delta_X {said!r} is not a usable sample interval (a number of seconds > 0); "
                         "fix the LVM channel header or give --sample-rate")
    # X_Columns No: an X_Value column may still be named, and left empty (lvm_read's short.lvm)
    time_col = None if file_head.get("x_columns", "one").lower() == "no" else \
        max([i for i in x_cols if i < picked[0]], default=None)
    units, unit_sources = {}, {}
    for j in picked:
        label = info[j]["unit"]
        try:
            signal_unit(label or "V", "")
        except InputError:
            raise InputError(f"{src}: channel {columns[j]!r} is in {label!r}, neither a voltage nor an acceleration "
                             f"(channels: {_listing(columns, chans, info)}); name "
                             "the accelerometer channels with --channels aE_t=<channel>,aE_n=<channel>") from None
        if label:
            units[columns[j]] = label
            unit_sources[columns[j]] = f"LVM Y_Unit_Label {label!r}"
    # Samples counts the first write of a segment (a VI appending one row at a time writes Samples 1
    # over many rows): the rows are the samples, cut only where a longer side channel runs on
    samples = {info[j]["samples"] for j in picked}
    longer = [j for j in left_out if (info[j]["samples"] or 0) > max(x or 0 for x in samples)]
    n_rows = min(samples) if longer and None not in samples else None
    assumptions = []
    if left_out:
        assumptions.append(f"read {', '.join(repr(columns[j]) for j in picked)} ({why}); left out "
                           + ", ".join(f"{columns[j]!r} ({_describe(info[j])})" for j in left_out))
    if comment:
        assumptions.append("the Comment column is read past (text, not samples)")
    offset = bom + sum(len(ln.encode("utf-8")) for ln in lines[:names_i + 1])
    lay = Layout(data_start=offset, delimiter=sep, decimal=dec, columns=columns, time_col=time_col,
                 time_unit_s=1.0 if time_col is not None else None, units=units, rate_hz=1.0 / delta if delta else None,
                 assumptions=assumptions, signal_cols=picked, n_rows=n_rows, names_as_written=True,
                 unit_sources=unit_sources, rate_source="the LVM header's Delta_X" if delta else "",
                 x0_s=info[picked[0]]["x0"], left_out=left_out)
    meta = {"lvm_" + k: v for k, v in file_head.items()}
    start = _start_time(info[picked[0]]["date"] or file_head.get("date"),
                        info[picked[0]]["time"] or file_head.get("time"))
    if start:
        meta["start_time_utc"] = start
        lay.assumptions.append("the LVM Date/Time taken as UTC")
    elif file_head.get("date") or file_head.get("time"):
        lay.assumptions.append(f"the LVM Date/Time {file_head.get('date', '')!r} {file_head.get('time', '')!r} is not "
                               "a date and time: the start time is left out")
    return open_table(path, lay, "lvm", meta, sample_rate_hz, time_unit_s, [])


def _pick(src, columns, chans, info, wanted):
    """(columns to read, columns left out, why) as the module docstring says; the read ones must
    share one Delta_X and one length."""
    if wanted:
        low = {columns[j].lower(): j for j in chans}
        missing = [w for w in wanted if w.lower() not in low]
        if missing:
            raise FileFormatError(f"{src}: channel {missing[0]!r} is not in the file (channels: "
                                  f"{', '.join(columns[j] for j in chans)}); name the file's channels with "
                                  "--channels aE_t=<channel>")
        picked = [next((j for j in chans if columns[j] == w), low[w.lower()]) for w in wanted]
        why = "named with --channels"
    else:
        picked = [j for j in chans if columns[j].lower() in [c.lower() for c in CHAIN]]
        why = "named like the chain's channels"
        if not picked:
            picked = [j for j in chans if _is_acceleration(info[j]["unit"])]
            why = "in a unit of acceleration"
        if not picked:
            longest = max(chans, key=lambda j: info[j]["samples"] or 0)
            key = (info[longest]["delta"], info[longest]["samples"])
            picked = [j for j in chans if (info[j]["delta"], info[j]["samples"]) == key]
            why = "the channels of the longest channel's rate and length"
    picked = sorted(set(picked), key=picked.index)
    deltas = {info[j]["delta"] for j in picked}
    if len(deltas) > 1:
        raise InputError(f"{src}: the channels read ({', '.join(repr(columns[j]) for j in picked)}) have different "
                         f"Delta_X {sorted(deltas, key=str)} s; labtool needs one rate: name the accelerometers "
                         "(and tacho) with --channels")
    lengths = {info[j]["samples"] for j in picked}
    if len(lengths) > 1 and None not in lengths:
        raise InputError(f"{src}: the channels read ({', '.join(repr(columns[j]) for j in picked)}) hold "
                         f"{sorted(lengths)} samples; labtool needs channels of one length: name the accelerometers "
                         "(and tacho) with --channels")
    return picked, [j for j in chans if j not in picked], why


def _listing(columns, chans, info) -> str:
    """'Excitation [Newtons], Response [m/s^2]': the file's channels with their units."""
    return ", ".join(f"{columns[j]} [{info[j]['unit'] or 'no unit'}]" for j in chans)


def _is_acceleration(label: str) -> bool:
    try:
        return bool(label) and signal_unit(label, "")[0] == "m/s^2"
    except InputError:
        return False


def _describe(c: dict) -> str:
    parts = []
    if c["samples"] is not None:
        parts.append(f"{c['samples']} samples")
    if c["delta"]:
        parts.append(f"at {1.0 / c['delta']:g} Hz")
    return ", ".join(parts) or "no Samples or Delta_X stated"


def _channel(chan: dict, k: int, n_chans: int, dec: str) -> dict:
    """The channel header's values of channel k (cell k of each line; one cell: for all)."""
    def cell(key):
        cells = [c.strip() for c in chan.get(key, [])]
        while cells and not cells[-1]:
            cells.pop()
        if len(cells) == 1 and n_chans > 1:
            return cells[0]
        return cells[k] if 0 <= k < len(cells) else ""

    def number(key):
        v = cell(key)
        if not v:
            return None
        try:
            return float(v.replace(dec, ".") if dec != "." else v)
        except ValueError:
            return math.nan

    samples = number("samples")
    return {"samples": int(samples) if samples is not None and math.isfinite(samples) else None,
            "delta": number("delta_x"), "x0": number("x0") or 0.0,
            "unit": cell("y_unit_label") or cell("unit_label"), "date": cell("date"), "time": cell("time")}


def _start_time(date, time) -> str | None:
    """ISO 8601 UTC from LVM's Date (2013/02/19) and Time (09:51:39,1970510124996275989); None if
    either is missing or not a date and time."""
    if not date or not time:
        return None
    m = re.fullmatch(r"\s*(\d{4})[/.-](\d{1,2})[/.-](\d{1,2})\s*", date)
    t = re.fullmatch(r"\s*(\d{1,2}):(\d{2}):(\d{2})(?:[.,](\d+))?\s*", time)
    if not m or not t:
        return None
    try:
        stamp = dt.datetime(int(m[1]), int(m[2]), int(m[3]), int(t[1]), int(t[2]), int(t[3]),
                            int((t[4] or "0")[:6].ljust(6, "0")), tzinfo=dt.timezone.utc)
    except ValueError:
        return None
    return stamp.isoformat(timespec="microseconds")


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
