"""Dynamic model with elastic cam-follower contact, paper section 2.1.2, eqs (12)-(19), in SI.

One degree of freedom: x (m), the displacement of the follower's contact point relative to the
cam's along the common normal, measured from the kinematic (rigid, no-backlash) motion. Sign
convention (docs/models.md, "elastic model"): x > 0 towards the exterior of the cam, which on this
mechanism is the rise direction of the follower; the interior flank (x <= 0 means penetration)
pushes the follower in the rise direction, the exterior flank (penetration x - j >= 0) pushes it
back. Phases: 0 interior contact, 1 flight in the gap (0 < x < j), 2 exterior contact.

Equation of motion (the "consistent" reading, default):

    M(t) x'' = F_int(x) - F_ext(x - j) - R31(t)

with F = Kc p^(10/9) (models.dynamics.contact), R31 = MR13D_kin / (l cos alpha) the normal force the cam
must exert to impose the kinematic motion (positive: pushes in the rise direction), and
M = M1 M2 / (M1 + M2), M1 = 4 Jcam / Db1^2, M2 = 4 J''red / Db2^2 (eqs 16-18). The paper's literal
eqs (12)-(14) read M x'' + Kc x^n = R31, i.e. the same with the sign of R31 reversed: a positive
(pushing) static reaction would then separate the follower from the flank that pushes it. That
reading is kept selectable (``reading="literal"``) and documented, not used by default.

The gap j between the flanks is the scene's backlash (``elastic_gap = "physical"``), or 0 with
``elastic_gap = "closed"``: the convention the paper's Table 3 was computed with (its indicators do
not depend on j and its xel max stays below j; docs/models.md, "The backlash in Table 3").

The cam turns at constant speed: n1 (omega1 'const') or n1 * n_sync / n_nominal (omega1 'var',
the speed the paper's variable-speed drive settles at; models.mechanism.motor.no_load_cam_speed).

Contact onset and separation are solve_ivp events (terminal, then restart in the new phase), so
every phase integrates a smooth right-hand side. ``rhs`` and the event functions are small pure
functions of (t, y) and plain arrays, for a later numba kernel.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import xarray as xr
from scipy.integrate import solve_ivp

from models.mechanism.cam_tables import angle_terms, grid_terms
from models.dynamics.contact import contact_force, contact_stiffness, hunt_crossley_force, static_penetration
from common.errors import InputError, SolverError
from models.mechanism.motor import cam_inertia, no_load_cam_speed, transmission_ratio
from models.dynamics.scene import Scene

INTERIOR, FLIGHT, EXTERIOR = 0, 1, 2
PHASE_NAMES = ("interior", "flight", "exterior")
READINGS = ("consistent", "literal")

# solver presets: relative tolerance; absolute tolerances as fractions of the scene's own scales
# (the static deflection under the largest |R31| for x, that times the contact's angular frequency
# for dx/dt), so that a stiffer contact (smaller x) is resolved as well as a soft one; max_step as a
# fraction of the linearised contact period
PRESETS = {
    "fast": dict(rtol=1e-6, atol=1e-5, steps_per_period=4.0),
    "standard": dict(rtol=1e-8, atol=1e-7, steps_per_period=8.0),
    "reference": dict(rtol=1e-10, atol=1e-9, steps_per_period=16.0),
}
OUTPUT_STEP = 2e-5        # s, output sampling (>= 25 samples per contact period of ~0.5 ms)
GRID_POINTS = 4001        # cam-angle grid for the kinematic tables (linear interpolation in time)
ZENO_SEGMENTS = 200       # this many phases in a row, each shorter than ZENO_DT, is endless chatter
ZENO_DT = 1e-9            # s
# the event functions' sign is read at this many points of every step (its dense output), not at
# the step's ends only: a micro-bounce that leaves a flank and returns within one step is an event
EVENT_SUBSTEPS = 8


@dataclass(frozen=True)
class Tables:
    """Kinematic quantities on a uniform time grid (the cam turns at constant omega1)."""

    t: np.ndarray          # s
    phi1: np.ndarray       # rad
    R31: np.ndarray        # N, normal force the cam must exert for the kinematic motion (+ = rise)
    M: np.ndarray          # kg, reduced mass of eq. (16)
    M1: np.ndarray         # kg
    M2: np.ndarray         # kg
    arm: np.ndarray        # m, l cos(alpha) = Db2/2, arm of the normal force about D
    phi2: np.ndarray       # rad, kinematic follower angle
    omega2: np.ndarray     # rad/s
    epsilon2: np.ndarray   # rad/s^2
    MR13D: np.ndarray      # N m, kinetostatic moment about D
    alpha: np.ndarray      # rad, pressure angle
    Db1: np.ndarray        # m
    Db2: np.ndarray        # m
    omega1: float          # rad/s


def cam_speed(scene: Scene) -> float:
    """Cam angular speed (rad/s) for the scene's omega1 mode."""
    if scene.omega1_mode == "var":
        return no_load_cam_speed(scene.mechanism, scene.omega1_nominal)
    return scene.omega1_nominal


