"""Dynamic model with elastic cam-follower contact, paper section 2.1.2, eqs (12)-(19), in SI.

One degree of freedom: x (m), the displacement of the follower's contact point relative to the
cam's along the common normal, measured from the kinematic (rigid, no-backlash) motion. Sign
convention (docs/models.md, "elastic model"): x > 0 towards the exterior of the cam, which on this
mechanism is the rise direction of the follower; the interior flank (x <= 0 means penetration)
pushes the follower in the rise direction, the exterior flank (penetration x - j >= 0) pushes it
back. Phases: 0 interior contact, 1 flight in the gap (0 < x < j), 2 exterior contact.

Equation of motion (the "consistent" reading, default):

    M(t) x'' = F_int(x) - F_ext(x - j) - R31(t)

with F = Kc p^(10/9) (labtool.models.dynamics.contact), R31 = MR13D_kin / (l cos alpha) the normal force the cam
must exert to impose the kinematic motion (positive: pushes in the rise direction), and
M = M1 M2 / (M1 + M2), M1 = 4 Jcam / Db1^2, M2 = 4 J''red / Db2^2 (eqs 16-18). The paper's literal
eqs (12)-(14) read M x'' + Kc x^n = R31, i.e. the same with the sign of R31 reversed: a positive
(pushing) static reaction would then separate the follower from the flank that pushes it. That
reading is kept selectable (``reading="literal"``) and documented, not used by default.

The gap j between the flanks is the scene's backlash (``elastic_gap = "physical"``), or 0 with
``elastic_gap = "closed"``: the convention the paper's Table 3 was computed with (its indicators do
not depend on j and its xel max stays below j; docs/models.md, "The backlash in Table 3").

The cam turns at constant speed: n1 (omega1 'const') or n1 * n_sync / n_nominal (omega1 'var',
the speed the paper's variable-speed drive settles at; labtool.models.dynamics.kinematic.cam_speed).

The equations, events, restart and initial state are compiled once
(labtool.models.dynamics.kernels.elastic_nb); ``integrate`` runs them in the shared compiled Dormand-Prince
loop (fast, standard) or in scipy's solve_ivp (reference). This module builds the tables, samples
the run into a Dataset, completes the event record and computes the indicators.

Events (labtool.models.dynamics.events): a separation when x leaves a flank's contact range, a contact when
a flight ends on a flank. A landing's impact window is its bounce time (the duration of a free
undamped landing at that speed on the contact law, ``bounce_time``) or the contact, whichever is
shorter: ``event_domega2`` is the change of x'/(l cos alpha) over it, ``event_percussion`` the
contact force's impulse over it (from the momentum balance, ``complete_events``); a contact that
lasts more than twice its bounce time (or to the end of the run) is persistent, and so is a
separation from one.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from labtool.common.errors import InputError, SolverError
from labtool.models.dynamics import events, validity
from labtool.models.dynamics.contact import N_EXP, contact_stiffness, penetration_under
from labtool.models.dynamics.compiling import announces
from labtool.models.dynamics.kernels import dopri5 as dp
from labtool.models.dynamics.kernels import elastic_nb as eq
from labtool.models.dynamics.kinematic import cam_speed
from labtool.models.dynamics.result import DatasetParts, SimulationResult, empty_indicators
from labtool.models.dynamics.scene import Scene
from labtool.models.dynamics.jit import jit, kernel
from labtool.models.mechanism.cam_profile import cached_sense, pitch_geometry
from labtool.models.mechanism.cam_tables import AngleTerms, angle_terms, grid_terms, load_arm, operating_point, stroke_spline
from labtool.models.mechanism.memo import cached
from labtool.models.mechanism.motor import cam_inertia, motor_moment_on_cam, transmission_ratio

INTERIOR, FLIGHT, EXTERIOR = eq.INTERIOR, eq.FLIGHT, eq.EXTERIOR
READINGS = ("consistent", "literal")

# solver presets: relative tolerance; absolute tolerances as fractions of the scene's own scales
# (the static deflection under the largest |R31| for x, that times the contact's angular frequency
# for dx/dt), so that a stiffer contact (smaller x) is resolved as well as a soft one; max_step as a
# fraction of the linearised contact period, in the contact phases, and in flight too where
# ``cap_flight`` (a flight has no contact to resolve: the fast and standard presets' flights are
# limited by their tolerances alone, which cuts Table 1's steps by 12 % at the same measured
# accuracy, labtool.models.dynamics.accuracy.MEASURED); the reference preset runs scipy's DOP853 (8th order,
# another method than the compiled Dormand-Prince 5(4): an independent check of the numerics)
PRESETS = {
    "fast": dict(rtol=1e-6, atol=1e-5, steps_per_period=4.0, cap_flight=False),
    "standard": dict(rtol=1e-8, atol=1e-7, steps_per_period=8.0, cap_flight=False),
    "reference": dict(rtol=1e-10, atol=1e-9, steps_per_period=16.0, cap_flight=True, method="DOP853"),
}
SOLVERS = {"fast": "compiled", "standard": "compiled", "reference": "scipy"}
OUTPUT_STEP = 2e-5        # s, output sampling (>= 25 samples per contact period of ~0.5 ms)
GRID_POINTS = 4001        # cam-angle grid for the kinematic tables (linear interpolation in time)
ZENO_SEGMENTS = 200       # this many phases in a row, each shorter than ZENO_DT, is endless chatter
ZENO_DT = 1e-9            # s
# the event functions' sign is read at this many points of every step (its dense output), not at
# the step's ends only: a micro-bounce that leaves a flank and returns within one step is an event
EVENT_SUBSTEPS = 8
BOUNDARY_NUDGE = eq.NUDGE  # m, how far inside the new phase a restart begins
MAX_STEPS = 2_000_000      # accepted steps per run (memory ~100 B a step)
MAX_SEGMENTS = 1_000_000   # phases per run
PERSISTENT_BOUNCES = 2.0   # a contact longer than this many bounce times is persistent
DRIVE_POINTS = 17          # samples of the drive's impulse over a landing's impact window
_DRIVE_FRACTIONS = np.linspace(0.0, 1.0, DRIVE_POINTS)


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


def mass_factor(Db1: float, Db2: float, arm: float) -> tuple:
    """The speed-independent factors of eq. (16) and of R31 = MR13D / arm at one angle, so that a
    run's tables take one division an angle instead of five: (4 / Db1^2 (inf where Db1 <= 0: the
    normal passes through A), 4 / Db2^2, Db1^2 / Db2^2 (0 there), 1 / arm), in 1/m^2, 1/m^2, 1
    and 1/m (Db, arm m; floats). Compiled inline into ``_mass_factors`` and ``_step_terms``."""
    if Db1 > 0.0:
        c1, rho = 4.0 / (Db1 * Db1), (Db1 * Db1) / (Db2 * Db2)
    else:
        c1, rho = math.inf, 0.0
    return c1, 4.0 / (Db2 * Db2), rho, 1.0 / arm


_mass_factor = kernel(mass_factor, inline="always", internal=True)


@kernel
def _mass_factors(Db1, Db2, arm, out):
    for i in range(arm.size):
        out[0, i], out[1, i], out[2, i], out[3, i] = _mass_factor(Db1[i], Db2[i], arm[i])


def mass_factors(Db1, Db2, arm) -> tuple:
    """``mass_factor`` at each angle (Db1, Db2, arm m, arrays of one size): (c1, c2, rho, inv_arm)."""
    Db1, Db2, arm = (np.ascontiguousarray(a, dtype=float).ravel() for a in (Db1, Db2, arm))
    out = np.empty((4, arm.size))
    _mass_factors(Db1, Db2, arm, out)
    return tuple(out)


@kernel(inline="always")
def _reduced_mass(J_cam, inv_J_cam, J_follower, c1, c2, rho):
    """M1, M2, M (kg) of eq. (16) at one angle: M1 = 4 Jcam/Db1^2, M2 = 4 Jfollower/Db2^2,
    M = M1 M2/(M1+M2) = M2 / (1 + M2/M1), with M2/M1 = (Jfollower/Jcam) Db1^2/Db2^2 (J kg m^2;
    inv_J_cam = 1/Jcam; c1, c2, rho the angle's ``mass_factors``). Where the normal passes through
    A (Db1 = 0) the cam cannot move along it: M1 = inf, M = M2."""
    M2 = J_follower * c2
    return J_cam * c1, M2, M2 / (1.0 + J_follower * inv_J_cam * rho)


_point = kernel(operating_point, inline="always", internal=True)     # the mechanism's combination, compiled
_pitch = kernel(pitch_geometry, internal=True)       # the groove's geometry, compiled
_load_arm = kernel(load_arm, internal=True)


@kernel
def _operating_tables(dpsi, ddpsi, J0, dJ0, M_gravity, m_load, c1, c2, rho, inv_arm, omega1, Fu, jt_factor, J_cam,
                      out):
    """``_tables``' per-angle arithmetic in one pass (cam_tables.operating_point, _reduced_mass and
    R31 = MR13D / arm; c1 .. inv_arm the ``mass_factors``): rows of ``out`` omega2, epsilon2,
    MR13D, M1, M2, M, R31."""
    inv_J_cam = 1.0 / J_cam
    for i in range(dpsi.size):
        omega2, epsilon2, moment, J = _point(dpsi[i], ddpsi[i], J0[i], dJ0[i], M_gravity[i], m_load[i],
                                             omega1, Fu, jt_factor)
        M1, M2, M = _reduced_mass(J_cam, inv_J_cam, J, c1[i], c2[i], rho[i])
        out[0, i], out[1, i], out[2, i] = omega2, epsilon2, moment
        out[3, i], out[4, i], out[5, i], out[6, i] = M1, M2, M, moment * inv_arm[i]


def build_tables(scene: Scene, t_end: float, n_points: int = GRID_POINTS, t=None,
                 linkage: str = "exact") -> Tables:
    """Kinematic tables over 0 <= t <= t_end at the scene's cam speed (phi1 = 0 at rise start);
    ``t`` (s, array) overrides the uniform grid, evaluated at those instants (the linkage exactly
    or from its stroke spline, ``linkage="spline"``: labtool.models.mechanism.cam_tables.angle_terms)."""
    omega1 = cam_speed(scene)
    if t is not None:
        t = np.asarray(t, dtype=float)
        terms = angle_terms(scene.mechanism, scene.program, omega1 * t, _until(scene), linkage=linkage)
        return _tables(scene, terms, t, omega1)
    return grid_tables(scene, omega1 * t_end, n_points)


def grid_tables(scene: Scene, span: float, n_points: int = GRID_POINTS) -> Tables:
    """Tables on the uniform cam-angle grid linspace(0, span, n_points) (rad), t = phi1/omega1.

    The speed-independent terms of the grid are shared with every run of the same mechanism, law
    and span (labtool.models.mechanism.cam_tables): only the combination with the operating point is per run.
    """
    omega1 = cam_speed(scene)
    terms = grid_terms(scene.mechanism, scene.program, span, n_points, _until(scene))
    block = _angle_block(scene, span, n_points)
    return _tables(scene, terms, terms.phi1 / omega1, omega1, block[_ARM], block[_FACTORS])


def _until(scene: Scene):
    # a rise-only run covers the closed rise [0, rise]: at phi1 = rise exactly the dwell would begin
    # (no acceleration, no load) and put a step into R31 at the run's last instant; the kinematics
    # there are the rise's left limit
    return float(np.nextafter(scene.program.rise_angle, 0.0)) if scene.rise_only else None


def _arm(mech, alpha):
    """l cos(alpha) (m), the normal force's arm about D, at pressure angles alpha (rad)."""
    return mech.l * np.cos(alpha)


