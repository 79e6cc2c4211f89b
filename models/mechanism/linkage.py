"""Position, velocity and acceleration analysis of the follower-side linkage (elements 2-5).

Given the follower angle phi2 (rad, absolute, counter-clockwise from x), its angular velocity
omega2 (rad/s) and acceleration epsilon2 (rad/s^2), returns every point and link of the
linkage in the fixed frame (origin A, y up, SI units). Pure functions on numpy arrays.

Vector loop of the rod (an inverted slider-crank with offset, docs/mechanism.md):

    G = E + s*u + e*n,     u = (cos phi4, sin phi4),  n = (-sin phi4, cos phi4)

with s = |EF| the distance from E to the foot F of the perpendicular from G, e = FG (signed).
Differentiating once and twice and projecting on u and n gives closed forms:

    phi4' = -(vE . n)/s,      s' = e*phi4' - vE . u
    phi4'' = (e*phi4'^2 - 2*s'*phi4' - aE . n)/s,   s'' = s*phi4'^2 + e*phi4'' - aE . u
"""
from __future__ import annotations

import dataclasses

import numpy as np

from labtool.models.mechanism import Mechanism


def _rot(angle):
    return np.stack([np.cos(angle), np.sin(angle)])


def _perp(v):
    """k x v: v turned by +90 degrees."""
    return np.stack([-v[1], v[0]])


@dataclasses.dataclass
class LinkageState:
    """Kinematic state of the follower-side linkage. Points are arrays of shape (2, n), in m;
    velocities in m/s; accelerations in m/s^2; angles in rad, angular rates in rad/s, rad/s^2."""

    phi2: np.ndarray
    omega2: np.ndarray
    epsilon2: np.ndarray
    C: np.ndarray
    vC: np.ndarray
    aC: np.ndarray
    E: np.ndarray
    vE: np.ndarray
    aE: np.ndarray
    K2: np.ndarray
    vK2: np.ndarray
    aK2: np.ndarray
    phi4: np.ndarray
    omega4: np.ndarray
    epsilon4: np.ndarray
    s: np.ndarray
    ds: np.ndarray
    dds: np.ndarray
    K4: np.ndarray
    vK4: np.ndarray
    aK4: np.ndarray
    N: np.ndarray
    vN: np.ndarray
    aN: np.ndarray
    F: np.ndarray
    H: np.ndarray
    K5: np.ndarray
    vK5: np.ndarray
    aK5: np.ndarray


def _on_rotating_link(origin, v_origin, a_origin, length, angle, omega, epsilon):
    """Point at ``length`` from ``origin`` along ``angle`` on a link turning at omega, epsilon."""
    r = length * _rot(angle)
    v = v_origin + omega * _perp(r)
    a = a_origin + epsilon * _perp(r) - omega**2 * r
    return origin + r, v, a


