"""Delimited-text sample tables (CSV exports, LabVIEW .lvm data blocks), read in chunks with pandas.

The format modules (csv.py, lvm.py) find the layout (where the data start, delimiter, decimal
mark, column names, time column and its unit) and say what they assumed; this module indexes the
rows once (byte offsets every ``BLOCK`` rows), parses blocks on demand with pandas' C parser, and
checks the time column in every block it reads, not only its first rows: a time step that is not
1/fs (a gap, rows out of order, a wrong unit) is refused where it happens.
"""
from __future__ import annotations

import dataclasses
import math
import re

import numpy as np

from labtool.common.errors import FileFormatError, InputError
from labtool.common.names import shown
from labtool.processing.readers.base import Recording, check_finite, check_sample_rate
from labtool.processing.readers.units import signal_unit, split_name_unit, time_unit, usable

BLOCK = 65536          # rows between two stored offsets
MIN_PLAUSIBLE_FS = 500.0  # Hz: below it 100 harmonics of a 20 rpm cam do not fit; a time unit is wrong
TIME_NAMES = ("time", "t", "x_value", "zeit", "timestamp", "datetime", "date/time")
CHAIN = ("ae_t", "ae_n", "tacho")     # the chain's channel names, lower case


@dataclasses.dataclass
class Layout:
    """Where and how the samples are written (found by the format module)."""
    data_start: int                 # byte offset of the first data row
    delimiter: str
    decimal: str
    columns: list                   # header names as written
    time_col: int | None = None
    time_unit_s: float | None = None  # seconds per unit of a numeric time column (None: not stated)
    units: dict = dataclasses.field(default_factory=dict)   # column name -> unit text from the header block
    rate_hz: float | None = None    # a rate the header states
    assumptions: list = dataclasses.field(default_factory=list)
    signal_cols: list | None = None   # the columns to read as channels (None: every column but time)
    n_rows: int | None = None         # rows that hold the channels read (None: every row)
    names_as_written: bool = False    # channel names as written, no unit taken from them (LVM)
    unit_sources: dict = dataclasses.field(default_factory=dict)   # column name -> where its unit was read
    rate_source: str = ""             # where rate_hz was read, in words
    x0_s: float | None = None         # the time of the first row the header states (s)
    comment: str | None = None        # lines starting with it are skipped anywhere (CSV: '#')
    x_precision_s: float = 0.0        # half the last printed digit of the time column (s), found when read
    left_out: list = dataclasses.field(default_factory=list)   # channel columns not read (side channels)
    data_stop: int | None = None      # byte offset where the rows end (None: the file's end; LVM segments)


def find_time_column(columns) -> int | None:
    for i, c in enumerate(columns):
        name, _ = split_name_unit(c)
        if name.strip().lower() in TIME_NAMES:
            return i
    return None


def _index_rows(path, start: int, comment: str | None = None, stop: int | None = None) -> tuple[list[int], int]:
    """Byte offsets of rows 0, BLOCK, 2 BLOCK, ... from ``start`` (to ``stop``, else the end), and the
    number of data rows.

    Blank lines, and lines starting with ``comment``, are skipped wherever they are (exporters
    write them between blocks of rows); pandas skips the same lines when it parses."""
    offsets: list[int] = []
    n, base, buf = 0, start, b""
    mark = ord(comment) if comment else -1
    left = math.inf if stop is None else stop - start
    with open(path, "rb") as fh:
        fh.seek(start)
        while True:
            more = fh.read(int(min(1 << 22, left)))
            left -= len(more)
            buf += more
            if not more and buf and not buf.endswith(b"\n"):
                buf += b"\n"
            nl = np.flatnonzero(np.frombuffer(buf, dtype=np.uint8) == 10)
            if len(nl):
                arr = np.frombuffer(buf, np.uint8)
                starts = np.concatenate([[0], nl[:-1] + 1])
                length = nl - starts
                first = arr[starts.clip(max=len(buf) - 1)]
                blank = (length == 0) | ((length == 1) & (first == 13)) | (first == mark)
                rows = np.flatnonzero(~blank)
                k = np.arange(n, n + len(rows))
                offsets.extend((base + starts[rows[k % BLOCK == 0]]).tolist())
                n += len(rows)
                cut = int(nl[-1]) + 1
                base += cut
                buf = buf[cut:]
            if not more:
                break
    return offsets, n