def _tables(scene: Scene, terms, t, omega1: float, arm=None, factors=None) -> Tables:
    """``arm``, ``factors``: ``_arm`` of terms.alpha and the ``mass_factors`` when the caller has
    them (speed-independent, cached)."""
    mech = scene.mechanism
    arm = _arm(mech, terms.alpha) if arm is None else arm
    factors = mass_factors(terms.Db1, terms.Db2, arm) if factors is None else factors
    it = transmission_ratio(mech, scene.omega1_nominal)
    rows = np.empty((7, t.size))
    _operating_tables(*(np.ascontiguousarray(a, dtype=float) for a in (terms.dpsi, terms.ddpsi, terms.J0, terms.dJ0,
                                                                       terms.M_gravity, terms.m_load, *factors)),
                      float(omega1), float(scene.Fu), float(scene.jt_factor), float(cam_inertia(mech, it)), rows)
    omega2, epsilon2, MR13D, M1, M2, M, R31 = rows
    return Tables(t=t, phi1=terms.phi1, R31=R31, M=M, M1=M1, M2=M2, arm=arm, phi2=terms.phi2, omega2=omega2,
                  epsilon2=epsilon2, MR13D=MR13D, alpha=terms.alpha, Db1=terms.Db1, Db2=terms.Db2, omega1=omega1)


# ---------------------------------------------------------------- the integration

class AtRest:
    """A phase with the follower at rest at x0 over [t0, t1] (the unloaded start)."""

    def __init__(self, t0: float, t1: float, x0: float):
        self.t = np.array([t0, t1])
        self.x0 = x0

    def __call__(self, tt):
        tt = np.atleast_1d(tt)
        return np.vstack([np.full(tt.size, self.x0), np.zeros(tt.size)])

    @property
    def sol(self):
        return self


def model_struct(t_grid, drive_grid, m_grid, kc, gap, damping=0.0, omega1=0.0) -> eq.ElasticModel:
    """The compiled model of a run (kernels.elastic_nb.ElasticModel)."""
    tab = np.ascontiguousarray(np.vstack([t_grid, drive_grid, m_grid]), dtype=np.float64)
    return eq.ElasticModel(tab, float(kc), float(gap), float(damping), float(omega1), float(BOUNDARY_NUDGE),
                           float(eq.grid_rate(tab[eq.TG])))


def integrate(t_grid, drive_grid, m_grid, kc, gap, damping=0.0, t_end=None, y0=None,
              rtol=1e-8, atol=(1e-13, 1e-9), max_step=np.inf, solver="compiled", method="RK45",
              max_steps=MAX_STEPS, max_segments=MAX_SEGMENTS, omega1=0.0, stats=None, model=None, raw=False):
    """Integrate M x'' = F - drive over the grid, phase by phase: (segments, event rows).

    segments: list of (phase, run) with ``run.t`` the step times and ``run(t)`` the dense output
    (x m, x' m/s); event rows: array (n, dopri5.EV_WIDTH) in labtool.models.dynamics.events' layout (the
    impact columns of landings not yet completed: ``simulate`` does that). ``y0`` = (x0, v0, phase)
    or None for the model's start (static equilibrium; with no drive at the start, at rest until it
    departs from zero). ``solver``: "compiled" (Dormand-Prince 5(4) of kernels.dopri5) or "scipy"
    (solve_ivp with ``method``). ``max_step`` (s): one for every phase, or one a mode (INTERIOR,
    FLIGHT, EXTERIOR: ``step_caps``). ``stats`` (dict) receives nfev and n_steps. ``model``: the
    ``model_struct`` of these arguments when the caller has it already. ``raw``: a compiled run
    that starts at t = 0 returns ``(None, rows, out)`` instead, ``out`` the loop's own arrays
    (kernels.dopri5.run, read by ``_raw_outputs``) without a Python object per phase; any other
    run returns its segments as without ``raw``.
    """
    tg = np.asarray(t_grid, dtype=float)
    model = model_struct(tg, drive_grid, m_grid, kc, gap, damping, omega1) if model is None else model
    t_end = float(tg[-1] if t_end is None else t_end)
    if y0 is None:
        phase, t0, x0, v0 = eq.start(model)
    else:
        (x0, v0, phase), t0 = y0, 0.0
    caps = np.minimum(np.broadcast_to(np.asarray(max_step, dtype=float), (3,)), t_end)   # one for all modes or one each
    ctl = dp.Controls(float(rtol), np.tile(np.asarray(atol, dtype=float), (3, 1)), caps, t_end, True,
                      int(max_steps), int(max_segments), EVENT_SUBSTEPS, ZENO_SEGMENTS, ZENO_DT, 2)
    ph0 = np.zeros(dp.PHASE_WIDTH)
    ph0[0] = phase
    y_start = np.array([x0, v0], dtype=float)
    if solver == "compiled":
        if method != "RK45":
            raise InputError("the compiled loop is Dormand-Prince 5(4) (RK45) only")
        out = dp.run(model, ctl, ph0, y_start, float(t0))
        if raw and t0 == 0:
            status, t_fail, nst, nev, nfev = out[0], out[1], out[3], out[5], out[6]
            _count(stats, nfev, nst)
            _raise_for(status, t_fail, max_steps, max_segments)
            return None, out[15][:nev].copy(), out
        status, t_fail, _, phases, rows, nfev, nst = dp.unpack(out, lambda row: 2)
    else:
        from labtool.models.dynamics import reference      # scipy's solve_ivp: loaded when a reference run needs it
        status, t_fail, _, phases, rows, nfev, nst = reference.run(model, eq, ctl, ph0, y_start, float(t0),
                                                                   method=method, name="elastic model")
    _count(stats, nfev, nst)
    _raise_for(status, t_fail, max_steps, max_segments)
    segments = [(int(p.row[0]), p.sol) for p in phases]
    if t0 > 0:
        segments.insert(0, (int(phase), AtRest(0.0, float(t0), float(x0))))
    return (segments, rows, None) if raw else (segments, rows)


