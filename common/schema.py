"""Validated TOML inputs: a schema per file kind; every problem is one line naming the file and key.

A schema is built from a few field types and checks a parsed document (a dict) completely: type,
range, choices, and **unknown keys** (a misspelt key is an error with a suggestion, never ignored).
Numbers must be finite; a TOML boolean is never taken for a number; an integer field refuses 1.5.

Usage::

    from labtool.common.schema import Number, Integer, String, Table, load_toml

    MECHANISM = Table({
        "name": String(default="my cam"),
        "frame": Table({"xD_mm": Number(unit="mm", ge=-1e4, le=1e4)}),
        "program": Table({"law": String(choices=("sine", "cosine"))}, required=False),
    })
    doc = load_toml(path, what="mechanism file")       # dict; InputError: missing, a folder,
                                                       # not UTF-8, not TOML, larger than 4 MB
    values = MECHANISM.check(doc, where=f"mechanism file {path}")

``check`` returns a new dict (numbers as float, optional fields with a default filled in, absent
optional fields without one left out) or raises :class:`SchemaError` (an ``InputError``, so the CLI
prints it as ``labtool: error: ...`` and exits 2). Messages read::

    mechanism file m.toml: [frame] xD_mm = "fast": expected a number [mm], got a string
    mechanism file m.toml: [cam] rr_min_mm = 1e+300: must be <= 1e+04 [mm]
    mechanism file m.toml: unknown key [roller] Rr_mm (did you mean R_mm?); known: R_mm, m3_kg

Field types: :class:`Number`, :class:`Integer`, :class:`Bool`, :class:`String`, :class:`ListOf`,
:class:`Table` (fixed keys), :class:`MapOf` (free keys, one value type: channels, signals),
:class:`OneOf` (the first alternative that fits). Each takes ``required`` (default True) and
``default``; a field with a default is optional. Subclass :class:`Field` (override ``_check``) for
a new kind of value.
"""
from __future__ import annotations

import difflib
import math
import stat
import tomllib
from pathlib import Path
from typing import Any, Iterable, Mapping

from labtool.common.errors import InputError
from labtool.common.names import shown

MAX_TOML_BYTES = 4 << 20      # no configuration file is this large; refuse rather than parse for ages
_MISSING = object()


class SchemaError(InputError):
    """A TOML document that does not fit its schema; the message names the file, the key and why."""


def load_toml(path, what: str = "TOML file") -> dict:
    """Read and parse a TOML file; any problem is an InputError naming ``what`` and the file."""
    return parse_toml(read_toml_bytes(path, what), f"{what} {shown(Path(path))}")


def read_toml_bytes(path, what: str = "TOML file") -> bytes:
    """The bytes of a TOML file, read once (a regular file of at most MAX_TOML_BYTES); any problem
    is an InputError naming ``what`` and the file. For a caller that also hashes what it parses."""
    path = Path(path)
    name = shown(path)
    try:
        if path.is_dir():
            raise InputError(f"{what} {name} is a folder; give the TOML file inside it")
        st = path.stat()
        if not stat.S_ISREG(st.st_mode):    # a FIFO or /dev/zero would block or never end
            raise InputError(f"{what} {name} is not a regular file (a pipe or a device); give a TOML file")
        size = st.st_size
        if size > MAX_TOML_BYTES:
            raise InputError(f"{what} {name} is {size / 2**20:.0f} MB; a {what} is at most "
                             f"{MAX_TOML_BYTES >> 20} MB of TOML text")
        return path.read_bytes()
    except FileNotFoundError:
        raise InputError(f"cannot read {what} {name}: not found") from None
    except OSError as exc:
        raise InputError(f"cannot read {what} {name}: {exc.strerror or exc}") from None


def parse_toml(raw: bytes | str, where: str) -> dict:
    """Parse TOML bytes (UTF-8) or text; InputError ``<where> is not ...`` otherwise."""
    if isinstance(raw, bytes):
        if raw[:2] in (b"\xff\xfe", b"\xfe\xff"):
            raise InputError(f"{where} is UTF-16 text (Notepad's 'Unicode'); save it as UTF-8")
        raw = raw.removeprefix(b"\xef\xbb\xbf")   # Notepad and Excel put a BOM before UTF-8 text
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            line = raw.count(b"\n", 0, exc.start) + 1
            raise InputError(f"{where} is not UTF-8 text (byte 0x{raw[exc.start]:02x} on line {line}); "
                             "save it as UTF-8") from None
    else:
        text = raw.removeprefix("\ufeff")
    if "\x00" in text:
        raise InputError(f"{where} is not a text file (it holds NUL bytes)")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{where} is not valid TOML: {exc}") from None
    except RecursionError:
        raise InputError(f"{where} is not valid TOML: nested too deeply") from None


