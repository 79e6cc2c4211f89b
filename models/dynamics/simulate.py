"""One entry point for every model level: ``simulate(scene, model) -> SimulationResult``.

Levels (DESIGN.md, fidelity ladder): ``kinematic`` (cam as input), ``rigid`` (eqs 1-11),
``elastic`` (eqs 12-19). Each level module exposes ``simulate(scene) -> SimulationResult``; they are
imported lazily so that a run loads only what its scene needs.
"""
from __future__ import annotations

import dataclasses
import importlib
import math
import time

import numpy as np
import xarray as xr

from common.errors import InputError
from models.dynamics.scene import Scene

# indicator keys of the paper's Tables 2 and 3 (DESIGN.md, --json contract)
INDICATORS = (
    "MR13D_max_Nm", "MR13D_min_Nm", "dphi2_max_deg", "domega2_max_rad_s", "domega1_max_rad_s",
    "percussion_max_Ns", "jumps", "impacts", "xel_max_mm", "xel_min_mm",
)

LEVELS = {
    "kinematic": "models.dynamics.simulate:_kinematic",
    "rigid": "models.dynamics.rigid:simulate",
    "elastic": "models.dynamics.elastic:simulate",
}


@dataclasses.dataclass
class SimulationResult:
    """Time series (xarray, SI, units on every variable) and the paper's indicators."""

    dataset: xr.Dataset
    indicators: dict
    model: str
    reason: str = ""
    wall_s: float = 0.0

    def summary(self) -> dict:
        out = {k: self.indicators.get(k) for k in INDICATORS}
        out.update(model=self.model, reason=self.reason, wall_s=self.wall_s)
        return out


def _resolve(level: str):
    try:
        target = LEVELS[level]
    except KeyError:
        raise InputError(f"unknown model '{level}'; known: auto, {', '.join(LEVELS)}") from None
    module, func = target.split(":")
    return getattr(importlib.import_module(module), func)


def simulate(scene: Scene, model: str = "auto") -> SimulationResult:
    """Run ``model`` (or the cheapest level the scene needs, for ``auto``) on ``scene``."""
    t0 = time.perf_counter()
    reason = f"requested --model {model}"
    if model == "auto":
        # models.dynamics.auto climbs the ladder (and escalates in time) itself; it sets model and reason
        from models.dynamics.auto import simulate_auto
        result = simulate_auto(scene)
        model, reason = result.model, result.reason
    else:
        result = _resolve(model)(scene)
    result.model = model
    result.reason = reason
    result.wall_s = time.perf_counter() - t0
    result.dataset.attrs.update(model=model, model_reason=reason, accuracy=scene.accuracy)
    return result


def _kinematic(scene: Scene) -> SimulationResult:
    """The kinematic level: cam as input at constant speed; MR13D kinetostatic."""
    from models.mechanism.kinematics import analyze, rise_summary
    omega1 = scene.omega1_nominal
    if scene.omega1_mode == "var":
        from models.mechanism.motor import no_load_cam_speed
        omega1 = no_load_cam_speed(scene.mechanism, omega1)
    rpm = omega1 * 30.0 / math.pi
    ds = analyze(scene.mechanism, scene.program, rpm, scene.Fu, scene.jt_factor)
    s = rise_summary(ds)
    ind = {k: None for k in INDICATORS}
    ind.update(MR13D_max_Nm=s["MR13D_max_Nm"], MR13D_min_Nm=s["MR13D_min_Nm"])
    ind["sign_change"] = s["sign_change"]
    return SimulationResult(ds, ind, "kinematic")
