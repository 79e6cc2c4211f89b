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
    truth = "kinematic"                  # sim: what moves the follower (default: the stand's own)
    ka_m_s2_per_v = 86.43                # sim: the chain's Ka
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
    revolutions = 1.0                    # simulated revolutions (the last whole one is compared)
    thresholds = "limits.toml"           # optional: reports.thresholds file (exit 1 if one fails)
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
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, Field, model_validator

from common.errors import InputError
from common.schema import STRICT, read_toml, shown, validate

MAX_POINTS = 500
MAX_RPM = 2000.0      # above the drive's synchronous speed; the models refuse beyond their own limit
Text = Field(default="", max_length=2000)


class CampaignInfo(BaseModel):
    model_config = STRICT
    name: str = Field(default="campaign", min_length=1, max_length=200)
    description: str = Text


class TestInfo(BaseModel):
    model_config = STRICT
    test_id: str = Field(default="", max_length=200)
    operator: str = Field(default="", max_length=200)
    notes: str = Text


class Device(BaseModel):
    model_config = STRICT
    kind: Literal["sim", "nidaqmx"] = "sim"
    rate_hz: float = Field(default=10000.0, ge=1000.0, le=1e6)
    seed: int = Field(default=0, ge=0, lt=2**32)
    pacing: Literal["fast", "realtime"] = "fast"
    truth: Literal["kinematic", "rigid", "elastic"] | None = None
    ka_m_s2_per_v: float = Field(default=86.43, gt=1e-3, lt=1e6)
    channels: str | None = Field(default=None, min_length=1, max_length=200)
    file: str | None = Field(default=None, min_length=1, max_length=4096)
    iepe_excitation: bool = False
    settle: Literal["none", "prompt", "tacho"] | None = None
    settle_tolerance: float = Field(default=0.01, gt=0, le=0.2)
    settle_revolutions: int = Field(default=5, ge=2, le=1000)
    settle_timeout_s: float = Field(default=120.0, gt=0, le=3600)

    @model_validator(mode="after")
    def _kind_keys(self):
        if self.kind == "nidaqmx" and not (self.channels or self.file):
            raise ValueError("a nidaqmx device needs 'channels' (e.g. \"Dev1/ai0:2\") or a device 'file'")
        if self.kind == "sim" and (self.channels or self.file):
            raise ValueError("'channels' and 'file' describe a nidaqmx device; the simulated stand has neither")
        return self

    @property
    def settle_mode(self) -> str:
        """The stand's way to a steady speed: the simulated one is steady at once; real hardware
        waits on the tacho unless the plan says otherwise."""
        return self.settle or ("none" if self.kind == "sim" else "tacho")


class Calibration(BaseModel):
    model_config = STRICT
    files: list[str] = Field(default_factory=list, max_length=20)


class PointValues(BaseModel):
    """An operating point's values; None = from [defaults], else the paper's experiment."""
    model_config = STRICT
    name: str | None = Field(default=None, min_length=1, max_length=60, pattern=r"^[A-Za-z0-9][A-Za-z0-9_.+-]*$")
    rpm: float | None = Field(default=None, gt=0, le=MAX_RPM)
    law: str | None = Field(default=None, min_length=1, max_length=40)
    Fu_N: float | None = Field(default=None, ge=0, le=1e4)
    backlash_mm: float | None = Field(default=None, ge=0, le=10)
    jt_factor: float | None = Field(default=None, gt=0, le=100)
    revolutions: float | None = Field(default=None, ge=2, le=10000)
    duration_s: float | None = Field(default=None, gt=0, le=3600)
    seed: int | None = Field(default=None, ge=0, lt=2**32)

    @model_validator(mode="after")
    def _one_length(self):
        if self.revolutions is not None and self.duration_s is not None:
            raise ValueError("give revolutions or duration_s, not both")
        return self


class Grid(BaseModel):
    """Every combination of the listed values (rpm varies fastest)."""
    model_config = STRICT
    rpm: list[float] = Field(default_factory=list, max_length=MAX_POINTS)
    law: list[str] = Field(default_factory=list, max_length=20)
    Fu_N: list[float] = Field(default_factory=list, max_length=100)
    backlash_mm: list[float] = Field(default_factory=list, max_length=100)
    jt_factor: list[float] = Field(default_factory=list, max_length=100)


