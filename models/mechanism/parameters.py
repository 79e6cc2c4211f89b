"""The mechanism as data: parameters of the paper's sec. 2 and 2.2 in SI, loaded from TOML.

``Mechanism.default()`` is the paper's STB-216 yarn-catcher drive (``models/data/stb216.toml``);
``Mechanism.from_toml(path)`` loads a user's file with the same keys. Keys carry their unit
(``_mm``, ``_deg``, ``_kg``, ``_kgm2``, ``_rpm``, ``_W``); values are converted to SI once, here.
"""
from __future__ import annotations

import dataclasses
import functools
import hashlib
import math
from importlib import resources
from pathlib import Path

import numpy as np

from labtool.common.errors import InputError
from labtool.common.names import shown
from labtool.common.schema import Number, String, Table, parse_toml, read_toml_bytes
from labtool.common.units import DEG, MM, RPM

_UNIT_SCALE = {"_mm": MM, "_deg": DEG, "_rpm": RPM}

# (section, key in file, attribute, may be zero, may be negative)
_FIELDS = [
    ("frame", "xD_mm", "xD", True, True),
    ("frame", "yD_mm", "yD", True, True),
    ("frame", "xG_mm", "xG", True, True),
    ("frame", "yG_mm", "yG", True, True),
    ("frame", "phiD_deg", "phiD", True, True),
    ("frame", "g_m_s2", "g", True, False),
    ("cam", "m1_kg", "m1", False, False),
    ("cam", "J1_kgm2", "J1", False, False),
    ("cam", "AK1_mm", "AK1", True, False),
    ("cam", "theta10_deg", "theta10", True, True),
    ("follower", "l_DC_mm", "l", False, False),
    ("follower", "DE_mm", "DE", False, False),
    ("follower", "m2_kg", "m2", False, False),
    ("follower", "J2_kgm2", "J2", False, False),
    ("follower", "DK2_mm", "DK2", True, False),
    ("follower", "theta20_deg", "theta20", True, True),
    ("follower", "psi0_deg", "psi0", False, False),
    ("follower", "psi_a_deg", "psi_a", False, True),
    ("roller", "R_mm", "R", False, False),
    ("roller", "m3_kg", "m3", True, False),
    ("rod", "EH_mm", "EH", False, False),
    ("rod", "m4_kg", "m4", True, False),
    ("rod", "J4_kgm2", "J4", True, False),
    ("rod", "EK4_mm", "EK4", True, False),
    ("rod", "theta40_deg", "theta40", True, True),
    ("rod", "EN_mm", "EN", True, False),
    ("rod", "thetaN_deg", "thetaN", True, True),
    ("slide_block", "FG_mm", "FG", True, True),
    ("slide_block", "m5_kg", "m5", True, False),
    ("slide_block", "J5_kgm2", "J5", True, False),
    ("slide_block", "GK5_mm", "GK5", True, False),
    ("slide_block", "theta50_deg", "theta50", True, True),
    ("motor", "Pn_W", "Pn", False, False),
    ("motor", "n_sync_rpm", "omega_sync_motor", False, False),
    ("motor", "n_nominal_rpm", "omega_nominal_motor", False, False),
    ("motor", "Jm_kgm2", "Jm", True, False),
]


# Plausible bounds of a cam mechanism on a test stand, by unit (a value outside is a typo or a
# unit mix-up, e.g. 1e300 or metres given as mm); the linkage's own geometry is checked by validate()
_BOUNDS = {"_mm": 1e4, "_deg": 720.0, "_kg": 1e3, "_kgm2": 1e3, "_m_s2": 100.0, "_W": 1e7, "_rpm": 1e5}
_UNITS = {"_mm": "mm", "_deg": "deg", "_kg": "kg", "_kgm2": "kg m^2", "_m_s2": "m/s^2", "_W": "W", "_rpm": "rpm"}


def _number(key: str, zero_ok: bool, negative_ok: bool, **kw) -> Number:
    suffix = next(s for s in _BOUNDS if key.endswith(s))
    bound = _BOUNDS[suffix]
    if negative_ok:
        return Number(ge=-bound, le=bound, nonzero=not zero_ok, unit=_UNITS[suffix], **kw)
    return Number(**({"ge": 0.0} if zero_ok else {"gt": 0.0}), le=bound, unit=_UNITS[suffix], **kw)


