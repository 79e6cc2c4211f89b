"""Kinematic analysis over the cam angle, with the cam as input (omega1 constant).

Produces an xarray Dataset over ``phi1`` (rad): the follower's phi2, omega2, epsilon2; positions,
velocities and accelerations of C, E, N and links 4, 5; the accelerations an ideal sensor at E
reads (aE_t, aE_n); the inertia reduced to the follower and to the cam; the pressure angle; and the
kinetostatic moment MR13D about D of the cam-on-follower reaction, for a load Fu and an inertia
factor Jt (sec. 2.1.1, 2.2).

Sign conventions (docs/architecture.md): psi, omega2, epsilon2 and MR13D are positive in the rise direction
(counter-clockwise); aE_t positive along increasing psi; aE_n positive towards D.
"""
from __future__ import annotations

import math

import numpy as np
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # loaded where a Dataset is built (a sweep's indicator path needs none)
    import xarray as xr

from labtool.models.mechanism.cam_profile import contact_geometry
from labtool.common.datasets import dataset
from labtool.common.errors import InputError
from labtool.common.units import rpm_to_rad_s
from labtool.models.mechanism.linkage import linkage_state, reduced_follower
from labtool.models.mechanism import Mechanism, sensor_point
from labtool.models.mechanism.motion_laws import CamProgram
from labtool.models.mechanism.motor import cam_inertia, transmission_ratio


def load_force_x(mech: Mechanism, program: CamProgram, phi1, phi2, Fu: float):
    """x component (N) of the load Fu at N: magnitude Fu, opposing the rod's sliding in block 5.

    The sliding direction follows the follower's nominal direction (rise +1, return -1), so the
    load is defined at the ends of the rise where omega2 = 0, and zero in the dwells.
    """
    unit = linkage_state(mech, phi2, 1.0, 0.0)
    ux = np.cos(unit.phi4)
    # the rod slides relative to the block with velocity -s' u; the load opposes its x component
    return Fu * np.sign(unit.ds * ux) * program.direction(phi1)


def follower_motion(program: CamProgram, mech: Mechanism, phi1, omega1: float, epsilon1: float = 0.0):
    """phi2 (rad, absolute), omega2 (rad/s), epsilon2 (rad/s^2), psi (rad) for cam angles phi1."""
    psi, dpsi, ddpsi, _ = program(phi1)
    phi2 = mech.phiD + mech.psi0 + psi
    return phi2, dpsi * omega1, ddpsi * omega1**2 + dpsi * epsilon1, psi


def kinetostatic_moment(mech, phi2, omega2, epsilon2, load_x, jt_factor=1.0):
    """MR13D (N*m): moment about D of the cam-on-follower reaction that drives elements 2-5.

    Lagrange's equation of the follower-side system: MR13D = J'' eps2 + 1/2 dJ''/dphi2 omega2^2
    - M_gravity - M_load.
    """
    red = reduced_follower(mech, phi2, load_x, jt_factor)
    return red.J * epsilon2 + 0.5 * red.dJ * omega2**2 - red.M_gravity - red.M_load, red