def reduced_masses(J_cam, J_follower, Db1, Db2):
    """M1, M2, M (kg) of eq. (16): M1 = 4 Jcam/Db1^2, M2 = 4 Jfollower/Db2^2, M = M1 M2/(M1+M2).

    Where the normal passes through A (Db1 = 0) the cam cannot move along it: M1 = inf, M = M2.
    """
    Db1 = np.asarray(Db1, dtype=float)
    with np.errstate(divide="ignore"):
        M1 = np.where(Db1 > 0, 4.0 * J_cam / np.where(Db1 > 0, Db1, 1.0) ** 2, np.inf)
    M2 = 4.0 * np.asarray(J_follower) / np.asarray(Db2) ** 2
    M = M2 / (1.0 + M2 / M1)          # = M1 M2 / (M1 + M2), and M2 where M1 = inf
    return M1, M2, M


def build_tables(scene: Scene, t_end: float, n_points: int = GRID_POINTS, t=None,
                 linkage: str = "exact") -> Tables:
    """Kinematic tables over 0 <= t <= t_end at the scene's cam speed (phi1 = 0 at rise start);
    ``t`` (s, array) overrides the uniform grid, evaluated at those instants (the linkage exactly
    or from its stroke spline, ``linkage="spline"``: models.mechanism.cam_tables.angle_terms)."""
    omega1 = cam_speed(scene)
    if t is not None:
        t = np.asarray(t, dtype=float)
        terms = angle_terms(scene.mechanism, scene.program, omega1 * t, _load_until(scene), linkage=linkage)
        return _tables(scene, terms, t, omega1)
    return grid_tables(scene, omega1 * t_end, n_points)


def grid_tables(scene: Scene, span: float, n_points: int = GRID_POINTS) -> Tables:
    """Tables on the uniform cam-angle grid linspace(0, span, n_points) (rad), t = phi1/omega1.

    The speed-independent terms of the grid are shared with every run of the same mechanism, law
    and span (models.mechanism.cam_tables): only the combination with the operating point is per run.
    """
    omega1 = cam_speed(scene)
    terms = grid_terms(scene.mechanism, scene.program, span, n_points, _load_until(scene))
    return _tables(scene, terms, terms.phi1 / omega1, omega1)


def _load_until(scene: Scene):
    # the load acts over the closed rise [0, rise]: at phi1 = rise exactly the dwell (no load) would
    # begin and put a step into R31 at the last instant of a rise-only run
    return float(np.nextafter(scene.program.rise_angle, 0.0)) if scene.rise_only else None


def _tables(scene: Scene, terms, t, omega1: float) -> Tables:
    mech = scene.mechanism
    op = terms.at_speed(omega1, scene.Fu, scene.jt_factor)
    arm = mech.l * np.cos(terms.alpha)
    it = transmission_ratio(mech, scene.omega1_nominal)
    M1, M2, M = reduced_masses(cam_inertia(mech, it), op["J_follower"], terms.Db1, terms.Db2)
    return Tables(t=t, phi1=terms.phi1, R31=op["MR13D"] / arm, M=M, M1=M1, M2=M2, arm=arm,
                  phi2=terms.phi2, omega2=op["omega2"], epsilon2=op["epsilon2"], MR13D=op["MR13D"],
                  alpha=terms.alpha, Db1=terms.Db1, Db2=terms.Db2, omega1=omega1)


# ---------------------------------------------------------------- pure kernels (numba-ready)

