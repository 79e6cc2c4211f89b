"""The dynamic model with rigid elements (paper sec. 2.1.1, eqs 1-11): motor, jumps, impacts.

Two bodies: the cam with the motor (reducing element the cam, inertia J' = ``cam_inertia``, eq. 5)
and the follower with links 3-5 (reducing element the follower, J''red(phi2), eq. 7). Modes:

contact (1 DOF, eqs 1-3)  the roller centre C rides on one flank: phi2 = f(phi1) with
    f = phiD + psi0 + psi(phi1) on the inner flank and f + j / A2(phi1) on the outer one.
    Jred(phi1) = J' + J''(f) f'^2;  Jred eps1 + 1/2 dJred/dphi1 omega1^2 = M1(omega1) + Mc(phi1)
    + (M_gravity + M_load) f'  (omega1 'var'); eps1 = 0 for omega1 'const' (cam as input).
    The reaction's moment about D: MR13D = J'' eps2 + 1/2 dJ'' omega2^2 - M_gravity - M_load and
    the normal force lam = MR13D / A2 (N, > 0 = the inner flank pushes C away from A).
free (2 DOF, eqs 4-7)     cam+motor and follower move independently inside the backlash:
    J' eps1 = M1(omega1) + Mc(phi1);  J'' eps2 + 1/2 dJ'' omega2^2 = M_gravity + M_load.
    State (phi1, omega1, q, omega2) with q = phi2 - phi2_pitch(phi1) the follower's angle off the
    inner flank (integrated directly so that the gap keeps full precision).
impact (eqs 8-11)         ``models.dynamics.impact.impact`` with Newton's k on the normal velocity of C.

The gap. The groove's flanks are offset curves of the pitch curve (inner at 0, outer at j along the
contact normal n). The normal distance of C from the pitch curve is linearised in q:
g = A2(phi1) q, A2 = n . (k x DC) = l cos(alpha) = Db2/2 (m), so the angular gap is j / A2
(the lead's j / (l cos alpha)). Neglected: terms of order j^2 / rho (rho the pitch curve's radius of
curvature, > 14 mm here), i.e. < 1 % of the gap for j <= 0.128 mm. The same g defines the contact
(g = 0 or j), the events and the impact's normal velocity v_n = dg/dt = A2 omega2 - G1 omega1 with
G1 = A2 psi' - A2' q (= the paper's A1 = Db1/2 on the inner flank, a check in the tests), so the
model is self-consistent: k = 1 conserves energy and v+ = -k v- hold to rounding.

Events (scipy ``solve_ivp``, terminal): contact loss when lam changes sign on the flank in contact;
the gap closing on either flank (g = 0 or g = j exactly; on the flank just left the event function
is divided by (t - t0) so that its trivial root at the start is removed without an offset); the end
of the simulated cam angle. After each impact the integration restarts. Zeno (k < 1): when the
normal impact speed before, or the rebound speed after, an impact falls below ``v_settle`` (m/s, per
accuracy preset) and the flank's force is compressive, the impact is made plastic and the follower
stays in contact (persistent contact): the accumulation point of the geometric series of impacts,
reached early by at most 2 v_settle / (a (1 - k)) (a the relative normal acceleration). At most
``max_events`` events per run, then ``SolverError``.

All functions of phi1 and phi2 are piecewise-cubic Hermite tables built once per scene from the
exact kinematics (motion law, linkage, contact geometry), with cells that never straddle a segment
boundary of the cam program (the motion law's jerk may jump there). The right-hand sides and event
functions are small pure functions of (tables, state) so that they can be compiled later.
"""
from __future__ import annotations

import dataclasses
import math
import time as _time

import numpy as np
import xarray as xr
from scipy.integrate import solve_ivp

from common.errors import InputError, SolverError
from models.dynamics.impact import impact, kinetic_energy
from models.mechanism.cam_tables import cached, linkage_columns
from models.mechanism import Mechanism
from models.mechanism.motion_laws import CamProgram
from models.mechanism.motor import cam_inertia, motor_moment_on_cam, motor_slope_on_cam, no_load_cam_speed, transmission_ratio
from models.dynamics.scene import Scene

TWO_PI = 2.0 * math.pi

# solver presets: relative tolerance, max step (fraction of the rise's duration), output samples
# per rise, impact speed below which an accumulation of impacts is ended (m/s), event cap. Their error and cost against 'reference' are measured in docs/rigid_model.md.
PRESETS = {
    "fast": dict(method="RK45", rtol=1e-6, max_step=1 / 250, samples=1000, v_settle=1e-5, max_events=2000),
    "standard": dict(method="RK45", rtol=1e-9, max_step=1 / 1000, samples=4000, v_settle=1e-6, max_events=5000),
    "reference": dict(method="DOP853", rtol=1e-12, max_step=1 / 4000, samples=16000, v_settle=1e-7, max_events=20000),
}

