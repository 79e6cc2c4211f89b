"""The three-phase asynchronous motor's linear characteristic, eq. (3), reduced to the cam."""
from __future__ import annotations

import numpy as np

from labtool.models.mechanism import Mechanism


def transmission_ratio(mech: Mechanism, omega1_nominal: float) -> float:
    """Motor-to-cam ratio it = omega_m / omega_1 (>0) for a nominal cam speed (rad/s).

    Assumption (docs/mechanism.md, "cam speed"): the speed variator maps the motor's nominal speed
    to the nominal cam speed, it = omega_nominal_motor / omega1_nominal (the loom's rating). Under the
    light load of this mechanism the motor runs close to synchronous, so with omega1 variable the
    cam turns up to omega_sync/omega_nominal = 1.087 times faster than nominal; the paper's
    Tables 2-3 carry exactly that factor (MR13D is 1.18 = 1.087^2 times the kinematic value at n1).
    """
    return mech.omega_nominal_motor / omega1_nominal


def no_load_cam_speed(mech: Mechanism, omega1_nominal: float) -> float:
    """Cam speed (rad/s) the omega1-variable drive settles at with no mean load:
    omega1_nominal * omega_sync / omega_nominal."""
    return omega1_nominal * mech.omega_sync_motor / mech.omega_nominal_motor


def motor_moment_on_cam(mech: Mechanism, omega1, it: float):
    """Driving moment on the camshaft M1(omega1) in N*m, eq. (3): it * Mn * (omega1*it - ws)/(wn - ws)."""
    ws, wn = mech.omega_sync_motor, mech.omega_nominal_motor
    return it * mech.M_nominal_motor * (np.asarray(omega1) * it - ws) / (wn - ws)


def motor_slope_on_cam(mech: Mechanism, it: float) -> float:
    """-dM1/domega1 in N*m*s/rad (positive: the motor's torque falls as the cam speeds up)."""
    ws, wn = mech.omega_sync_motor, mech.omega_nominal_motor
    return it**2 * mech.M_nominal_motor / (ws - wn)


def cam_inertia(mech: Mechanism, it: float) -> float:
    """Inertia of cam + motor reduced to the cam (kg*m^2), eq. (5) with a rigid drive."""
    return mech.J1 + mech.m1 * mech.AK1**2 + mech.Jm * it**2