def _count(stats, nfev: int, nst: int) -> None:
    if stats is not None:
        stats["nfev"] = stats.get("nfev", 0) + int(nfev)
        stats["n_steps"] = stats.get("n_steps", 0) + int(nst)


def _raise_for(status: int, t_fail: float, max_steps: int, max_segments: int) -> None:
    if status == dp.OK:
        return
    if status == dp.NO_PROGRESS:
        raise SolverError(f"elastic model: {ZENO_SEGMENTS} contact switches within {ZENO_SEGMENTS * ZENO_DT:.1g} s "
                          f"at t = {t_fail:.6g} s (endless chatter); add contact damping or check the scene")
    if status == dp.TOO_MANY_EVENTS:
        raise SolverError(f"elastic model: more than {max_segments} contact phases before t = {t_fail:.4g} s "
                          "(the phase cap per run)")
    raise SolverError(f"elastic model: {dp.STATUS_TEXT[status]} at t = {t_fail:.6g} s "
                      f"(limits: {max_steps} steps, {max_segments} phases per run)")


@jit
def step_caps(contact_cap: float, cap_flight: bool = True) -> np.ndarray:
    """The largest step (s) of each mode (INTERIOR, FLIGHT, EXTERIOR): ``contact_cap`` in contact,
    and in flight too if ``cap_flight``, else none (the tolerances alone). The loop still reads a
    flight's event signs at least every contact_cap / EVENT_SUBSTEPS s (kernels.dopri5)."""
    caps = np.full(3, float(contact_cap))
    if not cap_flight:
        caps[FLIGHT] = np.inf
    return caps


@jit(internal=True)
def _nan_min(a, b):
    """np.minimum of two floats (NaN if either is)."""
    if a != a or b != b:
        return np.nan
    return a if a < b else b


@jit
def _tolerances(R31, M, kc, atol_frac, steps_per_period, cap_flight, t_end):
    """A run's absolute tolerances and step caps from its tables (R31 N, M kg on the grid), the
    contact stiffness kc (N/m^(10/9)), the preset's atol fraction, steps per contact period and
    flight cap, and its end t_end (s): (atol (2,): m and m/s, caps (3,): s a mode, at most t_end).
    The scales (PRESETS' comment): the static deflection under the largest |R31| (at least 1 N)
    and that times the contact's angular frequency at the smallest M. NaN in R31 or M makes them
    NaN, as numpy's max and min would."""
    f, m_min, f_nan, m_nan = -np.inf, np.inf, False, False
    for i in range(R31.size):                      # no branch: a chain of compares cost 3x more
        a, mass = abs(R31[i]), M[i]
        f = a if a > f else f
        m_min = mass if mass < m_min else m_min
        f_nan |= a != a
        m_nan |= mass != mass
    f = np.nan if f_nan else f
    m_min = np.nan if m_nan else m_min
    f_scale = 1.0 if 1.0 > f else f                # max(f, 1.0)
    period = contact_period(kc, m_min, f_scale)
    x_scale = penetration_under(f_scale, kc)
    atol = np.empty(2)
    atol[0], atol[1] = atol_frac * x_scale, atol_frac * x_scale * 2.0 * math.pi / period
    caps = step_caps(period / steps_per_period, cap_flight)
    for mode in range(3):
        caps[mode] = _nan_min(caps[mode], t_end)
    return atol, caps


@jit
def contact_period(kc: float, m: float, force: float) -> float:
    """Period (s) of small oscillations of a mass m (kg) on the contact loaded by force (N)."""
    force = max(abs(force), 1.0)
    k_lin = (10.0 / 9.0) * force / float(penetration_under(float(force), float(kc)))
    return 2.0 * math.pi * math.sqrt(m / k_lin)


# int_0^1 du / sqrt(1 - u^(n+1)) = B(1/(n+1), 1/2) / (n+1), the beta function from gammas (scipy.special.beta's value)
_BOUNCE_INTEGRAL = (math.gamma(1.0 / (N_EXP + 1.0)) * math.gamma(0.5) / math.gamma(1.0 / (N_EXP + 1.0) + 0.5)
                    / (N_EXP + 1.0))


def bounce_time(kc: float, m: float, v: float) -> float:
    """Duration (s) of a free undamped landing of a mass m (kg) at speed v (m/s) on the contact law:
    2 p_max / v * int_0^1 du / sqrt(1 - u^(n+1)), p_max = ((n+1) m v^2 / (2 Kc))^(1/(n+1)); inf
    at v = 0. Floats; compiled inline into ``complete_events``' kernels too."""
    v = abs(v)
    if not v > 0.0:
        return math.inf
    p_max = ((N_EXP + 1.0) * m * v * v / (2.0 * kc)) ** (1.0 / (N_EXP + 1.0))
    return 2.0 * p_max / v * _BOUNCE_INTEGRAL


_bounce_time = kernel(bounce_time, internal=True)


def contact_gap(scene: Scene) -> float:
    """Gap (m) between the flanks in the elastic model: the scene's backlash j, or 0 when
    ``scene.elastic_gap == "closed"`` (the convention of the paper's Table 3, docs/models.md)."""
    gap = scene.backlash
    if not (math.isfinite(gap) and gap >= 0):
        raise InputError(f"backlash must be >= 0 mm, got {gap * 1e3:g} mm")
    return 0.0 if scene.elastic_gap == "closed" else gap


# ---------------------------------------------------------------- the event record

DRIVE_POINTS = 17          # samples of the drive's impulse over a landing's impact window


@dataclass(frozen=True)
class PhaseTable:
    """A run's contact phases in time order: their first and last instants (s) and its dense
    output, ``state_at(which, times)`` -> array (2, n): (x m, x' m/s) at times[i] (s) on phase
    which[i] (an integer array), each time read on the steps of its own phase only."""

    starts: np.ndarray
    ends: np.ndarray
    state_at: object


def phase_table(segments=None, raw=None) -> PhaseTable:
    """The ``PhaseTable`` of ``integrate``'s segments, or of its raw loop arrays (``raw=True``):
    the same instants and values (the same steps, read with ``dp.evaluate_steps``' arithmetic;
    compiled, ``dp.evaluate_at``, on the raw arrays)."""
    if raw is None:
        runs = [run for _, run in segments]
        return PhaseTable(np.array([run.t[0] for run in runs]), np.array([run.t[-1] for run in runs]),
                          lambda which, times: dp.evaluate_at_runs(runs, which, times))
    nst, nph = raw[3], raw[4]
    first = raw[14][:nph]
    last = np.append(first[1:] - 1, nst - 1)
    store = (raw[7][:nst], raw[8][:nst], raw[9][:nst], raw[10][:nst])

    def state_at(which, times):
        out = np.empty((2, times.size))              # evaluate_steps' values, compiled
        dp.evaluate_at(times, first[which], last[which], np.full(times.size, 2, dtype=np.int64), *store, out)
        return out

    return PhaseTable(raw[12][:nph], raw[13][:nph], state_at)


