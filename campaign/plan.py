"""The campaign plan (TOML): what to run, validated before anything is touched.

A plan names the device, the calibration(s), the test metadata, the operating points (a list, a
grid, or both) and what to compare with. Example (sample_data/plans/paper_3_speeds.toml)::

    [campaign]
    name = "paper-3-speeds"              # text, shown on the pages
    description = "..."

    [test]                               # run metadata, stored in every recording
    test_id = "STB216-sec2.4"
    operator = "A. N. Other"
    notes = ""

    [device]
    kind = "sim"                         # sim | nidaqmx
    rate_hz = 10000.0                    # sample rate (Hz)
    seed = 1                             # sim: noise seed of the first point; point k uses seed + k
    pacing = "fast"                      # sim: fast | realtime
    truth = "twin"                       # sim: what moves the follower (twin, kinematic, rigid, elastic;
                                         #      default: the stand's own, the twin)
    ka_m_s2_per_v = 864.3                # sim: the chain's Ka (default: the stand's, the 480C02 at x1)
    channels = "Dev1/ai0:2"              # nidaqmx: physical channels of aE_t, aE_n, tacho
    file = "stand_device.toml"           # nidaqmx: the device file (channels by role, ranges, ...)
    settle = "none"                      # none | prompt | tacho: how to wait for a steady cam speed
    settle_tolerance = 0.01              # tacho: relative speed tolerance
    settle_revolutions = 5               # tacho: revolutions that must all be within it
    settle_timeout_s = 120.0             # tacho: give up after this long

    [calibration]
    files = ["../calibration.toml"]      # applied by processing; paths relative to the plan

    [defaults]                           # every point's values unless the point says otherwise
    law = "sine"                         # (default: labtool's, labtool.common.operating_point)
    Fu_N = 0.0
    backlash_mm = 0.128                  # j
    jt_factor = 1.0                      # Jt / Jt nominal
    revolutions = 10                     # whole cam revolutions averaged (N + 1.5 periods recorded; or duration_s)

    [[points]]                           # a list ...
    rpm = 180
    [[points]]
    rpm = 300
    duration_s = 3.0

    [grid]                               # ... and/or a grid: every combination, rpm varying fastest
    rpm = [180, 300, 500]
    Fu_N = [0.0, 65.0]

    [compare]
    models = ["rigid", "elastic"]        # rigid, elastic, kinematic
    omega1 = ["const", "var"]
    accuracy = "fast"                    # fast | standard | reference
    revolutions = 6                      # simulated revolutions (default: labtool report's, 6)
    thresholds = "limits.toml"           # optional: labtool.reports.thresholds file (exit 1 if one fails)
    restitution = 0.2                    # optional model options, as labtool report's options
    contact_damping_s_per_m = 40.0       # (default: labtool's, labtool.common.operating_point)
    contact_length_mm = 6.0
    kc_factor = 1.0
    elastic_gap = "physical"

Unknown keys, wrong types and values out of range are refused with one line naming the key.
Paths are resolved relative to the plan file's folder.
"""
from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import math
import re
import types
from pathlib import Path

from labtool.common.errors import InputError
from labtool.common.names import shown
from labtool.common.operating_point import FIELD, OperatingPoint, schema_field
from labtool.common.schema import Bool, Integer, ListOf, Number, SchemaError, String, Table, load_toml
from labtool.common.units import MM

MAX_POINTS = 500
NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+-]*$")     # a point's folder name
# a point's operating point: the owner's fields and bounds (labtool.common.operating_point), in its
# edge units; a plan names the cam speed ``rpm``
POINT_KEYS = {"rpm": "cam_speed", "law": "law", "Fu_N": "Fu", "backlash_mm": "backlash", "jt_factor": "jt_factor"}
# the model options a plan's [compare] may set, by their owner's names (the rest are the owner's defaults)
COMPARE_OPTIONS = ("restitution", "contact_damping", "contact_length", "kc_factor", "elastic_gap")


def _opt(field):
    field.required = False
    return field


