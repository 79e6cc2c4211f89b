"""One model run as the report compares it: simulated at an operating point over whole
revolutions, resampled, filtered and conditioned like the measurement (labtool.reports.align),
and seen through the measuring chain when the point carries an identified Ka gain or delay.

Used by the report (labtool.reports.pipeline), the identification (labtool fit) and the search for
the speed that tells models apart (labtool.reports.discrimination).
"""
from __future__ import annotations

import dataclasses
import math
import time

import xarray as xr

from labtool.common.operating_point import OperatingPoint, from_attrs
from labtool.common.units import RPM
from labtool.reports import align

SIGNALS = ("omega2", "epsilon2")


@dataclasses.dataclass
class SimRun:
    requested: str            # model asked for (rigid, elastic, kinematic)
    model: str                # level that ran
    omega1: str               # const | var
    dataset: xr.Dataset
    indicators: dict
    cycle: align.SimulatedCycles | align.SimulatedCycle
    wall_s: float
    note: str = ""
    revolutions: float = 1.0  # cam revolutions simulated
    warning: str = ""         # what the reader must know (a stand-in level, a partial revolution)
    accuracy: str = "standard"
    events: dict | None = None   # predicted event statistics (labtool.reports.events.predicted)
    op: dict | None = None       # its own operating point (an identified model's); None = the report's

    @property
    def steady(self) -> range:
        """Indices of the simulated revolutions the model's cycle is made of (and its event statistics)."""
        if not isinstance(self.cycle, align.SimulatedCycles):
            return range(0, 1)
        k = self.cycle.revolutions[SIGNALS[0]].shape[0]
        return range(k - self.cycle.n_used, k)

    @property
    def label(self) -> str:
        name = self.requested if self.model == self.requested or self.op is not None else f"{self.requested} (ran {self.model})"
        return f"{name}, w1 = {'ct.' if self.omega1 == 'const' else 'var.'}"


def no_load_factor() -> float:
    """No-load over nominal cam speed of the models' drive with omega1 variable (n_sync / n_nominal)."""
    from labtool.models.mechanism import Mechanism
    m = Mechanism.default()
    return m.omega_sync_motor / m.omega_nominal_motor


def max_cam_speed_rpm() -> float:
    """The fastest cam speed the models take (rpm): the drive motor's synchronous speed."""
    from labtool.models.mechanism import Mechanism
    return Mechanism.default().max_cam_speed_rpm


def point_of(op: dict) -> OperatingPoint:
    """The OperatingPoint of a report's operating-point dict (``operating_point``'s)."""
    return from_attrs(op, where="the report's operating point")


def model_scene(op: dict, mode: str, accuracy: str, revolutions: float):
    """The models' Scene for the operating point ``op`` (``operating_point``'s dict) over whole
    revolutions; with omega1 var the drive's nominal n1 is ``omega1_var_n1_rpm`` (its no-load speed
    is the op's)."""
    from labtool.models.dynamics.scene import Scene
    rpm = op["cam_speed_rpm"] if mode == "const" else op.get("omega1_var_n1_rpm", op["cam_speed_rpm"])
    return Scene.at(point_of(op), cam_speed=rpm * RPM, omega1_mode=mode, accuracy=accuracy,
                    revolutions=revolutions, rise_only=False)


def run_simulation(op: dict, requested: str, mode: str, accuracy: str, revolutions: float,
                   cond: align.Conditioning, time_filter: align.TimeFilter | None = None) -> SimRun:
    """One model at one omega1 mode over ``revolutions`` whole revolutions, conditioned like the
    measurement (align.simulated_cycles): its steady cycle, periodic or as statistics."""
    from labtool.models.dynamics.simulate import simulate

    t0 = time.perf_counter()
    res = simulate(model_scene(op, mode, accuracy, revolutions), requested)
    # the rigid model's impacts are velocity jumps: its epsilon2 omits their impulses
    cycle = align.simulated_cycles(res.dataset, SIGNALS, cond, epsilon2_from_omega2=res.model == "rigid",
                                   time_filter=time_filter)
    if cycle is None:    # the kinematic level (one revolution on phi1) or a partial revolution
        cycle = align.simulated_cycle(res.dataset, SIGNALS, cond, epsilon2_from_omega2=res.model == "rigid",
                                      time_filter=time_filter)
    warning = cycle.note if not cycle.covered.all() or not cycle.periodic else ""
    return SimRun(requested, res.model, mode, res.dataset, res.indicators, chain_view(cycle, op),
                  time.perf_counter() - t0, cycle.note, revolutions, warning, accuracy)


CHAIN_KEYS = ("ka_gain", "delay_ms")   # measuring-side parameters of an operating point (labtool fit)


def chain_view(cycle, op: dict):
    """The simulated cycle as the measuring chain shows it when the operating point carries an
    identified Ka gain (true Ka over the one processing used) or delay (ms, channels behind the
    tacho): labtool.reports.align.cycle_as_measured; unchanged without them."""
    gain, delay_ms = float(op.get("ka_gain", 1.0)), float(op.get("delay_ms", 0.0))
    return align.cycle_as_measured(cycle, gain, delay_ms * 1e-3 * op["cam_speed_rpm"] * math.pi / 30.0)