def complete_events(rows, phases: "PhaseTable", model: eq.ElasticModel, tab: Tables):
    """The impact columns of the landings (module doc) and the persistence of every row, in place;
    ``phases``: the run's contact phases (``phase_table``).

    Over a landing's impact window [t_c, t_w] the equation of motion M x'' = F - drive gives the
    contact force's impulse as the momentum change plus the drive's impulse, M (v_w - v_c) +
    int drive dt (M varies by far less than 1e-3 over a window): two dense-output values a landing.
    Two compiled passes around the dense output (a run has a handful of landings, and numpy's
    calls on arrays that short cost ~0.15 ms a run, as much as the impulses' arithmetic 100 times)."""
    if not rows.size:
        return rows
    tg, mass, drive = model.tab[eq.TG], model.tab[eq.MASS], model.tab[eq.DRIVE]
    row, which, times, persistent = _landing_windows(rows, phases.starts, phases.ends, tg, mass, model.kc)
    v = phases.state_at(which, times)[1] if row.size else times
    _landing_impulses(rows, row, times, v, tg, mass, drive, tab.t, tab.arm, _DRIVE_FRACTIONS, persistent)
    return rows


@kernel
def _interp(x, xp, fp):
    """np.interp(x, xp, fp) at one float x (xp increasing): numpy's own arithmetic (the slope of
    the interval, then from its right end where the left one gives NaN), compiled without numba's
    np.interp, which allocates for a scalar."""
    n = xp.size
    if x != x:
        return x
    if x <= xp[0]:
        return fp[0]
    if x >= xp[n - 1]:
        return fp[n - 1]
    lo, hi = 0, n - 1                                   # xp[lo] <= x < xp[hi]
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if xp[mid] <= x:
            lo = mid
        else:
            hi = mid
    if xp[lo] == x:
        return fp[lo]
    slope = (fp[hi] - fp[lo]) / (xp[hi] - xp[lo])
    y = slope * (x - xp[lo]) + fp[lo]
    if y != y:
        y = slope * (x - xp[hi]) + fp[hi]
        if y != y and fp[lo] == fp[hi]:
            y = fp[lo]
    return y


@jit
def _landing_windows(rows, starts, ends, tg, mass, kc):
    """``complete_events``' first pass over the event rows (columns events.COL_*): zero every
    landing's impact columns, and return (the rows of the landings that start a contact phase,
    the phase each starts twice over, their windows' first instants t_c then their last ones t_w
    (s), the landings' persistence by row). A landing's contact is the last phase beginning at its
    instant (none at the run's end); its window is the bounce time or the contact, the shorter."""
    n, last = rows.shape[0], starts.size - 1
    persistent = np.zeros(n, dtype=np.bool_)
    phase = np.full(n, -1, dtype=np.int64)
    t_end = np.empty(n)
    m = 0
    for i in range(n):
        if rows[i, events.COL_KIND] != events.KIND_CONTACT:
            continue
        t = rows[i, events.COL_TIME]
        k = min(max(np.searchsorted(starts, t, side="right") - 1, 0), last)
        has = starts[k] == t
        duration = ends[k] - t if has else 0.0
        tau = _bounce_time(kc, _interp(t, tg, mass), rows[i, events.COL_V_REL])
        persistent[i] = not has or duration > PERSISTENT_BOUNCES * tau or ends[k] >= ends[last]
        rows[i, events.COL_PERCUSSION] = 0.0
        rows[i, events.COL_DOMEGA2] = 0.0
        if has:
            phase[i] = k
            t_end[i] = t + min(duration, tau)
            m += 1
    row = np.empty(m, dtype=np.int64)
    which = np.empty(2 * m, dtype=np.int64)
    times = np.empty(2 * m)
    q = 0
    for i in range(n):
        if phase[i] >= 0:
            row[q], which[q], which[m + q] = i, phase[i], phase[i]
            times[q], times[m + q] = rows[i, events.COL_TIME], t_end[i]
            q += 1
    return row, which, times, persistent


@kernel
def _landing_impulses(rows, row, times, v, tg, mass, drive, tab_t, tab_arm, fractions, persistent):
    """``complete_events``' second pass: the impact columns of the landings ``row`` from their
    windows ``times`` and the velocities x' (m/s) ``v`` there (``_landing_windows``' order), the
    drive's impulse by the trapezoidal rule on ``fractions`` of the window (numpy.trapezoid's
    terms, summed in order); then every row's persistence (a separation ends the contact the last
    landing, or the start of the run, began)."""
    m = row.size
    for q in range(m):
        t_c, t_w = times[q], times[m + q]
        dv = v[m + q] - v[q]
        impulse, t0, d0 = 0.0, t_c, _interp(t_c + (t_w - t_c) * fractions[0], tg, drive)
        for f in range(1, fractions.size):
            t1 = t_c + (t_w - t_c) * fractions[f]
            d1 = _interp(t1, tg, drive)
            impulse += (t1 - t0) * (d1 + d0) / 2.0
            t0, d0 = t1, d1
        M = 0.5 * (_interp(t_c, tg, mass) + _interp(t_w, tg, mass))
        rows[row[q], events.COL_PERCUSSION] = abs(M * dv + impulse)
        rows[row[q], events.COL_DOMEGA2] = dv / _interp(t_c, tab_t, tab_arm)
    since = True
    for i in range(rows.shape[0]):
        if rows[i, events.COL_KIND] == events.KIND_SEPARATION:
            persistent[i], since = since, True
        else:
            since = persistent[i]
        rows[i, events.COL_PERSISTENT] = 1.0 if persistent[i] else 0.0


# ---------------------------------------------------------------- the model

@announces("the elastic model")
def simulate(scene: Scene, reading: str = "consistent", solver: str | None = None, preset: dict | None = None,
             stats: dict | None = None) -> SimulationResult:
    """Elastic-contact model over the rise (or ``scene.revolutions`` cam turns if not rise_only).

    ``solver`` ("compiled" or "scipy") and ``preset`` (a dict like PRESETS[...]) override what
    ``scene.accuracy`` selects; ``stats`` (dict) receives nfev, n_steps and loop_s (s in the loop).
    """
    run = _solve(scene, reading, solver, preset, stats, raw=True)
    phases = phase_table(run.segments, run.raw)
    complete_events(run.rows, phases, run.model, run.tab)
    record = events.from_rows(run.rows)
    outputs = _outputs(run.tab, run.segments) if run.raw is None else _raw_outputs(run.tab, run.raw)
    parts, cols = _dataset(scene, run, reading, record, outputs)
    ind = _indicators(scene, cols, events.columns(record), phases.starts.size, reading, run.kc)
    warnings = run.warnings + validity.elastic_after(scene, cols, ind)
    parts.attrs["validity_warnings"] = validity.attribute(warnings)
    return SimulationResult(parts, ind, "elastic", warnings=warnings)


@announces("the elastic model")
def simulate_indicators(scene: Scene, reading: str = "consistent", solver: str | None = None,
                        preset: dict | None = None, stats: dict | None = None) -> dict:
    """The paper's Table 3 indicators of ``simulate`` (result.INDICATORS; those this model does not
    compute None), without its Dataset: the same loop, the same output instants and the same
    values (MR13D and x_el extremes, jumps, impacts). The refusals of ``simulate`` are the same
    (the motor's stall, the solver's failures, the deformation's range); its warnings are not made
    (the energy balance needs the contact force and the geometry at every output instant).

    A compiled run that starts loaded (nearly all) goes through one compiled pass, tables to counts
    (``_indicator_pass``); ``stats["loop_s"]`` is then that whole pass. A scipy run, or one whose
    drive is zero at the start (at rest until it departs), takes the general path."""
    preset = PRESETS[scene.accuracy] if preset is None else preset
    solver = SOLVERS[scene.accuracy] if solver is None else solver
    if solver != "compiled" or preset.get("method", "RK45") != "RK45" or reading not in READINGS:
        return _general_indicators(scene, reading, solver, preset, stats)
    validity.check_scene(scene)
    kc = contact_stiffness(scene.contact_length, scene.kc_factor)
    gap = contact_gap(scene)
    span, n_grid = _span(scene)
    omega1 = cam_speed(scene)
    mech = scene.mechanism
    block = _angle_block(scene, span, n_grid)
    it = transmission_ratio(mech, scene.omega1_nominal)
    check_motor = scene.omega1_mode == "var"
    motor0 = float(motor_moment_on_cam(mech, 0.0, it)) if check_motor else 0.0
    t_end = float(block[0, -1] / omega1)
    g = _grid_terms(scene, omega1, t_end, geometry=False)
    loop_stats = {} if stats is None else stats
    t0 = time.perf_counter()
    code, vals, rows = _indicator_pass(
        block, float(omega1), float(scene.Fu), float(scene.jt_factor), float(cam_inertia(mech, it)), check_motor,
        motor0, 1.0 if reading == "consistent" else -1.0, float(kc), float(gap), float(scene.contact_damping),
        float(preset["rtol"]), float(preset["atol"]), float(preset["steps_per_period"]),
        bool(preset.get("cap_flight", True)), _uniform_grid(t_end), g.dpsi, g.ddpsi, g.J0, g.dJ0, g.M_gravity,
        g.m_load)
    if code == _STALLS:
        raise validity.motor_stall(float(block[0, int(vals[_K_STALL])]))
    if code == _STARTS_AT_REST:
        return _general_indicators(scene, reading, solver, preset, stats)
    loop_stats["loop_s"] = loop_stats.get("loop_s", 0.0) + time.perf_counter() - t0
    _count(stats, int(vals[_NFEV]), int(vals[_NSTEPS]))
    _raise_for(code, vals[_T_FAIL], MAX_STEPS, MAX_SEGMENTS)
    ind = empty_indicators()
    ind.update(_table3((vals[_X_MAX], vals[_X_MIN]), (vals[_M_MAX], vals[_M_MIN]), rows,
                       events.flights_in_rows, events.impacts_in_rows))
    validity.deformation_range(scene, float(vals[_D_MAX]), int(vals[_D_PHASE]), float(vals[_D_PHI1]))
    return ind