POINT_FIELDS = {
    "name": _opt(String(max_len=60)),
    **{key: schema_field(name) for key, name in POINT_KEYS.items()},
    "revolutions": _opt(Number(ge=2, le=10000, whole=True)),       # whole revolutions: 8.5 is refused
    "duration_s": _opt(Number(gt=0, le=3600, unit="s")),
    "seed": _opt(Integer(ge=0, le=2**32 - 1)),
}
MODELS, MODES = ("rigid", "elastic", "kinematic"), ("const", "var")

PLAN = Table({
    "campaign": Table({"name": String(default="campaign", max_len=200),
                       "description": String(default="", max_len=2000, single_line=False)}, default={}),
    "test": Table({"test_id": String(default="", max_len=200), "operator": String(default="", max_len=200),
                   "notes": String(default="", max_len=2000, single_line=False)}, default={}),
    "device": Table({
        "kind": String(choices=("sim", "nidaqmx"), default="sim"),
        "rate_hz": Number(ge=1000.0, le=1e6, unit="Hz", default=10000.0),
        "seed": Integer(ge=0, le=2**32 - 1, default=0),
        "pacing": String(choices=("fast", "realtime"), default="fast"),
        "truth": _opt(String(choices=("twin", "kinematic", "rigid", "elastic"))),
        "ka_m_s2_per_v": _opt(Number(gt=1e-3, lt=1e6, unit="m/s^2/V")),
        "channels": _opt(String(max_len=200)),
        "file": _opt(String(max_len=4096)),
        "iepe_excitation": Bool(default=False),
        "settle": _opt(String(choices=("none", "prompt", "tacho"))),
        "settle_tolerance": Number(gt=0, le=0.2, default=0.01),
        "settle_revolutions": Integer(ge=2, le=1000, default=5),
        "settle_timeout_s": Number(gt=0, le=3600, unit="s", default=120.0),
    }, default={}),
    "calibration": Table({"files": ListOf(String(max_len=4096), max_len=20, default=[])}, default={}),
    "defaults": Table(POINT_FIELDS, default={}),
    "points": ListOf(Table(POINT_FIELDS), max_len=MAX_POINTS, default=[]),
    "grid": Table({key: _opt(ListOf(schema_field(name, required=True), max_len=MAX_POINTS))
                   for key, name in POINT_KEYS.items()}, required=False),
    "compare": Table({
        "models": ListOf(String(choices=MODELS), min_len=1, default=["rigid", "elastic"]),
        "omega1": ListOf(String(choices=MODES), min_len=1, default=["const", "var"]),
        "accuracy": String(choices=("fast", "standard", "reference"), default="fast"),
        "revolutions": _opt(Number(ge=1.0, le=50.0)),      # default: labtool report's
        "thresholds": _opt(String(max_len=4096)),
        **{FIELD[n].attr: schema_field(n) for n in COMPARE_OPTIONS},
    }, default={}),
})
COMPARE = PLAN.fields["compare"]


class Section(types.SimpleNamespace):
    """A checked table of the plan, read by attribute; absent optional keys read as None."""

    def __getattr__(self, name):
        if name.startswith("__"):
            raise AttributeError(name)
        return None

    def as_dict(self) -> dict:
        return dict(vars(self))


class Device(Section):
    @property
    def settle_mode(self) -> str:
        """The stand's way to a steady speed: the simulated one is steady at once; real hardware
        waits on the tacho unless the plan says otherwise."""
        return self.settle or ("none" if self.kind == "sim" else "tacho")


def check_compare(data: dict, where: str) -> Section:
    """A [compare] table checked (also for 'campaign report' options)."""
    c = COMPARE.check(data, where=where)
    for key in ("models", "omega1"):
        if len(set(c[key])) != len(c[key]):
            raise SchemaError(f"{where}: [compare] {key}: a value is repeated")
    return Section(**c)