# event kinds in the output dataset (CF flag_values / flag_meanings)
LIFTOFF, REBOUND, SETTLE = 1, 2, 3
EVENT_MEANINGS = "liftoff impact_rebound impact_settle"
INNER, OUTER, FREE = 1, -1, 0


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


def interp(tab: Table, x):
    """All columns of ``tab`` at x (scalar -> array (ncols,), array (n,) -> (ncols, n)).
    Outside the nodes the end cubics are extrapolated."""
    i = np.clip(np.searchsorted(tab.nodes, x, side="right") - 1, 0, tab.inv_h.size - 1)
    t = (x - tab.nodes[i]) * tab.inv_h[i]
    c = tab.coef[:, i]
    return c[..., 0] + t * (c[..., 1] + t * (c[..., 2] + t * c[..., 3]))


# --------------------------------------------------------------------------------------------
# the plant: numbers and tables the right-hand sides need
# --------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Plant:
    """Everything the equations of motion need, SI.

    phi1 table columns: psi, psi', psi'', A2 (m), A2' (m/rad), A2'' (m/rad^2), Mc (N m, cam gravity),
    direction (+1 rise, -1 return, 0 dwell). phi2 table columns (per unit inertia factor for the
    first two): J'' (kg m^2), dJ''/dphi2 (kg m^2/rad), M_gravity (N m), M_load per N of Fu_x * direction.
    """

    tab1: Table
    tab2: Table
    phi20: float          # phiD + psi0: follower angle at psi = 0 (rad)
    jt: float             # inertia factor of elements 2-5
    Jcam: float           # J' (kg m^2)
    inv_Jcam: float       # 1/J', 0 for the cam as input
    const: bool           # omega1 constant (cam as input)
    m0: float             # motor moment on the cam: M1 = m0 - m1 * omega1 (N m)
    m1: float             # (N m s/rad)
    Fu: float             # load magnitude (N)
    j: float              # backlash (m)
    k: float              # restitution


def _arms(mech: Mechanism, sense: int, psi, p):
    """Moment arms (m) of the contact normal about D (A2) and A (A1) for follower stroke psi and
    dpsi/dphi1 = p (the normal depends on both; the same construction as models.mechanism.cam_profile)."""
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
        # load per N of Fu and per unit direction (models.mechanism.kinematics.load_force_x): Fu_x = Fu *
        # sign(ds ux) * direction; its moment about D is Fu_x * vN_x (vN per unit omega2)
        return np.stack([J, dJ, Mg, np.sign(slide) * vNx])

    h = 1e-6
    v = cols(phi2)
    d = (cols(phi2 + h) - cols(phi2 - h)) / (2 * h)
    d[0] = v[1]  # dJ''/dphi2 is known exactly
    return make_table(phi2, v[:, :-1], v[:, 1:], d[:, :-1], d[:, 1:])


def build_plant(scene: Scene, backlash: float | None = None, phi1_hi: float | None = None) -> tuple[Plant, dict]:
    """The plant of a scene (backlash overrides scene.backlash, e.g. 0 for the no-backlash run)."""
    from models.mechanism.cam_profile import cached_sense

    mech, program = scene.mechanism, scene.program
    sense = cached_sense(mech, program)
    it = transmission_ratio(mech, scene.omega1_nominal)
    Jcam = cam_inertia(mech, it)
    span = simulated_span(scene)
    hi = (span if phi1_hi is None else phi1_hi) + 0.2
    # both tables depend on the mechanism and the cam program only: built once per process and
    # shared by every speed, load, inertia factor and backlash (models.mechanism.cam_tables.cached)
    tab1 = cached(("rigid_cam_table", repr(mech), program, sense, -0.05, hi),
                  lambda: cam_table(mech, program, sense, -0.05, hi))
    lo2, hi2 = mech.phiD + mech.psi0 - 0.05, mech.phiD + mech.psi0 + program.stroke + 0.05
    tab2 = cached(("rigid_follower_table", repr(mech), lo2, hi2), lambda: follower_table(mech, lo2, hi2))
    j = scene.backlash if backlash is None else backlash
    if not (Jcam > 0 and math.isfinite(Jcam)):
        raise InputError(f"the cam's reduced inertia must be > 0 kg m^2, got {Jcam}")
    if np.any(interp(tab2, mech.phiD + mech.psi0 + np.linspace(0, program.stroke, 50))[0] * scene.jt_factor <= 0):
        raise InputError("the follower's reduced inertia J''red must be > 0 kg m^2")
    if j < 0:
        raise InputError(f"backlash must be >= 0 mm, got {j * 1e3:g} mm")
    m0 = float(motor_moment_on_cam(mech, 0.0, it))
    m1 = motor_slope_on_cam(mech, it)
    plant = Plant(tab1, tab2, mech.phiD + mech.psi0, scene.jt_factor, Jcam,
                  0.0 if scene.omega1_mode == "const" else 1.0 / Jcam, scene.omega1_mode == "const",
                  m0, m1, scene.Fu, j, scene.restitution)
    info = dict(sense=sense, transmission_ratio=it, J_cam=Jcam, motor_slope=m1)
    return plant, info