def _general_indicators(scene: Scene, reading: str, solver, preset, stats) -> dict:
    """``simulate_indicators`` through ``_solve`` and the loop's own arrays (any solver)."""
    run = _solve(scene, reading, solver, preset, stats, raw=True)
    t, x, _, phase, _ = _outputs(run.tab, run.segments) if run.raw is None else _raw_outputs(run.tab, run.raw)
    cols = {"deformation": _deformation(x, run.model.gap), "contact_phase": phase, "phi1": run.tab.omega1 * t}
    ind = empty_indicators()
    ind.update(_table3(_extremes(x), kinetostatic_extremes(scene, run.tab), events.columns(events.from_rows(run.rows))))
    validity.elastic_after(scene, cols, ind)
    return ind


def _span(scene: Scene) -> tuple:
    """(cam angle a run covers, rad; points of its tables' grid)."""
    span = scene.program.rise_angle if scene.rise_only else 2.0 * math.pi * scene.revolutions
    return span, (GRID_POINTS if scene.rise_only else int(GRID_POINTS * span / scene.program.rise_angle))


_ANGLE_ROWS = ("phi1", "dpsi", "ddpsi", "J0", "dJ0", "M_gravity", "m_load", "Db2", "arm", "c1", "c2", "rho",
               "inv_arm")
_ARM = _ANGLE_ROWS.index("arm")
_FACTORS = slice(_ANGLE_ROWS.index("c1"), _ANGLE_ROWS.index("inv_arm") + 1)     # mass_factors' rows


def _angle_block(scene: Scene, span: float, n_points: int) -> np.ndarray:
    """``grid_tables``' speed-independent inputs stacked, rows _ANGLE_ROWS (the grid_terms', the
    arm ``_arm`` and the ``mass_factors``), per process."""
    mech, until = scene.mechanism, _until(scene)

    def build():
        terms = grid_terms(mech, scene.program, span, n_points, until)
        arm = _arm(mech, terms.alpha)
        factors = dict(zip(("c1", "c2", "rho", "inv_arm"), mass_factors(terms.Db1, terms.Db2, arm)))
        return np.vstack([arm if name == "arm" else factors[name] if name in factors else getattr(terms, name)
                          for name in _ANGLE_ROWS])
    return cached(("elastic_angle_block", mech.cache_key, scene.program, float(span), int(n_points), until), build)


# what ``_indicator_pass`` returns beside dopri5's status codes, and the layout of its values
_STALLS, _STARTS_AT_REST = 100, 101
_T_FAIL, _K_STALL, _X_MAX, _X_MIN, _D_MAX, _D_PHASE, _D_PHI1, _M_MAX, _M_MIN, _NFEV, _NSTEPS = range(11)


@jit
def _indicator_pass(block, omega1, Fu, jt_factor, J_cam, check_motor, motor0, sign, kc, gap, damping,
                    rtol, atol_frac, steps_per_period, cap_flight, grid, dpsi, ddpsi, J0, dJ0, M_gravity, m_load):
    """``simulate_indicators``' run in one compiled pass, the same arithmetic as the general path in
    its order: the tables (``_tables``) on the angle grid ``block`` (rows _ANGLE_ROWS) at the cam
    speed omega1 (rad/s); the motor's energy budget (validity.elastic_before) if ``check_motor``;
    the scales, tolerances and step caps of ``_solve``; the loop (dopri5.run, what ``integrate``
    runs); its outputs merged on the uniform ``grid`` (``_raw_outputs``); their x and deformation
    extremes; the kinetostatic MR13D extremes on the grid's terms (``kinetostatic_extremes``).
    Units: Fu N, J_cam kg m^2, motor0 N m (the motor's standstill moment on the cam), kc
    N/m^(10/9), gap m, damping s/m, ``grid`` s, the moment terms those of cam_tables.AngleTerms;
    rtol, atol_frac and steps_per_period the preset's. ``sign`` +1 for the consistent reading, -1
    for the literal. Returns (code, values, event rows):
    code dopri5's status, or _STALLS (values[_K_STALL] the first angle index) or _STARTS_AT_REST
    (no drive at t = 0: the general path runs it); values in the layout _T_FAIL ... _NSTEPS."""
    vals = np.zeros(11)
    no_rows = np.empty((0, dp.EV_WIDTH))
    n = block.shape[1]
    t = block[0] / omega1
    rows = np.empty((7, n))
    # block rows (_ANGLE_ROWS): 1-6 the angle terms, 7 Db2, 9-12 the mass_factors
    _operating_tables(block[1], block[2], block[3], block[4], block[5], block[6], block[9], block[10], block[11],
                      block[12], omega1, Fu, jt_factor, J_cam, rows)
    if check_motor:
        slack = np.empty(n)
        validity._energy_budget(t, block[0], rows[4], block[7], rows[0], rows[2], J_cam, omega1, motor0, slack, False)
        k = validity.stall_index(slack)
        if k >= 0:
            vals[_K_STALL] = k
            return _STALLS, vals, no_rows
    tab = np.empty((3, n))                          # model_struct's rows
    for i in range(n):
        tab[eq.TG, i], tab[eq.DRIVE, i], tab[eq.MASS, i] = t[i], sign * rows[6, i], rows[5, i]
    t_end = t[n - 1]
    pair, caps = _tolerances(rows[6], rows[5], kc, atol_frac, steps_per_period, cap_flight, t_end)
    atol = np.empty((3, 2))                         # integrate's: one row a mode
    for mode in range(3):
        atol[mode, 0], atol[mode, 1] = pair[0], pair[1]
    model = eq.ElasticModel(tab, kc, gap, damping, omega1, BOUNDARY_NUDGE, eq.grid_rate(t))
    phase, t0, x0, v0 = eq.start(model)
    if t0 != 0.0:
        return _STARTS_AT_REST, vals, no_rows
    ctl = dp.Controls(rtol, atol, caps, t_end, True, MAX_STEPS, MAX_SEGMENTS, EVENT_SUBSTEPS, ZENO_SEGMENTS, ZENO_DT, 2)
    ph0 = np.zeros(dp.PHASE_WIDTH)
    ph0[0] = phase
    y0 = np.empty(2)
    y0[0], y0[1] = x0, v0
    out = dp.run(model, ctl, ph0, y0, 0.0)
    status, nev = out[0], out[5]
    vals[_T_FAIL], vals[_NFEV], vals[_NSTEPS] = out[1], out[6], out[3]
    if status != dp.OK:
        return status, vals, no_rows
    out_t, out_y, out_seg, _ = dp.merge_run(grid, out, 1)       # x alone: its extremes
    x_max, x_min, d_max, k = -np.inf, np.inf, -np.inf, 0
    for i in range(out_t.size):                      # x.max(), x.min(), _deformation's max and argmax
        x = out_y[0, i]
        if x_max == x_max and (x > x_max or x != x):
            x_max = x
        if x_min == x_min and (x < x_min or x != x):
            x_min = x
        d = -x if x < 0 else (x - gap if x > gap else 0.0)
        if d > d_max:
            d_max, k = d, i
    vals[_X_MAX], vals[_X_MIN], vals[_D_MAX] = x_max, x_min, d_max
    vals[_D_PHASE], vals[_D_PHI1] = out[11][out_seg[k], 0], omega1 * out_t[k]
    vals[_M_MAX], vals[_M_MIN] = _moment_extremes(dpsi, ddpsi, J0, dJ0, M_gravity, m_load, omega1, Fu, jt_factor)
    return status, vals, out[15][:nev].copy()