def _type_name(value) -> str:
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int):
        return "an integer"
    if isinstance(value, float):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, dict):
        return "a table"
    return f"a {type(value).__name__}"      # dates and times


def _short(value, limit: int = 40) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        text = f"{value:g}"
    elif isinstance(value, str):
        text = '"' + shown(value.encode("utf-8", "surrogateescape"))[:limit].replace('"', '\\"') + '"'
    elif isinstance(value, dict):
        return "{...}"
    elif hasattr(value, "isoformat"):      # TOML dates and times
        text = value.isoformat()
    else:
        text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _bound_text(bound) -> str:
    return str(bound) if isinstance(bound, int) else f"{bound:g}"


class KeyPath:
    """Where a value sits in the document, printed as TOML would: ``[a.b] key`` or ``key[2]``."""

    def __init__(self, tables: tuple = (), key: str | None = None):
        self.tables, self.key = tables, key

    def child(self, key: str) -> "KeyPath":
        if self.key is None:
            return KeyPath(self.tables, key)
        return KeyPath(self.tables + (self.key,), key)

    def item(self, index: int) -> "KeyPath":
        return KeyPath(self.tables, f"{self.key}[{index}]")

    def __str__(self) -> str:
        # a quoted TOML key may hold any character: shown() keeps a newline in one from breaking
        # the message's one line
        head = f"[{'.'.join(shown(t) for t in self.tables)}] " if self.tables else ""
        return f"{head}{shown(self.key)}" if self.key is not None else (head.strip() or "the file")


class Field:
    """One value of the document. ``required``: absence is an error; ``default``: used if absent."""

    def __init__(self, *, required: bool = True, default: Any = _MISSING, doc: str = ""):
        self.default = default
        self.required = required and default is _MISSING
        self.doc = doc

    def check(self, value, where: str = "", at: KeyPath | None = None):
        """The checked (and converted) value; SchemaError naming ``where`` and the key otherwise."""
        return self._check(value, where, at or KeyPath())

    def _check(self, value, where: str, at: KeyPath):
        return value

    def describe(self) -> str:
        """What the field takes, for messages ("a number [mm]")."""
        return "a value"

    types: tuple = (object,)      # the Python types of the TOML values it takes (bool only if listed)

    def takes_type(self, value) -> bool:
        """Whether ``value`` is of the kind this field takes (its range aside); used by OneOf."""
        if isinstance(value, bool) and bool not in self.types:
            return False
        return isinstance(value, self.types)

    def _require_type(self, value, where, at) -> None:
        if not self.takes_type(value):
            self._expected(where, at, value)

    def _fail(self, where: str, at: KeyPath, value, why: str):
        prefix = f"{where}: " if where else ""
        shown_at = str(at)
        if at.key is not None:
            shown_at += f" = {_short(value)}"
        raise SchemaError(f"{prefix}{shown_at}: {why}")

    def _expected(self, where, at, value):
        self._fail(where, at, value, f"expected {self.describe()}, got {_type_name(value)}")


