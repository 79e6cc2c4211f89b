"""The rigid model's tables: every function of phi1 and phi2 it needs, as piecewise-cubic Hermite
tables built once per mechanism and cam program from the exact kinematics (motion law, linkage,
contact geometry), with cells that never straddle a segment boundary of the cam program (the motion
law's jerk may jump there). The compiled equations (labtool.models.dynamics.kernels.rigid_nb) read them.

cam table (columns over phi1, rad): psi, psi', psi'', A2 (m), A2' (m/rad), A2'' (m/rad^2),
Mc (N m, cam gravity), direction (+1 rise, -1 return, 0 dwell). follower table (over phi2, rad,
per unit inertia factor for the first two): J'' (kg m^2), dJ''/dphi2 (kg m^2/rad), M_gravity (N m),
the load's arm per N of Fu_x times direction (m).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from labtool.common.errors import InputError
from labtool.models.mechanism import Mechanism
from labtool.models.mechanism.cam_tables import linkage_columns
from labtool.models.mechanism.motion_laws import CamProgram

TWO_PI = 2.0 * math.pi


# --------------------------------------------------------------------------------------------
# piecewise cubic Hermite tables (one node array, several columns)
# --------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Table:
    """Columns of piecewise cubics on the cells [x_i, x_{i+1}): coef shape (ncols, ncells, 4) so
    that value = c0 + t (c1 + t (c2 + t c3)), t = (x - x_i) / h_i in [0, 1]."""

    nodes: np.ndarray
    inv_h: np.ndarray
    coef: np.ndarray

    def packed(self) -> np.ndarray:
        """One array (ncells + 1, 2 + 4 ncols) for the compiled model: row i = (x_i, 1/h_i, the
        cubics' coefficients of cell i, column by column); the last row holds the last node only.
        One array, not three: a compiled struct pays a reference count for each array it reads."""
        ncols, ncells, _ = self.coef.shape
        out = np.zeros((ncells + 1, 2 + 4 * ncols))
        out[:, 0] = self.nodes
        out[:-1, 1] = self.inv_h
        out[:-1, 2:] = self.coef.transpose(1, 0, 2).reshape(ncells, 4 * ncols)
        return out


def make_table(nodes, left, right, slope_left, slope_right) -> Table:
    """Hermite cubics per cell from the values and slopes at both ends of each cell.

    left/right: arrays (ncols, ncells) of the values at x_i (from inside the cell) and x_{i+1}
    (from inside); slope_left/right likewise, in units of column per unit x. One-sided ends let a
    cell end exactly at a discontinuity of the derivative.
    """
    nodes = np.asarray(nodes, dtype=float)
    h = np.diff(nodes)
    if np.any(h <= 0):
        raise InputError("table nodes must increase")
    v0, v1 = np.asarray(left, float), np.asarray(right, float)
    s0, s1 = np.asarray(slope_left, float) * h, np.asarray(slope_right, float) * h
    coef = np.stack([v0, s0, 3.0 * (v1 - v0) - 2.0 * s0 - s1, 2.0 * (v0 - v1) + s0 + s1], axis=-1)
    return Table(nodes, 1.0 / h, coef)


# --------------------------------------------------------------------------------------------
# the plant: numbers and tables the right-hand sides need
# --------------------------------------------------------------------------------------------
def _arms(mech: Mechanism, sense: int, psi, p):
    """Moment arms (m) of the contact normal about D (A2) and A (A1) for follower stroke psi and
    dpsi/dphi1 = p (the normal depends on both; the same construction as labtool.models.mechanism.cam_profile)."""
    phi2 = mech.phiD + mech.psi0 + psi
    r = mech.l * np.stack([np.cos(phi2), np.sin(phi2)])
    C = mech.D[:, None] + r
    perp = lambda v: np.stack([-v[1], v[0]])  # noqa: E731
    t = p * perp(r) - sense * perp(C)
    n = perp(t) / np.hypot(t[0], t[1])
    n = n * np.where(np.einsum("ij,ij->j", n, C) < 0, -1.0, 1.0)   # away from A
    return np.einsum("ij,ij->j", perp(r), n), sense * np.einsum("ij,ij->j", perp(C), n)


def _A2_derivatives(mech, sense, psi, d1, d2, d3):
    """A2 and its first two derivatives wrt phi1 by the chain rule through (psi, psi'): exact in the
    motion law's derivatives (so jerk jumps are respected), central differences for the partials."""
    hs, hp = 1e-4, 1e-4
    a = lambda s, p: _arms(mech, sense, s, p)[0]  # noqa: E731
    f = a(psi, d1)
    fs = (a(psi + hs, d1) - a(psi - hs, d1)) / (2 * hs)
    fp = (a(psi, d1 + hp) - a(psi, d1 - hp)) / (2 * hp)
    fss = (a(psi + hs, d1) - 2 * f + a(psi - hs, d1)) / hs**2
    fpp = (a(psi, d1 + hp) - 2 * f + a(psi, d1 - hp)) / hp**2
    fsp = (a(psi + hs, d1 + hp) - a(psi + hs, d1 - hp) - a(psi - hs, d1 + hp) + a(psi - hs, d1 - hp)) / (4 * hs * hp)
    dA = fs * d1 + fp * d2
    ddA = fss * d1**2 + 2 * fsp * d1 * d2 + fpp * d2**2 + fs * d2 + fp * d3
    return f, dA, ddA


def _phi1_nodes(program: CamProgram, lo: float, hi: float, h: float) -> np.ndarray:
    """Nodes on [lo, hi] that include every segment boundary of the (periodic) cam program."""
    edges = np.cumsum([0.0] + [s.beta for s in program.segments])[:-1]
    bounds = [lo, hi]
    for rev in range(math.floor(lo / TWO_PI) - 1, math.ceil(hi / TWO_PI) + 1):
        bounds += [e + rev * TWO_PI for e in edges if lo < e + rev * TWO_PI < hi]
    bounds = np.unique(np.round(bounds, 14))
    pieces = [np.linspace(a, b, max(2, math.ceil((b - a) / h) + 1))[:-1] for a, b in zip(bounds[:-1], bounds[1:])]
    return np.concatenate(pieces + [[bounds[-1]]])


def _phi1_columns(mech, program, sense, phi):
    psi, d1, d2, d3 = program(phi)
    A2, dA2, ddA2 = _A2_derivatives(mech, sense, psi, d1, d2, d3)
    ang = mech.theta10 + sense * phi
    # cam gravity: K1 at AK1 from A, angle theta10 in the cam frame (cam frame = fixed frame at
    # phi1 = 0, an assumption; |Mc| <= m1 g AK1 = 0.018 N m); M = -m1 g dyK1/dphi1
    Mc = -mech.m1 * mech.g * mech.AK1 * sense * np.cos(ang)
    dMc = mech.m1 * mech.g * mech.AK1 * np.sin(ang)
    direction = program.direction(phi)
    values = np.stack([psi, d1, d2, A2, dA2, ddA2, Mc, direction])
    slopes = np.stack([d1, d2, d3, dA2, ddA2, np.zeros_like(phi), dMc, np.zeros_like(phi)])
    return values, slopes


def cam_table(mech: Mechanism, program: CamProgram, sense: int, lo: float, hi: float,
              h: float = TWO_PI / 20000) -> Table:
    """Table of the cam-angle functions on [lo, hi] (rad)."""
    nodes = _phi1_nodes(program, lo, hi, h)
    vl, sl = _phi1_columns(mech, program, sense, nodes[:-1])
    # right ends evaluated just inside the cell (left limit): derivatives may jump at boundaries
    vr, sr = _phi1_columns(mech, program, sense, nodes[1:] - 1e-11)
    # A2'' is interpolated linearly (its derivative needs psi''''): slopes = secant
    sec = (vr[5] - vl[5]) / np.diff(nodes)
    sl[5] = sec
    sr[5] = sec
    # the direction is constant in a cell (cells never straddle a boundary): use the cell's value
    mid = program.direction(0.5 * (nodes[:-1] + nodes[1:]))
    vl[7] = mid
    vr[7] = mid
    return make_table(nodes, vl, vr, sl, sr)


def follower_table(mech: Mechanism, lo: float, hi: float, n: int = 4001) -> Table:
    """Table of the follower-side functions of phi2 on [lo, hi] (rad), for unit inertia factor."""
    phi2 = np.linspace(lo, hi, n)

    def cols(x):
        J, dJ, Mg, vNx, slide = linkage_columns(mech, x)
        # load per N of Fu and per unit direction (labtool.models.mechanism.kinematics.load_force_x): Fu_x = Fu *
        # sign(ds ux) * direction; its moment about D is Fu_x * vN_x (vN per unit omega2)
        return np.stack([J, dJ, Mg, np.sign(slide) * vNx])

    h = 1e-6
    v = cols(phi2)
    d = (cols(phi2 + h) - cols(phi2 - h)) / (2 * h)
    d[0] = v[1]  # dJ''/dphi2 is known exactly
    return make_table(phi2, v[:, :-1], v[:, 1:], d[:, :-1], d[:, 1:])