def simulated_span(scene: Scene) -> float:
    """Cam angle simulated (rad) from the start of the rise: whole revolutions, or, with rise_only,
    the revolutions before the last one plus the last one's rise."""
    if scene.rise_only:
        return TWO_PI * (math.ceil(scene.revolutions) - 1) + scene.program.rise_angle
    return TWO_PI * scene.revolutions


# --------------------------------------------------------------------------------------------
# equations of motion (pure functions of plant and state; scalar or array state)
# --------------------------------------------------------------------------------------------
def flank_offset(P: Plant, flank: int, A2, dA2, ddA2):
    """Angular offset of the flank in contact from the pitch curve and its two phi1 derivatives."""
    if flank == OUTER and P.j > 0.0:
        qc = P.j / A2
        return qc, -P.j * dA2 / A2**2, P.j * (2.0 * dA2**2 / A2**3 - ddA2 / A2**2)
    return 0.0 * A2, 0.0 * A2, 0.0 * A2


def contact_terms(P: Plant, phi1, omega1, flank: int):
    """1-DOF motion on a flank: (eps1, phi2, omega2, eps2, MR13D, lam, q, A2, psi').

    eps1 rad/s^2 (0 for the cam as input), phi2 rad, omega2 rad/s, eps2 rad/s^2, MR13D N m,
    lam N (normal force on the roller, > 0 along n = away from A), q rad, A2 m.
    """
    psi, d1, d2, A2, dA2, ddA2, Mc, dirn = interp(P.tab1, phi1)
    qc, dqc, ddqc = flank_offset(P, flank, A2, dA2, ddA2)
    phi2 = P.phi20 + psi + qc
    f1, f2 = d1 + dqc, d2 + ddqc
    J, dJ, Mg, MLu = interp(P.tab2, phi2)
    J, dJ, ML = J * P.jt, dJ * P.jt, P.Fu * dirn * MLu
    if P.const:
        eps1 = 0.0 * omega1
    else:
        Jred = P.Jcam + J * f1 * f1                       # eq. (2), cam as reducing element
        dJred = dJ * f1**3 + 2.0 * J * f1 * f2
        eps1 = (P.m0 - P.m1 * omega1 + Mc + (Mg + ML) * f1 - 0.5 * dJred * omega1**2) / Jred   # eq. (1)
    omega2 = f1 * omega1
    eps2 = f2 * omega1**2 + f1 * eps1
    MR = J * eps2 + 0.5 * dJ * omega2**2 - Mg - ML
    return eps1, phi2, omega2, eps2, MR, MR / A2, qc, A2, d1


def free_terms(P: Plant, phi1, omega1, q, omega2):
    """2-DOF motion in the gap: (eps1, dq/dt, eps2, gap g [m], phi2, A2, psi', A2')."""
    psi, d1, d2, A2, dA2, ddA2, Mc, dirn = interp(P.tab1, phi1)
    phi2 = P.phi20 + psi + q
    J, dJ, Mg, MLu = interp(P.tab2, phi2)
    eps1 = 0.0 * omega1 if P.const else (P.m0 - P.m1 * omega1 + Mc) * P.inv_Jcam      # eq. (4)
    eps2 = (Mg + P.Fu * dirn * MLu - 0.5 * P.jt * dJ * omega2**2) / (P.jt * J)        # eq. (6)
    return eps1, omega2 - d1 * omega1, eps2, A2 * q, phi2, A2, d1, dA2


def contact_rhs(t, y, P, flank):
    return [y[1], contact_terms(P, y[0], y[1], flank)[0]]


def free_rhs(t, y, P):
    eps1, dq, eps2 = free_terms(P, y[0], y[1], y[2], y[3])[:3]
    return [y[1], eps1, dq, eps2]