class Number(Field):
    """A finite real number (TOML integer or float, not a boolean), returned as float.

    ``gt``/``ge``/``lt``/``le``: bounds; ``nonzero``: refuse 0; ``unit``: shown in messages;
    ``allow_inf``: accept TOML ``inf`` (never ``nan``), e.g. "record until stopped"; ``whole``:
    a count that TOML may write as 10 or 10.0, never 8.5."""

    types = (int, float)

    def __init__(self, *, gt=None, ge=None, lt=None, le=None, nonzero: bool = False, unit: str = "",
                 allow_inf: bool = False, whole: bool = False, **kw):
        super().__init__(**kw)
        self.gt, self.ge, self.lt, self.le, self.nonzero, self.unit = gt, ge, lt, le, nonzero, unit
        self.allow_inf, self.whole = allow_inf, whole

    def _u(self) -> str:
        return f" [{self.unit}]" if self.unit else ""

    def describe(self) -> str:
        return f"a number{self._u()}"

    def _number(self, value, where, at):
        self._require_type(value, where, at)
        try:
            number = float(value)
        except OverflowError:
            self._fail(where, at, value, f"is too large{self._u()}")
        if not math.isfinite(number) and not (self.allow_inf and not math.isnan(number)):
            self._fail(where, at, value, f"must be a finite number{self._u()}")
        return number

    def _bounds(self, number, value, where, at):
        u = self._u()
        f = _bound_text
        if self.gt is not None and not number > self.gt:
            if self.gt == 0:
                self._fail(where, at, value, "must not be negative; it must be greater than zero" if number < 0
                           else "must be greater than zero")
            self._fail(where, at, value, f"must be > {f(self.gt)}{u}")
        if self.ge is not None and not number >= self.ge:
            self._fail(where, at, value, "must not be negative" if self.ge == 0 else f"must be >= {f(self.ge)}{u}")
        if self.lt is not None and not number < self.lt:
            self._fail(where, at, value, f"must be < {f(self.lt)}{u}")
        if self.le is not None and not number <= self.le:
            self._fail(where, at, value, f"must be <= {f(self.le)}{u}")
        if self.nonzero and number == 0:
            self._fail(where, at, value, f"must not be zero{u}")
        if self.whole and math.isfinite(number) and number != math.floor(number):
            self._fail(where, at, value, f"must be a whole number{u}")

    def _check(self, value, where, at):
        number = self._number(value, where, at)
        self._bounds(number, value, where, at)
        return number


class Integer(Number):
    """A TOML integer (not 1.5, not 2.0, not a boolean) within the bounds (default: int64), as int."""

    types = (int,)

    def __init__(self, *, ge=-(2**63), le=2**63 - 1, **kw):
        super().__init__(ge=ge, le=le, **kw)

    def describe(self) -> str:
        return f"an integer{self._u()}"

    def _check(self, value, where, at):
        self._require_type(value, where, at)
        self._bounds(value, value, where, at)
        return int(value)


class Bool(Field):
    """``true`` or ``false`` (not 0/1, not "yes")."""

    types = (bool,)

    def describe(self) -> str:
        return "true or false"

    def _check(self, value, where, at):
        self._require_type(value, where, at)
        return value


class String(Field):
    """A string; ``choices``: the allowed values; ``max_len``: longest accepted (characters);
    ``single_line``: refuse newlines and other control characters (names written into files)."""

    types = (str,)

    def __init__(self, *, choices: Iterable[str] | None = None, max_len: int = 4096, single_line: bool = True, **kw):
        super().__init__(**kw)
        self.choices = tuple(choices) if choices is not None else None
        self.max_len, self.single_line = max_len, single_line

    def describe(self) -> str:
        if self.choices:
            return "one of " + ", ".join(f'"{c}"' for c in self.choices)
        return "a string"

    def _check(self, value, where, at):
        self._require_type(value, where, at)
        if self.choices is not None and value not in self.choices:
            self._fail(where, at, value, f"expected {self.describe()}{_suggest(value, self.choices)}")
        if len(value) > self.max_len:
            self._fail(where, at, value, f"longer than {self.max_len} characters")
        if self.single_line and any(c < " " or c == "\x7f" for c in value if c != "\t"):
            self._fail(where, at, value, "must be one line without control characters")
        return value


class ListOf(Field):
    """A list whose items all fit ``item``; ``min_len``/``max_len`` bound its length."""

    types = (list,)

    def __init__(self, item: Field, *, min_len: int = 0, max_len: int | None = None, **kw):
        super().__init__(**kw)
        self.item, self.min_len, self.max_len = item, min_len, max_len

    def describe(self) -> str:
        return f"a list of {self.item.describe().removeprefix('a ').removeprefix('an ')}s"

    def _check(self, value, where, at):
        self._require_type(value, where, at)
        if len(value) < self.min_len:
            self._fail(where, at, value, f"needs at least {self.min_len} item(s)")
        if self.max_len is not None and len(value) > self.max_len:
            self._fail(where, at, value, f"takes at most {self.max_len} item(s), got {len(value)}")
        return [self.item._check(v, where, at.item(i)) for i, v in enumerate(value)]


