"""A simulation scene: an operating point, the extent of the run and the mechanism (SI inside).

One dataclass shared by every model level (kinematic, rigid, elastic), the simulated stand's model
truths and the DOE. Its operating-point fields, units, defaults and bounds are
:class:`labtool.common.operating_point.OperatingPoint`'s; a Scene adds what to simulate and the
checks that need the mechanism.
"""
from __future__ import annotations

import dataclasses
import functools
import math

from labtool.common.errors import InputError
from labtool.common.operating_point import FIELD, OperatingPoint
from labtool.models.mechanism import Mechanism
from labtool.models.mechanism.kinematics import check_load_and_inertia
from labtool.models.mechanism.memo import cached
from labtool.models.mechanism.motion_laws import CamProgram, get_law

ACCURACY_PRESETS = FIELD["accuracy"].choices
# how the backlash enters the elastic model (docs/models.md, "the backlash in Table 3"):
# physical = the follower crosses the gap j between the flanks; closed = the flanks touch (j is not
# used by the elastic model), the convention that reproduces the paper's Table 3
ELASTIC_GAPS = FIELD["elastic_gap"].choices


@dataclasses.dataclass(frozen=True)
class Scene(OperatingPoint):
    """An operating point and model options (OperatingPoint's fields, SI), and:

    revolutions    cam revolutions to simulate (the first starts at the start of the rise)
    rise_only      simulate the rise only, as the paper's tables do
    mechanism      the mechanism (default: the paper's STB-216)
    """

    revolutions: float = 1.0
    rise_only: bool = True
    mechanism: Mechanism = dataclasses.field(default_factory=Mechanism.default, repr=False)

    def __post_init__(self):
        super().__post_init__()
        if not (isinstance(self.revolutions, (int, float)) and not isinstance(self.revolutions, bool)
                and math.isfinite(self.revolutions) and self.revolutions > 0):
            raise InputError(f"revolutions must be > 0, got {self.revolutions}")
        get_law(self.law)
        self.mechanism.check_cam_speed(self.cam_speed_rpm)
        check_load_and_inertia(self.Fu, self.jt_factor)

    @classmethod
    def at(cls, point: OperatingPoint, **changes) -> "Scene":
        """The scene of ``point`` (its operating-point fields), with ``changes`` (any Scene field:
        ``revolutions``, ``rise_only``, ``mechanism``, or an operating-point field to replace)."""
        return cls(**{**{f.name: getattr(point, f.name) for f in dataclasses.fields(OperatingPoint)}, **changes})

    @functools.cached_property
    def program(self) -> CamProgram:
        """The cam program of the mechanism with the scene's law: one object per mechanism and law
        in a process, so that the per-process tables keyed on it (labtool.models.mechanism.memo) find it by
        identity, without comparing its segments."""
        return cached(("cam_program", self.mechanism.cache_key, self.law),
                      lambda: CamProgram.for_mechanism(self.mechanism, law=self.law))
