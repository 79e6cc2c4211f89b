"""Validated TOML inputs: a pydantic model per file kind, and one clear line for what is wrong.

Every TOML file labtool reads (calibration, campaign plan) is parsed with ``tomllib`` and
validated with a pydantic model whose config is ``STRICT``: strict types (a bool is not a number,
a string is not a number; an int is accepted where a float is expected), finite numbers only,
ranges from the model's fields, and unknown keys refused by name. ``load_toml(path, Model, what)``
returns the validated model or raises InputError/FileFormatError with one line
``<file>: <key.path>: <what is wrong> (<what to give>)``.
"""
from __future__ import annotations

import tomllib
import types
import typing
from pathlib import Path

from pydantic import BaseModel, ConfigDict, ValidationError

from common.errors import FileFormatError, InputError

STRICT = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, frozen=True)
MAX_BYTES = 4 << 20  # a TOML configuration is small; anything bigger is the wrong file


def shown(text) -> str:
    """A file name, key or channel name as it can be shown on one line: control characters escaped."""
    s = str(text)
    if s.isprintable():
        return s
    return s.encode("unicode_escape", "backslashreplace").decode("ascii")


def _loc(loc) -> str:
    """('points', 2, 'rpm') -> 'points[2].rpm' (list indices 0-based, as in the file's order)."""
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + shown(part)
    return out


def _known_keys(model: type[BaseModel], loc) -> list[str]:
    """Field names of the (sub)model that ``loc`` (the unknown key's path) sits in."""
    ann, parts, i = model, list(loc[:-1]), 0
    while i < len(parts):
        cls = _model_in(ann)
        field = None if cls is None or isinstance(parts[i], int) else cls.model_fields.get(parts[i])
        if field is None:
            return []
        ann, i = field.annotation, i + 1
        if _is_container(ann):
            i += 1           # a dict key or a list index comes next in the path
    cls = _model_in(ann)
    return sorted(cls.model_fields) if cls is not None else []


def _is_container(ann) -> bool:
    if typing.get_origin(ann) in (dict, list, tuple):
        return True
    return typing.get_origin(ann) in (typing.Union, types.UnionType) and any(
        _is_container(a) for a in typing.get_args(ann))


def _model_in(ann):
    """The BaseModel class inside an annotation (Model, Model | None, dict[str, Model], list[Model])."""
    if isinstance(ann, type) and issubclass(ann, BaseModel):
        return ann
    for arg in typing.get_args(ann):
        found = _model_in(arg)
        if found is not None:
            return found
    return None


def describe_error(exc: ValidationError, model: type[BaseModel]) -> str:
    """The first problem of a validation error as one line (the count of the others appended)."""
    errors = exc.errors(include_url=False)
    parts = []
    for err in errors[:3]:
        loc = tuple(err.get("loc", ()))
        where = _loc(loc) or "(top level)"
        kind = err.get("type", "")
        if kind == "extra_forbidden":
            known = [k for k in _known_keys(model, loc) if not k.startswith("_")]
            parts.append(f"{where}: unknown key" + (f" (known: {', '.join(known)})" if known else ""))
        elif kind == "missing":
            parts.append(f"{where}: missing")
        else:
            got = err.get("input")
            got_text = shown(repr(got))
            if len(got_text) > 60:
                got_text = got_text[:57] + "..."
            parts.append(f"{where}: {shown(err.get('msg', 'invalid'))}, got {got_text}")
    more = len(errors) - len(parts)
    return "; ".join(parts) + (f" (and {more} more)" if more > 0 else "")


def validate(data: dict, model: type[BaseModel], where: str):
    """``model.model_validate(data)``, or InputError ``<where>: <problem>``."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise InputError(f"{shown(where)}: {describe_error(exc, model)}") from None


def read_toml(path, what: str) -> dict:
    """The TOML document at ``path`` as a dict; InputError/FileFormatError naming ``what`` and the file."""
    p = Path(path)
    if not p.exists():
        raise InputError(f"{what} {shown(p)} does not exist")
    if not p.is_file():
        raise InputError(f"{what} {shown(p)} is not a file")
    try:
        size = p.stat().st_size
        if size > MAX_BYTES:
            raise FileFormatError(f"{what} {shown(p)} is {size} bytes; a TOML file of this kind is a few kB "
                                  "(is it the right file?)")
        text = p.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{what} {shown(p)} is not UTF-8 text (byte {exc.start})") from None
    except OSError as exc:
        raise InputError(f"cannot read {what} {shown(p)}: {exc.strerror or exc}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise FileFormatError(f"{what} {shown(p)} is not valid TOML: {shown(exc)}") from None


def load_toml(path, model: type[BaseModel], what: str):
    """Read and validate a TOML file: the model instance, or one-line InputError/FileFormatError."""
    return validate(read_toml(path, what), model, str(path))
