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
    law = "sine"
    Fu_N = 0.0
    backlash_mm = 0.128                  # j
    jt_factor = 1.0                      # Jt / Jt nominal
    revolutions = 10                     # whole cam revolutions to record (or duration_s)

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
    restitution = 1.0                    # optional model options (labtool report's)
    contact_damping = 0.0
    contact_length_mm = 6.0
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
from labtool.common.schema import Bool, Integer, ListOf, Number, SchemaError, String, Table, load_toml

MAX_POINTS = 500
MAX_RPM = 2000.0      # the schema's bound; expand_points then holds each point to the models' own range
NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+-]*$")     # a point's folder name


def _opt(field):
    field.required = False
    return field


POINT_FIELDS = {
    "name": _opt(String(max_len=60)),
    "rpm": _opt(Number(gt=0, le=MAX_RPM, unit="rpm")),
    "law": _opt(String(max_len=40)),
    "Fu_N": _opt(Number(ge=0, le=1e4, unit="N")),
    "backlash_mm": _opt(Number(ge=0, le=10, unit="mm")),
    "jt_factor": _opt(Number(gt=0, le=100)),
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
    "grid": Table({"rpm": _opt(ListOf(Number(gt=0, le=MAX_RPM, unit="rpm"), max_len=MAX_POINTS)),
                   "law": _opt(ListOf(String(max_len=40), max_len=20)),
                   "Fu_N": _opt(ListOf(Number(ge=0, le=1e4, unit="N"), max_len=100)),
                   "backlash_mm": _opt(ListOf(Number(ge=0, le=10, unit="mm"), max_len=100)),
                   "jt_factor": _opt(ListOf(Number(gt=0, le=100), max_len=100))}, required=False),
    "compare": Table({
        "models": ListOf(String(choices=MODELS), min_len=1, default=["rigid", "elastic"]),
        "omega1": ListOf(String(choices=MODES), min_len=1, default=["const", "var"]),
        "accuracy": String(choices=("fast", "standard", "reference"), default="fast"),
        "revolutions": _opt(Number(ge=1.0, le=50.0)),      # default: labtool report's
        "thresholds": _opt(String(max_len=4096)),
        "restitution": _opt(Number(ge=0, le=1)),
        "contact_damping": _opt(Number(ge=0, le=1e4, unit="s/m")),
        "contact_length_mm": _opt(Number(gt=0, le=100, unit="mm")),
        "elastic_gap": _opt(String(choices=("physical", "closed"))),
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


# the paper's experiment (sec. 2.4): what a point is when neither it nor [defaults] says
PAPER_POINT = {"law": "sine", "Fu_N": 0.0, "backlash_mm": 0.128, "jt_factor": 1.0, "revolutions": 10.0}


@dataclasses.dataclass(frozen=True)
class Point:
    """One operating point, complete (edge units: rpm, N, mm)."""
    index: int
    name: str
    rpm: float
    law: str
    Fu_N: float
    backlash_mm: float
    jt_factor: float
    duration_s: float        # seconds to record
    seed: int

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
    # N whole revolutions need N + 1 periods: the recording starts and ends mid-revolution in general
    return (float(v["revolutions"]) + 1.0) * 60.0 / rpm


def expand_points(doc) -> list[Point]:
    """The plan's points: the [[points]] list, then the [grid]'s combinations, each completed from
    [defaults] and the paper's experiment; InputError for none, too many, or a missing rpm."""
    base = dict(PAPER_POINT)
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
    from labtool.models.mechanism import Mechanism

    mech = Mechanism.default()                     # the mechanism the campaign's scenes use
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
        for key, test, what in (("rpm", lambda x: 0 < x <= MAX_RPM, f"in (0, {MAX_RPM:g}]"),
                                ("Fu_N", lambda x: 0 <= x <= 1e4, "in [0, 1e4] N"),
                                ("backlash_mm", lambda x: 0 <= x <= 10, "in [0, 10] mm"),
                                ("jt_factor", lambda x: 0 < x <= 100, "in (0, 100]")):
            if not (math.isfinite(float(v[key])) and test(float(v[key]))):
                raise InputError(f"{where}: {key} = {v[key]!r} must be {what}")
        rpm = float(v["rpm"])
        try:                                       # every point is compared with the models: their range
            mech.check_cam_speed(rpm)
        except InputError as exc:
            raise InputError(f"{where}: {exc}") from None
        name = v.get("name") or _auto_name(i, rpm, v, raw)
        if name in names:
            raise InputError(f"{where}: two points are named {name}; give each a different 'name'")
        names.add(name)
        out.append(Point(i, name, rpm, str(v["law"]), float(v["Fu_N"]), float(v["backlash_mm"]),
                         float(v["jt_factor"]), _duration(v, rpm), int(v.get("seed", doc.device.seed + i))))
    return out


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
    from labtool.models.mechanism.motion_laws import ALIASES, LAWS
    for p in points:
        if p.law not in LAWS and p.law not in ALIASES:
            raise InputError(f"plan {shown(path)}: point {p.name}: unknown motion law {shown(p.law)!r}; known: {', '.join(sorted(LAWS))}")
    if not check_files:
        return Plan(path, doc, tuple(points), (), None, None)
    base = path.resolve().parent
    cals = tuple(_resolve(base, f, "calibration file") for f in doc.calibration.files)
    th = _resolve(base, doc.compare.thresholds, "thresholds file") if doc.compare.thresholds else None
    dev = _resolve(base, doc.device.file, "device file") if doc.device.file else None
    return Plan(path, doc, tuple(points), cals, th, dev)