def _parse(path, offset: int, nrows: int, lay: Layout) -> "object":
    import pandas as pd
    with open(path, "rb") as fh:
        fh.seek(offset)
        try:
            # names for every column: a row without its trailing Comment cell, or with empty cells of
            # a side channel that ended, is filled with NaN, not refused as short
            return pd.read_csv(fh, sep=lay.delimiter, decimal=lay.decimal, header=None, nrows=nrows,
                               names=range(len(lay.columns)), comment=lay.comment,
                               engine="c", skip_blank_lines=True, dtype=str if nrows <= 8 else None,
                               # one type per column over the whole block (a Comment column with
                               # text in a few rows), not per internal chunk with a DtypeWarning
                               low_memory=False, encoding="utf-8", encoding_errors="replace")
        except (ValueError, pd.errors.ParserError) as exc:
            raise FileFormatError(f"{path}: bad table near row {nrows}: {str(exc).splitlines()[0]}") from None


def open_table(path, lay: Layout, fmt: str, meta: dict, sample_rate_hz: float | None, time_unit_s: float | None,
               warn_list: list, units: dict | None = None, wanted: list | None = None) -> Recording:
    """A Recording over the table; ``sample_rate_hz``/``time_unit_s``: the user's overrides (or None);
    ``units``: the user's unit per column (name as written, or without its unit), replacing the file's;
    ``wanted``: the columns the user named (--channels). A column in a unit that is neither a voltage
    nor an acceleration is left out (and said) when the accelerometer's columns are known (named, or
    called aE_t and aE_n), and refused otherwise, the refusal naming the option that settles it."""
    src = str(path)
    offsets, n = _index_rows(path, lay.data_start, lay.comment, lay.data_stop)
    if lay.n_rows is not None:
        if lay.n_rows < n:
            offsets = offsets[:(lay.n_rows - 1) // BLOCK + 1] if lay.n_rows else offsets[:1]
        n = min(n, lay.n_rows)
    if n == 0:
        raise FileFormatError(f"{src}: the table holds no samples")
    head = _parse(path, offsets[0], min(n, 8), lay)
    if head.iloc[:, -1].isna().all() and len(lay.columns) > 1 and lay.signal_cols is None:
        raise FileFormatError(f"{src}: rows have fewer values than the header names columns ({len(lay.columns)}) "
                              f"(delimiter {lay.delimiter!r} right? give --delimiter)")
    keep = list(lay.signal_cols) if lay.signal_cols is not None else \
        [i for i in range(len(lay.columns)) if i != lay.time_col]
    given = {str(k).lower(): str(v) for k, v in (units or {}).items()}
    split = {i: ((lay.columns[i], None) if lay.names_as_written else split_name_unit(lay.columns[i])) for i in keep}
    # the accelerometer's columns are known: named with --channels, or called as the chain calls them
    known = {w.lower() for w in wanted} if wanted else \
        ({c for c in CHAIN} if {"ae_t", "ae_n"} <= {split[i][0].lower() for i in keep} else None)
    names, units, factors, sources, aside = [], [], [], [], []
    for i in keep:
        name, unit = split[i]
        unit = unit or lay.units.get(name) or lay.units.get(lay.columns[i])
        source = None
        mine = given.get(name.lower(), given.get(lay.columns[i].lower()))
        if mine is not None:
            unit, source = mine, f"--units {name}={mine}"
        if unit is None:
            lay.assumptions.append(f"column '{name}' states no unit: read as volts")
            unit = "V"
        if not usable(unit) and known is not None and name.lower() not in known and lay.columns[i].lower() not in known:
            aside.append(i)       # a side channel (a temperature, a force) beside the accelerometer's
            lay.assumptions.append(f"column '{name}' is in {unit!r}, not a voltage or an acceleration: left out")
            continue
        kind, f = signal_unit(unit, f"{src}: column '{name}'", name)
        names.append(name)
        units.append(kind)
        factors.append(f)
        sources.append(source or (lay.unit_sources.get(lay.columns[i], "column header") if unit != "V" or
                                  lay.columns[i] in lay.unit_sources else "column header"))
    keep = [i for i in keep if i not in aside]
    lay.left_out = list(lay.left_out) + aside
    if len(set(names)) != len(names):
        raise FileFormatError(f"{src}: channel names {names} are repeated; name the ones to read with --channels")
    fs, t0, start_iso = _rate(src, path, offsets, n, lay, head, sample_rate_hz, time_unit_s)
    factors = np.asarray(factors)

    def read(start: int, stop: int) -> np.ndarray:
        b0 = start // BLOCK
        df = _parse(path, offsets[b0], stop - b0 * BLOCK, lay).iloc[start - b0 * BLOCK:]
        if df.shape != (stop - start, len(lay.columns)):
            raise FileFormatError(f"{src}: rows {start + 1}..{stop} do not have {len(lay.columns)} values each")
        if lay.time_col is not None and fs is not None:
            _check_time(src, df.iloc[:, lay.time_col], start, fs, t0, lay)
        try:
            out = df.iloc[:, keep].to_numpy(dtype=np.float64) * factors[None, :]
        except (TypeError, ValueError):
            raise FileFormatError(f"{src}: a value in rows {start + 1}..{stop} is not a number "
                                  f"(decimal mark {lay.decimal!r} right? give --decimal)") from None
        check_finite(out, start, names, src)
        return out

    attrs = {k: v for k, v in meta.items()}
    rpm = _stated(meta, "cam_speed_rpm", "rpm", src)
    ka = np.array([_stated(meta, f"ka_{c.lower()}", "m/s^2/V", src) for c in names])
    rec = Recording(source=src, format=fmt, sample_rate_hz=fs, channel_names=names, n_samples=n, read=read,
                    ka_m_s2_per_v=ka, start_time_utc=start_iso or str(meta.get("start_time_utc", "")),
                    cam_speed_rpm=rpm if rpm > 0 else math.nan, attrs=attrs, channel_units=units,
                    unit_sources=sources, assumptions=list(lay.assumptions))
    rec.left_out = [lay.columns[i] for i in lay.left_out]
    said = [f"{nm} in {u}" for nm, u, f in zip(names, units, factors) if u != "V" or f != 1.0]
    if said:   # the unit stated is used: say so, an acceleration gets no Ka
        rec.assumptions.append("units as stated: " + ", ".join(said))
    rec.warnings.extend(f"{src}: assumed: {a}" for a in lay.assumptions)
    rec.warnings.extend(warn_list)
    return rec


def _number(v) -> float:
    try:
        return float(str(v).replace(",", ".")) if v is not None else math.nan
    except ValueError:
        return math.nan


def _stated(meta: dict, key: str, unit: str, src: str) -> float:
    """The header's ``key`` as one number (NaN when absent or empty); text that is not one number
    ("864.3 m/s^2/V", "fast") is refused: read as "not stated", a Ka fell back to the paper's."""
    v = meta.get(key)
    if v is None or not str(v).strip():
        return math.nan
    x = _number(v)
    if math.isnan(x) and str(v).strip().lower() != "nan":
        raise FileFormatError(f"{src}: header '{key}' = {shown(str(v))!r} is not one number ({unit}); "
                              f"write the number alone, in {unit}")
    return x


def _rate(src, path, offsets, n, lay: Layout, head, given_fs, given_unit):
    """(fs Hz, first time value in s, ISO start or None) from the time column, the header, or the user."""
    fs_header = lay.rate_hz
    if lay.time_col is None:
        fs = fs_header if fs_header else given_fs
        if fs is None:
            raise InputError(f"{src}: the table states no sample rate and has no time column; give --sample-rate")
        return check_sample_rate(fs, src), 0.0, None
    col = head.iloc[:, lay.time_col].astype(str).str.strip()
    name, unit_text = split_name_unit(lay.columns[lay.time_col])
    first = _parse(path, offsets[0], min(n, 2000), lay).iloc[:, lay.time_col]
    iso = _as_datetime(col)
    if iso is not None:
        ts = _as_datetime(first.astype(str).str.strip())
        if ts is None:
            raise FileFormatError(f"{src}: time column '{name}' mixes timestamps and other values")
        sec = (ts - ts[0]) / np.timedelta64(1, "s")
        lay.time_unit_s = "datetime"
        start_iso = np.datetime_as_string(ts[0], unit="us") + "+00:00"
        lay.assumptions.append(f"time column '{name}' holds timestamps, taken as UTC")
    else:
        unit = given_unit or (time_unit(unit_text) if unit_text else None) or lay.time_unit_s
        texts = first.astype(str).str.strip().str.replace(lay.decimal, ".", regex=False)
        try:
            sec = texts.astype(float).to_numpy()
        except ValueError:
            raise FileFormatError(f"{src}: time column '{name}' holds values that are neither numbers nor timestamps")
        if unit is None and given_fs:
            # the user's rate stands; a time column of unknown unit is not checked against it
            lay.assumptions.append(f"sample rate {given_fs:g} Hz from --sample-rate; time column '{name}' states no "
                                   "unit and is not read")
            lay.time_col = None
            return check_sample_rate(given_fs, src), 0.0, None
        if unit is None:
            d = np.median(np.diff(sec)) if len(sec) > 1 else math.nan
            if not (d > 0 and 1.0 / d >= MIN_PLAUSIBLE_FS):
                raise InputError(f"{src}: time column '{name}' states no unit; in seconds it gives "
                                 f"{1.0 / d if d > 0 else float('nan'):g} Hz, too slow for cam data: give --time-unit "
                                 "(s, ms, us) or --sample-rate")
            unit = 1.0
            lay.assumptions.append(f"time column '{name}' states no unit: read in seconds")
        lay.time_unit_s = unit
        lay.x_precision_s = _printed_precision(texts) * unit
        sec = sec * unit
        start_iso = None
    if len(sec) < 2:
        raise FileFormatError(f"{src}: one row is not a recording")
    d = float(np.median(np.diff(sec)))
    if not d > 0:
        raise InputError(f"{src}: time column '{name}' does not increase")
    t0 = float(sec[0]) if iso is None else 0.0
    if lay.x0_s is not None and abs(t0 - lay.x0_s) <= 2 * lay.x_precision_s + 1e-12:
        t0 = lay.x0_s                     # the header's exact X0, which the column rounds
    prec = lay.x_precision_s
    if given_fs:
        fs = given_fs
        lay.assumptions.append(f"sample rate {fs:g} Hz from --sample-rate; the time column is checked against it")
    elif fs_header and _agrees(sec, t0, fs_header, prec):
        fs = fs_header
        lay.assumptions.append(f"sample rate {fs:g} Hz from {lay.rate_source or 'the header'}; the time column "
                               f"'{name}' agrees with it within its printed precision ({2 * prec:g} s)")
    elif fs_header:
        raise InputError(f"{src}: the header states {fs_header:g} Hz ({lay.rate_source or 'its rate'}) but the time "
                         f"column '{name}' steps by {d:g} s ({1 / d:g} Hz), beyond its printed precision "
                         f"({2 * prec:g} s); give --sample-rate with the rate the device ran at (Hz)")
    else:
        # a rounded column's median step is no rate (51.2 kHz printed to 1 us steps 19 or 20 us):
        # the slope over the first rows, and a whole number of Hz where the rows agree with it
        k = np.arange(len(sec))
        fs = 1.0 / float(np.polyfit(k, sec, 1)[0])
        if _agrees(sec, t0, round(fs), prec):
            fs = float(round(fs))
        lay.assumptions.append(f"sample rate {fs:g} Hz read from the time column '{name}'")
    return check_sample_rate(fs, src), t0, start_iso


def _printed_precision(texts) -> float:
    """Half the last digit the time column prints ('0.000020' -> 5e-7 s, '1.953125E-5' -> 5e-12 s):
    the finest among its first cells (a %g format drops trailing zeros, so '0' or '0.5' say less)."""
    finest = math.inf
    for t in list(texts[:200]):
        m = isinstance(t, str) and re.fullmatch(r"[+-]?\d*(?:\.(\d*))?(?:[eE]([+-]?\d+))?", t)
        if m:
            finest = min(finest, 0.5 * 10.0 ** (int(m.group(2) or 0) - len(m.group(1) or "")))
    return finest if math.isfinite(finest) else 0.0


def _agrees(sec, t0: float, fs: float, prec: float) -> bool:
    """Every time equals t0 + i / fs within the column's printed precision and 1 % of a step."""
    expect = t0 + np.arange(len(sec)) / fs
    return bool(np.all(np.abs(sec - expect) <= 0.01 / fs + 2 * prec + 1e-9 * np.abs(expect)))


def _as_datetime(col):
    """datetime64[ns] array if every value is an ISO timestamp (not a plain number), else None."""
    import pandas as pd
    vals = col.to_numpy(dtype=str)
    if not len(vals) or all(_isnum(v) for v in vals[:4]):
        return None
    try:
        ts = pd.to_datetime(pd.Series(vals), utc=True, format="ISO8601")
    except (ValueError, TypeError):
        return None
    return ts.dt.tz_convert("UTC").dt.tz_localize(None).to_numpy(dtype="datetime64[ns]")


def _isnum(v: str) -> bool:
    try:
        float(v.replace(",", "."))
        return True
    except ValueError:
        return False


def _check_time(src, col, start: int, fs: float, t0: float, lay: Layout) -> None:
    """Every row's time equals t0 + row / fs within 1 % of a step: no gap, no reordering, one rate."""
    if lay.time_unit_s == "datetime":
        ts = _as_datetime(col.astype(str).str.strip())
        if ts is None:
            raise FileFormatError(f"{src}: a time value in rows {start + 1}.. is not a timestamp")
        t = (ts - ts[0]) / np.timedelta64(1, "s")
        expect = np.arange(len(t)) / fs
        bad = np.abs(t - expect) > 0.01 / fs
    else:
        t = col.astype(str).str.replace(lay.decimal, ".", regex=False).astype(float).to_numpy() * lay.time_unit_s
        expect = t0 + (start + np.arange(len(t))) / fs
        bad = np.abs(t - expect) > 0.01 / fs + 2 * lay.x_precision_s + 1e-9 * np.abs(expect)
    if bad.any():
        k = int(np.argmax(bad))
        raise FileFormatError(f"{src}: the time column is not uniform at row {start + k + 1} "
                              f"({t[k]:.9g} s where {expect[k]:.9g} s follows from {fs:g} Hz): a gap, rows out of "
                              "order or a second rate; labtool reads uniformly sampled tables only")