def gap_event(P: Plant, flank: int, left: int, t0: float, v0: float):
    """Event function of the gap closing on ``flank``: g (inner) or g - j (outer), in m.

    On the flank the follower has just left (at t0 with gap rate v0, m/s) the function starts at a
    root; dividing it by (t - t0) removes that root without an offset, so the return to the flank
    is found exactly (an offset would feed energy into accumulating impacts: v ~ sqrt(2 a offset)).
    """
    target = 0.0 if flank == INNER else P.j

    def fun(t, y, *args):
        g = free_terms(P, y[0], y[1], y[2], y[3])[3] - target
        if flank != left:
            return g
        return g / (t - t0) if t > t0 else v0
    return fun


def _event(fun, direction):
    fun.terminal = True
    fun.direction = direction
    return fun


# --------------------------------------------------------------------------------------------
# the event-driven integration
# --------------------------------------------------------------------------------------------
@dataclasses.dataclass
class Phase:
    kind: str          # "contact" or "free"
    flank: int         # INNER / OUTER in contact, FREE in flight
    t0: float
    t1: float
    sol: object        # scipy OdeSolution (dense output)


def integrate(P: Plant, phi1_end: float, omega1_0: float, preset: dict, t_rise: float,
              start: tuple | None = None) -> tuple[list[Phase], list[dict]]:
    """Integrate from t = 0 until phi1 reaches phi1_end (rad).

    start: None = the follower in contact at phi1 = 0 on the flank whose force is compressive;
    or ("free", phi1, omega1, q, omega2) to start in the gap (tests).
    Returns the phases and the event records.
    """
    rtol = preset["rtol"]
    max_step = preset["max_step"] * t_rise
    t_max = 4.0 * phi1_end / max(omega1_0, 1e-9) + 1.0
    atol_contact = [rtol * 1e-3, rtol * 1e-2]
    atol_free = [rtol * 1e-3, rtol * 1e-2, rtol * 1e-6, rtol * 1e-3]
    end = _event(lambda t, y, *a: y[0] - phi1_end, 1)
    phases: list[Phase] = []
    events: list[dict] = []
    t = 0.0
    if start is None:
        phi1, omega1 = 0.0, omega1_0
        lam = contact_terms(P, phi1, omega1, INNER)[5]
        mode, flank = "contact", (INNER if (lam >= 0 or P.j == 0.0) else OUTER)
        q = omega2 = 0.0
    else:
        mode, phi1, omega1, q, omega2 = start
        flank = FREE
    left, v_left = FREE, 0.0          # the flank the follower just left and the gap rate then
    short = 0
    while True:
        if len(events) > preset["max_events"]:
            raise SolverError(
                f"rigid model: more than {preset['max_events']} contact events before phi1 = "
                f"{math.degrees(phi1):.3f} deg (t = {t:.6g} s): the impacts do not settle; "
                "try another restitution k or accuracy preset")
        if mode == "contact":
            evs = [end]
            if P.j > 0.0:
                f = flank
                evs.append(_event(lambda t, y, *a: f * contact_terms(P, y[0], y[1], f)[5], -1))
            sol = solve_ivp(contact_rhs, (t, t_max), [phi1, omega1], method=preset["method"], rtol=rtol,
                            atol=atol_contact, max_step=max_step, events=evs, dense_output=True, args=(P, flank))
        else:
            evs = [end, _event(gap_event(P, INNER, left, t, v_left), -1), _event(gap_event(P, OUTER, left, t, v_left), 1)]
            sol = solve_ivp(free_rhs, (t, t_max), [phi1, omega1, q, omega2], method=preset["method"], rtol=rtol,
                            atol=atol_free, max_step=max_step, events=evs, dense_output=True, args=(P,))
        if sol.status == -1:
            raise SolverError(f"rigid model: the integrator failed at t = {sol.t[-1]:.6g} s "
                              f"(phi1 = {math.degrees(sol.y[0, -1]):.3f} deg): {sol.message}")
        hit = [i for i, te in enumerate(sol.t_events) if te.size]
        if sol.status == 0 or not hit:
            raise SolverError(f"rigid model: the cam did not reach phi1 = {math.degrees(phi1_end):.2f} deg "
                              f"within {t_max:.3g} s (motor stalled?)")
        which = min(hit, key=lambda i: sol.t_events[i][0])
        t_new = float(sol.t_events[which][0])
        y = sol.y_events[which][0]
        if which != 0 and float(y[0]) >= phi1_end - 1e-12:
            # a force jump at the very end of the span (the end of the rise, where the load is
            # removed) ends the run: not a lift-off inside the span (docs/performance.md)
            which = 0
        phases.append(Phase(mode, flank if mode == "contact" else FREE, t, t_new, sol.sol))
        short = short + 1 if t_new - t < 1e-13 else 0
        if short > 100:
            raise SolverError(f"rigid model: stalled in zero-length phases at t = {t:.6g} s")
        t = t_new
        if which == 0:                       # end of the simulated cam angle
            return phases, events
        if mode == "contact":                # contact loss: the flank's force changed sign
            phi1, omega1 = float(y[0]), float(y[1])
            _, phi2, omega2, _, _, _, q, A2, _ = contact_terms(P, phi1, omega1, flank)
            omega2, q = float(omega2), float(q)
            events.append(dict(time=t, phi1=phi1, kind=LIFTOFF, flank=flank, v_before=0.0, v_after=0.0,
                               percussion=0.0, omega1_before=omega1, omega1_after=omega1,
                               omega2_before=omega2, omega2_after=omega2, phi2=float(phi2),
                               energy_before=np.nan, energy_after=np.nan))
            mode, left, v_left = "free", flank, 0.0
            continue
        # impact on the inner (which == 1) or outer (which == 2) flank
        phi1, omega1, q, omega2 = (float(v) for v in y)
        hit_flank = INNER if which == 1 else OUTER
        _, _, _, _, phi2, A2, d1, dA2 = free_terms(P, phi1, omega1, q, omega2)
        q = 0.0 if hit_flank == INNER else P.j / float(A2)          # project onto the flank
        G1 = float(A2 * d1 - dA2 * q)
        J2 = float(interp(P.tab2, phi2)[0]) * P.jt
        approach = (float(A2) * omega2 - G1 * omega1) * hit_flank   # < 0 when closing
        k = P.k
        settle = False
        if min(-approach, -k * approach) < preset["v_settle"]:
            # accumulation of impacts (or a grazing touch): plastic impact, then stay if pressed
            w1, w2 = impact(omega1, omega2, G1, float(A2), P.inv_Jcam, J2, 0.0)[:2]
            lam = contact_terms(P, phi1, w1, hit_flank)[5]
            settle = hit_flank * lam > 0
            k = 0.0 if settle else k
        w1, w2, Pimp, v_b, v_a = impact(omega1, omega2, G1, float(A2), P.inv_Jcam, J2, k)
        Jc = P.Jcam
        events.append(dict(time=t, phi1=phi1, kind=SETTLE if settle else REBOUND, flank=hit_flank,
                           v_before=v_b, v_after=v_a, percussion=Pimp, omega1_before=omega1,
                           omega1_after=w1, omega2_before=omega2, omega2_after=w2, phi2=float(phi2),
                           energy_before=kinetic_energy(omega1, omega2, Jc, J2),
                           energy_after=kinetic_energy(w1, w2, Jc, J2)))
        omega1, omega2 = w1, w2
        if settle:
            mode, flank = "contact", hit_flank
        else:
            mode, left, v_left = "free", hit_flank, v_a