@dataclass(frozen=True)
class _Run:
    """What the compiled loop made of a scene, before any output."""

    tab: Tables
    model: eq.ElasticModel
    segments: list
    rows: np.ndarray
    kc: float
    warnings: list
    raw: tuple | None = None      # the compiled loop's own arrays (``integrate(raw=True)``), segments None


def _solve(scene: Scene, reading: str, solver, preset, stats, raw: bool = False) -> _Run:
    """The tables, the loop and its event rows (impact columns not yet completed); ``raw``: see
    ``integrate``."""
    if reading not in READINGS:
        raise InputError(f"elastic model reading must be one of {', '.join(READINGS)}, got '{reading}'")
    warnings = validity.check_scene(scene)
    kc = contact_stiffness(scene.contact_length, scene.kc_factor)
    gap = contact_gap(scene)
    tab = grid_tables(scene, *_span(scene))
    drive = tab.R31 if reading == "consistent" else -tab.R31
    preset = PRESETS[scene.accuracy] if preset is None else preset
    solver = SOLVERS[scene.accuracy] if solver is None else solver
    warnings += validity.elastic_before(scene, tab)
    atol, caps = _tolerances(tab.R31, tab.M, float(kc), float(preset["atol"]), float(preset["steps_per_period"]),
                             bool(preset.get("cap_flight", True)), float(tab.t[-1]))
    loop_stats = {} if stats is None else stats
    t0 = time.perf_counter()
    model = model_struct(tab.t, drive, tab.M, kc, gap, scene.contact_damping, tab.omega1)
    result = integrate(tab.t, drive, tab.M, kc, gap, scene.contact_damping, rtol=preset["rtol"], atol=atol,
                       max_step=caps, solver=solver,
                       method=preset.get("method", "RK45"), omega1=tab.omega1, stats=loop_stats, model=model, raw=raw)
    segments, rows, loop_arrays = result if raw else (*result, None)
    loop_stats["loop_s"] = loop_stats.get("loop_s", 0.0) + time.perf_counter() - t0
    return _Run(tab, model, segments, rows, kc, warnings, loop_arrays)


def _table3(x_extremes: tuple, m_static: tuple, ev, flights=events.flights, impacts=events.impacts) -> dict:
    """Table 3's indicators from the largest and smallest x_el (m) at the output instants, the
    largest and smallest kinetostatic MR13D (N m) on the uniform output grid
    (``kinetostatic_extremes``) and the event record ``ev`` counted by ``flights`` and ``impacts``
    (events' counts of a record, or their ``*_in_rows`` forms of the loop's rows): one definition
    for every path."""
    return dict(
        MR13D_max_Nm=float(m_static[0]), MR13D_min_Nm=float(m_static[1]),
        xel_max_mm=float(x_extremes[0] * 1e3), xel_min_mm=float(x_extremes[1] * 1e3),
        # Table 3's jumps: x leaves the interior flank (the paper's criterion); impacts: every landing
        jumps=flights(ev, side=events.INTERIOR), impacts=impacts(ev),
    )


def _deformation(x, gap: float):
    """Deformation (m) of the flank in contact at relative displacements x (m), gap j (m)."""
    return np.where(x < 0, -x, np.where(x > gap, x - gap, 0.0))


def _indicators(scene: Scene, cols: dict, ev: dict, n_phases: int, reading: str, kc: float) -> dict:
    """The indicators from the dataset's columns (numpy arrays, ``_dataset``), event record and
    number of contact phases."""
    x, m_contact = cols["x_el"], cols["MR13D"]
    ind = empty_indicators()
    ind.update(
        **_table3(_extremes(x), _extremes(cols["MR13D_static"][cols["grid_index"] >= 0]), ev),
        MR13D_contact_max_Nm=float(m_contact.max()), MR13D_contact_min_Nm=float(m_contact.min()),
        deformation_max_mm=float(cols["deformation"].max() * 1e3),
        separations=events.flights(ev), lift_offs=events.lift_offs(ev), settles=events.settles(ev),
        contact_phases=int(n_phases), reading=reading, elastic_gap=scene.elastic_gap,
        contact_length_mm=scene.contact_length * 1e3, Kc_SI=kc,
        energy_error=energy_error(cols, kc) if scene.contact_damping == 0.0 else None,
    )
    return ind


def energy_error(cols, kc: float) -> float:
    """The energy balance of an undamped run, relative to its energy scale: with
    M(t) x'' = F(x) - R31(t), d/dt (M v^2/2 + U) = -R31 v + Mdot v^2/2 (U the flanks' Palmgren
    potential, 9/19 Kc p^(19/9) = 9/19 |F| p undamped); the residual of its trapezoidal integration
    over the output samples, Mdot by np.gradient's second-order differences. ``cols``: the dataset
    or its columns (time, dx_el, reduced_mass, deformation, contact_force, R31). One compiled pass
    (``_energy_residual``; tests/test_elastic.py holds it to the numpy expression it replaced)."""
    t, v, M, p, F, R31 = (np.ascontiguousarray(cols[k], dtype=float) for k in ("time", "dx_el", "reduced_mass",
                                                                                "deformation", "contact_force", "R31"))
    if t.size < 2:
        raise ValueError("energy_error needs at least 2 output samples")
    return float(_energy_residual(t, v, M, p, F, R31))


@kernel
def _energy_residual(t, v, M, p, F, R31):
    """max |E - E0 - W| / max(max |E|, max |W|, 1e-300), E = M v^2/2 + 9/19 |F| p, W the
    trapezoidal integral of -R31 v + Mdot v^2/2 (Mdot: np.gradient of M over t, edges first
    order), in numpy's order of operations."""
    n = t.size
    uniform = True                          # np.gradient's test: then its central differences
    for i in range(1, n - 1):
        if t[i + 1] - t[i] != t[1] - t[0]:
            uniform = False
            break
    E0 = 0.5 * M[0] * v[0] ** 2 + (9.0 / 19.0) * abs(F[0]) * p[0]
    W, scale_e, scale_w, worst = 0.0, abs(E0), 0.0, 0.0
    power_prev = 0.0
    nan = False                             # max() would drop a NaN that numpy's max keeps
    for i in range(n):
        if i == 0:
            dM = (M[1] - M[0]) / (t[1] - t[0])
        elif i == n - 1:
            dM = (M[n - 1] - M[n - 2]) / (t[n - 1] - t[n - 2])
        elif uniform:
            dM = (M[i + 1] - M[i - 1]) / (2.0 * (t[1] - t[0]))
        else:
            dx1, dx2 = t[i] - t[i - 1], t[i + 1] - t[i]
            a = -dx2 / (dx1 * (dx1 + dx2))
            b = (dx2 - dx1) / (dx1 * dx2)
            c = dx1 / (dx2 * (dx1 + dx2))
            dM = a * M[i - 1] + b * M[i] + c * M[i + 1]
        power = -R31[i] * v[i] + 0.5 * dM * v[i] ** 2
        if i > 0:
            W += 0.5 * (power + power_prev) * (t[i] - t[i - 1])
        power_prev = power
        E = 0.5 * M[i] * v[i] ** 2 + (9.0 / 19.0) * abs(F[i]) * p[i]
        nan = nan or E != E or W != W
        scale_e = max(scale_e, abs(E))
        scale_w = max(scale_w, abs(W))
        worst = max(worst, abs(E - E0 - W))
    if nan:
        return np.nan
    return worst / max(scale_e, scale_w, 1e-300)


