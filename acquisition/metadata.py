"""What a recording says about its run: the operating point (with who stated each value) and the
run metadata (test ID, operator, sensor, conditioner, notes). Names: common/recording_attrs.py.

Pure validation: every value is checked here, before the device or the file is touched, so a bad
value ends the command in one line and leaves nothing behind.
"""
from __future__ import annotations

import math

from labtool.common import recording_attrs as names
from labtool.common.errors import InputError
from labtool.common.operating_point import BY_ATTR, FIELD, STATED
from labtool.common.names import shown
from labtool.models.mechanism.motion_laws import ALIASES, LAWS

MAX_TEXT = 2000  # characters of a free-text attribute

# option name of each operating-point value, for messages and sources (the owner's, and the free text)
OPTION = {**{FIELD[n].attr: FIELD[n].option for n in STATED}, "motor_setting": "--motor-setting"}


def check_text(name: str, value) -> str:
    """A free-text attribute: a str of at most MAX_TEXT characters without NUL; InputError otherwise."""
    if not isinstance(value, str):
        raise InputError(f"{name} must be text, got {value!r}")
    if "\x00" in value or len(value) > MAX_TEXT:
        raise InputError(f"{name} must be text of at most {MAX_TEXT} characters without NUL bytes")
    if any("\ud800" <= c <= "\udfff" for c in value):     # a byte the shell passed that is not UTF-8
        option = OPTION.get(name, "--" + name.replace("_", "-"))
        raise InputError(f"{name} ({option}) is not UTF-8 text: {shown(value)}; type it again in UTF-8 (a "
                         "terminal set to Latin-1 sends a byte such as \\xe9 for an accented letter)")
    return value.strip()


def check_number(name: str, value) -> float:
    """An operating-point number (by its attribute name, edge units) against its owner's bounds, or
    the conditioner's gain (> 0)."""
    if name in BY_ATTR:
        return BY_ATTR[name].edge_value(value)
    if isinstance(value, bool):
        raise InputError(f"{name} must be a number, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number, got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise InputError(f"{name} must be > 0, got {value!r}")
    return v


def check_law(value) -> str:
    law = check_text("law", value)
    if law not in LAWS and law not in ALIASES:
        raise InputError(f"unknown motion law '{law}'; known: {', '.join(sorted(LAWS))}")
    return law


def operating_point_attrs(values: dict, source: str | dict) -> dict:
    """Root attributes for the operating point ``values`` (names of OPERATING_POINT; None = not
    stated): each value validated, with ``<name>_source`` = ``source`` (one text, or one per name)."""
    out = {}
    for name, v in values.items():
        if name not in names.OPERATING_POINT:
            raise ValueError(f"not an operating-point name: {name}")
        if v is None:
            continue
        if name == "law":
            v = check_law(v)
        elif name == "motor_setting":
            v = check_text(name, v)
        else:
            v = check_number(name, v)
        out[name] = v
        out[names.source_name(name)] = source if isinstance(source, str) else source[name]
    return out


def run_metadata_attrs(values: dict) -> dict:
    """Root attributes for the run metadata (names of RUN_METADATA; None or '' = not given)."""
    out = {}
    for name, v in values.items():
        if name not in names.RUN_METADATA:
            raise InputError(f"unknown metadata '{name}'; known: {', '.join(names.RUN_METADATA)}")
        if v is None or v == "":
            continue
        out[name] = check_number(name, v) if name == "conditioner_gain" else check_text(name, v)
    return out


def missing_operating_point(attrs: dict) -> list[str]:
    """Operating-point values a model comparison needs that the recording does not state."""
    return [FIELD[n].attr for n in STATED if FIELD[n].attr not in attrs]
