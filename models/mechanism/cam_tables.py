"""Speed-independent kinematic terms over the cam angle, computed once per mechanism and program.

With the cam turning at a constant speed omega1 every kinematic quantity the dynamic models need
is a function of the cam angle phi1 times a power of omega1, plus the load Fu and the inertia
factor Jt as scalar multipliers (sec. 2.1.1):

    omega2   = omega1 psi'(phi1)                  epsilon2 = omega1^2 psi''(phi1)
    MR13D    = Jt (J0 epsilon2 + 1/2 dJ0 omega2^2) - M_gravity - Fu m_load
    J''red   = Jt J0

with J0, dJ0 the follower-side inertia reduced to the follower at Jt = 1 (labtool.models.mechanism.linkage), m_load
the moment about D of a unit load (N m per N, its sign opposing the rod's sliding, zero in the
dwells: labtool.models.mechanism.kinematics.load_force_x), and the contact geometry (pressure angle, Db1, Db2:
labtool.models.mechanism.cam_profile) a function of phi1 alone. So the expensive part (the linkage and the cam
geometry, ~0.7 us per angle) is evaluated once on an angle grid and shared by every speed, load
and inertia factor: the 16 runs of Table 1 share one table. ``at_speed`` combines a table with an
operating point in a handful of array operations.

Values agree with labtool.models.mechanism.kinematics (follower_motion, load_force_x, kinetostatic_moment) and
labtool.models.mechanism.cam_profile.contact_geometry to rounding (tests/test_cam_tables.py).

The grids and the stroke spline are memoised per process (labtool.models.mechanism.memo).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from labtool.models.mechanism.cam_profile import cached_sense, contact_geometry
from labtool.models.mechanism.linkage import linkage_state, reduced_follower
from labtool.models.mechanism import Mechanism
from labtool.models.mechanism.memo import cached
from labtool.models.mechanism.motion_laws import CamProgram


@dataclasses.dataclass(frozen=True)
class AngleTerms:
    """Kinematic terms at cam angles ``phi1`` (rad), independent of the cam speed, load and Jt."""

    phi1: np.ndarray        # rad, cam angle from the start of the rise
    psi: np.ndarray         # rad, follower stroke
    dpsi: np.ndarray        # rad/rad, dpsi/dphi1
    ddpsi: np.ndarray       # rad/rad^2
    phi2: np.ndarray        # rad, absolute follower angle
    J0: np.ndarray          # kg m^2, J''red at Jt = 1
    dJ0: np.ndarray         # kg m^2/rad, dJ''red/dphi2 at Jt = 1
    M_gravity: np.ndarray   # N m, moment of gravity on elements 2-5 about D
    m_load: np.ndarray      # N m per N, moment about D of the load per N of Fu (signed)
    alpha: np.ndarray       # rad, pressure angle (None: computed without the contact geometry)
    Db1: np.ndarray         # m (None: without the contact geometry)
    Db2: np.ndarray         # m (None: without the contact geometry)

    def at_speed(self, omega1: float, Fu: float, jt_factor: float) -> dict:
        """The operating point's kinematics at these angles (cam at constant omega1 rad/s, load Fu
        N, inertia factor Jt): dict of arrays omega2 (rad/s), epsilon2 (rad/s^2), MR13D (N m),
        J_follower (kg m^2, J''red with Jt applied)."""
        omega2, epsilon2, MR13D, J = operating_point(self.dpsi, self.ddpsi, self.J0, self.dJ0, self.M_gravity,
                                                     self.m_load, omega1, Fu, jt_factor)
        return dict(omega2=omega2, epsilon2=epsilon2, MR13D=MR13D, J_follower=J)


def operating_point(dpsi, ddpsi, J0, dJ0, M_gravity, m_load, omega1, Fu, jt_factor):
    """The module doc's combination of the terms (arrays, or floats at one angle) with an operating
    point (omega1 rad/s, Fu N, Jt): (omega2 rad/s, epsilon2 rad/s^2, MR13D N m, J''red kg m^2).
    Plain arithmetic only, so that compiled code (labtool.models.dynamics.elastic) runs this same source."""
    omega2 = dpsi * omega1
    epsilon2 = ddpsi * omega1**2
    J = jt_factor * J0
    MR13D = J * epsilon2 + 0.5 * (jt_factor * dJ0) * omega2**2 - M_gravity - Fu * m_load
    return omega2, epsilon2, MR13D, J


def angle_terms(mech: Mechanism, program: CamProgram, phi1, until: float | None = None,
                linkage: str = "exact", geometry: bool = True) -> AngleTerms:
    """The terms at any cam angles ``phi1`` (rad).

    ``until`` (rad): every term is taken at min(phi1, until) (``phi1`` itself is kept), so that a
    run ending at the end of the rise keeps the rise's motion and load at its last instant instead
    of the dwell's (labtool.models.dynamics.elastic).
    ``linkage``: "exact" evaluates the linkage at every angle; "spline" reads J0, dJ0, M_gravity
    and the load's arm from a cubic spline over the follower's stroke (``stroke_spline``: the
    linkage depends on phi2 alone, analytically; 1e-13 relative, 1e-11 for dJ0), 4x cheaper for
    thousands of arbitrary instants. The motion law and the contact geometry are always exact.
    ``geometry=False`` leaves the contact geometry out (alpha, Db1, Db2 None): what the kinetostatic
    moment alone needs (``at_speed``), half the cost (labtool.models.dynamics.elastic's indicator path).
    """
    phi1 = np.asarray(phi1, dtype=float)
    at = phi1 if until is None else np.minimum(phi1, until)
    motion = program(at)
    psi, dpsi, ddpsi, _ = motion
    phi2 = mech.phiD + mech.psi0 + psi
    spline = stroke_spline(mech) if linkage == "spline" else None
    if spline is not None and phi2.size and spline.x[0] <= phi2.min() and phi2.max() <= spline.x[-1]:
        J0, dJ0, M_gravity, vNx, slide = spline(phi2).T
    else:
        J0, dJ0, M_gravity, vNx, slide = linkage_columns(mech, phi2)
    m_load = load_arm(slide, program.direction(at), vNx)
    geo = (contact_geometry(mech, program, at, sense=cached_sense(mech, program), motion=motion) if geometry
           else dict.fromkeys(("pressure_angle", "Db1", "Db2")))
    return AngleTerms(phi1=phi1, psi=psi, dpsi=dpsi, ddpsi=ddpsi, phi2=phi2, J0=J0, dJ0=dJ0,
                      M_gravity=M_gravity, m_load=m_load, alpha=geo["pressure_angle"],
                      Db1=geo["Db1"], Db2=geo["Db2"])


def load_arm(slide, direction, vNx):
    """The moment about D of a unit load (N m per N): labtool.models.mechanism.kinematics.load_force_x per N
    of Fu (its sign opposes the rod's sliding ``slide``, zero in a dwell: ``direction`` +1 rise, -1
    return, 0 dwell) times its arm, the x velocity coefficient of N ``vNx`` (m/rad). Plain
    arithmetic on arrays or floats, so that compiled code (labtool.models.dynamics.elastic) runs it too."""
    return np.sign(slide) * direction * vNx


STROKE_POINTS = 2049    # spline knots over the stroke (+-5 %): h = 1.3e-4 rad


def linkage_columns(mech: Mechanism, phi2):
    """(J0, dJ0, M_gravity, vN_x, ds cos(phi4)) at follower angles phi2 (rad), from one evaluation
    of the unit-velocity linkage: J''red and dJ''red/dphi2 at Jt = 1 (kg m^2, kg m^2/rad), the
    moment of gravity about D (N m), the x velocity coefficient of N (m/rad, the load's arm) and the
    x component of the rod's sliding per unit omega2 (its sign opposes the load,
    labtool.models.mechanism.kinematics.load_force_x)."""
    unit = linkage_state(mech, phi2, 1.0, 0.0)
    red = reduced_follower(mech, phi2, None, 1.0, unit=unit)
    return red.J, red.dJ, red.M_gravity, unit.vN[0], unit.ds * np.cos(unit.phi4)


def stroke_spline(mech: Mechanism):
    """Cubic spline phi2 (rad) -> ``linkage_columns`` over the follower's stroke widened by 5 %
    either side, per mechanism (``scipy.interpolate.CubicSpline``, cached)."""
    from scipy.interpolate import CubicSpline

    def build():
        lo = mech.phiD + mech.psi0 - 0.05 * mech.psi_a
        phi2 = np.linspace(lo, lo + 1.10 * mech.psi_a, STROKE_POINTS)
        return CubicSpline(phi2, np.column_stack(linkage_columns(mech, phi2)))

    return cached(("stroke_spline", mech.cache_key), build)


def grid_terms(mech: Mechanism, program: CamProgram, span: float, n_points: int,
               until: float | None = None) -> AngleTerms:
    """The terms on the uniform grid ``linspace(0, span, n_points)`` (rad), cached per process.

    The arrays of a cached table are read-only: they are shared by every caller.
    """
    key = ("angle_terms", mech.cache_key, program, float(span), int(n_points), until)
    return cached(key, lambda: angle_terms(mech, program, np.linspace(0.0, span, int(n_points)), until))
