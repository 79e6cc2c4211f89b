"""A simulation scene: what to simulate and at which operating point (SI inside).

One dataclass shared by every model level (kinematic, rigid, elastic) and by the DOE. The CLI
converts its edge units (rpm, mm) into a Scene once.
"""
from __future__ import annotations

import dataclasses
import functools
import math

from labtool.common.errors import InputError
from labtool.common.units import rpm_to_rad_s
from labtool.models.mechanism import Mechanism
from labtool.models.mechanism.kinematics import check_load_and_inertia
from labtool.models.mechanism.memo import cached
from labtool.models.mechanism.motion_laws import CamProgram, get_law

ACCURACY_PRESETS = ("fast", "standard", "reference")
# how the backlash enters the elastic model (docs/models.md, "the backlash in Table 3"):
# physical = the follower crosses the gap j between the flanks; closed = the flanks touch (j is not
# used by the elastic model), the convention that reproduces the paper's Table 3
ELASTIC_GAPS = ("physical", "closed")


@dataclasses.dataclass(frozen=True)
class Scene:
    """Operating point and model options.

    law            motion law name (labtool.models.mechanism.motion_laws.LAWS)
    cam_speed_rpm  nominal cam speed n1 (rpm; the only non-SI field, as the paper's factor C)
    Fu             load at N (N, >= 0)
    backlash       groove backlash j (m, >= 0)
    jt_factor      inertia factor of elements 2-5 (paper's factor D: 1 or 4)
    omega1_mode    "const" (cam as input) or "var" (motor characteristic, eq. 3)
    restitution    Newton's coefficient k in [0, 1] (rigid model impacts)
    contact_length lw, roller-groove contact length (m) for Kc = 8.05e4 lw^(8/9) (elastic model)
    kc_factor      multiplier of Kc (stability studies)
    contact_damping Hunt-Crossley damping coefficient (s/m); 0 = none, as in the paper
    elastic_gap    how j enters the elastic model: "physical" (the follower crosses the gap) or
                   "closed" (no gap, the convention of the paper's Table 3; docs/models.md)
    accuracy       solver preset: fast | standard | reference
    revolutions    cam revolutions to simulate (the first starts at the start of the rise)
    rise_only      simulate the rise only, as the paper's tables do
    """

    law: str = "sine"
    cam_speed_rpm: float = 180.0
    Fu: float = 0.0
    backlash: float = 0.016e-3
    jt_factor: float = 1.0
    omega1_mode: str = "var"
    restitution: float = 1.0
    contact_length: float = 6e-3     # fitted to Table 3's contact deformations (docs/models.md)
    kc_factor: float = 1.0
    contact_damping: float = 0.0
    elastic_gap: str = "physical"
    accuracy: str = "standard"
    revolutions: float = 1.0
    rise_only: bool = True
    mechanism: Mechanism = dataclasses.field(default_factory=Mechanism.default, repr=False)

    def __post_init__(self):
        get_law(self.law)
        self.mechanism.check_cam_speed(self.cam_speed_rpm)
        checks = [
            (math.isfinite(self.Fu) and self.Fu >= 0, f"load Fu must be >= 0 N, got {self.Fu}"),
            (math.isfinite(self.backlash) and self.backlash >= 0, f"backlash must be >= 0 mm, got {self.backlash * 1e3:g} mm"),
            (math.isfinite(self.jt_factor) and self.jt_factor > 0, f"inertia factor Jt must be > 0, got {self.jt_factor}"),
            (self.omega1_mode in ("const", "var"), f"omega1 mode must be 'const' or 'var', got '{self.omega1_mode}'"),
            (math.isfinite(self.restitution) and 0.0 <= self.restitution <= 1.0, f"restitution k must lie in [0, 1], got {self.restitution}"),
            (math.isfinite(self.contact_length) and self.contact_length > 0, f"contact length lw must be > 0 mm, got {self.contact_length * 1e3:g} mm"),
            (math.isfinite(self.kc_factor) and self.kc_factor > 0, f"contact stiffness factor must be > 0, got {self.kc_factor}"),
            (math.isfinite(self.contact_damping) and self.contact_damping >= 0, f"contact damping must be >= 0, got {self.contact_damping}"),
            (self.elastic_gap in ELASTIC_GAPS, f"elastic gap must be one of {', '.join(ELASTIC_GAPS)}, got '{self.elastic_gap}'"),
            (self.accuracy in ACCURACY_PRESETS, f"accuracy must be one of {', '.join(ACCURACY_PRESETS)}, got '{self.accuracy}'"),
            (math.isfinite(self.revolutions) and self.revolutions > 0, f"revolutions must be > 0, got {self.revolutions}"),
        ]
        for ok, message in checks:
            if not ok:
                raise InputError(message)
        check_load_and_inertia(self.Fu, self.jt_factor)

    @property
    def omega1_nominal(self) -> float:
        """Nominal cam speed in rad/s."""
        return rpm_to_rad_s(self.cam_speed_rpm)

    @functools.cached_property
    def program(self) -> CamProgram:
        """The cam program of the mechanism with the scene's law: one object per mechanism and law
        in a process, so that the per-process tables keyed on it (labtool.models.mechanism.memo) find it by
        identity, without comparing its segments."""
        return cached(("cam_program", self.mechanism.cache_key, self.law),
                      lambda: CamProgram.for_mechanism(self.mechanism, law=self.law))

    def replace(self, **changes) -> "Scene":
        return dataclasses.replace(self, **changes)