def normal_force(x, v, phase, kc, gap, damping):
    """Force of the groove on the follower along +x (N) in a given phase.

    Interior flank: penetration -x, pushes +x. Exterior flank: penetration x - gap, pushes -x.
    Flight: 0. Damping (Hunt-Crossley, s/m) acts on the penetration rate.
    """
    if phase == INTERIOR:
        return hunt_crossley_force(-x, -v, kc, damping) if damping > 0 else contact_force(-x, kc)
    if phase == EXTERIOR:
        pen = x - gap
        return -(hunt_crossley_force(pen, v, kc, damping) if damping > 0 else contact_force(pen, kc))
    return 0.0


def rhs(t, y, phase, t_grid, drive_grid, m_grid, kc, gap, damping):
    """d/dt (x, v) with M(t) v' = F(x, v) - drive(t); drive = R31 (consistent) or -R31 (literal)."""
    x, v = y[0], y[1]
    drive = np.interp(t, t_grid, drive_grid)
    m = np.interp(t, t_grid, m_grid)
    return np.array([v, (normal_force(x, v, phase, kc, gap, damping) - drive) / m])


def ev_zero(t, y, *args):
    """x = 0: the interior flank's contact boundary."""
    return y[0]


def ev_gap(t, y, phase, t_grid, drive_grid, m_grid, kc, gap, damping):
    """x = j: the exterior flank's contact boundary."""
    return y[0] - gap


def _events_for(phase, gap):
    """(event function, direction, next phase) for the boundaries of ``phase``."""
    if phase == INTERIOR:
        return [(ev_zero, 1.0, FLIGHT if gap > 0 else EXTERIOR)]
    if phase == EXTERIOR:
        return [(ev_gap, -1.0, FLIGHT if gap > 0 else INTERIOR)]
    return [(ev_zero, -1.0, INTERIOR), (ev_gap, 1.0, EXTERIOR)]


def _make_event(func, direction):
    def event(t, y, *args):
        return func(t, y, *args)
    event.terminal = True
    event.direction = direction
    return event


def initial_state(drive0: float, kc: float, gap: float):
    """Static equilibrium (x0 m, v0 = 0, phase) under the drive force at t = 0."""
    if drive0 > 0:
        return -float(static_penetration(drive0, kc)), 0.0, INTERIOR
    if drive0 < 0:
        return gap + float(static_penetration(-drive0, kc)), 0.0, EXTERIOR
    return 0.0, 0.0, FLIGHT if gap > 0 else INTERIOR


def integrate(t_grid, drive_grid, m_grid, kc, gap, damping=0.0, t_end=None, y0=None,
              rtol=1e-8, atol=(1e-13, 1e-9), max_step=np.inf, method="RK45"):
    """Integrate phase by phase with terminal events; returns (segments, events).

    segments: list of (phase, OdeSolution-backed solve_ivp result); events: list of dicts with
    t (s), kind ('leave_interior', 'land_exterior', 'leave_exterior', 'land_interior', ...), v (m/s).
    """
    t_end = float(t_grid[-1] if t_end is None else t_end)
    t0 = 0.0
    segments, events = [], []
    if y0 is None:
        x0, v0, phase = initial_state(float(drive_grid[0]), kc, gap)
        nonzero = np.flatnonzero(drive_grid)
        if drive_grid[0] == 0 and nonzero.size:
            # unloaded start: nothing moves until the drive departs from zero; then sit against the
            # flank it loads, so the run does not begin with a zero-speed "landing" or "jump"
            phase = INTERIOR if drive_grid[nonzero[0]] > 0 else EXTERIOR
            x0 = _restart_position(phase == INTERIOR, phase, gap)
            t0 = float(t_grid[nonzero[0] - 1])
            if t0 > 0:
                segments.append((phase, _AtRest(0.0, t0, x0)))
    else:
        x0, v0, phase = y0
    y = np.array([x0, v0], dtype=float)
    args = (t_grid, drive_grid, m_grid, kc, gap, damping)
    short = 0                     # consecutive phases shorter than ZENO_DT
    while t0 < t_end:
        if short >= ZENO_SEGMENTS:
            raise SolverError(f"elastic model: {ZENO_SEGMENTS} contact switches within "
                              f"{ZENO_SEGMENTS * ZENO_DT:.1g} s at t = {t0:.6g} s (endless chatter); "
                              "add contact damping or check the scene")
        specs = _events_for(phase, gap)
        evs = [_make_event(f, d) for f, d, _ in specs]
        sol = solve_ivp(rhs, (t0, t_end), y, method=method, args=(phase,) + args, events=evs,
                        dense_output=True, rtol=rtol, atol=list(atol), max_step=max_step)
        if sol.status == -1:
            raise SolverError(f"elastic model: integration failed at t = {sol.t[-1]:.6g} s: {sol.message}")
        hidden = _hidden_crossing(sol, specs, gap)
        if hidden is not None:
            sol = _Truncated(sol, hidden[1])
        segments.append((phase, sol))
        short = short + 1 if sol.t[-1] - t0 < ZENO_DT else 0
        if sol.status != 1:
            break
        if hidden is not None:
            hit, t_hit = hidden
            y_hit = np.array(sol.sol(t_hit), dtype=float)
        else:
            hit = next(i for i, te in enumerate(sol.t_events) if len(te))
            t_hit, y_hit = sol.t_events[hit][0], sol.y_events[hit][0].copy()
        new_phase = specs[hit][2]
        events.append({"t": float(t_hit), "kind": _event_kind(phase, new_phase), "v": float(y_hit[1]),
                       "from": PHASE_NAMES[phase], "to": PHASE_NAMES[new_phase]})
        # restart a hair inside the new phase: started exactly on the boundary, the new phase's own
        # boundary event can fire again on its first step from rounding alone (endless switching)
        y_hit[0] = _restart_position(specs[hit][0] is ev_zero, new_phase, gap)
        t0, y, phase = float(t_hit), y_hit, new_phase
    return segments, events


