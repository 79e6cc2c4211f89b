"""The parameters a fit can free: names, models, the search's bounds and scale.

A scene parameter is a field of the operating point, and its unit, its scale to SI, its key in
the operating point and JSON, and the values it can take are that field's
(labtool.common.operating_point.FIELDS, the one owner); what is the fit's own is here: the
search's default bounds, whether it searches on a log scale, where it starts when neither the
scene nor the user says, and whether the parameter is a property of the stand (the same at every
operating point, ``stand``) or an effective value that may change with the operating point (a
joint fit over several measurements shares the first kind by default). The chain parameters (Ka
gain, delay) are not operating-point fields; their units and limits are here.

Edge units (mm, s/m, ms, -) are what a user types and reads (CLI, JSON); inside, values are SI
(m, s/m, s, -), converted here once. The search works in the unit box u in [0, 1]^p: u = 0 at the
lower bound, u = 1 at the upper, linear in the value or in its logarithm (``log``) for quantities
that span decades (backlash, contact length, gain).

Two kinds: ``scene`` parameters change the simulation (one model run per new value); ``chain``
parameters (Ka gain, delay) act on the measuring side only and are applied to a simulated cycle
already computed (labtool.reports.align.as_measured), so they cost no model run.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from labtool.common.errors import InputError
from labtool.common.operating_point import FIELD, Field


@dataclasses.dataclass(frozen=True)
class Chain:
    """A measuring-side quantity that is not an operating-point field: its JSON key (edge unit in
    the name), edge unit, SI value of one edge unit, and possible values (edge units, inclusive)."""

    key: str
    unit: str
    scale: float
    limits: tuple


@dataclasses.dataclass(frozen=True)
class FreeParameter:
    """One identifiable parameter.

    name      CLI name (``--free backlash,...``)
    models    the models it exists in
    bounds    default search bounds (edge units)
    log       search on a log scale
    start     the value used when neither the scene nor the user gives one (edge units)
    stand     a property of the stand, the same at every operating point (shared by a joint fit
              unless told otherwise); False: an effective value that may change with it
    meaning   one line for --help and the docs
    field     a scene parameter's operating-point field (unit, scale, key, limits: its owner's)
    chain     a chain parameter's own unit and limits
    """

    name: str
    models: tuple
    bounds: tuple
    log: bool
    start: float
    stand: bool
    meaning: str
    field: Field | None = None
    chain: Chain | None = None

    @property
    def kind(self) -> str:
        """"scene" (a Scene field, needs a model run) or "chain" (applied to the simulated cycle)."""
        return "scene" if self.field is not None else "chain"

    @property
    def key(self) -> str:
        """JSON key, with the edge unit (``backlash_mm``); also its key in the report's operating
        point (labtool.reports.pipeline.operating_point: the owner's attribute name, edge units)."""
        return self.field.attr if self.field is not None else self.chain.key

    op_key = key

    @property
    def unit(self) -> str:
        """Edge unit, as printed ("-" for a pure number)."""
        u = self.field.edge_unit if self.field is not None else self.chain.unit
        return u or "-"

    @property
    def si_per_unit(self) -> float:
        """SI value of one edge unit (1e-3 for mm, ms)."""
        return self.field.scale if self.field is not None else self.chain.scale

    @property
    def limits(self) -> tuple:
        """Physically possible values (edge units), and whether the lower one is excluded."""
        if self.field is not None:
            hi = math.inf if self.field.hi is None else self.field.hi
            return (self.field.lo, hi)
        return self.chain.limits

    @property
    def lo_open(self) -> bool:
        return bool(self.field is not None and self.field.lo_open)

    def to_edge(self, si: float) -> float:
        return float(si) / self.si_per_unit

    def describe(self) -> str:
        unit = f" [{self.unit}]" if self.unit != "-" else ""
        return f"{self.name}{unit}: {self.meaning}"


CATALOGUE = {p.name: p for p in (
    FreeParameter("backlash", ("rigid", "elastic"), (0.01, 0.6), True, FIELD["backlash"].default_edge, True,
                  "groove backlash j (the gap the follower crosses)", field=FIELD["backlash"]),
    FreeParameter("restitution", ("rigid",), (0.0, 1.0), False, 0.5, False,
                  "Newton's restitution k of the rigid model's impacts", field=FIELD["restitution"]),
    FreeParameter("contact_damping", ("elastic",), (0.0, 400.0), False, FIELD["contact_damping"].default_edge, False,
                  "Hunt-Crossley damping of the elastic contact", field=FIELD["contact_damping"]),
    FreeParameter("contact_length", ("elastic",), (1.0, 30.0), True, FIELD["contact_length"].default_edge, True,
                  "roller-groove contact length lw behind Kc = 8.05e4 lw^(8/9)", field=FIELD["contact_length"]),
    FreeParameter("ka_gain", ("rigid", "elastic"), (0.5, 2.0), True, 1.0, True,
                  "true Ka over the Ka the processing used (the measured signals are the truth divided by it)",
                  chain=Chain("ka_gain", "-", 1.0, (1e-3, 1e3))),
    FreeParameter("delay", ("rigid", "elastic"), (-5.0, 5.0), False, 0.0, True,
                  "delay of the acceleration channels behind the tacho (> 0: the measurement is late)",
                  chain=Chain("delay_ms", "ms", 1e-3, (-1e3, 1e3))),
)}

MODELS = ("rigid", "elastic")


def parse_free(text: str, model: str, elastic_gap: str = "physical") -> list[FreeParameter]:
    """``--free backlash,restitution`` -> the parameters, checked against the model."""
    if model not in MODELS:
        raise InputError(f"--model must be one of {', '.join(MODELS)}, got '{model}'")
    names = [n.strip() for n in str(text).split(",") if n.strip()]
    if not names:
        raise InputError("--free names no parameter; give e.g. --free backlash,restitution")
    known = [p.name for p in CATALOGUE.values() if model in p.models]
    out = []
    for n in names:
        p = CATALOGUE.get(n)
        if p is None:
            raise InputError(f"--free: unknown parameter '{n}'; the {model} model's are: {', '.join(known)}")
        if model not in p.models:
            raise InputError(f"--free: '{n}' is not a parameter of the {model} model ({p.meaning}, "
                             f"{' and '.join(p.models)} only); the {model} model's are: {', '.join(known)}")
        if p in out:
            raise InputError(f"--free: '{n}' is given twice")
        out.append(p)
    if model == "elastic" and elastic_gap == "closed" and any(p.name == "backlash" for p in out):
        raise InputError("--free backlash: with --elastic-gap closed the elastic model does not use the backlash "
                         "(the flanks touch); use the physical gap or free other parameters")
    if all(p.kind == "chain" for p in out):
        raise InputError("--free names only chain parameters (ka_gain, delay); free at least one model parameter "
                         "(e.g. backlash) or use 'labtool report' for a gain or delay alone")
    return out


def parse_assignments(text: str | None, option: str, ranges: bool = False) -> dict:
    """``name=value,...`` (or ``name=lo:hi,...`` when ``ranges``) in edge units -> {name: value}."""
    if text is None or not str(text).strip():
        return {}
    out = {}
    for item in str(text).split(","):
        item = item.strip()
        if not item:
            continue
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or not name:
            form = "name=lo:hi" if ranges else "name=value"
            raise InputError(f"{option}: '{item}' is not {form} (e.g. {option} backlash={'0.02:0.4' if ranges else '0.1'})")
        if name not in CATALOGUE:
            raise InputError(f"{option}: unknown parameter '{name}'; known: {', '.join(CATALOGUE)}")
        try:
            if ranges:
                lo, colon, hi = value.partition(":")
                if not colon:
                    raise ValueError
                v = (float(lo), float(hi))
            else:
                v = float(value)
        except ValueError:
            raise InputError(f"{option}: '{item}' needs {'two numbers lo:hi' if ranges else 'a number'} "
                             f"in {CATALOGUE[name].unit}") from None
        out[name] = v
    return out


@dataclasses.dataclass(frozen=True)
class Space:
    """The free parameters with their bounds (edge units): the map between values and the unit box."""

    params: tuple
    lo: np.ndarray
    hi: np.ndarray

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.params]

    @property
    def keys(self) -> list[str]:
        return [p.key for p in self.params]

    def to_unit(self, edge) -> np.ndarray:
        x = np.asarray(edge, float)
        log = np.array([p.log for p in self.params])
        with np.errstate(divide="ignore", invalid="ignore"):
            u_log = np.log(x / self.lo) / np.log(self.hi / self.lo)
        return np.where(log, u_log, (x - self.lo) / (self.hi - self.lo))

    def from_unit(self, u) -> np.ndarray:
        u = np.asarray(u, float)
        log = np.array([p.log for p in self.params])
        with np.errstate(divide="ignore", invalid="ignore"):
            x_log = self.lo * (self.hi / self.lo) ** u
        return np.where(log, x_log, self.lo + u * (self.hi - self.lo))

    def value(self, i: int, u: float) -> float:
        """Parameter i's value (edge units) at unit-box coordinate u, beyond the bounds too."""
        if math.isnan(u):
            return math.nan
        if math.isinf(u):
            return 0.0 if self.params[i].log and u < 0 else float(u)
        lo, hi = float(self.lo[i]), float(self.hi[i])
        if not self.params[i].log:
            return lo + u * (hi - lo)
        try:
            return lo * (hi / lo) ** u
        except OverflowError:          # far beyond the bounds (a widened interval): no finite value
            return math.inf


    def as_dict(self, edge) -> dict:
        return {p.name: float(v) for p, v in zip(self.params, np.asarray(edge, float))}