def _outputs(tab: Tables, segments):
    """The output instants (a uniform grid of OUTPUT_STEP, plus the solver's own steps: extremes
    are not lost) and the state there: (t s, x m, x' m/s, phase, grid index or -1 at a step time),
    in time order; an instant shared by two phases (an event) keeps the value of the phase that
    ends. One compiled pass (kernels.dopri5.merge_outputs); a phase that is not a compiled run (at
    rest, or scipy's) is evaluated by itself at its instants afterwards."""
    t_uniform = output_grid(tab)
    starts = np.array([run.t[0] for _, run in segments])
    ends = np.array([run.t[-1] for _, run in segments])
    shared = dp.shared_store([run for _, run in segments])
    if shared is not None and shared[0][2].shape[1] == 2:      # one loop's phases: its store, in place
        (t0s, hs, y0s, Qs), first = shared
        sizes = np.array([run.t0s.size for _, run in segments], dtype=np.int64)
        last, count = first + sizes - 1, int(sizes.sum())
    else:
        t0s, hs, y0s, Qs, first, last, count = _joined_steps(segments)
    t, y, seg, grid_index = dp.merged(t_uniform, starts, ends, first, last, t0s, hs, y0s, Qs, count)
    for k, (_, run) in enumerate(segments):
        if not isinstance(run, dp.DenseRun):
            sel = seg == k
            y[:, sel] = np.asarray(run(t[sel]), dtype=float).reshape(2, -1)
    phases = np.array([ph for ph, _ in segments], dtype=np.int64)
    return t, y[0], y[1], phases[seg], grid_index


def _joined_steps(segments):
    """The phases' steps joined into arrays of their own (t0s, hs, y0s, Qs), each phase's first and
    last row there and their count; a phase that is not a compiled run gives its step times with
    zero values (``_outputs`` evaluates it afterwards)."""
    n_seg = len(segments)
    first, last = np.empty(n_seg, dtype=np.int64), np.empty(n_seg, dtype=np.int64)
    parts, count = [], 0
    for k, (_, run) in enumerate(segments):
        if isinstance(run, dp.DenseRun):
            parts.append((run.t0s, run.hs, run.y0s, run.Qs))
        else:
            n = run.t.size - 1
            parts.append((run.t[:-1], np.zeros(n), np.zeros((n, 2)), np.zeros((n, 2, 4))))
        first[k], last[k] = count, count + parts[-1][0].size - 1
        count += parts[-1][0].size
    t0s, hs, y0s, Qs = (np.ascontiguousarray(np.concatenate([p[i] for p in parts])) for i in range(4))
    return t0s, hs, y0s, Qs, first, last, count


def _raw_outputs(tab: Tables, out):
    """``_outputs`` of a compiled run from the loop's own arrays (``integrate(raw=True)``): the same
    instants and values (the same ``merge_outputs`` pass over the same steps), without a Python
    object per phase."""
    t, y, seg, grid_index = dp.merge_run(output_grid(tab), out, 2)
    return t, y[0], y[1], out[11][:out[4], 0].astype(np.int64)[seg], grid_index


def _extremes(values) -> tuple:
    return float(values.max()), float(values.min())


def kinetostatic_extremes(scene: Scene, tab: Tables) -> tuple:
    """(largest, smallest) kinetostatic MR13D (N m) on the uniform output grid (``output_grid``),
    from the per-process table of ``output_terms``: the extremes of the dataset's MR13D_static at
    its grid instants, Table 3's (MR13D)max and min. A function of the cam angle alone, taken on
    the grid so that they do not depend on where the solver put its steps (they would move with
    the preset by ~1e-9 relative). One compiled pass, no array (NaN if any value is)."""
    g = _grid_terms(scene, tab.omega1, float(tab.t[-1]), geometry=False)
    return _moment_extremes(g.dpsi, g.ddpsi, g.J0, g.dJ0, g.M_gravity, g.m_load, float(tab.omega1),
                            float(scene.Fu), float(scene.jt_factor))


@kernel
def _moment_extremes(dpsi, ddpsi, J0, dJ0, M_gravity, m_load, omega1, Fu, jt_factor):
    hi, lo = -np.inf, np.inf
    for i in range(dpsi.size):
        moment = _point(dpsi[i], ddpsi[i], J0[i], dJ0[i], M_gravity[i], m_load[i], omega1, Fu, jt_factor)[2]
        if moment != moment:
            return np.nan, np.nan
        hi, lo = max(hi, moment), min(lo, moment)
    return hi, lo


def _grid_terms(scene: Scene, omega1: float, t_end: float, geometry: bool = True) -> AngleTerms:
    """The kinematic terms on the uniform output grid of a run over [0, t_end] (s) at the cam speed
    omega1 (rad/s), per process (per mechanism, law, cam speed and span): the linkage evaluated
    exactly (a few ms once per speed; the stroke spline would load scipy.interpolate, 0.5 s, into
    every process of a sweep); ``geometry=False`` without the contact geometry (what the
    kinetostatic moment needs; its other terms are the same values)."""
    mech, program = scene.mechanism, scene.program
    return cached(_grid_key(scene, omega1, t_end, geometry),
                  lambda: angle_terms(mech, program, omega1 * _uniform_grid(t_end), _until(scene), geometry=geometry))


def _grid_key(scene: Scene, omega1: float, t_end: float, geometry: bool) -> tuple:
    return ("elastic_output_terms", scene.mechanism.cache_key, scene.program, float(omega1), float(t_end),
            _output_size(t_end), _until(scene), geometry)


def output_grid(tab: Tables) -> np.ndarray:
    """The uniform output instants (s) of a run over tab's span: OUTPUT_STEP or finer."""
    return _uniform_grid(float(tab.t[-1]))


def _uniform_grid(t_end: float) -> np.ndarray:
    """``output_grid`` of a run over [0, t_end] (s), per process (shared, read-only)."""
    return cached(("elastic_output_grid", float(t_end)), lambda: np.linspace(0.0, t_end, _output_size(t_end)))


def _output_size(t_end: float) -> int:
    return max(int(math.ceil(t_end / OUTPUT_STEP)) + 1, 2)


_TERMS = ("psi", "dpsi", "ddpsi", "phi2", "J0", "dJ0", "M_gravity", "m_load", "alpha", "Db1", "Db2")


_FACTOR_ROWS = ("arm", "c1", "c2", "rho", "inv_arm")     # _tables' arm and mass_factors, after _TERMS
_BLOCK_ROWS = len(_TERMS) + len(_FACTOR_ROWS)


def _grid_block(scene: Scene, omega1: float, t_end: float) -> np.ndarray:
    """The terms _TERMS of ``_grid_terms`` and their _FACTOR_ROWS stacked, (len(_TERMS) + 5, grid
    size), per process."""
    def build():
        g = _grid_terms(scene, omega1, t_end)
        arm = _arm(scene.mechanism, g.alpha)
        return np.vstack([getattr(g, name) for name in _TERMS] + [arm, *mass_factors(g.Db1, g.Db2, arm)])
    return cached(_grid_key(scene, omega1, t_end, True) + ("block", _TERMS + _FACTOR_ROWS), build)


def output_terms(scene: Scene, tab: Tables, t, grid_index):
    """The kinematic terms (cam_tables.angle_terms) at the output instants t (s) of ``_outputs``,
    with their arm (m, ``_arm``) and ``mass_factors``: (AngleTerms, arm, factors) for ``_tables``;
    those on the uniform output grid (grid_index >= 0) from a per-process table shared by every run
    of the same mechanism, law, cam speed and span (a sweep over the load, Jt, j or Kc reuses it,
    ``_grid_terms``), the solver's step instants computed with the linkage from its stroke spline
    (1e-13 relative of the exact linkage, 4x cheaper at thousands of arbitrary instants): the motion
    law in numpy, the rest in one compiled pass (``_step_terms``) that gives angle_terms(...,
    linkage="spline")'s values (tests/test_cam_tables.py); where the stroke leaves the spline's
    range, angle_terms itself (the exact linkage)."""
    mech, program, omega1 = scene.mechanism, scene.program, tab.omega1
    on_grid = _grid_block(scene, tab.omega1, float(tab.t[-1]))
    at_step = np.flatnonzero(grid_index < 0)
    phi1 = omega1 * t[at_step]
    until = _until(scene)
    at = phi1 if until is None else np.minimum(phi1, until)
    psi, dpsi, ddpsi, _ = program(at)
    spline = stroke_spline(mech)
    block = np.empty((_BLOCK_ROWS, t.size))        # rows _TERMS, _FACTOR_ROWS
    if not _step_terms(on_grid, grid_index, psi, dpsi, ddpsi, program.direction(at), mech.phiD + mech.psi0,
                       spline.x, spline.c, float(mech.xD), float(mech.yD), float(mech.l),
                       float(cached_sense(mech, program)), block):
        at_steps = angle_terms(mech, program, phi1, until, linkage="spline")
        arm = _arm(mech, at_steps.alpha)
        rows = [getattr(at_steps, name) for name in _TERMS] + [arm, *mass_factors(at_steps.Db1, at_steps.Db2, arm)]
        _interleave(on_grid, grid_index, np.vstack(rows), block)
    n = len(_TERMS)
    return AngleTerms(phi1=omega1 * t, **dict(zip(_TERMS, block))), block[n], tuple(block[n + 1:])