def _hidden_crossing(sol, specs, gap: float):
    """(spec index, t) of a boundary crossing that solve_ivp did not see, or None.

    solve_ivp reads an event's sign at the ends of each step only, so a crossing and its return
    within one step (a micro-bounce off a flank) is missed. The dense output is read at
    EVENT_SUBSTEPS points of every step; a crossing in the event's direction before the last
    sub-interval (which ends at solve_ivp's own event, if any) is the phase's real end, located by
    brentq on the dense output. The compiled twin
    (models.dynamics.kernels.elastic_nb._crossing) applies the same rule.
    """
    from scipy.optimize import brentq

    ts = sol.t
    if ts.size < 2:
        return None
    frac = np.arange(1, EVENT_SUBSTEPS + 1) / EVENT_SUBSTEPS
    tt = np.concatenate([[ts[0]], (ts[:-1, None] + np.diff(ts)[:, None] * frac).ravel()])
    tt[EVENT_SUBSTEPS::EVENT_SUBSTEPS] = ts[1:]             # the step ends exactly
    x = sol.sol(tt)[0]
    best = None
    for i, (func, direction, _) in enumerate(specs):
        boundary = 0.0 if func is ev_zero else gap            # x of the event's flank
        g = x - boundary
        a, b = g[:-1], g[1:]
        cross = (a <= 0) & (b >= 0) if direction > 0 else (a >= 0) & (b <= 0)
        k = np.flatnonzero(cross)
        if not k.size:
            continue
        k = int(k[0])
        if sol.status == 1 and k + 1 >= tt.size - 1:
            continue                 # the last sub-interval ends at solve_ivp's own event: its root stands
        f = lambda t, b=boundary: sol.sol(t)[0] - b  # noqa: E731
        t_hit = tt[k + 1] if f(tt[k + 1]) == 0 else brentq(f, tt[k], tt[k + 1], xtol=1e-15, rtol=4 * np.finfo(float).eps)
        if best is None or t_hit < best[1]:
            best = (i, float(t_hit))
    return best


class _Truncated:
    """A solve_ivp result cut at t_hit (a crossing found inside a step): .t, .sol, .status = 1."""

    def __init__(self, sol, t_hit: float):
        self.t = np.append(sol.t[sol.t < t_hit], t_hit)
        self.sol = sol.sol
        self.status = 1


class _AtRest:
    """A phase segment with the follower at rest at x0 over [t0, t1] (solve_ivp result look-alike)."""

    def __init__(self, t0: float, t1: float, x0: float):
        self.t = np.array([t0, t1])
        self.x0 = x0
        self.y = np.array([[x0, x0], [0.0, 0.0]])

    def sol(self, tt):
        tt = np.atleast_1d(tt)
        return np.vstack([np.full(tt.size, self.x0), np.zeros(tt.size)])


BOUNDARY_NUDGE = 1e-13   # m, how far inside the new phase a restart begins (<< any deformation)


