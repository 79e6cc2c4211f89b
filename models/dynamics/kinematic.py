"""The kinematic level of the fidelity ladder: the cam as input at constant speed, MR13D kinetostatic."""
from __future__ import annotations

from labtool.common.units import rad_s_to_rpm
from labtool.models.dynamics import validity
from labtool.models.dynamics.result import SimulationResult, empty_indicators
from labtool.models.dynamics.scene import Scene
from labtool.models.mechanism.kinematics import analyze, rise_summary
from labtool.models.mechanism.motor import no_load_cam_speed


def cam_speed(scene: Scene) -> float:
    """Cam speed (rad/s) of the kinematic level: n1, or with omega1 'var' the speed the motor
    settles at with no mean load (labtool.models.mechanism.motor.no_load_cam_speed)."""
    if scene.omega1_mode == "var":
        return no_load_cam_speed(scene.mechanism, scene.omega1_nominal)
    return scene.omega1_nominal


def simulate(scene: Scene) -> SimulationResult:
    """Kinematics over one revolution at the cam speed above; MR13D max/min over the rise."""
    warnings = validity.check_scene(scene, refuse=False)
    ds = analyze(scene.mechanism, scene.program, rad_s_to_rpm(cam_speed(scene)), scene.Fu, scene.jt_factor)
    s = rise_summary(ds)
    ind = empty_indicators()
    ind.update(MR13D_max_Nm=s["MR13D_max_Nm"], MR13D_min_Nm=s["MR13D_min_Nm"], sign_change=s["sign_change"])
    ds.attrs["validity_warnings"] = validity.attribute(warnings)
    return SimulationResult(ds, ind, "kinematic", warnings=warnings)
