"""Reader of LabVIEW measurement files (.lvm, "Write To Measurement File" text format), as LabVIEW
writes them.

Layout (NI's LVM specification): a file header from ``LabVIEW Measurement`` to
``***End_of_Header***`` (``Separator`` Tab/Comma/Semicolon/Space, ``Decimal_Separator``, ``Date``,
``Time``, ``X_Columns`` No/One/Multi), then a channel header to a second ``***End_of_Header***``
(``Channels``, ``Samples``, ``Date``, ``Time``, ``Y_Unit_Label``, ``X0``, ``Delta_X`` per channel,
perhaps a ``Notes`` line), then the column names (``X_Value`` columns, the channel names, a
``Comment`` column) and the data: one segment. A file of several segments (a channel header, names
and rows each) is scanned whole for their headers; segments that share channels, units and rate are
joined in order, placed by their X0 (contiguous, or after a gap event: _joined); others are refused.

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

import numpy as np

from labtool.common.errors import FileFormatError, InputError
from labtool.common.names import shown
from labtool.processing.readers.csv import read_head
from labtool.processing.readers.text import Layout, open_table
from labtool.processing.readers.base import Event, Recording
from labtool.processing.readers.units import other_quantity, signal_unit, usable

END = "***End_of_Header***"
SEPARATORS = {"tab": "\t", "comma": ",", "semicolon": ";", "space": " "}
CHAIN = ("aE_t", "aE_n", "tacho")


def open_lvm(path, sample_rate_hz: float | None = None, time_unit_s: float | None = None,
             wanted: list[str] | None = None, units: dict | None = None):
    """A Recording of the LVM file ``path``; ``wanted``: the file's channel names to read (the
    sources named by ``--channels``), None to choose as the module says; ``units``: the user's unit
    per channel (``--units``), replacing the Y_Unit_Label. Several segments are joined when they
    share channels, units and rate (_joined)."""
    src = shown(str(path))
    text, _ = read_head(path, 1 << 18)
    body = [ln.rstrip("\r\n") for ln in text.splitlines()]
    first = next((i for i, ln in enumerate(body) if ln.strip().startswith(END)), None)
    if not body or not body[0].startswith("LabVIEW Measurement") or first is None:
        raise FileFormatError(f"{src}: not a complete LabVIEW measurement file (its two headers end with {END})")
    file_head = _pairs(body[1:first])
    sep = SEPARATORS.get(file_head.get("separator", "tab").lower())
    if sep is None:
        raise FileFormatError(f"{src}: LVM separator {file_head.get('separator')!r} is not known")
    dec = file_head.get("decimal_separator", ".") or "."
    heads = _segment_heads(path, src)
    if not heads:
        raise FileFormatError(f"{src}: not a complete LabVIEW measurement file (its two headers end with {END})")
    recs = []
    try:
        for k, (h0, h1) in enumerate(heads):
            stop = heads[k + 1][0] if k + 1 < len(heads) else None
            recs.append(_open_segment(path, src, file_head, sep, dec, (h0, h1, stop), sample_rate_hz, time_unit_s,
                                      wanted, units or {}))
    except BaseException:
        for r in recs:
            r.close()
        raise
    return recs[0] if len(recs) == 1 else _joined(src, recs)


def _segment_heads(path, src) -> list[tuple[int, int]]:
    """(first byte of the channel header, first byte after its End_of_Header line) of every segment:
    the whole file is scanned (a later segment's header may lie past any head read)."""
    marks = _marker_lines(path)
    heads = []
    with open(path, "rb") as fh:
        for k in range(1, len(marks)):
            start = marks[k - 1][1]
            if k > 1:
                # a later segment's header begins at its Channels line, after the previous rows
                lo = max(marks[k - 1][1], marks[k][0] - (1 << 16))
                fh.seek(lo)
                chunk = fh.read(marks[k][0] - lo)
                i = chunk.rfind(b"\nChannels")
                if i < 0:
                    raise FileFormatError(f"{src}: LVM segment {k} has no Channels line before its {END}")
                start = lo + i + 1
            heads.append((start, marks[k][1]))
    return heads


def _marker_lines(path) -> list[tuple[int, int]]:
    """(first byte, first byte after the line) of every line that starts with End_of_Header."""
    key = END.encode()
    found, pos, carry = [], 0, b""
    with open(path, "rb") as fh:
        while True:
            block = fh.read(1 << 22)
            if not block:
                break
            buf = carry + block
            base = pos - len(carry)
            i = buf.find(key)
            while i >= 0:
                at = base + i
                if (i > 0 and buf[i - 1:i] == b"\n" or at == 0) and (not found or at > found[-1]):
                    found.append(at)
                i = buf.find(key, i + 1)
            pos += len(block)
            carry = buf[-len(key):]
        out = []
        for at in found:
            fh.seek(at)
            line = fh.readline()
            out.append((at, at + len(line)))
    return out


def _decode(raw: bytes) -> str:
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("latin-1")    # LabVIEW on a Western Windows: 'Press\xe3o'


def _open_segment(path, src, file_head, sep, dec, where, sample_rate_hz, time_unit_s, wanted, given):
    """The Recording of one segment: its channel header from byte h0, its rows from the names line
    after byte h1 to ``stop`` (the next segment's header; None: the file's end)."""
    h0, h1, stop = where
    with open(path, "rb") as fh:
        fh.seek(h0)
        head = fh.read(h1 - h0).split(b"\n")
        fh.seek(h1)
        after = fh.read(min(1 << 16, (stop - h1) if stop is not None else 1 << 16))
    chan = _fields([_decode(ln).rstrip("\r") for ln in head if not _decode(ln).strip().startswith(END)], sep)
    raw_lines = after.split(b"\n")
    names_i = next((i for i, ln in enumerate(raw_lines[:-1]) if ln.strip()), None)
    if names_i is None:
        raise FileFormatError(f"{src}: the LVM file holds no data")
    columns = [c.strip() for c in _decode(raw_lines[names_i]).rstrip("\r").split(sep)]
    x_cols = [i for i, c in enumerate(columns) if c.lower() == "x_value"]
    comment = [i for i, c in enumerate(columns) if c.lower() == "comment" and i == len(columns) - 1]
    chans = [i for i in range(len(columns)) if i not in x_cols and i not in comment]
    if not chans:
        raise FileFormatError(f"{src}: the LVM file names no channel columns")
    # channel header cells: one per channel, except with X_Columns Multi, where they stand under
    # the data columns (an empty cell under each X_Value)
    multi = file_head.get("x_columns", "one").lower() == "multi"
    info = {j: _channel(chan, j - 1 if multi else k, len(chans), dec) for k, j in enumerate(chans)}
    mine = {str(k).lower(): str(v) for k, v in given.items()}
    for j in chans:
        if columns[j].lower() in mine:
            info[j]["unit"], info[j]["unit_given"] = mine[columns[j].lower()], True
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
        if not usable(label or "V"):
            _refuse_unit(src, columns, chans, info, j)
        if label:
            units[columns[j]] = label
            unit_sources[columns[j]] = (f"--units {columns[j]}={label}" if info[j].get("unit_given")
                                        else f"LVM Y_Unit_Label {label!r}")
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
    offset = h1 + sum(len(ln) + 1 for ln in raw_lines[:names_i + 1])
    lay = Layout(data_start=offset, delimiter=sep, decimal=dec, columns=columns, time_col=time_col,
                 time_unit_s=1.0 if time_col is not None else None, units=units, rate_hz=1.0 / delta if delta else None,
                 assumptions=assumptions, signal_cols=picked, n_rows=n_rows, names_as_written=True,
                 unit_sources=unit_sources, rate_source="the LVM header's Delta_X" if delta else "",
                 x0_s=info[picked[0]]["x0"], left_out=left_out, data_stop=stop)
    meta = {"lvm_" + k: v for k, v in file_head.items()}
    x0 = info[picked[0]]["x0_stated"]
    if x0 is not None and math.isfinite(x0):
        meta["lvm_segment_x0_s"] = x0     # where the segment starts (s): joined segments are placed by it
    start = _start_time(info[picked[0]]["date"] or file_head.get("date"),
                        info[picked[0]]["time"] or file_head.get("time"))
    if start:
        meta["start_time_utc"] = start
        lay.assumptions.append("the LVM Date/Time taken as UTC")
    elif file_head.get("date") or file_head.get("time"):
        lay.assumptions.append(f"the LVM Date/Time {file_head.get('date', '')!r} {file_head.get('time', '')!r} is not "
                               "a date and time: the start time is left out")
    return open_table(path, lay, "lvm", meta, sample_rate_hz, time_unit_s, [])


def _refuse_unit(src, columns, chans, info, j):
    """The channel picked is in a unit labtool cannot read: why, and the option that settles it."""
    label = info[j]["unit"]
    listing = _listing(columns, chans, info)
    if not any(usable(info[i]["unit"] or "V") for i in chans):
        raise InputError(f"{src}: none of its channels is in a unit of voltage or acceleration ({listing}): not a "
                         "recording of an accelerometer")
    if other_quantity(label):
        raise InputError(f"{src}: channel {columns[j]!r} is in {label!r}, a unit of another quantity than voltage or "
                         f"acceleration (channels: {listing}); name the accelerometer channels with "
                         "--channels aE_t=<channel>,aE_n=<channel>")
    raise InputError(f"{src}: channel {columns[j]!r} is in {label!r}, neither a voltage nor an acceleration "
                     f"(channels: {listing}): if you know the unit it was recorded in, give it with "
                     f"--units '{columns[j]}=V' (or mV, m/s^2, g); else name the accelerometer channels with "
                     "--channels aE_t=<channel>,aE_n=<channel>")


def _joined(src, recs):
    """One Recording of the segments of an LVM file, in order: they must share their channels, units
    and rate. A segment that starts where the previous one ends (by X0 and Delta_X) continues it; one
    that starts later is joined after a gap event with the samples lost (processed as a segment of its
    own, as a recorder's gap is); one whose X0 says nothing of that, after a gap of unknown loss."""
    first = recs[0]
    for k, r in enumerate(recs[1:], start=2):
        differs = [what for what, a, b in (("channels", first.channel_names, r.channel_names),
                                           ("units", first.channel_units, r.channel_units))
                   if a != b] + (["sample rate"] if abs(r.sample_rate_hz / first.sample_rate_hz - 1) > 1e-9 else [])
        if differs:
            raise InputError(
                f"{src}: its segment {k} differs from segment 1 in its {' and '.join(differs)} "
                f"({_describe_rec(r)}; segment 1: {_describe_rec(first)}); labtool joins the segments of one "
                "measurement: copy the file header and the segment you want into a file of its own and process that")
    fs = first.sample_rate_hz
    bounds = np.cumsum([0] + [r.n_samples for r in recs])
    events, said = [], []
    for k in range(1, len(recs)):
        prev, cur = recs[k - 1], recs[k]
        x_prev, x_cur = prev.attrs.get("lvm_segment_x0_s"), cur.attrs.get("lvm_segment_x0_s")
        if x_prev is None or x_cur is None:
            events.append(Event(int(bounds[k]), "gap", f"LVM segment {k + 1}: its X0 does not say where it starts"))
            said.append(f"segment {k + 1} after a gap of unknown length (no X0)")
            continue
        gap = x_cur - (x_prev + prev.n_samples / fs)
        lost = int(round(gap * fs))
        if abs(gap) <= 0.5 / fs:
            said.append(f"segment {k + 1} continuing segment {k}")
        elif lost > 0:
            events.append(Event(int(bounds[k]), "gap", f"missing_samples={lost} (LVM segment {k + 1} starts "
                                                          f"{gap:.6g} s after segment {k} ends)"))
            said.append(f"segment {k + 1} after a gap of {lost} samples ({gap:.6g} s)")
        else:
            events.append(Event(int(bounds[k]), "gap", f"LVM segment {k + 1} starts {-gap:.6g} s before segment {k} "
                                                        "ends"))
            said.append(f"segment {k + 1} overlapping segment {k} by {-gap:.6g} s: joined after a gap of unknown "
                        "length")

    def read(start: int, stop: int) -> np.ndarray:
        parts = []
        for k, r in enumerate(recs):
            a, b = max(start, bounds[k]), min(stop, bounds[k + 1])
            if a < b:
                parts.append(r.read(int(a - bounds[k]), int(b - bounds[k])))
        return np.concatenate(parts) if parts else np.empty((0, first.n_channels))

    def close() -> None:
        for r in recs:
            r.close()

    note = f"{len(recs)} LVM segments joined: " + "; ".join(said)
    warnings = list(dict.fromkeys(w for r in recs for w in r.warnings))
    return Recording(source=first.source, format=f"lvm ({len(recs)} segments)", sample_rate_hz=fs,
                     channel_names=list(first.channel_names), n_samples=int(bounds[-1]), read=read,
                     ka_m_s2_per_v=first.ka_m_s2_per_v, start_time_utc=first.start_time_utc,
                     cam_speed_rpm=first.cam_speed_rpm, events=events, attrs=dict(first.attrs),
                     warnings=warnings + [f"{src}: assumed: {note}"], close=close,
                     channel_units=list(first.channel_units), unit_sources=list(first.unit_sources),
                     assumptions=list(first.assumptions) + [note], left_out=list(first.left_out))


def _describe_rec(r) -> str:
    return ", ".join(f"{n} [{u}]" for n, u in zip(r.channel_names, r.channel_units)) + f" at {r.sample_rate_hz:g} Hz"


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
            "delta": number("delta_x"), "x0": number("x0") or 0.0, "x0_stated": number("x0"),
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