def linkage_state(mech: Mechanism, phi2, omega2, epsilon2) -> LinkageState:
    """Full kinematics of elements 2 (follower), 3 (roller centre), 4 (rod), 5 (slide block)."""
    phi2 = np.atleast_1d(np.asarray(phi2, dtype=float))
    omega2 = np.broadcast_to(np.asarray(omega2, dtype=float), phi2.shape)
    epsilon2 = np.broadcast_to(np.asarray(epsilon2, dtype=float), phi2.shape)
    D = mech.D[:, None] * np.ones_like(phi2)
    zero = np.zeros_like(D)

    C, vC, aC = _on_rotating_link(D, zero, zero, mech.l, phi2, omega2, epsilon2)
    E, vE, aE = _on_rotating_link(D, zero, zero, mech.DE, phi2, omega2, epsilon2)
    K2, vK2, aK2 = _on_rotating_link(D, zero, zero, mech.DK2, phi2 + mech.theta20, omega2, epsilon2)

    # rod through the slide block: G = E + s u + e n
    e = mech.FG
    r = mech.G[:, None] - E
    rho = np.hypot(r[0], r[1])
    beta = np.arctan2(r[1], r[0])
    phi4 = beta - np.arcsin(e / rho)
    s = np.sqrt(rho**2 - e**2)
    u, n = _rot(phi4), _perp(_rot(phi4))
    omega4 = -np.einsum("ij,ij->j", vE, n) / s
    ds = e * omega4 - np.einsum("ij,ij->j", vE, u)
    epsilon4 = (e * omega4**2 - 2.0 * ds * omega4 - np.einsum("ij,ij->j", aE, n)) / s
    dds = s * omega4**2 + e * epsilon4 - np.einsum("ij,ij->j", aE, u)

    K4, vK4, aK4 = _on_rotating_link(E, vE, aE, mech.EK4, phi4 + mech.theta40, omega4, epsilon4)
    N, vN, aN = _on_rotating_link(E, vE, aE, mech.EN, phi4 + mech.thetaN, omega4, epsilon4)
    Gm = mech.G[:, None] * np.ones_like(phi2)
    K5, vK5, aK5 = _on_rotating_link(Gm, zero, zero, mech.GK5, phi4 + mech.theta50, omega4, epsilon4)
    F = E + s * u
    H = E + mech.EH * u
    return LinkageState(phi2, omega2, epsilon2, C, vC, aC, E, vE, aE, K2, vK2, aK2,
                        phi4, omega4, epsilon4, s, ds, dds, K4, vK4, aK4, N, vN, aN, F, H, K5, vK5, aK5)


def _dot(a, b):
    return np.einsum("ij,ij->j", a, b)


@dataclasses.dataclass
class ReducedFollower:
    """Inertia, gravity and load of elements 2-5 reduced to the follower (per unit omega2).

    ``J`` = J''red(phi2) in kg*m^2 and ``dJ`` = dJ''red/dphi2 (eq. 7), both times the inertia
    factor; ``M_gravity`` and ``M_load`` the moments about D (N*m, positive counter-clockwise, i.e.
    in the rise direction) that gravity and the load Fu exert on the follower through the linkage.
    """

    J: np.ndarray
    dJ: np.ndarray
    M_gravity: np.ndarray
    M_load: np.ndarray


def reduced_follower(mech: Mechanism, phi2, load_force=None, jt_factor: float = 1.0,
                     unit: LinkageState | None = None) -> ReducedFollower:
    """Reduce elements 2-5 to the follower at angles phi2.

    ``load_force`` is the x component (N) of the load Fu at N, an array matching phi2 (the paper
    applies Fux = +-Fu, Fuy = 0, opposing the rod's sliding in the block). ``jt_factor`` scales
    every inertia (masses' kinetic terms and moments of inertia) of elements 2-5 as the paper's
    factor D (Jt); gravity keeps the true masses. ``unit`` is ``linkage_state(mech, phi2, 1, 0)``
    when the caller has it already.
    """
    if unit is None:
        unit = linkage_state(mech, phi2, 1.0, 0.0)  # velocities = velocity coefficients (per omega2)
    bodies = [
        (mech.m2, mech.J2, unit.vK2, unit.aK2, 1.0, 0.0),
        (mech.m3, 0.0, unit.vC, unit.aC, 1.0, 0.0),   # roller: translation of C only (sec. 2.1.1)
        (mech.m4, mech.J4, unit.vK4, unit.aK4, unit.omega4, unit.epsilon4),
        (mech.m5, mech.J5, unit.vK5, unit.aK5, unit.omega4, unit.epsilon4),
    ]
    J = np.zeros_like(unit.phi2)
    dJ = np.zeros_like(unit.phi2)
    Mg = np.zeros_like(unit.phi2)
    for m, Ji, v, a, w, e in bodies:
        J += m * _dot(v, v) + Ji * w**2
        # with omega2 = 1 and epsilon2 = 0, a = d(v)/dphi2 and e = d(w)/dphi2
        dJ += 2.0 * (m * _dot(v, a) + Ji * w * e)
        Mg += -m * mech.g * v[1]
    ML = np.zeros_like(unit.phi2) if load_force is None else np.asarray(load_force) * unit.vN[0]
    return ReducedFollower(jt_factor * J, jt_factor * dJ, Mg, ML)