# --------------------------------------------------------------------------------------------
# sampling, indicators, dataset
# --------------------------------------------------------------------------------------------
def sample(P: Plant, phases: list[Phase], times: np.ndarray) -> dict:
    """State and derived quantities at ``times`` (s), each from the phase that contains it."""
    n = times.size
    out = {k: np.full(n, np.nan) for k in ("phi1", "omega1", "epsilon1", "phi2", "omega2", "epsilon2",
                                           "MR13D", "R13n", "gap")}
    out["contact"] = np.zeros(n, dtype=np.int8)
    t0s = np.array([ph.t0 for ph in phases])
    idx = np.clip(np.searchsorted(t0s, times, side="right") - 1, 0, len(phases) - 1)
    for k, ph in enumerate(phases):
        sel = np.nonzero(idx == k)[0]
        if sel.size == 0:
            continue
        y = ph.sol(times[sel])
        if ph.kind == "contact":
            eps1, phi2, omega2, eps2, MR, lam, q, A2, _ = contact_terms(P, y[0], y[1], ph.flank)
            gap = A2 * q
            out["contact"][sel] = ph.flank
        else:
            eps1, _, eps2, gap, phi2, _, _, _ = free_terms(P, y[0], y[1], y[2], y[3])
            omega2, MR, lam = y[3], 0.0, 0.0
        for name, val in zip(("phi1", "omega1", "epsilon1", "phi2", "omega2", "epsilon2", "MR13D", "R13n", "gap"),
                             (y[0], y[1], eps1, phi2, omega2, eps2, MR, lam, gap)):
            out[name][sel] = val
    return out


def _reference_at(P0: Plant, phases0: list[Phase], times):
    """The no-backlash (rfj) run at ``times``: phi1, omega1, phi2, omega2 (it is one contact phase)."""
    s = sample(P0, phases0, np.asarray(times, dtype=float))
    return s["phi1"], s["omega1"], s["phi2"], s["omega2"]


def _in_rise(program: CamProgram, phi1):
    return np.mod(phi1, TWO_PI) < program.rise_angle