def check_plan(data: dict, where: str):
    """The plan checked: (sections by name, the raw point tables); SchemaError (one line) if bad."""
    d = PLAN.check(data, where=where)
    dev = d["device"]
    if dev["kind"] == "nidaqmx" and not (dev.get("channels") or dev.get("file")):
        raise SchemaError(f"{where}: [device] kind = \"nidaqmx\" needs channels (e.g. \"Dev1/ai0:2\") or a device file")
    if dev["kind"] == "sim" and (dev.get("channels") or dev.get("file")):
        raise SchemaError(f"{where}: [device] channels and file describe a nidaqmx device; the simulated stand has neither")
    for label, p in [("[defaults]", d["defaults"])] + [(f"points[{i}]", p) for i, p in enumerate(d["points"])]:
        if "revolutions" in p and "duration_s" in p:
            raise SchemaError(f"{where}: {label}: give revolutions or duration_s, not both")
        if "name" in p and not NAME.match(p["name"]):
            raise SchemaError(f"{where}: {label} name = {p['name']!r}: a point name is letters, digits and _ . + - "
                              "(it names a folder)")
    sections = {"campaign": Section(**d["campaign"]), "test": Section(**d["test"]), "device": Device(**dev),
                "calibration": Section(**d["calibration"]), "defaults": d["defaults"], "points": d["points"],
                "grid": d.get("grid"), "compare": check_compare(d["compare"], where)}
    return types.SimpleNamespace(**sections)


# what a point is when neither it nor [defaults] says: labtool's defaults, 10 revolutions
BASE_POINT = {key: FIELD[name].default_edge for key, name in POINT_KEYS.items() if key != "rpm"}
BASE_POINT["revolutions"] = 10.0


@dataclasses.dataclass(frozen=True)
class Point:
    """One operating point of the plan, complete: ``point`` holds what the recording states (law,
    speed, load, backlash, inertia; the other fields are the owner's defaults)."""
    index: int
    name: str
    point: OperatingPoint
    duration_s: float        # seconds to record
    seed: int

    @property
    def rpm(self) -> float:
        return self.point.cam_speed_rpm

    @property
    def law(self) -> str:
        return self.point.law

    @property
    def Fu_N(self) -> float:
        return self.point.Fu

    @property
    def backlash_mm(self) -> float:
        return self.point.backlash / MM

    @property
    def jt_factor(self) -> float:
        return self.point.jt_factor

    def spec(self) -> dict:
        """What defines the point's acquisition (its identity for resuming)."""
        return {k: getattr(self, k) for k in ("name", "rpm", "law", "Fu_N", "backlash_mm", "jt_factor",
                                              "duration_s", "seed")}

    def label(self) -> str:
        return f"{self.name} ({self.rpm:g} rpm, Fu {self.Fu_N:g} N, j {self.backlash_mm:g} mm, Jt x{self.jt_factor:g}, {self.law})"


@dataclasses.dataclass(frozen=True)
class Plan:
    """A validated plan with its points expanded and its paths resolved."""
    path: Path
    doc: types.SimpleNamespace      # check_plan's sections
    points: tuple
    calibration_files: tuple     # Path
    thresholds: Path | None
    device_file: Path | None

    def digest(self, part: str) -> str:
        """sha256 of one part of the plan (canonical JSON): how a step knows its inputs changed."""
        data = getattr(self.doc, part).as_dict()
        return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()


def _resolve(base: Path, rel: str, what: str) -> Path:
    p = Path(rel).expanduser()
    p = p if p.is_absolute() else base / p
    if not p.is_file():
        raise InputError(f"{what} {shown(p)} does not exist (paths in a plan are relative to its folder)")
    return p


def _duration(v: dict, rpm: float) -> float:
    if v.get("duration_s") is not None:
        return float(v["duration_s"])
    # N whole revolutions averaged need N + 1 tacho marks with the rise after the last one whole:
    # a recording that starts at a mark (the simulated stand's, at phi1 = 0) sees no edge there, and
    # processing completes a revolution once the next rise is whole (0.2 of a period on the STB-216).
    # N + 1.5 periods: N revolutions from such a start, N or N + 1 from any other
    return (float(v["revolutions"]) + 1.5) * 60.0 / rpm