def make_space(free: list[FreeParameter], bounds: dict | None = None) -> Space:
    """The search space: default bounds, or the user's (``--bounds``), checked against the limits."""
    bounds = bounds or {}
    extra = set(bounds) - {p.name for p in free}
    if extra:
        raise InputError(f"--bounds: {', '.join(sorted(extra))} is not free (add it to --free or drop its bounds)")
    lo, hi = [], []
    for p in free:
        a, b = bounds.get(p.name, p.bounds)
        unit = "" if p.unit == "-" else f" {p.unit}"
        if not (math.isfinite(a) and math.isfinite(b) and a < b):
            raise InputError(f"--bounds {p.name}={a:g}:{b:g}: need finite lo < hi{unit}")
        low, high = p.limits
        if a < low or (p.lo_open and a <= low) or b > high:
            raise InputError(f"--bounds {p.name}={a:g}:{b:g}{unit} leaves the possible range "
                             f"{'(' if p.lo_open else '['}{low:g}, {high:g}]{unit}")
        if p.log and a <= 0:
            raise InputError(f"--bounds {p.name}={a:g}:{b:g}: its lower bound must be > 0{unit} "
                             f"(it is searched on a log scale); e.g. {p.bounds[0]:g}")
        lo.append(float(a))
        hi.append(float(b))
    return Space(tuple(free), np.array(lo), np.array(hi))


def check_start(space: Space, start: dict) -> np.ndarray:
    """The starting values (edge units) as a vector; InputError when one lies outside its bounds."""
    x = []
    for p, a, b in zip(space.params, space.lo, space.hi):
        v = float(start[p.name])
        unit = "" if p.unit == "-" else f" {p.unit}"
        if not (math.isfinite(v) and a <= v <= b):
            raise InputError(f"the start {p.name} = {v:g}{unit} lies outside its bounds [{a:g}, {b:g}]{unit}; "
                             f"give --start inside them or widen --bounds")
        x.append(v)
    return np.array(x)
