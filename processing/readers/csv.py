"""Reader of CSV-like exports: labtool's CSV, NI "Write To Measurement File" text, generic DAQ exports.

What is detected, and reported as an assumption (a warning and the history's ``read`` step):
- an optional header block before the column names: ``# key = value`` (labtool), ``key<sep>value``
  or ``key: value`` lines; ``sample_rate_hz``/``Sample Rate``/``Fs`` (Hz), ``dt``/``Delta_X`` (s),
  ``cam_speed_rpm``, ``ka_<channel>`` (m/s^2/V), ``start_time_utc`` are understood;
- the delimiter (comma, semicolon, tab) and the decimal mark (a comma with ; or tab delimiters);
- the column names row; units in the names (``aE_t [V]``, ``time (ms)``, ``t_ms``);
- a time column (time, t, X_Value, Timestamp): numbers with a unit, or ISO 8601 timestamps; read
  in full and checked row by row (text.py).
What is ambiguous is refused with one line naming the option that settles it (``--delimiter``,
``--decimal``, ``--time-unit``, ``--sample-rate``).
"""
from __future__ import annotations

import re

from labtool.common.errors import FileFormatError, InputError
from labtool.processing.readers.text import Layout, find_time_column, open_table
from labtool.processing.readers.units import signal_unit, time_unit

COMMENT = "#"   # lines starting with it are skipped, before the table and between its rows

DELIMITERS = {",": "comma", ";": "semicolon", "\t": "tab"}
RATE_KEYS = {"sample_rate_hz": 1, "sample rate": 1, "samplerate": 1, "sampling rate": 1, "sample_rate": 1, "fs": 1,
             "rate": 1, "scan rate": 1}
STEP_KEYS = ("dt", "delta_x", "delta t", "sample interval", "wf_increment")


def read_head(path, size: int = 1 << 16) -> tuple[str, int]:
    """(decoded start of the file, bytes that make the BOM)."""
    with open(path, "rb") as fh:
        raw = fh.read(size)
    bom = 3 if raw.startswith(b"\xef\xbb\xbf") else 0
    raw = raw[bom:]
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        if exc.start < len(raw) - 4:
            text = raw.decode("latin-1")
        else:
            text = raw[:exc.start].decode("utf-8")
    return text, bom


def _is_number(cell: str, decimal: str) -> bool:
    c = cell.strip()
    if decimal == ",":
        c = c.replace(".", "").replace(",", ".") if re.fullmatch(r"[-+]?[\d.]*,\d*([eE][-+]?\d+)?", c) else c
    try:
        float(c)
        return True
    except ValueError:
        return False


def _data_like(cells, decimal) -> bool:
    """A data row: every cell a number, except perhaps one timestamp."""
    non = [c for c in cells if not _is_number(c, decimal)]
    return len(cells) >= 2 and (not non or (len(non) == 1 and re.match(r"\d{4}-\d\d-\d\d", non[0].strip())))