def expand_points(doc) -> list[Point]:
    """The plan's points: the [[points]] list, then the [grid]'s combinations, each completed from
    [defaults] and the paper's experiment; InputError for none, too many, or a missing rpm."""
    base = dict(BASE_POINT)
    if doc.defaults.get("name") is not None or doc.defaults.get("seed") is not None:
        raise InputError("defaults: 'name' and 'seed' belong to a point, not to [defaults]")
    base.update(doc.defaults)
    if "duration_s" in doc.defaults:
        base.pop("revolutions", None)
    raw = [dict(p) for p in doc.points]
    if doc.grid:
        axes = {k: v for k, v in doc.grid.items() if v}
        if axes:
            n = math.prod(len(v) for v in axes.values())
            if n + len(raw) > MAX_POINTS:
                raise InputError(f"the plan has {n + len(raw)} points; at most {MAX_POINTS} per campaign")
            keys = list(axes)[::-1]   # the first key (rpm) varies fastest
            for combo in itertools.product(*(axes[k] for k in keys)):
                raw.append(dict(zip(keys, combo)))
    if not raw:
        raise InputError("the plan has no operating points: add [[points]] with an rpm, or a [grid]")
    out, names = [], set()
    for i, p in enumerate(raw):
        given = {k: v for k, v in p.items() if v is not None}
        v = dict(base)
        if "duration_s" in given:
            v.pop("revolutions", None)
        if "revolutions" in given:
            v.pop("duration_s", None)
        v.update(given)
        where = f"point {i + 1}" if i < len(doc.points) else f"grid point {i + 1 - len(doc.points)}"
        if v.get("rpm") is None:
            raise InputError(f"{where}: no rpm (give it in the point, the grid or [defaults])")
        point = checked_point({name: v[key] for key, name in POINT_KEYS.items()}, where)
        name = v.get("name") or _auto_name(i, point.cam_speed_rpm, v, raw)
        if name in names:
            raise InputError(f"{where}: two points are named {name}; give each a different 'name'")
        names.add(name)
        out.append(Point(i, name, point, _duration(v, point.cam_speed_rpm), int(v.get("seed", doc.device.seed + i))))
    return out


def checked_point(edge: dict, where: str) -> OperatingPoint:
    """A plan point's operating point (edge values by field name), checked completely before anything
    runs: each value against the owner's bounds, then as the models take it (the cam speed the motor
    can drive, the law, the groove the backlash leaves: labtool.models.dynamics.validity)."""
    from labtool.models.dynamics.scene import Scene
    from labtool.models.dynamics.validity import check_scene

    try:
        point = OperatingPoint(**{name: FIELD[name].check_edge(value) for name, value in edge.items()})
        check_scene(Scene.at(point, rise_only=False))
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None
    return point


def _auto_name(i: int, rpm: float, v: dict, raw: list) -> str:
    """'01_180rpm', with the other values that vary between the points ('02_300rpm_Fu65N')."""
    varying = [k for k in ("Fu_N", "backlash_mm", "jt_factor", "law") if len({str(p.get(k)) for p in raw}) > 1]
    unit = {"Fu_N": ("Fu", "N"), "backlash_mm": ("j", "mm"), "jt_factor": ("Jt", "x"), "law": ("", "")}
    parts = [f"{i + 1:02d}_{rpm:g}rpm"]
    for k in varying:
        pre, suf = unit[k]
        parts.append(f"{pre}{v[k]:g}{suf}" if k != "law" else str(v[k]))
    return "_".join(parts).replace("/", "-")


def load_plan(path, check_files: bool = True) -> Plan:
    """Read, validate and expand a plan file; InputError (one line) for anything wrong.

    ``check_files=False`` (the copy kept in a campaign folder, read for its metadata) leaves the
    calibration, thresholds and device files unresolved."""
    path = Path(path)
    doc = check_plan(load_toml(path, "plan"), f"plan {shown(path)}")
    try:
        points = expand_points(doc)
    except InputError as exc:
        raise InputError(f"plan {shown(path)}: {exc}") from None
    if not check_files:
        return Plan(path, doc, tuple(points), (), None, None)
    base = path.resolve().parent
    cals = tuple(_resolve(base, f, "calibration file") for f in doc.calibration.files)
    th = _resolve(base, doc.compare.thresholds, "thresholds file") if doc.compare.thresholds else None
    dev = _resolve(base, doc.device.file, "device file") if doc.device.file else None
    return Plan(path, doc, tuple(points), cals, th, dev)
