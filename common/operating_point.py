"""The operating point and the model options: their one owner.

Every command, the simulated stand, the report, a campaign plan, a DOE and a simulation's
provenance take the operating point from here: its fields (SI), their units at the edges (rpm, mm),
their defaults and why, their bounds, and one round trip to and from file attributes, with where
each value came from (an option, a file, a default).

The defaults are the simulated stand's (docs/twin.md), so that a default report of a default
recording compares like with like; the paper's simulated experiment (Table 1, k = 1, no contact
damping, the motor's characteristic) is :data:`PAPER_EXPERIMENT`, which ``labtool doe run`` and
the paper's tables use.

Field-level checks live here (finite, in range, one of the choices); the checks that need the
mechanism (the law's name, the cam speed the motor can drive, an undercut groove) are the models'
(:class:`labtool.models.dynamics.scene.Scene`).
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable, Mapping

from labtool.common.errors import InputError
from labtool.common.units import MM, RPM

SOURCE_SUFFIX = "_source"


@dataclasses.dataclass(frozen=True)
class Field:
    """One field of the operating point: its SI unit, its name and unit at the edges, its bounds,
    its default and the reason for it.

    name       attribute of :class:`OperatingPoint` (SI value)
    attr       name at the edges: file attributes, plan and scene-file keys, JSON (edge units)
    option     command-line option
    symbol     the paper's symbol
    unit       SI unit (UDUNITS spelling) of the field
    edge_unit  unit of ``attr`` and ``option`` (what people type and read)
    scale      SI value per edge value (``value_SI = scale * value_edge``)
    lo, hi     bounds in edge units (inclusive unless ``lo_open``); None = unbounded
    choices    the allowed texts of a text field
    stated     a property of a stand's run that a recording states (law, speed, load, backlash,
               inertia); the others are model options
    """

    name: str
    attr: str
    option: str
    symbol: str
    long_name: str
    unit: str
    edge_unit: str
    scale: float
    default: Any
    reason: str
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    choices: tuple[str, ...] = ()
    stated: bool = False
    applies_to: str = "all models"
    label: str = ""          # how messages name it ("load Fu"); default: long name and symbol

    @property
    def named(self) -> str:
        return self.label or f"{self.long_name} {self.symbol}"

    @property
    def text(self) -> bool:
        return isinstance(self.default, str)

    def to_edge(self, value):
        return value if self.text else value / self.scale

    def from_edge(self, value):
        return value if self.text else value * self.scale

    @property
    def default_edge(self):
        return self.to_edge(self.default)

    def shown(self, value_si) -> str:
        """A value in edge units with its unit, as the messages and pages print it."""
        if self.text:
            return str(value_si)
        v = self.to_edge(value_si)
        return f"{v:g} {self.edge_unit}" if self.edge_unit else f"{v:g}"

    def bounds_text(self) -> str:
        if self.choices:
            return "one of " + ", ".join(self.choices)
        unit = f" {self.edge_unit}" if self.edge_unit else ""
        if self.hi is None:
            return f"{'>' if self.lo_open else '>='} {self.lo:g}{unit}"
        return f"in {'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}]{unit}"

    def help(self) -> str:
        """The command-line help of the option: what, unit, default and why."""
        unit = f" [{self.edge_unit}]" if self.edge_unit else ""
        default = self.default if self.text else f"{self.default_edge:g}"
        extra = f"; {self.applies_to}" if self.applies_to != "all models" else ""
        choices = f" ({', '.join(self.choices)})" if self.choices and self.choices[0] not in self.long_name else ""
        return f"{self.long_name}{unit}{choices}{extra} (default {default}: {self.reason})"

    def check_edge(self, value, where: str = "") -> Any:
        """``value`` in edge units, checked; the SI value, or InputError naming the field and ``where``."""
        v = self._checked(value, where)
        return v if self.text else v * self.scale

    def edge_value(self, value, where: str = "") -> Any:
        """``value`` in edge units, checked and returned in edge units (a float, or the text)."""
        return self._checked(value, where)

    def check(self, value_si, where: str = "") -> Any:
        """The SI value, checked against the field's bounds and returned unchanged (a float), or
        InputError as ``check_edge``."""
        if self.text or isinstance(value_si, bool):
            return self._checked(value_si, where)
        try:
            v = float(value_si)
        except (TypeError, ValueError):
            return self._checked(value_si, where)       # the message for a value that is not a number
        self._checked(v / self.scale, where)
        return v

    def _checked(self, value, where: str):
        at = f"{where}: " if where else ""
        if self.text:
            if not isinstance(value, str) or not value.strip() or len(value) > 64:
                raise InputError(f"{at}{self.named} must be text ({self.bounds_text() if self.choices else 'a name'}), "
                                 f"got {value!r} ({self.option})")
            value = value.strip()
            if self.choices and value not in self.choices:
                raise InputError(f"{at}{self.named} must be {self.bounds_text()}, got '{value}' ({self.option})")
            return value
        unit = f" {self.edge_unit}" if self.edge_unit else ""
        if isinstance(value, bool):
            raise InputError(f"{at}{self.named} must be a number{unit and ' [' + self.edge_unit + ']'}, got {value!r} "
                             f"({self.option})")
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise InputError(f"{at}{self.named} must be a number{unit and ' [' + self.edge_unit + ']'}, got {value!r} "
                             f"({self.option})") from None
        ok = math.isfinite(v) and (v > self.lo if self.lo_open else v >= self.lo) and (self.hi is None or v <= self.hi)
        if not ok:
            raise InputError(f"{at}{self.named} must be {self.bounds_text()}, got {v:g}{unit} ({self.option})")
        return v


_STAND = "the simulated stand's, docs/twin.md"
FIELDS: tuple[Field, ...] = (
    Field("law", "law", "--law", "law", "motion law", "", "", 1.0, "sine",
          "the STB-216's rise", stated=True, label="motion law"),
    Field("cam_speed", "cam_speed_rpm", "--rpm", "n1", "nominal cam speed", "rad s-1", "rpm", RPM, 180.0 * RPM,
          "the paper's Table 1, low level", lo=0.0, lo_open=True, stated=True, label="cam speed n1"),
    Field("Fu", "Fu_N", "--fu", "Fu", "load at point N", "N", "N", 1.0, 0.0,
          "the paper's experiment, no load", lo=0.0, hi=1e6, stated=True, label="load Fu"),
    Field("backlash", "backlash_mm", "--backlash-mm", "j", "groove backlash", "m", "mm", MM, 0.128 * MM,
          "the STB-216's groove, the paper's experiment", lo=0.0, hi=10.0, stated=True, label="backlash j"),
    Field("jt_factor", "jt_factor", "--jt-factor", "Jt", "inertia factor of the follower side", "1", "", 1.0, 1.0,
          "the nominal inertia", lo=0.0, hi=1e6, lo_open=True, stated=True, label="inertia factor Jt"),
    Field("omega1_mode", "omega1_mode", "--omega1", "omega1", "cam speed mode: const (cam as input) or var "
          "(the motor's characteristic, eq. 3)", "", "", 1.0, "const",
          "the stand's drive holds its speed", choices=("const", "var"), label="omega1 mode"),
    Field("restitution", "restitution", "--restitution", "k", "Newton's restitution coefficient", "1", "", 1.0, 0.2,
          _STAND, lo=0.0, hi=1.0, applies_to="rigid model", label="restitution k"),
    Field("contact_damping", "contact_damping_s_per_m", "--contact-damping", "c", "Hunt-Crossley contact damping",
          "s m-1", "s/m", 1.0, 40.0, _STAND, lo=0.0, hi=1e4, applies_to="elastic model", label="contact damping"),
    Field("contact_length", "contact_length_mm", "--contact-length-mm", "lw", "roller-groove contact length "
          "(Kc = 8.05e4 lw^(8/9))", "m", "mm", MM, 6.0 * MM, "fitted to the paper's Table 3",
          lo=0.0, hi=100.0, lo_open=True, applies_to="elastic model", label="contact length lw"),
    Field("kc_factor", "kc_factor", "--kc-factor", "Kc", "multiplier of the contact stiffness Kc", "1", "", 1.0, 1.0,
          "the paper's Kc", lo=0.0, hi=1e6, lo_open=True, applies_to="elastic model", label="contact stiffness factor"),
    Field("elastic_gap", "elastic_gap", "--elastic-gap", "gap", "how the backlash enters the elastic model: "
          "physical (the follower crosses the gap j) or closed (the convention of the paper's Table 3)", "", "", 1.0,
          "physical", "the stand's groove has its gap", choices=("physical", "closed"), applies_to="elastic model", label="elastic gap"),
    Field("accuracy", "accuracy", "--accuracy", "accuracy", "solver preset", "", "", 1.0, "standard",
          "errors measured in docs/performance.md", choices=("fast", "standard", "reference"), label="accuracy"),
)
FIELD = {f.name: f for f in FIELDS}
BY_ATTR = {f.attr: f for f in FIELDS}
STATED = tuple(f.name for f in FIELDS if f.stated)
MODEL_OPTIONS = tuple(f.name for f in FIELDS if not f.stated)


@dataclasses.dataclass(frozen=True)
class OperatingPoint:
    """The operating point and the model options, in SI.

    Every field has a default (labtool's: the simulated stand's, ``labtool.DEFAULT``) and is
    checked when the point is made: a value out of its bounds raises
    :class:`labtool.common.errors.InputError` naming the field, its unit and its bounds.
    ``FIELDS`` gives each field's unit, its name and unit at the edges, its bounds and why its
    default is what it is. Make one with the fields you change, in SI
    (``OperatingPoint(cam_speed=300 * RPM, backlash=0.05 * MM)``), or change another with
    ``point.replace(...)``.

    Parameters
    ----------
    law : str
        Motion law of the rise and return: sine (the default), cosine, poly345, poly4567, modtrap
        or modsine (``labtool.models.mechanism.motion_laws.LAWS``).
    cam_speed : float
        Nominal cam speed n1 [rad/s] (``180 * RPM``; the property ``cam_speed_rpm`` gives rpm).
    Fu : float
        Load at point N [N], opposing the rod's sliding.
    backlash : float
        Groove backlash j [m] (``0.128 * MM``).
    jt_factor : float
        Inertia factor of the follower side Jt [-] (the paper's 1 or 4).
    omega1_mode : {"const", "var"}
        ``const``: the cam as input at ``cam_speed``; ``var``: the cam driven through the motor's
        characteristic (the paper's eq. 3).
    restitution : float
        Newton's restitution coefficient k of the rigid model's impacts [-], in [0, 1].
    contact_damping : float
        Hunt-Crossley damping of the elastic model's contact [s/m].
    contact_length : float
        Roller-groove contact length lw [m] (Kc = 8.05e4 lw^(8/9)).
    kc_factor : float
        Multiplier of the contact stiffness Kc [-].
    elastic_gap : {"physical", "closed"}
        How the backlash enters the elastic model: ``physical`` (the follower crosses the gap j)
        or ``closed`` (the convention of the paper's Table 3).
    accuracy : {"fast", "standard", "reference"}
        Solver preset; each one's error and cost are measured (docs/performance.md).

    Examples
    --------
    >>> from labtool import OperatingPoint
    >>> from labtool.units import RPM, MM
    >>> p = OperatingPoint(cam_speed=300 * RPM, backlash=0.05 * MM)
    >>> round(p.cam_speed_rpm, 6), p.restitution
    (300.0, 0.2)
    """

    law: str = FIELD["law"].default
    cam_speed: float = FIELD["cam_speed"].default
    Fu: float = FIELD["Fu"].default
    backlash: float = FIELD["backlash"].default
    jt_factor: float = FIELD["jt_factor"].default
    omega1_mode: str = FIELD["omega1_mode"].default
    restitution: float = FIELD["restitution"].default
    contact_damping: float = FIELD["contact_damping"].default
    contact_length: float = FIELD["contact_length"].default
    kc_factor: float = FIELD["kc_factor"].default
    elastic_gap: str = FIELD["elastic_gap"].default
    accuracy: str = FIELD["accuracy"].default

    def __post_init__(self):
        for f in FIELDS:
            object.__setattr__(self, f.name, f.check(getattr(self, f.name)))

    @property
    def cam_speed_rpm(self) -> float:
        """Nominal cam speed n1 [rpm]."""
        return self.cam_speed / RPM

    @property
    def omega1_nominal(self) -> float:
        """Nominal cam speed [rad/s] (the same as ``cam_speed``)."""
        return self.cam_speed

    def replace(self, **changes):
        """A copy with ``changes`` (fields by name, SI), checked as a new point is."""
        return dataclasses.replace(self, **changes)

    def point(self) -> "OperatingPoint":
        """The operating point and model options alone (a Scene's without its extent)."""
        return OperatingPoint(**{f.name: getattr(self, f.name) for f in FIELDS})

    def attrs(self, names=None) -> dict:
        """Attributes in edge units (``cam_speed_rpm``, ``backlash_mm``, ...), of ``names`` (default all)."""
        return {FIELD[n].attr: FIELD[n].to_edge(getattr(self, n)) for n in (names or FIELD)}

    def describe(self) -> str:
        """One line: law, speed, load, backlash, inertia (edge units)."""
        return (f"{self.law} law, {self.cam_speed_rpm:g} rpm, Fu = {self.Fu:g} N, j = {self.backlash / MM:g} mm, "
                f"Jt x{self.jt_factor:g}")


DEFAULT = OperatingPoint()
# the paper's simulated experiment (Table 1's first run; the rigid model's impacts perfectly
# elastic, k = 1, eq. 11; no contact damping; the cam driven through the motor's characteristic)
PAPER_EXPERIMENT = OperatingPoint(backlash=0.016 * MM, omega1_mode="var", restitution=1.0, contact_damping=0.0)


def default_source(name: str, base: OperatingPoint = DEFAULT) -> str:
    f = FIELD[name]
    if base is DEFAULT or getattr(base, name) == f.default:
        return f"default ({f.reason})"
    return "default (the paper's experiment)" if base is PAPER_EXPERIMENT else "default"


@dataclasses.dataclass(frozen=True)
class Sourced:
    """An operating point with where each value came from (``sources[field]``) and what a reader
    should know about how it was found (``notes``: a stated value that could not be used)."""

    point: OperatingPoint
    sources: dict
    notes: tuple = ()

    def source_attrs(self) -> dict:
        """``<attr>_source`` attributes for every field."""
        return {FIELD[n].attr + SOURCE_SUFFIX: s for n, s in self.sources.items()}

    def rows(self, names=None) -> list[tuple[str, str, str]]:
        """(what, value with its unit, where it came from) for each field of ``names`` (default all)."""
        return [(FIELD[n].named, FIELD[n].shown(getattr(self.point, n)), self.sources[n]) for n in (names or FIELD)]

    def assumed(self, names=STATED) -> list[str]:
        """Fields among ``names`` that no option and no file stated (a default stood in)."""
        return [n for n in names if self.sources[n].startswith("default")]


def stated_in(attrs: Mapping, name: str, where: str) -> Any | None:
    """The SI value of field ``name`` that ``attrs`` (edge units) states, None if it states none.

    A value that is there but cannot be used (text for a number, out of range) is an InputError
    naming the attribute and the option that replaces it; a cam speed of 0 or NaN means "not
    stated" (what some exporters write for an unknown speed) and gives None."""
    f = FIELD[name]
    if f.attr not in attrs:
        return None
    raw = attrs[f.attr]
    if hasattr(raw, "tolist"):          # numpy scalar or 1-element array from h5py / netCDF
        raw = raw.tolist()
    if isinstance(raw, list) and len(raw) == 1:
        raw = raw[0]
    if isinstance(raw, bytes):
        raw = raw.decode("utf-8", "replace")
    if name == "cam_speed" and not isinstance(raw, (str, bool)):
        try:
            if float(raw) == 0 or math.isnan(float(raw)):       # 0 or NaN: the exporter's "unknown"
                return None
        except (TypeError, ValueError):
            pass
    try:
        return f.check_edge(raw, f"{where}: attribute {f.attr}")
    except InputError as exc:
        raise InputError(f"{exc}; give {f.option} to replace it") from None


def resolve(given: Mapping[str, Any] | None = None, attrs: Mapping | None = None, *,
            where: str = "the file", base: OperatingPoint = DEFAULT,
            option_source: Callable[[Field], str] | None = None) -> Sourced:
    """The operating point from given values, a file's attributes and the defaults, with where
    each value came from.

    Each field is taken from, in this order: ``given``, then ``attrs``, then ``base``; every
    value is checked against the field's bounds.

    Parameters
    ----------
    given : mapping, optional
        Values by field name, in SI (``{"cam_speed": 300 * RPM}``); None means "not given".
    attrs : mapping, optional
        A file's attributes, in edge units (``cam_speed_rpm`` [rpm], ``backlash_mm`` [mm],
        ``Fu_N`` [N], ...: ``labtool.common.operating_point.FIELDS`` names them); each
        ``<attr>_source`` attribute is kept in the value's source.
    where : str
        What ``attrs`` came from, named in the messages (a file name).
    base : OperatingPoint
        The values of the fields neither ``given`` nor ``attrs`` states: ``labtool.DEFAULT``
        (the simulated stand's) or ``labtool.PAPER_EXPERIMENT``.
    option_source : callable, optional
        ``option_source(field) -> str``: how a given value's source is named (default
        ``"option --rpm"`` and so on).

    Returns
    -------
    Sourced
        ``point`` (the :class:`OperatingPoint`), ``sources`` (field name -> where its value came
        from: an option, a file attribute, a default and why) and ``notes``.

    Raises
    ------
    labtool.common.errors.InputError
        A value out of its field's bounds, naming the field, the file and the option to use.

    Examples
    --------
    >>> import labtool
    >>> s = labtool.resolve({"Fu": 65.0}, {"cam_speed_rpm": 300.0}, where="run.h5")
    >>> s.point.cam_speed_rpm, s.point.Fu
    (300.0, 65.0)
    >>> s.sources["cam_speed"]
    'file attribute cam_speed_rpm'
    """
    given = {k: v for k, v in (given or {}).items() if v is not None}
    unknown = set(given) - set(FIELD)
    if unknown:
        raise ValueError(f"not operating-point fields: {sorted(unknown)}")
    values, sources, notes = {}, {}, []
    for f in FIELDS:
        if f.name in given:
            values[f.name] = f.check(given[f.name])
            sources[f.name] = option_source(f) if option_source else f"option {f.option}"
            continue
        v = stated_in(attrs, f.name, where) if attrs is not None else None
        if v is not None:
            values[f.name] = v
            said = attrs.get(f.attr + SOURCE_SUFFIX)
            said = said.decode("utf-8", "replace") if isinstance(said, bytes) else said
            sources[f.name] = f"file attribute {f.attr}" + (f", {said}" if said else "")
            continue
        if attrs is not None and f.attr in attrs and f.name == "cam_speed":
            notes.append(f"{where} states a cam speed of {attrs[f.attr]!r} rpm, which means no speed: "
                         "taken as not stated")
        values[f.name] = getattr(base, f.name)
        sources[f.name] = default_source(f.name, base)
    return Sourced(OperatingPoint(**values), sources, tuple(notes))


def from_attrs(attrs: Mapping, where: str = "the file", base: OperatingPoint = DEFAULT) -> OperatingPoint:
    """The operating point a file's attributes state (the others from ``base``)."""
    return resolve(None, attrs, where=where, base=base).point


def from_edge(values: Mapping[str, Any], where: str = "") -> dict:
    """Edge values by attribute name (``{"cam_speed_rpm": 180, "backlash_mm": 0.1}``, None = not
    given) as checked SI values by field name, for :func:`resolve` or ``OperatingPoint(**...)``."""
    out = {}
    for key, v in values.items():
        if key not in BY_ATTR:
            raise InputError(f"{where + ': ' if where else ''}unknown operating-point key {key!r}; known: "
                             + ", ".join(BY_ATTR))
        if v is not None:
            f = BY_ATTR[key]
            out[f.name] = f.check_edge(v, where)
    return out


def schema_field(name: str, required: bool = False):
    """The TOML schema field (labtool.common.schema) of field ``name`` in edge units, with the
    owner's bounds and choices: plan, scene and device files check a value as the options do."""
    from labtool.common.schema import Number, String

    f = FIELD[name]
    if f.text:
        return String(choices=f.choices, required=required) if f.choices else String(max_len=64, required=required)
    lo = {"gt": f.lo} if f.lo_open else {"ge": f.lo}
    return Number(**lo, le=f.hi, unit=f.edge_unit, required=required)