def _restart_position(at_zero: bool, new_phase: int, gap: float) -> float:
    """x (m) just inside ``new_phase`` at the boundary x = 0 (at_zero) or x = gap."""
    eps = BOUNDARY_NUDGE if gap == 0 else min(BOUNDARY_NUDGE, 0.25 * gap)
    boundary = 0.0 if at_zero else gap
    inward = {INTERIOR: -1.0, EXTERIOR: 1.0}.get(new_phase, 1.0 if at_zero else -1.0)
    return boundary + inward * eps


def _event_kind(old, new):
    if old == INTERIOR:
        return "leave_interior"
    if old == EXTERIOR:
        return "leave_exterior"
    return "land_interior" if new == INTERIOR else "land_exterior"


def count_events(events):
    """Jumps and impacts (docs/models.md, 'counting').

    jump: the follower loses contact with the interior flank, i.e. x crosses 0 upwards (the paper's
    criterion, sec. 2.1.2: "when the relative displacement becomes equal to zero or changes the
    sign, the jump occurs"). impact: the follower comes into contact with one of the flanks after a
    flight through the gap (the paper's definition, sec. 2.1.1), i.e. every landing.
    """
    jumps = sum(1 for e in events if e["kind"] == "leave_interior")
    impacts = sum(1 for e in events if e["kind"] in ("land_exterior", "land_interior"))
    return jumps, impacts


def contact_period(kc: float, m: float, force: float) -> float:
    """Period (s) of small oscillations of a mass m (kg) on the contact loaded by force (N)."""
    force = max(abs(force), 1.0)
    k_lin = (10.0 / 9.0) * force / float(static_penetration(force, kc))
    return 2.0 * math.pi * math.sqrt(m / k_lin)


def contact_gap(scene: Scene) -> float:
    """Gap (m) between the flanks in the elastic model: the scene's backlash j, or 0 when
    ``scene.elastic_gap == "closed"`` (the convention of the paper's Table 3, docs/models.md)."""
    gap = scene.backlash
    if not (math.isfinite(gap) and gap >= 0):
        raise InputError(f"backlash must be >= 0 mm, got {gap * 1e3:g} mm")
    return 0.0 if scene.elastic_gap == "closed" else gap


def simulate(scene: Scene, reading: str = "consistent", integrate=None, preset: dict | None = None) -> "SimulationResult":
    """Elastic-contact model over the rise (or ``scene.revolutions`` cam turns if not rise_only)."""
    from models.dynamics.simulate import INDICATORS, SimulationResult

    if reading not in READINGS:
        raise InputError(f"elastic model reading must be one of {', '.join(READINGS)}, got '{reading}'")
    kc = contact_stiffness(scene.contact_length, scene.kc_factor)
    gap = contact_gap(scene)
    span = scene.program.rise_angle if scene.rise_only else 2.0 * math.pi * scene.revolutions
    n_grid = GRID_POINTS if scene.rise_only else int(GRID_POINTS * span / scene.program.rise_angle)
    tab = grid_tables(scene, span, n_grid)
    drive = tab.R31 if reading == "consistent" else -tab.R31
    preset = PRESETS[scene.accuracy] if preset is None else preset
    if integrate is None:
        # compiled twin (models.dynamics.kernels.elastic_nb) for fast/standard, solve_ivp for reference
        from models.dynamics.accuracy import integrator
        integrate = integrator("elastic", scene.accuracy)
    f_scale = max(float(np.max(np.abs(tab.R31))), 1.0)
    period = contact_period(kc, float(np.min(tab.M)), f_scale)
    x_scale = float(static_penetration(f_scale, kc))
    atol = (preset["atol"] * x_scale, preset["atol"] * x_scale * 2.0 * math.pi / period)
    segments, events = integrate(tab.t, drive, tab.M, kc, gap, scene.contact_damping,
                                 rtol=preset["rtol"], atol=atol,
                                 max_step=period / preset["steps_per_period"])
    ds = _dataset(scene, tab, segments, events, kc, gap, reading)
    ds.attrs.update(elastic_gap=scene.elastic_gap, scene_backlash_m=scene.backlash)
    jumps, impacts = count_events(events)
    x, m_static, m_contact = (ds[k].values for k in ("x_el", "MR13D_static", "MR13D"))
    ind = {k: None for k in INDICATORS}
    ind.update(
        MR13D_max_Nm=float(m_static.max()), MR13D_min_Nm=float(m_static.min()),
        xel_max_mm=float(x.max() * 1e3), xel_min_mm=float(x.min() * 1e3), jumps=jumps, impacts=impacts,
        MR13D_contact_max_Nm=float(m_contact.max()), MR13D_contact_min_Nm=float(m_contact.min()),
        deformation_max_mm=float(ds["deformation"].values.max() * 1e3),
        separations=sum(1 for e in events if e["kind"] in ("leave_exterior", "leave_interior")),
        contact_phases=len(segments), reading=reading, elastic_gap=scene.elastic_gap, contact_length_mm=scene.contact_length * 1e3,
        Kc_SI=kc,
    )
    return SimulationResult(ds, ind, "elastic")


