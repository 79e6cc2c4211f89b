"""CF-1.10 conventions for labtool's NetCDF outputs (process, simulate, kinematics).

What CF asks and labtool does (https://cfconventions.org, version 1.10):
- global ``Conventions = "CF-1.10"``, ``title``, ``institution``, ``source``, ``history``;
- every variable with ``units`` in UDUNITS syntax (``m s-2``, ``rad s-1``, ``1`` for counts and
  flags) and a ``long_name``; ``standard_name`` only where the CF standard-name table has the
  quantity (of labtool's, only ``time``: angles and rates of a mechanism are not in the table);
- ``time`` as absolute time, ``seconds since <start in ISO 8601, UTC>`` with ``calendar``
  ``standard`` and ``axis = "T"``, when the start is known; elapsed seconds (``s``) otherwise;
- a coordinate variable on every dimension (an index where nothing better exists).

Usable without xarray (:func:`variable_attrs`, :func:`global_attrs`, :func:`time_units`) by
writers that stream with h5netcdf, and on an xarray Dataset with :func:`apply`.
"""
from __future__ import annotations

import datetime as _dt
import math

CONVENTIONS = "CF-1.10"

# labtool unit strings -> UDUNITS spelling
_UNITS = {
    "m/s^2": "m s-2", "m/s2": "m s-2", "rad/s": "rad s-1", "rad/s^2": "rad s-2", "rad/s2": "rad s-2",
    "(m/s^2)^2/Hz": "m2 s-4 Hz-1", "N m": "N m", "N*m": "N m", "Nm": "N m", "N s": "N s",
    "m/s": "m s-1", "kg m^2": "kg m2", "kg*m^2": "kg m2", "V": "V", "deg": "degree", "mm": "mm",
    "": "1", "-": "1", "1": "1", "none": "1", "count": "1",
}
STANDARD_NAMES = {"time": "time"}


def udunits(units: str) -> str:
    """labtool's unit text in UDUNITS syntax: the table above, else a product of powers written
    ``a b^2/c d^3`` becomes ``a b2 c-1 d-3`` (other text passes unchanged)."""
    text = str(units).strip()
    if text in _UNITS:
        return _UNITS[text]
    if "(" in text or text.count("/") > 1 or not ("/" in text or "^" in text):
        return text
    num, _, den = text.partition("/")

    def powers(part: str, sign: int) -> list[str]:
        out = []
        for tok in part.replace("*", " ").split():
            base, _, exp = tok.partition("^")
            n = sign * (int(exp) if exp.lstrip("-").isdigit() else 1)
            out.append(base if n == 1 else f"{base}{n}")
        return out

    top = [t for t in powers(num, 1) if t != "1"]
    return " ".join(top + powers(den, -1)) or text


def start_time(text) -> _dt.datetime | None:
    """A recording's ISO 8601 start time as an aware UTC datetime; None when absent or unreadable."""
    if not isinstance(text, str) or not text.strip():
        return None
    try:
        t = _dt.datetime.fromisoformat(text.strip().replace("Z", "+00:00"))
    except ValueError:
        return None
    return (t if t.tzinfo else t.replace(tzinfo=_dt.timezone.utc)).astimezone(_dt.timezone.utc)


def time_units(start) -> str:
    """``seconds since <start>`` (start: datetime or ISO text), or ``s`` when the start is unknown."""
    t = start if isinstance(start, _dt.datetime) else start_time(start)
    if t is None:
        return "s"
    return "seconds since " + t.strftime("%Y-%m-%dT%H:%M:%S") + (
        f".{t.microsecond:06d}".rstrip("0") if t.microsecond else "") + "+00:00"


def in_seconds(units) -> bool:
    """Whether a time variable's stated ``units`` are seconds (``s``, ``seconds``, ``seconds since
    <start>``, as :func:`time_units` writes them); no unit stated counts as seconds."""
    if units is None:
        return True
    text = (units.decode("utf-8", "replace") if isinstance(units, bytes) else str(units)).strip()
    return text.partition(" since ")[0].strip() in ("", "s", "sec", "secs", "second", "seconds")


def time_attrs(start, long_name: str = "time") -> dict:
    """Attributes of a ``time`` coordinate (absolute when the start is known)."""
    units = time_units(start)
    out = {"units": units, "long_name": long_name, "axis": "T"}
    if units != "s":
        out.update(standard_name="time", calendar="standard")
    return out


def variable_attrs(name: str, units: str, long_name: str, **extra) -> dict:
    """CF attributes of one variable: UDUNITS units, long_name, standard_name where CF has one."""
    out = {"units": udunits(units), "long_name": long_name}
    if name in STANDARD_NAMES:
        out["standard_name"] = STANDARD_NAMES[name]
    out.update(extra)
    return out


def global_attrs(title: str, source: str, history: str = "", **extra) -> dict:
    """Global attributes: Conventions, title, institution, source, history (one line per command)."""
    version = _version()
    now = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    out = {"Conventions": CONVENTIONS, "title": title, "institution": "labtool cam-follower test stand",
           "source": source, "history": f"{now} labtool {version}: {history}".rstrip(": ")}
    out.update({k: v for k, v in extra.items() if v is not None and not (isinstance(v, float) and math.isnan(v))})
    return out


def _version() -> str:
    try:
        from importlib.metadata import version
        return version("labtool")
    except Exception:  # not installed (a source checkout)
        return "unknown"


def apply(ds, title: str, source: str, history: str = "", start=None):
    """Make an xarray Dataset CF-1.10 in place and return it: global attributes, UDUNITS units,
    standard names, an absolute ``time`` when ``start`` (datetime/ISO text) is given, and an index
    coordinate on every dimension that has none. Call it just before writing, e.g.
    ``labtool.common.cf.apply(ds, title="labtool simulation", source="labtool simulate --model rigid ...")``.
    """
    for name in list(ds.variables):
        v = ds[name]
        if v.dtype.kind in "OSU":
            v.attrs.pop("units", None)
            continue
        if name == "time" and start is not None and "since" not in str(v.attrs.get("units", "")):
            v.attrs.update(time_attrs(start, v.attrs.get("long_name", "time")))
            continue
        v.attrs["units"] = udunits(v.attrs.get("units", "1"))
        v.attrs.setdefault("long_name", name)
        if name == "time" and v.dims == ("time",):      # a simulation's elapsed time: still the T axis
            v.attrs.setdefault("axis", "T")
        if name in STANDARD_NAMES:
            v.attrs.setdefault("standard_name", STANDARD_NAMES[name])
    for dim in ds.dims:
        if dim not in ds.variables:
            ds.coords[dim] = (dim, range(ds.sizes[dim]), {"units": "1", "long_name": f"index along {dim}"})
    ds.attrs.update(global_attrs(title, source, history))
    return ds


def elapsed_seconds(values):
    """Seconds from the first element, for a time coordinate read back decoded (datetime64) or as
    plain seconds; numpy array."""
    import numpy as np
    v = np.asarray(values)
    if np.issubdtype(v.dtype, np.datetime64) or np.issubdtype(v.dtype, np.timedelta64):
        return (v - v[0]) / np.timedelta64(1, "s") if v.size else v.astype(float)
    return v.astype(float)