def _suggest(name: str, known: Iterable[str]) -> str:
    """' (did you mean X?)' for a misspelt key: case, a missing unit suffix (fu -> Fu_N), typos."""
    known = list(known)
    lower = {k.lower(): k for k in known}
    key = name.lower()
    same = lower.get(key) or next((k for k in known if k.lower().split("_")[0] == key), None)
    if same is None:
        close = difflib.get_close_matches(key, list(lower), n=1, cutoff=0.6)
        same = lower[close[0]] if close else None
    return f" (did you mean {same}?)" if same and same != name else ""


class Table(Field):
    """A TOML table with fixed keys: ``fields`` maps each key to its Field. Keys not in ``fields``
    are an error naming them, unless ``extra=True`` (then kept unchecked)."""

    types = (dict,)

    def __init__(self, fields: Mapping[str, Field], *, extra: bool = False, **kw):
        super().__init__(**kw)
        self.fields, self.extra = dict(fields), extra

    def describe(self) -> str:
        return "a table"

    def _check(self, value, where, at):
        self._require_type(value, where, at)
        if not self.extra:
            for key in value:
                if key not in self.fields:
                    self._unknown(key, where, at, value[key])
        out = {}
        for key, field in self.fields.items():
            sub = at.child(key)
            if key in value:
                out[key] = field._check(value[key], where, sub)
            elif field.default is not _MISSING:   # a table's default gets its own fields' defaults
                out[key] = field._check(field.default, where, sub) if isinstance(field, (Table, MapOf)) else field.default
            elif field.required:
                prefix = f"{where}: " if where else ""
                raise SchemaError(f"{prefix}missing parameter {sub} ({field.describe()})")
        if self.extra:
            out.update({k: v for k, v in value.items() if k not in self.fields})
        return out

    def _unknown(self, key, where, at, value=None):
        prefix = f"{where}: " if where else ""
        sub = at.child(str(key))
        if isinstance(value, dict):    # a misnamed section reads as one: [extra], [frame.sub]
            what = "table [" + ".".join(shown(part) for part in sub.tables + (sub.key,)) + "]"
        else:
            what = f"key {sub}"
        known = ", ".join(self.fields) or "(none)"
        raise SchemaError(f"{prefix}unknown {what}{_suggest(str(key), self.fields)}; known: {known}")


class MapOf(Field):
    """A table with free keys (channel names, signals) whose values all fit ``value``.

    ``keys``: the allowed key names (None = any); ``key_max_len`` bounds a free key's length;
    ``noun``: what a key is called in messages ("unknown metric [omega2] nrmsee")."""

    types = (dict,)

    def __init__(self, value: Field, *, keys: Iterable[str] | None = None, key_max_len: int = 256,
                 min_len: int = 0, noun: str = "key", **kw):
        super().__init__(**kw)
        self.value, self.keys, self.key_max_len, self.min_len = value, (tuple(keys) if keys else None), key_max_len, min_len
        self.noun = noun

    def describe(self) -> str:
        return "a table"

    def _check(self, value, where, at):
        self._require_type(value, where, at)
        if len(value) < self.min_len:
            self._fail(where, at, value, f"needs at least {self.min_len} entr{'y' if self.min_len == 1 else 'ies'}")
        out = {}
        for key, item in value.items():
            sub = at.child(key)
            if self.keys is not None and key not in self.keys:
                prefix = f"{where}: " if where else ""
                raise SchemaError(f"{prefix}unknown {self.noun} {sub}{_suggest(key, self.keys)}; "
                                  f"known: {', '.join(self.keys)}")
            if len(key) > self.key_max_len:
                self._fail(where, at, value, f"a key is longer than {self.key_max_len} characters")
            out[key] = self.value._check(item, where, sub)
        return out


class OneOf(Field):
    """The first of ``options`` that accepts the value; else the error says what each would take."""

    def __init__(self, *options: Field, **kw):
        super().__init__(**kw)
        self.options = options

    def describe(self) -> str:
        return " or ".join(o.describe() for o in self.options)

    def _check(self, value, where, at):
        for option in self.options:
            if option.takes_type(value):
                return option._check(value, where, at)   # its own message (range, keys) is the useful one
        self._expected(where, at, value)