def _dataset(scene, tab: Tables, segments, events, kc, gap, reading) -> xr.Dataset:
    """Sample every phase on a uniform time grid (plus the solver's own steps) into a Dataset."""
    t_end = tab.t[-1]
    n = max(int(math.ceil(t_end / OUTPUT_STEP)) + 1, 2)
    t_uniform = np.linspace(0.0, t_end, n)
    times = []
    for k, (phase, sol) in enumerate(segments):
        lo, hi = sol.t[0], sol.t[-1]
        a = np.searchsorted(t_uniform, lo, side="left")
        b = np.searchsorted(t_uniform, hi, side="right" if k == len(segments) - 1 else "left")
        times.append(np.concatenate([t_uniform[a:b], sol.t]))   # the solver's steps: extremes are not lost
    runs = [sol for _, sol in segments]
    from models.dynamics.kernels.dopri5 import DenseRun, evaluate_runs   # numba only when a run needs it
    if all(isinstance(r, DenseRun) for r in runs):
        y = evaluate_runs(runs, times)                          # compiled loop: one pass over all phases
    else:
        y = np.concatenate([sol.sol(tt) for sol, tt in zip(runs, times)], axis=1)
    t = np.concatenate(times)
    phase = np.repeat([ph for ph, _ in segments], [tt.size for tt in times])
    # in time order; an instant shared by two phases (an event) keeps the value of the phase that ends
    order = np.argsort(t, kind="stable")
    t, x, v, phase = t[order], y[0][order], y[1][order], phase[order]
    keep = np.concatenate([[True], np.diff(t) > 0])
    t, x, v, phase = t[keep], x[keep], v[keep], phase[keep]

    # kinematics at the output instants, not interpolated in time (the linkage from its stroke
    # spline, accurate to rounding)
    exact = build_tables(scene, t_end, t=t, linkage="spline")
    arm, R31, M = exact.arm, exact.R31, exact.M
    F = _force_vector(x, v, phase, kc, gap, scene.contact_damping)
    drive = R31 if reading == "consistent" else -R31
    a = (F - drive) / M
    darm = np.interp(t, tab.t, np.gradient(tab.arm, tab.t))
    phi2 = exact.phi2 + x / arm                                           # eq. (19)
    omega2 = exact.omega2 + v / arm                                       # eq. (19)
    epsilon2 = exact.epsilon2 + a / arm - v * darm / arm**2               # d/dt of eq. (19)
    deformation = np.where(x < 0, -x, np.where(x > gap, x - gap, 0.0))

    def var(data, units, long_name):
        return ("time", np.asarray(data, dtype=float), {"units": units, "long_name": long_name})

    ds = xr.Dataset(
        data_vars={
            "phi1": var(tab.omega1 * t, "rad", "cam angle (0 at rise start)"),
            "omega1": var(np.full(t.size, tab.omega1), "rad/s", "cam angular velocity"),
            "x_el": var(x, "m", "follower-cam relative displacement along the normal (+ towards the exterior flank)"),
            "dx_el": var(v, "m/s", "rate of x_el"),
            "contact_force": var(F, "N", "groove-on-follower normal force (+ pushes in the rise direction)"),
            "deformation": var(deformation, "m", "contact deformation of the flank in contact"),
            "contact_phase": var(phase, "1", "0 interior flank, 1 flight in the gap, 2 exterior flank"),
            "MR13D": var(F * arm, "N m", "moment about D of the cam-on-follower contact force"),
            "MR13D_static": var(exact.MR13D, "N m", "moment about D of the static reaction R31 (kinetostatic)"),
            "R31": var(R31, "N", "static reaction of the cam on the follower along the normal (+ rise)"),
            "reduced_mass": var(M, "kg", "reduced mass M of eq. (16)"),
            "phi2": var(phi2, "rad", "follower angle, eq. (19)"),
            "omega2": var(omega2, "rad/s", "follower angular velocity, eq. (19)"),
            "epsilon2": var(epsilon2, "rad/s^2", "follower angular acceleration (time derivative of eq. 19)"),
            "phi2_kin": var(exact.phi2, "rad", "kinematic follower angle"),
            "omega2_kin": var(exact.omega2, "rad/s", "kinematic follower angular velocity"),
        },
        coords={"time": ("time", t, {"units": "s", "long_name": "time from the start of the rise"})},
        attrs={
            "title": "labtool elastic-contact model (paper eqs 12-19)",
            "reading": reading, "Kc_SI": kc, "Kc_units": "N/m^(10/9)",
            "contact_length_m": scene.contact_length, "backlash_m": gap,
            "contact_damping_s_per_m": scene.contact_damping, "omega1_mode": scene.omega1_mode,
            "omega1_rad_s": tab.omega1, "law": scene.law, "Fu_N": scene.Fu, "jt_factor": scene.jt_factor,
            "event_times_s": np.array([e["t"] for e in events], dtype=float),
            "event_kinds": ",".join(e["kind"] for e in events),
        },
    )
    return ds