def simulate(scene: Scene, integrate=None, preset: dict | None = None):
    """Run the rigid model on a scene. Returns models.dynamics.simulate.SimulationResult.

    ``integrate``: the integration loop (default: ``models.dynamics.accuracy.integrator``: the compiled twin
    ``models.dynamics.kernels.rigid_nb.integrate`` for fast/standard, this module's solve_ivp loop for
    reference); ``preset``: a preset dict instead of PRESETS[scene.accuracy] (benchmarks, tests).
    """
    if integrate is None:
        from models.dynamics.accuracy import integrator
        integrate = integrator("rigid", scene.accuracy)
    from models.dynamics.simulate import INDICATORS, SimulationResult

    t_start = _time.perf_counter()
    preset = PRESETS[scene.accuracy] if preset is None else preset
    program, mech = scene.program, scene.mechanism
    span = simulated_span(scene)
    plant, info = build_plant(scene, phi1_hi=span)
    if scene.omega1_mode == "const":
        omega1_0 = scene.omega1_nominal
    else:
        # steady state of the preceding dwell (no follower torque there, motor time constant
        # J'/slope ~ 5 ms << dwell): M1(omega1) + Mc(0) = 0, i.e. the no-load speed n1 * 1000/920
        omega1_0 = (plant.m0 + float(interp(plant.tab1, 0.0)[6])) / plant.m1
    t_rise = program.rise_angle / omega1_0
    phases, events = integrate(plant, span, omega1_0, preset, t_rise)
    if plant.j > 0.0:
        plant0 = dataclasses.replace(plant, j=0.0)
        phases0, _ = integrate(plant0, span + 0.1, omega1_0, preset, t_rise)
    else:
        plant0, phases0 = plant, phases
    t_end = phases[-1].t1
    n = max(int(preset["samples"] * span / program.rise_angle), 200)
    times = np.linspace(0.0, t_end, n + 1)
    # the last sample just inside the simulated span: at phi1 = rise exactly the dwell begins (the
    # load switches off, as in models.mechanism.kinematics), which would put a step into every time series
    times[-1] = t_end * (1.0 - 1e-9)
    s = sample(plant, phases, times)
    rfj_full = sample(plant0, phases0, times)
    ref = (rfj_full["phi1"], rfj_full["omega1"], rfj_full["phi2"], rfj_full["omega2"])
    ind = indicators(program, s, ref, events, plant0, phases0)
    ind = {**{k: None for k in INDICATORS}, **ind}
    ds = _dataset(scene, plant, info, omega1_0, times, s, rfj_full, events)
    ds.attrs["wall_s_model"] = _time.perf_counter() - t_start
    return SimulationResult(ds, ind, "rigid")


def indicators(program, s, ref, events, plant0, phases0) -> dict:
    """The paper's Table 2 indicators over the rise (rcj = with backlash, rfj = j = 0 run)."""
    rise = _in_rise(program, s["phi1"])
    contact = rise & (s["contact"] != FREE)
    mr = s["MR13D"][contact]
    dphi2 = np.abs(s["phi2"] - ref[2])[rise]
    dw2 = np.abs(s["omega2"] - ref[3])[rise]
    dw1 = np.abs(s["omega1"] - ref[1])[rise]
    ev = [e for e in events if _in_rise(program, e["phi1"])]
    if ev:  # the exact states just before and after each event (grid samples miss the jumps)
        te = np.array([e["time"] for e in ev])
        _, rw1, rphi2, rw2 = _reference_at(plant0, phases0, te)
        for key, w1k, w2k in (("before", "omega1_before", "omega2_before"), ("after", "omega1_after", "omega2_after")):
            w1 = np.array([e[w1k] for e in ev])
            w2 = np.array([e[w2k] for e in ev])
            dw1 = np.concatenate([dw1, np.abs(w1 - rw1)])
            dw2 = np.concatenate([dw2, np.abs(w2 - rw2)])
        dphi2 = np.concatenate([dphi2, np.abs(np.array([e["phi2"] for e in ev]) - rphi2)])
    impacts = [e for e in ev if e["kind"] in (REBOUND, SETTLE)]
    return {
        "MR13D_max_Nm": float(mr.max()) if mr.size else None,
        "MR13D_min_Nm": float(mr.min()) if mr.size else None,
        "dphi2_max_deg": float(np.degrees(dphi2.max())) if dphi2.size else 0.0,
        "domega2_max_rad_s": float(dw2.max()) if dw2.size else 0.0,
        "domega1_max_rad_s": float(dw1.max()) if dw1.size else 0.0,
        "percussion_max_Ns": float(max((abs(e["percussion"]) for e in impacts), default=0.0)),
        # a jump = a flight: every loss of contact, by lift-off or by rebound after an impact
        "jumps": int(sum(1 for e in ev if e["kind"] in (LIFTOFF, REBOUND))),
        "impacts": int(len(impacts)),
        "liftoffs": int(sum(1 for e in ev if e["kind"] == LIFTOFF)),
        "settles": int(sum(1 for e in ev if e["kind"] == SETTLE)),
    }