def detect(path, delimiter: str | None = None, decimal: str | None = None) -> tuple[Layout, dict]:
    """The table's layout and the header block's key/values."""
    text, bom = read_head(path)
    lines = text.splitlines(keepends=True)
    if len(lines) > 1 and not text.endswith(("\n", "\r")):
        lines = lines[:-1]  # the last line may be cut at the read size
    body = [ln.rstrip("\r\n") for ln in lines]
    assumptions = []
    sep_line = re.fullmatch(r'"?sep=(.)"?', body[0].strip()) if body else None
    if sep_line:   # Excel's first line names the delimiter
        delimiter = delimiter or sep_line.group(1)
        body[0] = ""
    cands = [delimiter] if delimiter else list(DELIMITERS)
    found = None
    for d in cands:
        for dec in ([decimal] if decimal else ([".", ","] if d != "," else ["."])):
            start = next((i for i, ln in enumerate(body) if ln.strip() and _data_like(ln.split(d), dec)), None)
            if start is None:
                continue
            width = len(body[start].split(d))
            tail = [ln for ln in body[start:start + 50] if ln.strip() and not ln.lstrip().startswith(COMMENT)]
            if all(len(ln.split(d)) == width and _data_like(ln.split(d), dec) for ln in tail):
                found = (d, dec, start, width)
                break
        if found:
            break
    if found is None:
        raise FileFormatError(f"{path}: no table of numbers found (delimiter comma, semicolon or tab; give "
                              "--delimiter and --decimal if the file uses others)")
    d, dec, start, width = found
    if not delimiter:
        assumptions.append(f"delimiter {DELIMITERS.get(d, repr(d))} and decimal mark {dec!r} (detected)")
    header_i = next((i for i in range(start - 1, -1, -1) if body[i].strip() and not body[i].lstrip().startswith("#")), None)
    units_row = None
    if header_i is not None and _units_row(body[header_i].split(d)):
        # DEWESoft and others write the units in a row under the names
        units_row = [c.strip().strip('"').strip() for c in body[header_i].split(d)]
        header_i = next((i for i in range(header_i - 1, -1, -1)
                         if body[i].strip() and not body[i].lstrip().startswith("#")), None)
    if header_i is None or len(body[header_i].split(d)) != width:
        raise FileFormatError(f"{path}: the table has no row of column names ({width} names, "
                              f"{DELIMITERS.get(d, d)}-separated, just above the numbers)")
    columns = [c.strip().strip('"') for c in body[header_i].split(d)]
    if any(not c for c in columns) or len(set(columns)) != len(columns):
        raise FileFormatError(f"{path}: column names {columns} are empty or repeated")
    meta = _header_block(body[:header_i], d)
    offset = bom + sum(len(ln.encode("utf-8")) for ln in lines[:start])
    lay = Layout(data_start=offset, delimiter=d, decimal=dec, columns=columns, time_col=find_time_column(columns),
                 assumptions=assumptions, comment=COMMENT)
    lay.rate_hz, lay.units = _rate_from_meta(meta, path), {k[5:]: v for k, v in meta.items() if k.startswith("unit_")}
    if units_row:
        lay.units.update({c: u for c, u in zip(columns, units_row) if u})
        lay.unit_sources.update({c: f"the units row ({u!r})" for c, u in zip(columns, units_row) if u})
        if lay.time_col is not None and units_row[lay.time_col]:
            lay.time_unit_s = time_unit(units_row[lay.time_col])
    return lay, meta


def _units_row(cells) -> bool:
    """Every cell a unit (of time, voltage or acceleration) or empty, and one at least not empty."""
    vals = [c.strip().strip('"').strip() for c in cells]
    if not any(vals):
        return False
    for v in vals:
        if not v or time_unit(v) is not None:
            continue
        try:
            signal_unit(v, "")
        except InputError:
            return False
    return True


def _header_block(lines, d) -> dict:
    meta = {}
    for ln in lines:
        s = ln.strip().lstrip("#").strip()
        if not s:
            continue
        for sep in ("=", ":", d):
            if sep in s:
                k, v = s.split(sep, 1)
                meta[k.strip().lower()] = v.strip().strip(d).strip()
                break
    return meta


def _rate_from_meta(meta: dict, path) -> float | None:
    for k in RATE_KEYS:
        if k in meta:
            return _num(meta[k], path, k)
    for k in STEP_KEYS:
        if k in meta:
            dt = _num(meta[k], path, k)
            if not dt > 0:
                raise InputError(f"{path}: header '{k}' = {meta[k]!r} is not a usable sample interval")
            return 1.0 / dt
    return None


RATE_UNITS = ("", "hz", "1/s", "s-1", "s/s", "sa/s", "samples/s", "sps")   # what may follow a rate's number
STEP_UNITS = ("", "s", "sec", "second", "seconds")                          # ... and a sample interval's


def _num(text, path, what) -> float:
    m = re.match(r"\s*([-+]?[\d.,]+(?:[eE][-+]?\d+)?)", str(text))
    try:
        x = float(m.group(1).replace(",", ".")) if m else float("nan")
    except ValueError:
        raise InputError(f"{path}: header '{what}' = {text!r} is not a number") from None
    # a unit after the number must be the key's own: "10 kHz" was read as 10 Hz, "0.1 ms" as 0.1 s
    units, unit = (STEP_UNITS, "s") if what in STEP_KEYS else (RATE_UNITS, "Hz")
    if m and str(text)[m.end():].strip().lower() not in units:
        raise InputError(f"{path}: header '{what}' = {text!r} is not a number in {unit}; write it in {unit} "
                         "(10 kHz is 10000 Hz, 0.1 ms is 0.0001 s)")
    return x


def open_csv(path, sample_rate_hz: float | None = None, delimiter: str | None = None, decimal: str | None = None,
             time_unit_s: float | None = None, units: dict | None = None, wanted: list | None = None):
    """A Recording of the CSV file ``path``; ``units``: the user's unit per column (--units);
    ``wanted``: the columns named with --channels (the others may be side channels)."""
    lay, meta = detect(path, delimiter, decimal)
    return open_table(path, lay, "csv", meta, sample_rate_hz, time_unit_s, [], units, wanted)