def _force_vector(x, v, phase, kc, gap, damping):
    """normal_force over arrays (same law, vectorised)."""
    F = np.zeros_like(x)
    i = phase == INTERIOR
    e = phase == EXTERIOR
    if damping > 0:
        F[i] = hunt_crossley_force(-x[i], -v[i], kc, damping)
        F[e] = -hunt_crossley_force(x[e] - gap, v[e], kc, damping)
    else:
        F[i] = contact_force(-x[i], kc)
        F[e] = -contact_force(x[e] - gap, kc)
    return F


def compare_table3(accuracy: str = "standard", contact_length: float | None = None, law: str = "sine",
                   elastic_gap: str = "closed"):
    """Table 1's 16 runs (omega1 variable) against the paper's Table 3: a DataFrame, one row a run.

    Columns: factors, our indicators, the paper's, and % differences for MR13D and xel.
    ``elastic_gap`` "closed" (default) is the convention Table 3 was computed with, "physical"
    lets the follower cross the backlash (docs/models.md, "the backlash in Table 3").
    """
    import pandas as pd

    from models.study.paper import read_reference, table1_runs

    t3 = read_reference("table3_elastic")
    rows = []
    for run, ref in zip(table1_runs().itertuples(), t3.itertuples()):
        extra = {} if contact_length is None else {"contact_length": contact_length}
        scene = Scene(law=law, cam_speed_rpm=run.n1_rpm, Fu=run.Fu_N, backlash=run.j_mm * 1e-3,
                      jt_factor=run.Jt_factor, omega1_mode="var", accuracy=accuracy,
                      elastic_gap=elastic_gap, **extra)
        ind = simulate(scene).indicators
        pct = lambda ours, paper: 100.0 * (ours / paper - 1.0)
        rows.append({
            "run": run.run, "Fu_N": run.Fu_N, "j_mm": run.j_mm, "n1_rpm": run.n1_rpm, "Jt": run.Jt_factor,
            "MR13D_max": ind["MR13D_max_Nm"], "paper_MR13D_max": ref.MR13D_max_Nm,
            "MR13D_max_pct": pct(ind["MR13D_max_Nm"], ref.MR13D_max_Nm),
            "MR13D_min": ind["MR13D_min_Nm"], "paper_MR13D_min": ref.MR13D_min_Nm,
            "MR13D_min_pct": pct(ind["MR13D_min_Nm"], ref.MR13D_min_Nm),
            "contact_max": ind["MR13D_contact_max_Nm"], "contact_min": ind["MR13D_contact_min_Nm"],
            "xel_max_mm": ind["xel_max_mm"], "paper_xel_max_mm": ref.xel_max_mm,
            "xel_max_pct": pct(ind["xel_max_mm"], ref.xel_max_mm),
            "xel_min_mm": ind["xel_min_mm"], "paper_xel_min_mm": ref.xel_min_mm,
            "xel_min_pct": pct(ind["xel_min_mm"], ref.xel_min_mm),
            "deformation_max_mm": ind["deformation_max_mm"],
            "jumps": ind["jumps"], "paper_jumps": int(ref.jumps),
            "impacts": ind["impacts"], "paper_impacts": int(ref.impacts),
            "separations": ind["separations"],
        })
    return pd.DataFrame(rows)