def _dataset(scene, plant, info, omega1_0, times, s, r, events) -> xr.Dataset:
    def var(data, units, long_name, dims=("time",), **extra):
        return (dims, np.asarray(data), {"units": units, "long_name": long_name, **extra})

    DE = scene.mechanism.DE
    data = {
        "phi1": var(s["phi1"], "rad", "cam angle from the start of the rise"),
        "omega1": var(s["omega1"], "rad/s", "cam angular velocity"),
        "epsilon1": var(s["epsilon1"], "rad/s^2", "cam angular acceleration"),
        "phi2": var(s["phi2"], "rad", "follower angle of DC from the x axis"),
        "omega2": var(s["omega2"], "rad/s", "follower angular velocity"),
        "epsilon2": var(s["epsilon2"], "rad/s^2", "follower angular acceleration (impacts excluded: impulsive)"),
        "aE_t": var(s["epsilon2"] * DE, "m/s^2", "tangential acceleration of E (ideal sensor)"),
        "aE_n": var(s["omega2"] ** 2 * DE, "m/s^2", "normal acceleration of E, towards D (ideal sensor)"),
        "MR13D": var(s["MR13D"], "N m", "moment about D of the cam-on-follower reaction (0 in flight)"),
        "R13n": var(s["R13n"], "N", "normal cam-on-roller force, > 0 = inner flank pushing C away from A"),
        "gap": var(s["gap"], "m", "normal distance of the roller centre from the inner-flank contact position (0..j)"),
        "contact": var(s["contact"], "1", "flank in contact", flag_values=np.array([-1, 0, 1], dtype=np.int8),
                       flag_meanings="outer_flank free inner_flank"),
        "phi1_rfj": var(r["phi1"], "rad", "cam angle, no-backlash run (j = 0)"),
        "omega1_rfj": var(r["omega1"], "rad/s", "cam angular velocity, no-backlash run"),
        "phi2_rfj": var(r["phi2"], "rad", "follower angle, no-backlash run"),
        "omega2_rfj": var(r["omega2"], "rad/s", "follower angular velocity, no-backlash run"),
        "MR13D_rfj": var(r["MR13D"], "N m", "MR13D of the no-backlash run"),
        "dphi2": var(s["phi2"] - r["phi2"], "rad", "phi2rcj - phi2rfj (Figure 8a)"),
        "domega2": var(s["omega2"] - r["omega2"], "rad/s", "omega2rcj - omega2rfj (Figure 8b)"),
        "domega1": var(s["omega1"] - r["omega1"], "rad/s", "omega1rcj - omega1rfj (Figure 8c)"),
    }
    ev = {k: np.array([e[k] for e in events], dtype=float) for k in
          ("time", "phi1", "v_before", "v_after", "percussion", "omega1_before", "omega1_after",
           "omega2_before", "omega2_after", "energy_before", "energy_after")} if events else None
    edim = ("event",)
    if ev is not None:
        kinds = np.array([e["kind"] for e in events], dtype=np.int8)
        flanks = np.array([e["flank"] for e in events], dtype=np.int8)
    else:
        ev = {k: np.zeros(0) for k in ("time", "phi1", "v_before", "v_after", "percussion", "omega1_before",
                                       "omega1_after", "omega2_before", "omega2_after", "energy_before", "energy_after")}
        kinds = flanks = np.zeros(0, dtype=np.int8)
    data.update({
        "event_time": var(ev["time"], "s", "time of the contact event", edim),
        "event_phi1": var(ev["phi1"], "rad", "cam angle of the contact event", edim),
        "event_kind": var(kinds, "1", "contact event", edim, flag_values=np.array([1, 2, 3], dtype=np.int8),
                          flag_meanings=EVENT_MEANINGS),
        "event_flank": var(flanks, "1", "flank: 1 inner, -1 outer", edim),
        "event_v_before": var(ev["v_before"], "m/s", "normal relative velocity of C before (gap rate)", edim),
        "event_v_after": var(ev["v_after"], "m/s", "normal relative velocity of C after", edim),
        "event_percussion": var(ev["percussion"], "N s", "percussion (normal impulse on the roller) (Figure 8d)", edim),
        "event_omega1_before": var(ev["omega1_before"], "rad/s", "cam speed before", edim),
        "event_omega1_after": var(ev["omega1_after"], "rad/s", "cam speed after", edim),
        "event_omega2_before": var(ev["omega2_before"], "rad/s", "follower speed before", edim),
        "event_omega2_after": var(ev["omega2_after"], "rad/s", "follower speed after", edim),
        "event_energy_before": var(ev["energy_before"], "J", "kinetic energy of cam+motor and follower side before", edim),
        "event_energy_after": var(ev["energy_after"], "J", "kinetic energy after", edim),
    })
    ds = xr.Dataset(data, coords={"time": ("time", times, {"units": "s", "long_name": "time from the start of the rise"})})
    ds.attrs.update({
        "title": "labtool rigid-element dynamic model (paper sec. 2.1.1, eqs 1-11)",
        "mechanism": scene.mechanism.name, "law": scene.law, "cam_speed_rpm": scene.cam_speed_rpm,
        "Fu_N": scene.Fu, "backlash_m": scene.backlash, "jt_factor": scene.jt_factor,
        "omega1_mode": scene.omega1_mode, "restitution": scene.restitution, "accuracy": scene.accuracy,
        "omega1_start_rad_s": omega1_0, "no_load_cam_speed_rad_s": no_load_cam_speed(scene.mechanism, scene.omega1_nominal),
        "cam_sense": int(info["sense"]), "transmission_ratio": info["transmission_ratio"],
        "J_cam_kgm2": info["J_cam"], "v_settle_m_s": PRESETS[scene.accuracy]["v_settle"],
        "rise_only": int(scene.rise_only), "revolutions": scene.revolutions,
    })
    return ds


