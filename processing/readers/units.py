"""Units of recorded channels, read from the file and converted, or refused; never assumed silently.

A channel is either a voltage (Ka still to apply) or an acceleration (already in physical units, as
DAQmx logs an accelerometer channel with its sensitivity: TDMS ``unit_string = "m/s^2"``).
Readers multiply by the factor to V or to m/s^2 and report which of the two the channel is in.
"""
from __future__ import annotations

import re

from labtool.common.errors import InputError

G0 = 9.80665  # m/s^2 per g (standard gravity, as DAQmx's g unit)

_VOLT = {"v": 1.0, "volt": 1.0, "volts": 1.0, "mv": 1e-3, "uv": 1e-6, "µv": 1e-6, "kv": 1e3}
_ACCEL = {"m/s^2": 1.0, "m/s2": 1.0, "m/s²": 1.0, "m s-2": 1.0, "m/s/s": 1.0, "ms^-2": 1.0, "m*s^-2": 1.0,
          "metrespersecondsquared": 1.0, "meterspersecondsquared": 1.0, "accelunit_meterspersecondsquared": 1.0,
          "mm/s^2": 1e-3, "mm/s2": 1e-3, "mm/s²": 1e-3, "g": G0, "g0": G0, "gn": G0, "accelunit_g": G0}
_TIME = {"s": 1.0, "sec": 1.0, "second": 1.0, "seconds": 1.0, "ms": 1e-3, "msec": 1e-3, "millisecond": 1e-3,
         "milliseconds": 1e-3, "us": 1e-6, "µs": 1e-6, "microseconds": 1e-6, "min": 60.0}


# units of other quantities (pressure, force, temperature, volume, length, speed, angle, current,
# power, time, ratio): a channel in one of them is not an accelerometer's, whatever it is named
_OTHER = {"pa", "kpa", "mpa", "hpa", "bar", "mbar", "psi", "n", "kn", "lbf", "nm", "n*m", "°c", "degc", "c", "k",
          "°f", "degf", "ml", "l", "m^3", "m", "cm", "mm", "um", "µm", "in", "m/s", "mm/s", "rpm", "hz", "deg", "°",
          "rad", "a", "ma", "w", "kw", "ohm", "Ω", "%", "s", "ms", "us", "min", "h", "kg", "g/s", "l/min"}


def signal_unit(text, where: str, name: str | None = None) -> tuple[str, float]:
    """("V" or "m/s^2", factor to that unit) of a channel's unit text; InputError for anything else,
    whose advice names the channel ``name`` (as the file names it) in the option that settles it."""
    key = re.sub(r"\s+", "", str(text)).lower()
    if key in _VOLT:
        return "V", _VOLT[key]
    if key in _ACCEL:
        return "m/s^2", _ACCEL[key]
    if other_quantity(text):
        raise InputError(f"{where}: unit {text!r} is a unit of another quantity than voltage or acceleration: not an "
                         "accelerometer's channel; name the accelerometer's channels with "
                         "--channels aE_t=<channel>,aE_n=<channel>")
    named = name if name is not None else "<channel>"
    raise InputError(f"{where}: unit {text!r} is neither a voltage (V, mV) nor an acceleration (m/s^2, g); labtool "
                     f"will not guess its scale: if you know the unit it was recorded in, give it with "
                     f"--units '{named}=V' (or mV, m/s^2, g)")


def other_quantity(text) -> bool:
    """True for the unit of a quantity that no accelerometer channel is in (MPa, degC, N, ml, ...)."""
    return re.sub(r"\s+", "", str(text)).lower() in _OTHER or str(text).strip() in _OTHER


def usable(text) -> bool:
    """True when signal_unit reads ``text``."""
    key = re.sub(r"\s+", "", str(text)).lower()
    return key in _VOLT or key in _ACCEL


def time_unit(text) -> float | None:
    """Seconds per unit of a time unit text (s, ms, us, min); None when not a known time unit."""
    return _TIME.get(re.sub(r"\s+", "", str(text)).lower())


def split_name_unit(header: str) -> tuple[str, str | None]:
    """'aE_t [V]' / 'aE_t (m/s^2)' / 'Time_ms' -> (name, unit or None)."""
    h = header.strip()
    m = re.match(r"^(.*?)\s*[\[(]\s*([^\])]*)\s*[\])]\s*$", h)
    if m:
        return m.group(1).strip(), m.group(2).strip()
    m = re.match(r"^(time|t)[_ ]?(s|ms|us)$", h, flags=re.IGNORECASE)
    if m:
        return m.group(1), m.group(2)
    return h, None