def analyze(mech: Mechanism | None = None, program: CamProgram | None = None, rpm: float = 180.0,
            Fu: float = 0.0, jt_factor: float = 1.0, n_points: int = 1441,
            cam_sense: int | None = None, phi1=None) -> xr.Dataset:
    """Kinematics of one cam revolution at constant cam speed ``rpm``.

    Fu in N (magnitude, >= 0), jt_factor dimensionless (> 0). ``phi1`` overrides the grid (rad).
    """
    mech = mech or Mechanism.default()
    program = program or CamProgram.for_mechanism(mech)
    _check(rpm, Fu, jt_factor, n_points)
    omega1 = rpm_to_rad_s(rpm)
    if phi1 is None:
        phi1 = np.linspace(0.0, 2.0 * math.pi, n_points)
    phi1 = np.asarray(phi1, dtype=float)
    phi2, omega2, epsilon2, psi = follower_motion(program, mech, phi1, omega1)
    st = linkage_state(mech, phi2, omega2, epsilon2)
    load_x = load_force_x(mech, program, phi1, phi2, Fu)
    MR13D, red = kinetostatic_moment(mech, phi2, omega2, epsilon2, load_x, jt_factor)
    _, dpsi, _, _ = program(phi1)
    it = transmission_ratio(mech, omega1)
    J_cam = cam_inertia(mech, it) + red.J * dpsi**2
    geo = contact_geometry(mech, program, phi1, sense=cam_sense)

    def var(data, units, long_name, dims=("phi1",)):
        return (dims, np.asarray(data, dtype=float), {"units": units, "long_name": long_name})

    aE_t, aE_n = sensor_point.acceleration_at_E(mech.DE, omega2, epsilon2)
    data = {
        "time": var(phi1 / omega1, "s", "time at constant cam speed"),
        "psi": var(psi, "rad", "follower stroke from the start of the rise"),
        "phi2": var(phi2, "rad", "follower angle of DC from the x axis"),
        "omega2": var(omega2, "rad/s", "follower angular velocity"),
        "epsilon2": var(epsilon2, "rad/s^2", "follower angular acceleration"),
        "aE_t": var(aE_t, "m/s^2", "tangential acceleration of E (ideal sensor)"),
        "aE_n": var(aE_n, "m/s^2", "normal acceleration of E, towards D (ideal sensor)"),
        "phi4": var(st.phi4, "rad", "rod 4 angle from the x axis"),
        "omega4": var(st.omega4, "rad/s", "rod 4 angular velocity"),
        "epsilon4": var(st.epsilon4, "rad/s^2", "rod 4 angular acceleration"),
        "s_EF": var(st.s, "m", "distance from E to F along the rod (slide position)"),
        "v_slide": var(st.ds, "m/s", "rate of change of |EF| (sliding of rod 4 in block 5)"),
        "J_red_follower": var(red.J, "kg m^2", "inertia of elements 2-5 reduced to the follower (J''red)"),
        "dJ_red_follower": var(red.dJ, "kg m^2/rad", "dJ''red/dphi2"),
        "J_red_cam": var(J_cam, "kg m^2", "inertia reduced to the cam (Jred, eq. 2), motor included"),
        "M_gravity": var(red.M_gravity, "N m", "moment of gravity on elements 2-5 about D"),
        "M_load": var(red.M_load, "N m", "moment of the load Fu about D"),
        "MR13D": var(MR13D, "N m", "moment about D of the cam-on-follower reaction (kinetostatic)"),
        "pressure_angle": var(geo["pressure_angle"], "rad", "pressure angle"),
        "Db1": var(geo["Db1"], "m", "diameter of the circle about A tangent to the contact normal"),
        "Db2": var(geo["Db2"], "m", "diameter of the circle about D tangent to the contact normal"),
        "rho_pitch": var(geo["rho_pitch"], "m", "radius of curvature of the pitch curve (signed)"),
        "rho_inner": var(geo["rho_inner"], "m", "radius of curvature of the inner flank (signed)"),
        "rho_outer": var(geo["rho_outer"], "m", "radius of curvature of the outer flank (signed)"),
        "load_x": var(load_x, "N", "x component of the load at N"),
    }
    for name, pts in [("C", (st.C, st.vC, st.aC)), ("E", (st.E, st.vE, st.aE)), ("N", (st.N, st.vN, st.aN)),
                      ("K4", (st.K4, st.vK4, st.aK4)), ("K5", (st.K5, st.vK5, st.aK5))]:
        for kind, arr, unit in zip(("", "v", "a"), pts, ("m", "m/s", "m/s^2")):
            for k, axis in enumerate("xy"):
                data[f"{kind}{name}_{axis}"] = var(arr[k], unit, f"{axis} of {'position' if not kind else ('velocity' if kind == 'v' else 'acceleration')} of {name}")
    # one construction: adding 30 variables one by one re-aligns the Dataset each time (45 ms)
    ds = dataset(data, coords={"phi1": ("phi1", phi1, {"units": "rad", "long_name": "cam angle from the start of the rise"})})
    ds.attrs.update({
        "title": "labtool kinematic analysis (cam as input, omega1 constant)",
        "mechanism": mech.name,
        "law": program.segments[0].law.name,
        "cam_speed_rpm": float(rpm),
        "omega1_rad_s": omega1,
        "Fu_N": float(Fu),
        "jt_factor": float(jt_factor),
        "rise_deg": math.degrees(program.rise_angle),
        "stroke_deg": math.degrees(program.stroke),
        "cam_sense": int(geo["sense"]),
        "transmission_ratio": it,
    })
    return ds


def rise_summary(ds: xr.Dataset) -> dict:
    """Indicators over the rise (0 <= phi1 <= rise): MR13D max/min (N*m) and whether it changes sign."""
    rise = math.radians(ds.attrs["rise_deg"])
    # the rise is [0, rise): at phi1 = rise the dwell (no load, no motion) begins
    phi1 = ds["phi1"].values
    on = (phi1 >= 0.0) & (phi1 < rise)
    # the four arrays only: selecting on the whole Dataset (55 variables) costs 4 ms
    mr, om, ep, pa = (ds[k].values[on] for k in ("MR13D", "omega2", "epsilon2", "pressure_angle"))
    return {
        "MR13D_max_Nm": float(mr.max()),
        "MR13D_min_Nm": float(mr.min()),
        "sign_change": bool(mr.max() > 0 > mr.min()),
        "omega2_max_rad_s": float(np.abs(om).max()),
        "epsilon2_max_rad_s2": float(np.abs(ep).max()),
        "pressure_angle_max_deg": float(np.degrees(np.abs(pa).max())),
    }


# Bounds of the load and the inertia factor: far past anything the STB-216's follower bears (the
# paper's levels: 0-65 N, x1-x4), well inside what a float holds through MR13D and the models'
# energies. Past them kinematics overflowed to inf (simulate printed null, report crashed drawing
# it) and the simulated stand's twin ran for ever.
MAX_LOAD_N = 1e6
MAX_JT_FACTOR = 1e6


def check_load_and_inertia(Fu: float, jt_factor: float) -> None:
    """InputError unless Fu (N) <= MAX_LOAD_N and jt_factor (-) <= MAX_JT_FACTOR (the lower
    bounds, Fu >= 0 and jt_factor > 0, are each caller's own check)."""
    if Fu > MAX_LOAD_N:
        raise InputError(f"load Fu = {Fu:g} N is past what the models take (at most {MAX_LOAD_N:g} N; "
                         "the paper's levels are 0 and 65 N)")
    if jt_factor > MAX_JT_FACTOR:
        raise InputError(f"inertia factor Jt = x{jt_factor:g} is past what the models take (at most "
                         f"x{MAX_JT_FACTOR:g} of the nominal inertia; the paper's levels are x1 and x4)")


def _check(rpm, Fu, jt_factor, n_points):
    if not (math.isfinite(rpm) and rpm > 0):
        raise InputError(f"cam speed must be a positive number of rpm, got {rpm}")
    if not (math.isfinite(Fu) and Fu >= 0):
        raise InputError(f"load Fu must be a finite force >= 0 N, got {Fu}")
    if not (math.isfinite(jt_factor) and jt_factor > 0):
        raise InputError(f"inertia factor Jt must be > 0, got {jt_factor}")
    check_load_and_inertia(Fu, jt_factor)
    if n_points < 16:
        raise InputError("at least 16 points per revolution are needed")