# --------------------------------------------------------------------------------------------
# the paper's Table 2: the 16 runs of Table 1 (sine law, omega1 variable)
# --------------------------------------------------------------------------------------------
TABLE2_KEYS = ("MR13D_max_Nm", "dphi2_max_deg", "domega2_max_rad_s", "domega1_max_rad_s", "percussion_max_Ns", "jumps")

# the direction of each factor's effect as the paper's Discussion states it for the rigid model
# (A = Fu, B = j, C = n1, D = Jt; +1 = a bigger factor gives a bigger indicator)
PAPER_DIRECTIONS = {
    "MR13D_max_Nm": {"A": +1, "C": +1, "D": +1},
    "dphi2_max_deg": {"B": +1, "D": +1, "A": -1},
    "domega2_max_rad_s": {"B": +1, "C": +1, "D": +1, "A": -1},
    "domega1_max_rad_s": {"C": +1, "D": +1, "A": -1},
    "percussion_max_Ns": {"B": +1, "C": +1, "D": +1, "A": -1},
    "jumps": {"A": +1, "C": +1, "B": -1},
}


def rigid_vs_table2(accuracy: str = "standard", law: str = "sine", omega1_mode: str = "var"):
    """The 16 runs of Table 1 with the rigid model against Table 2: a DataFrame with, per run, the
    factors, our indicators, the paper's and the % differences (jumps: the difference in counts)."""
    import pandas as pd

    from models.study.paper import read_reference, table1_runs

    t2 = read_reference("table2_rigid")
    rows = []
    for run, paper in zip(table1_runs().itertuples(), t2.itertuples()):
        scene = Scene(law=law, cam_speed_rpm=run.n1_rpm, Fu=run.Fu_N, backlash=run.j_mm * 1e-3,
                      jt_factor=run.Jt_factor, omega1_mode=omega1_mode, accuracy=accuracy)
        ind = simulate(scene).indicators
        row = {"run": run.run, "Fu_N": run.Fu_N, "j_mm": run.j_mm, "n1_rpm": run.n1_rpm, "Jt_factor": run.Jt_factor,
               "A": int(paper.A_Fu_level), "B": int(paper.B_j_level), "C": int(paper.C_n1_level), "D": int(paper.D_Jt_level)}
        for key in TABLE2_KEYS:
            ours, ref = ind[key], getattr(paper, key)
            row[key] = ours
            row[f"paper_{key}"] = ref
            if key == "jumps":
                row["jumps_diff"] = ours - ref
            else:
                row[f"{key}_diff_pct"] = 100.0 * (ours / ref - 1.0) if ref != 0 else (0.0 if ours == 0 else float("inf"))
        row["impacts"] = ind["impacts"]
        row["liftoffs"] = ind["liftoffs"]
        rows.append(row)
    return pd.DataFrame(rows)


def main_effects(df, prefix: str = "") -> dict:
    """Main effect of each factor (mean at level 2 - mean at level 1) on each Table 2 indicator."""
    return {key: {f: float(df.loc[df[f] == 2, prefix + key].mean() - df.loc[df[f] == 1, prefix + key].mean())
                  for f in "ABCD"} for key in TABLE2_KEYS}