def _schema() -> Table:
    """The mechanism file's schema: the parameters of _FIELDS (required) and the optional extras."""
    sections: dict = {}
    for section, key, _attr, zero_ok, negative_ok in _FIELDS:
        sections.setdefault(section, {})[key] = _number(key, zero_ok, negative_ok)
    sections["cam"].update(diameter_mm=_number("diameter_mm", False, False, default=120.0),
                           rr_min_mm=_number("rr_min_mm", False, False, required=False),
                           rr_max_mm=_number("rr_max_mm", False, False, required=False))
    program = Table({"law": String(required=False),
                     **{k: _number(k, True, False, required=False)
                        for k in ("rise_deg", "upper_dwell_deg", "return_deg", "lower_dwell_deg")}},
                    default={})
    return Table({"name": String(required=False, max_len=200), "program": program,
                  **{name: Table(fields) for name, fields in sections.items()}})


SCHEMA = _schema()


@dataclasses.dataclass(frozen=True)
class Mechanism:
    """Parameters of the cam-follower linkage in SI units (m, rad, kg, kg*m^2, W, rad/s).

    Geometry (docs/mechanism.md): origin at the cam axis A, y up. The follower (2) pivots at D;
    the roller centre C and the rod joint E lie on one line from D, at angle
    ``phi2 = phiD + psi0 + psi`` from the x axis (psi the follower stroke, rise positive,
    counter-clockwise). Rod 4 is pinned at E and slides through block 5 pivoted at G; its axis
    passes at the signed distance ``FG`` from G (positive: G on the left of the rod axis E->H).
    """

    name: str
    xD: float
    yD: float
    xG: float
    yG: float
    phiD: float
    g: float
    m1: float
    J1: float
    AK1: float
    theta10: float
    l: float
    DE: float
    m2: float
    J2: float
    DK2: float
    theta20: float
    psi0: float
    psi_a: float
    R: float
    m3: float
    EH: float
    m4: float
    J4: float
    EK4: float
    theta40: float
    EN: float
    thetaN: float
    FG: float
    m5: float
    J5: float
    GK5: float
    theta50: float
    Pn: float
    omega_sync_motor: float
    omega_nominal_motor: float
    Jm: float
    cam_diameter: float = 0.120
    rr_min: float | None = None
    rr_max: float | None = None
    program: dict = dataclasses.field(default_factory=dict)
    source: str = "built-in"
    source_sha256: str = ""          # of the TOML text the parameters were read from

    # --- derived -------------------------------------------------------------
    @functools.cached_property
    def cache_key(self) -> str:
        """Every parameter as text: the key of the per-process tables (labtool.models.mechanism.memo) that
        depend on the mechanism (a dataclass with a dict field is not hashable; its repr is, and
        costs 80 us, so it is made once)."""
        return repr(self)

    @property
    def d(self) -> float:
        """Centre distance |AD| in m."""
        return math.hypot(self.xD, self.yD)

    @property
    def D(self) -> np.ndarray:
        return np.array([self.xD, self.yD])

    @property
    def G(self) -> np.ndarray:
        return np.array([self.xG, self.yG])

    @property
    def M_nominal_motor(self) -> float:
        """Nominal motor torque Pn / omega_n in N*m."""
        return self.Pn / self.omega_nominal_motor

    MAX_TRANSMISSION_RATIO = 1000.0      # motor-to-cam speed ratio of any real drive train

    @property
    def max_cam_speed_rpm(self) -> float:
        """The fastest cam speed the models take (rpm): the drive motor's synchronous speed."""
        return self.omega_sync_motor * 30.0 / math.pi

    @property
    def min_cam_speed_rpm(self) -> float:
        """The slowest cam speed the models take (rpm): the motor's nominal speed over a drive
        ratio of MAX_TRANSMISSION_RATIO (eq. 3 scales the motor by the ratio squared: at 1e-266
        rpm it overflowed)."""
        return self.omega_nominal_motor * 30.0 / math.pi / self.MAX_TRANSMISSION_RATIO

    def check_cam_speed(self, rpm: float) -> float:
        """``rpm`` if min_cam_speed_rpm <= rpm <= max_cam_speed_rpm, else InputError stating the
        range. One range for every command (simulate, kinematics, doe, report, the simulated stand):
        the motor cannot drive the cam past its synchronous speed (past it MR13D grows as n1^2 to
        nonsense), nor through a drive ratio above 1000."""
        lo, top = self.min_cam_speed_rpm, self.max_cam_speed_rpm
        if not (math.isfinite(rpm) and lo * (1 - 1e-12) <= rpm <= top * (1 + 1e-12)):    # rpm -> rad/s -> rpm
            raise InputError(f"cam speed {rpm:.10g} rpm is outside the range the models take: {lo:.4g} <= n1 <= "
                             f"{top:.10g} rpm (the drive motor's synchronous speed, [motor] n_sync_rpm, and its "
                             "nominal speed over a drive ratio of 1000)")
        return rpm

    def replace(self, **changes) -> "Mechanism":
        """A copy with some parameters changed (SI values), validated again."""
        new = dataclasses.replace(self, **changes)
        new.validate()
        return new

    # --- loading -------------------------------------------------------------
    @classmethod
    def default(cls) -> "Mechanism":
        """The paper's mechanism (sec. 2, 2.2)."""
        text = resources.files("labtool.models.data").joinpath("stb216.toml").read_text()
        return cls.from_toml_text(text, source="built-in STB-216 (models/data/stb216.toml)")

    @classmethod
    def from_toml(cls, path: str | Path) -> "Mechanism":
        """A user's mechanism file (labtool.common.schema: types, bounds and unknown keys checked)."""
        raw = read_toml_bytes(path, what="mechanism file")      # read once: what is parsed is what is hashed
        doc = parse_toml(raw, f"mechanism file {shown(Path(path))}")
        return cls.from_dict(doc, source=str(path), sha256=hashlib.sha256(raw).hexdigest())

    @classmethod
    def from_toml_text(cls, text: str, source: str = "<text>") -> "Mechanism":
        return cls.from_dict(parse_toml(text, f"mechanism file {source}"), source=source,
                             sha256=hashlib.sha256(text.encode("utf-8")).hexdigest())

    @classmethod
    def from_dict(cls, data: dict, source: str = "<dict>", sha256: str = "") -> "Mechanism":
        """From a parsed mechanism document; InputError names the file and the key at fault.
        ``sha256``: of the text it was parsed from (provenance), empty if none."""
        doc = SCHEMA.check(data, where=f"mechanism file {source}")
        values: dict = {}
        def si(section, key, scale):
            value = doc[section][key] * scale
            if value == 0 and doc[section][key] != 0:   # 5e-324 mm is 0 m: refused, not read as zero
                raise InputError(f"mechanism file {source}: [{section}] {key} = {doc[section][key]!r} is too "
                                 "small to be represented in SI units")
            return value

        for section, key, attr, _zero_ok, _negative_ok in _FIELDS:
            scale = next((s for suffix, s in _UNIT_SCALE.items() if key.endswith(suffix)), 1.0)
            values[attr] = si(section, key, scale)
        cam = doc["cam"]
        values["cam_diameter"] = si("cam", "diameter_mm", MM)
        values["rr_min"] = si("cam", "rr_min_mm", MM) if "rr_min_mm" in cam else None
        values["rr_max"] = si("cam", "rr_max_mm", MM) if "rr_max_mm" in cam else None
        values["program"] = dict(doc["program"])
        mech = cls(name=doc.get("name", source), source=source, source_sha256=sha256, **values)
        mech.validate()
        return mech

    def validate(self) -> None:
        """Raise InputError when the linkage cannot be assembled over the follower's stroke."""
        if self.omega_nominal_motor >= self.omega_sync_motor:
            raise InputError(
                "motor: nominal speed must be below the synchronous speed (asynchronous motor slip > 0)"
            )
        if self.psi0 + self.psi_a >= math.pi or self.psi0 <= 0:
            raise InputError("follower: psi0 + psi_a must lie in (0, 180) degrees")
        psi = np.linspace(self.psi0, self.psi0 + max(self.psi_a, 0.0), 64)
        phi2 = self.phiD + psi
        C = self.D[:, None] + self.l * np.vstack([np.cos(phi2), np.sin(phi2)])
        AC = np.hypot(C[0], C[1])
        if np.any(AC <= self.R):
            raise InputError(
                f"impossible geometry: the roller (R = {self.R*1e3:.3g} mm) covers the cam axis; "
                f"|AC| min = {AC.min()*1e3:.3g} mm"
            )
        E = self.D[:, None] + self.DE * np.vstack([np.cos(phi2), np.sin(phi2)])
        EG = np.hypot(self.xG - E[0], self.yG - E[1])
        if np.any(EG <= abs(self.FG)):
            raise InputError(
                f"impossible geometry: the rod cannot close through the slide block at G "
                f"(|EG| = {EG.min()*1e3:.4g} mm <= offset FG = {abs(self.FG)*1e3:.4g} mm)"
            )