@kernel
def _step_terms(on_grid, grid_index, psi, dpsi, ddpsi, direction, phi2_0, knots, coeffs, xD, yD, l, sense, out):
    """``output_terms``' block (rows _TERMS, _FACTOR_ROWS) in one pass: out[:, i] =
    on_grid[:, grid_index[i]] where grid_index[i] >= 0, else the terms at the next step instant
    (in order) of its motion (psi, dpsi, ddpsi, direction: the program at those angles) with the
    linkage columns from the stroke spline (knots rad, coeffs: scipy PPoly's (4, knots - 1, 5),
    evaluated in scipy's order of operations), the groove's geometry (``_pitch``), the arm and
    the ``mass_factor``. False (out incomplete) if a follower angle leaves the spline's knots."""
    if out.shape[0] != _BLOCK_ROWS or on_grid.shape[0] != _BLOCK_ROWS or out.shape[1] != grid_index.size:
        raise ValueError("_step_terms: out and on_grid must have the block's rows, out one column an instant")
    j = 0
    last = knots.size - 1
    inv_h = last / (knots[last] - knots[0])
    for i in range(grid_index.size):
        g = grid_index[i]
        if g >= 0:
            for k in range(out.shape[0]):
                out[k, i] = on_grid[k, g]
            continue
        phi2 = phi2_0 + psi[j]
        if not knots[0] <= phi2 <= knots[last]:
            return False
        # scipy's interval, knots[lo] <= phi2 < knots[lo + 1] (the last one closed): the knots are
        # uniform, so the quotient is within one of it and the comparisons settle it
        lo = min(max(int((phi2 - knots[0]) * inv_h), 0), last - 1)
        while lo > 0 and knots[lo] > phi2:
            lo -= 1
        while lo < last - 1 and knots[lo + 1] <= phi2:
            lo += 1
        s = phi2 - knots[lo]
        _, _, _, _, _, alpha, Db1, Db2, _ = _pitch(xD, yD, l, sense, phi2, dpsi[j], ddpsi[j])
        out[0, i], out[1, i], out[2, i], out[3, i] = psi[j], dpsi[j], ddpsi[j], phi2
        out[4, i], out[5, i], out[6, i] = _cubic(coeffs, lo, 0, s), _cubic(coeffs, lo, 1, s), _cubic(coeffs, lo, 2, s)
        out[7, i] = _load_arm(_cubic(coeffs, lo, 4, s), direction[j], _cubic(coeffs, lo, 3, s))
        out[8, i], out[9, i], out[10, i] = alpha, Db1, Db2
        arm = l * math.cos(alpha)                                 # _arm
        out[11, i] = arm
        out[12, i], out[13, i], out[14, i], out[15, i] = _mass_factor(Db1, Db2, arm)
        j += 1
    return True


@kernel(internal=True)
def _cubic(coeffs, interval, column, s):
    """A PPoly cubic's value at s (rad) into its interval: scipy's evaluate_poly1 (the powers of s
    accumulated, the highest-order coefficient first in coeffs)."""
    z = s * s
    return ((coeffs[3, interval, column] + coeffs[2, interval, column] * s) + coeffs[1, interval, column] * z
            + coeffs[0, interval, column] * (z * s))


@kernel
def _interleave(on_grid, grid_index, at_steps, out):
    """out[:, i] = on_grid[:, grid_index[i]] where grid_index[i] >= 0, else the next column of
    at_steps (in order): ``output_terms``' columns in one pass (numpy's 2-D fancy indexing cost
    ~0.1 ms a call there)."""
    j = 0
    for i in range(grid_index.size):
        g = grid_index[i]
        if g >= 0:
            for k in range(out.shape[0]):
                out[k, i] = on_grid[k, g]
        else:
            for k in range(out.shape[0]):
                out[k, i] = at_steps[k, j]
            j += 1


def _arm_rate(scene: Scene, tab: Tables) -> np.ndarray:
    """d(l cos alpha)/dt (m/s) on the tables' grid (np.gradient), per process and cam speed."""
    key = ("elastic_arm_rate", scene.mechanism.cache_key, scene.program, float(tab.omega1), float(tab.t[-1]),
           tab.t.size, _until(scene))
    return cached(key, lambda: np.gradient(tab.arm, tab.t))


def _dataset(scene, run: _Run, reading, record: dict, outputs):
    """The Dataset of a run sampled at ``outputs`` (``_outputs``), not built yet: (its
    result.DatasetParts, its time series as numpy arrays by name, 'time' included; the very arrays
    the Dataset will hold)."""
    tab, model = run.tab, run.model
    t, x, v, phase, grid_index = outputs
    # kinematics at the output instants, not interpolated in time (the linkage from its stroke
    # spline, accurate to rounding)
    terms, arm, factors = output_terms(scene, tab, t, grid_index)
    exact = _tables(scene, terms, t, tab.omega1, arm, factors)
    arm, R31, M = exact.arm, exact.R31, exact.M
    F = np.empty(t.size)
    eq.forces(model, phase.astype(np.int64), x, v, F)
    drive = R31 if reading == "consistent" else -R31
    a = (F - drive) / M
    darm = np.interp(t, tab.t, _arm_rate(scene, tab))
    phi2 = exact.phi2 + x / arm                                           # eq. (19)
    omega2 = exact.omega2 + v / arm                                       # eq. (19)
    epsilon2 = exact.epsilon2 + a / arm - v * darm / arm**2               # d/dt of eq. (19)
    gap = model.gap
    deformation = _deformation(x, gap)

    cols = {"time": t, "grid_index": grid_index}

    def var(name, data, units, long_name):
        values = np.asarray(data, dtype=float)
        cols[name] = values
        return ("time", values, {"units": units, "long_name": long_name})

    parts = DatasetParts(
        data_vars={
            "phi1": var("phi1", tab.omega1 * t, "rad", "cam angle (0 at rise start)"),
            "omega1": var("omega1", np.full(t.size, tab.omega1), "rad/s", "cam angular velocity"),
            "x_el": var("x_el", x, "m", "follower-cam relative displacement along the normal (+ towards the exterior flank)"),
            "dx_el": var("dx_el", v, "m/s", "rate of x_el"),
            "contact_force": var("contact_force", F, "N", "groove-on-follower normal force (+ pushes in the rise direction)"),
            "deformation": var("deformation", deformation, "m", "contact deformation of the flank in contact"),
            "contact_phase": var("contact_phase", phase, "1", "0 interior flank, 1 flight in the gap, 2 exterior flank"),
            "MR13D": var("MR13D", F * arm, "N m", "moment about D of the cam-on-follower contact force"),
            "MR13D_static": var("MR13D_static", exact.MR13D, "N m", "moment about D of the static reaction R31 (kinetostatic)"),
            "R31": var("R31", R31, "N", "static reaction of the cam on the follower along the normal (+ rise)"),
            "reduced_mass": var("reduced_mass", M, "kg", "reduced mass M of eq. (16)"),
            "phi2": var("phi2", phi2, "rad", "follower angle, eq. (19)"),
            "omega2": var("omega2", omega2, "rad/s", "follower angular velocity, eq. (19)"),
            "epsilon2": var("epsilon2", epsilon2, "rad/s^2", "follower angular acceleration (time derivative of eq. 19)"),
            "phi2_kin": var("phi2_kin", exact.phi2, "rad", "kinematic follower angle"),
            "omega2_kin": var("omega2_kin", exact.omega2, "rad/s", "kinematic follower angular velocity"),
            **record,
        },
        coords={"time": ("time", t, {"units": "s", "long_name": "time from the start of the rise"})},
        attrs={
            "title": "labtool elastic-contact model (paper eqs 12-19)",
            "reading": reading, "Kc_SI": model.kc, "Kc_units": "N/m^(10/9)", "elastic_gap_m": gap,
            "elastic_gap": scene.elastic_gap, "omega1_rad_s": tab.omega1,
            "event_record": events.RECORD_VERSION,
        },
    )
    return parts, cols