class Compare(BaseModel):
    model_config = STRICT
    models: list[Literal["rigid", "elastic", "kinematic"]] = Field(default=["rigid", "elastic"], min_length=1)
    omega1: list[Literal["const", "var"]] = Field(default=["const", "var"], min_length=1)
    accuracy: Literal["fast", "standard", "reference"] = "fast"
    revolutions: float = Field(default=1.0, ge=1.0, le=20.0)
    thresholds: str | None = Field(default=None, min_length=1, max_length=4096)
    restitution: float | None = Field(default=None, ge=0, le=1)
    contact_damping: float | None = Field(default=None, ge=0, le=1e4)
    contact_length_mm: float | None = Field(default=None, gt=0, le=100)
    elastic_gap: Literal["physical", "closed"] | None = None

    @model_validator(mode="after")
    def _unique(self):
        if len(set(self.models)) != len(self.models) or len(set(self.omega1)) != len(self.omega1):
            raise ValueError("models and omega1 must not repeat a value")
        return self


class PlanDoc(BaseModel):
    model_config = STRICT
    campaign: CampaignInfo = CampaignInfo()
    test: TestInfo = TestInfo()
    device: Device = Device()
    calibration: Calibration = Calibration()
    defaults: PointValues = PointValues()
    points: list[PointValues] = Field(default_factory=list, max_length=MAX_POINTS)
    grid: Grid | None = None
    compare: Compare = Compare()


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
    doc: PlanDoc
    points: tuple
    calibration_files: tuple     # Path
    thresholds: Path | None
    device_file: Path | None

    def digest(self, part: str) -> str:
        """sha256 of one part of the plan (canonical JSON): how a step knows its inputs changed."""
        data = getattr(self.doc, part).model_dump(mode="json")
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


def expand_points(doc: PlanDoc) -> list[Point]:
    """The plan's points: the [[points]] list, then the [grid]'s combinations, each completed from
    [defaults] and the paper's experiment; InputError for none, too many, or a missing rpm."""
    base = dict(PAPER_POINT)
    base.update({k: v for k, v in doc.defaults.model_dump().items() if v is not None and k not in ("name", "seed")})
    if doc.defaults.duration_s is not None:
        base.pop("revolutions", None)
    if doc.defaults.name is not None or doc.defaults.seed is not None:
        raise InputError("defaults: 'name' and 'seed' belong to a point, not to [defaults]")
    raw = [p.model_dump() for p in doc.points]
    if doc.grid is not None:
        g = doc.grid.model_dump()
        axes = {k: v for k, v in g.items() if v}
        if axes:
            n = math.prod(len(v) for v in axes.values())
            if n + len(raw) > MAX_POINTS:
                raise InputError(f"the plan has {n + len(raw)} points; at most {MAX_POINTS} per campaign")
            keys = list(axes)[::-1]   # the first key (rpm) varies fastest
            for combo in itertools.product(*(axes[k] for k in keys)):
                raw.append(dict(zip(keys, combo)))
    if not raw:
        raise InputError("the plan has no operating points: add [[points]] with an rpm, or a [grid]")
    if len(raw) > MAX_POINTS:
        raise InputError(f"the plan has {len(raw)} points; at most {MAX_POINTS} per campaign")
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
    doc = validate(read_toml(path, "plan"), PlanDoc, str(path))
    points = expand_points(doc)
    from models.mechanism.motion_laws import ALIASES, LAWS
    for p in points:
        if p.law not in LAWS and p.law not in ALIASES:
            raise InputError(f"{shown(path)}: point {p.name}: unknown motion law {shown(p.law)!r}; known: {', '.join(sorted(LAWS))}")
    if not check_files:
        return Plan(path, doc, tuple(points), (), None, None)
    base = path.resolve().parent
    cals = tuple(_resolve(base, f, "calibration file") for f in doc.calibration.files)
    th = _resolve(base, doc.compare.thresholds, "thresholds file") if doc.compare.thresholds else None
    dev = _resolve(base, doc.device.file, "device file") if doc.device.file else None
    return Plan(path, doc, tuple(points), cals, th, dev)
