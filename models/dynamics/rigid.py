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
impact (eqs 8-11)         Newton's k on the normal velocity of C (labtool.models.dynamics.impact).

The gap. The groove's flanks are offset curves of the pitch curve (inner at 0, outer at j along the
contact normal n). The normal distance of C from the pitch curve is linearised in q:
g = A2(phi1) q, A2 = n . (k x DC) = l cos(alpha) = Db2/2 (m), so the angular gap is j / A2
(the lead's j / (l cos alpha)). Neglected: terms of order j / rho (rho the pitch curve's radius of
curvature, > 14 mm here), i.e. < 1 % of the gap for j <= 0.128 mm (labtool.models.dynamics.validity warns
above 5 %). The same g defines the contact (g = 0 or j), the events and the impact's normal velocity
v_n = dg/dt = A2 omega2 - G1 omega1 with G1 = A2 psi' - A2' q (= the paper's A1 = Db1/2 on the inner
flank, a check in the tests), so the model is self-consistent: k = 1 conserves energy and
v+ = -k v- hold to rounding.

The equations, events, impact, settle rule, restart and initial state are compiled once
(labtool.models.dynamics.kernels.rigid_nb, read the event and settle rules there); ``integrate`` runs them in
the shared compiled Dormand-Prince loop (fast, standard) or in scipy's solve_ivp (reference, DOP853).
This module builds the model struct from a scene, samples the run, computes the indicators and
writes the dataset with the event record of labtool.models.dynamics.events. At most ``max_events`` events
per run, then ``SolverError``.
"""
from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass

import numpy as np
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # xarray is loaded where a Dataset is built (the indicator path of a sweep needs none)
    import xarray as xr

from labtool.common.errors import InputError, SolverError
from labtool.models.dynamics import events, validity
from labtool.models.dynamics.contact import contact_stiffness
from labtool.models.dynamics.compiling import announces
from labtool.models.dynamics.kernels import dopri5 as dp
from labtool.models.dynamics.kernels import rigid_nb as eq
from labtool.models.dynamics.result import DatasetParts, SimulationResult, empty_indicators
from labtool.models.dynamics.rigid_tables import cam_table, follower_table
from labtool.models.dynamics.scene import Scene
from labtool.models.mechanism import sensor_point
from labtool.models.mechanism.cam_profile import cached_sense
from labtool.models.mechanism.memo import cached
from labtool.models.mechanism.motion_laws import CamProgram
from labtool.models.mechanism.motor import cam_inertia, motor_moment_on_cam, motor_slope_on_cam, no_load_cam_speed, transmission_ratio

TWO_PI = 2.0 * math.pi
INNER, OUTER, FREE = eq.INNER, eq.OUTER, eq.FREE
CONTACT, FREE_MODE = eq.CONTACT_MODE, eq.FREE_MODE

# solver presets: relative tolerance, max step (fraction of the rise's duration), output samples
# per rise, event cap. Their error and cost against the reference solution are measured in
# labtool.models.dynamics.accuracy (benchmarks/work_precision.py). The step caps are what the stated
# accuracy needs (measured over Table 1): standard at rise/1000 made 204 000 RHS
# evaluations for 1.5e-8 in omega2, at rise/20 14 700 for 1.9e-8 (stated 1e-7); fast at rise/250
# 52 300 for 3.8e-6, at rise/50 12 300 for 6.1e-6 (stated 1e-5); no event lost or added.
PRESETS = {
    "fast": dict(method="RK45", rtol=1e-6, max_step=1 / 50, samples=1000, max_events=2000),
    "standard": dict(method="RK45", rtol=1e-9, max_step=1 / 20, samples=4000, max_events=5000),
    "reference": dict(method="DOP853", rtol=1e-12, max_step=1 / 4000, samples=16000, max_events=20000),
}
SOLVERS = {"fast": "compiled", "standard": "compiled", "reference": "scipy"}
MAX_STEPS = 2_000_000
EVENT_SUBSTEPS = 4                    # event sign checks per step (its dense output), not its ends only:
# with the step caps above (rise/20) a grazing flight can begin and end inside one step
ZENO_PHASES, ZENO_DT = 101, 1e-13     # this many consecutive phases shorter than ZENO_DT s: stalled
TIME_BOUND_FACTOR = 4.0               # the cam must reach the end within 4x its nominal time + 1 s
EXTRA_COLUMNS = {
    "event_omega1_before": (eq.COL_OMEGA1_BEFORE, "rad/s", "cam speed before the event"),
    "event_omega1_after": (eq.COL_OMEGA1_AFTER, "rad/s", "cam speed after the event"),
    "event_omega2_before": (eq.COL_OMEGA2_BEFORE, "rad/s", "follower speed before the event"),
    "event_omega2_after": (eq.COL_OMEGA2_AFTER, "rad/s", "follower speed after the event"),
    "event_energy_before": (eq.COL_ENERGY_BEFORE, "J", "kinetic energy of cam+motor and follower side before an impact"),
    "event_energy_after": (eq.COL_ENERGY_AFTER, "J", "kinetic energy after an impact"),
    "event_v_before": (eq.COL_V_BEFORE, "m/s", "normal relative velocity of C before (gap rate, + opening towards the outer flank)"),
    "event_v_after": (eq.COL_V_AFTER, "m/s", "normal relative velocity of C after"),
    "event_phi2": (eq.COL_PHI2, "rad", "follower angle at the event"),
}


@dataclass
class Phase:
    kind: str          # "contact" or "free"
    flank: int         # INNER / OUTER in contact, FREE in flight
    t0: float
    t1: float
    sol: object        # dense output: sol(times) -> (n_state, n)


def simulated_span(scene: Scene) -> float:
    """Cam angle simulated (rad) from the start of the rise: whole revolutions, or, with rise_only,
    the revolutions before the last one plus the last one's rise."""
    if scene.rise_only:
        return TWO_PI * (math.ceil(scene.revolutions) - 1) + scene.program.rise_angle
    return TWO_PI * scene.revolutions


def build_model(scene: Scene, backlash: float | None = None, phi1_end: float | None = None) -> tuple[eq.RigidModel, dict]:
    """The compiled model of a scene (backlash overrides scene.backlash, e.g. 0 for the no-backlash
    run; phi1_end (rad) the end of the simulated cam angle, default the scene's span)."""
    mech, program = scene.mechanism, scene.program
    sense = cached_sense(mech, program)
    it = transmission_ratio(mech, scene.omega1_nominal)
    Jcam = cam_inertia(mech, it)
    span = simulated_span(scene) if phi1_end is None else phi1_end
    hi = simulated_span(scene) + 0.2
    # both tables depend on the mechanism and the cam program only: built once per process and
    # shared by every speed, load, inertia factor and backlash (labtool.models.mechanism.memo.cached)
    cam = cached(("rigid_cam_table", mech.cache_key, program, sense, -0.05, hi),
                 lambda: cam_table(mech, program, sense, -0.05, hi).packed())
    lo2, hi2 = mech.phiD + mech.psi0 - 0.05, mech.phiD + mech.psi0 + program.stroke + 0.05
    fol = cached(("rigid_follower_table", mech.cache_key, lo2, hi2), lambda: follower_table(mech, lo2, hi2).packed())
    j = scene.backlash if backlash is None else backlash
    if not (Jcam > 0 and math.isfinite(Jcam)):
        raise InputError(f"the cam's reduced inertia must be > 0 kg m^2, got {Jcam}")
    if j < 0:
        raise InputError(f"backlash must be >= 0 mm, got {j * 1e3:g} mm")
    model = eq.RigidModel(
        cam, fol, float(mech.phiD + mech.psi0), float(scene.jt_factor), float(Jcam),
        0.0 if scene.omega1_mode == "const" else 1.0 / Jcam, scene.omega1_mode == "const",
        float(motor_moment_on_cam(mech, 0.0, it)), float(motor_slope_on_cam(mech, it)), float(scene.Fu),
        float(j), float(scene.restitution), float(span), contact_stiffness(scene.contact_length, scene.kc_factor))
    # J''red at the follower table's nodes over the stroke (column 2: each cell's value at its node;
    # the last row holds no cell)
    nodes = fol[:-1, 0]
    on_stroke = (nodes >= model.phi20 - 1e-9) & (nodes <= model.phi20 + program.stroke + 1e-9)
    if float(np.min(fol[:-1, 2][on_stroke])) * scene.jt_factor <= 0:
        raise InputError("the follower's reduced inertia J''red must be > 0 kg m^2")
    info = dict(sense=sense, transmission_ratio=it, J_cam=Jcam, motor_slope=model.m1)
    return model, info


def cam_columns(model: eq.RigidModel, phi1) -> np.ndarray:
    """The cam table's columns (psi, psi', psi'', A2, A2', A2'', Mc, direction) at angles phi1 (rad),
    array (8, n)."""
    phi1 = np.ascontiguousarray(np.atleast_1d(phi1), dtype=float)
    out = np.empty((8, phi1.size))
    eq.cam_rows(model, phi1, out)
    return out


def start_speed(scene: Scene, model: eq.RigidModel) -> float:
    """omega1 (rad/s) at phi1 = 0: n1 (cam as input), or the steady state of the preceding dwell
    (no follower torque there, motor time constant J'/slope ~ 5 ms << dwell): M1(omega1) + Mc(0) = 0,
    the no-load speed n1 * n_sync / n_nominal."""
    if scene.omega1_mode == "const":
        return scene.omega1_nominal
    return (model.m0 + eq.cam_row(model, 0.0)[6]) / model.m1


def integrate(model: eq.RigidModel, omega1_0: float, preset: dict, t_rise: float, start: tuple | None = None,
              t_start: float = 0.0, solver: str = "compiled", stats: dict | None = None,
              max_steps: int = MAX_STEPS) -> tuple[list[Phase], np.ndarray]:
    """Integrate from t_start until phi1 reaches model.phi1_end: (phases, event rows).

    start: None = contact at phi1 = 0, omega1_0, on the flank whose force is compressive;
    ("contact", phi1, omega1, flank) to start on a flank (labtool.models.dynamics.auto escalates this way);
    ("free", phi1, omega1, q, omega2) to start in the gap. ``solver``: "compiled" (kernels.dopri5)
    or "scipy" (solve_ivp with preset["method"]). ``stats`` (dict) receives nfev and n_steps.
    Event rows: array (n, dopri5.EV_WIDTH) in labtool.models.dynamics.events' layout.
    """
    ph0 = np.zeros(dp.PHASE_WIDTH)
    if start is None or start[0] == "contact":
        phi1, omega1 = (0.0, float(omega1_0)) if start is None else (float(start[1]), float(start[2]))
        flank = eq.start_flank(model, phi1, omega1) if start is None or start[3] == FREE else int(start[3])
        ph0[0], ph0[1] = CONTACT, flank
        y0 = np.array([phi1, omega1])
    else:
        ph0[0], ph0[1], ph0[3] = FREE_MODE, FREE, t_start
        y0 = np.array(start[1:5], dtype=float)
    rtol = float(preset["rtol"])
    atol = np.array([[rtol * 1e-3, rtol * 1e-2, 0.0, 0.0], [rtol * 1e-3, rtol * 1e-2, rtol * 1e-6, rtol * 1e-3]])
    t_bound = t_start + TIME_BOUND_FACTOR * model.phi1_end / max(omega1_0, 1e-9) + 1.0
    max_step = np.full(atol.shape[0], float(preset["max_step"] * t_rise))      # s, the same in every mode
    ctl = dp.Controls(rtol, atol, max_step, float(t_bound), False, int(max_steps),
                      int(preset["max_events"]), EVENT_SUBSTEPS, ZENO_PHASES, ZENO_DT, 4)
    width = lambda row: 2 if int(row[0]) == CONTACT else 4  # noqa: E731
    if solver == "compiled":
        status, t, y, raw, rows, nfev, nst = dp.unpack(dp.run(model, ctl, ph0, y0, float(t_start)), width)
    else:
        from labtool.models.dynamics import reference      # scipy's solve_ivp: loaded when a reference run needs it
        status, t, y, raw, rows, nfev, nst = reference.run(model, eq, ctl, ph0, y0, float(t_start),
                                                           method=preset["method"], name="rigid model")
    if stats is not None:
        stats["nfev"] = stats.get("nfev", 0) + nfev
        stats["n_steps"] = stats.get("n_steps", 0) + nst
    _raise_for(status, t, float(y[0]), model, preset, t_bound - t_start, max_steps)
    phases = [Phase("contact" if int(p.row[0]) == CONTACT else "free", int(p.row[1]), p.t0, p.t1, p.sol) for p in raw]
    return phases, rows


def _raise_for(status, t, phi1, model, preset, t_span, max_steps) -> None:
    where = f"phi1 = {math.degrees(phi1):.3f} deg (t = {t:.6g} s)"
    if status == dp.OK:
        return
    if status == dp.TOO_MANY_EVENTS:
        raise SolverError(f"rigid model: more than {preset['max_events']} contact events before {where}: "
                          "the impacts do not settle; try another restitution k or accuracy preset")
    if status == dp.STALLED:
        raise SolverError(f"rigid model: the cam did not reach phi1 = {math.degrees(model.phi1_end):.2f} deg "
                          f"within {t_span:.3g} s: the motor stalled (it cannot drive this load at this speed)")
    if status == dp.NO_PROGRESS:
        raise SolverError(f"rigid model: stalled in zero-length phases at {where}")
    if status == dp.TOO_MANY_STEPS:
        raise SolverError(f"rigid model: the step cap of {max_steps} steps per run was reached at {where}")
    raise SolverError(f"rigid model: {dp.STATUS_TEXT[status]} at {where}")


# --------------------------------------------------------------------------------------------
# sampling, indicators, dataset
# --------------------------------------------------------------------------------------------
SAMPLED = ("phi1", "omega1", "epsilon1", "phi2", "omega2", "epsilon2", "MR13D", "R13n", "gap")


def sample(model: eq.RigidModel, phases: list[Phase], times: np.ndarray) -> dict:
    """State and derived quantities at ``times`` (s), each from the phase that contains it."""
    n = times.size
    t0s = np.array([ph.t0 for ph in phases])
    idx = np.clip(np.searchsorted(t0s, times, side="right") - 1, 0, len(phases) - 1)
    Y = np.zeros((4, n))
    if all(isinstance(ph.sol, dp.DenseRun) for ph in phases):
        _dense_states(phases, times, idx, Y)
    else:                                   # scipy's phases (the reference preset)
        for k, ph in enumerate(phases):
            sel = np.flatnonzero(idx == k)
            if sel.size:
                y = np.asarray(ph.sol(times[sel]), dtype=float)
                Y[: y.shape[0], sel] = y
    modes = np.array([CONTACT if ph.kind == "contact" else FREE_MODE for ph in phases], dtype=np.int64)[idx]
    flanks = np.array([ph.flank for ph in phases], dtype=np.int64)[idx]
    out = np.empty((len(SAMPLED), n))
    eq.derived(model, modes, flanks, Y, out)
    result = dict(zip(SAMPLED, out))
    result["contact"] = np.where(modes == CONTACT, flanks, 0).astype(np.int8)
    return result


def _dense_states(phases: list[Phase], times, idx, Y) -> None:
    """The compiled phases' dense output at ``times`` (phase idx[m] for times[m]) into Y (4, n),
    in one compiled pass (kernels.dopri5.evaluate_at: each phase's own steps, as its ``sol``)."""
    sizes = np.array([ph.sol.t0s.size for ph in phases])
    width = np.array([ph.sol.y0s.shape[1] for ph in phases])
    shared = dp.shared_store([ph.sol for ph in phases])
    if shared is not None and shared[0][2].shape[1] == 4:
        # the phases of one loop: its step store, in place; a width-2 phase's last two columns
        # there are never read (evaluate_at reads width[m] components)
        (t0s_all, hs, y0s, Qs), first = shared
    else:
        first = np.concatenate(([0], np.cumsum(sizes)[:-1]))
        n_steps = int(sizes.sum())
        y0s, Qs = np.zeros((n_steps, 4)), np.zeros((n_steps, 4, 4))
        for ph, f, w in zip(phases, first, width):
            y0s[f:f + ph.sol.t0s.size, :w] = ph.sol.y0s
            Qs[f:f + ph.sol.t0s.size, :w] = ph.sol.Qs
        t0s_all = np.concatenate([ph.sol.t0s for ph in phases])
        hs = np.concatenate([ph.sol.hs for ph in phases])
    dp.evaluate_at(np.ascontiguousarray(times, dtype=float), first[idx], (first + sizes - 1)[idx], width[idx],
                   t0s_all, hs, y0s, Qs, Y)


def _in_rise(program: CamProgram, phi1):
    return np.mod(phi1, TWO_PI) < program.rise_angle


@announces("the rigid model")
def simulate(scene: Scene, solver: str | None = None, preset: dict | None = None, stats: dict | None = None,
             integrate_with=None) -> SimulationResult:
    """Run the rigid model on a scene.

    ``solver`` ("compiled" | "scipy") and ``preset`` (a dict like PRESETS[...]) override what
    ``scene.accuracy`` selects; ``stats`` (dict) receives nfev, n_steps and loop_s (s in the
    loops); ``integrate_with`` replaces ``integrate`` (same arguments: labtool.models.dynamics.auto shares
    the no-backlash prefix this way).
    """
    t_start = _time.perf_counter()
    run, s, rfj, record, ind = _run(scene, solver, preset, stats, integrate_with)
    parts = _dataset(scene, run.info, run.omega1_0, run.times, s, rfj, record)
    warnings = run.warnings + validity.rigid_after(scene, s, ind)
    parts.attrs.update(wall_s_model=_time.perf_counter() - t_start, validity_warnings=validity.attribute(warnings))
    return SimulationResult(parts, ind, "rigid", warnings=warnings)


@announces("the rigid model")
def simulate_indicators(scene: Scene, solver: str | None = None, preset: dict | None = None, stats: dict | None = None) -> dict:
    """The indicators of ``simulate`` (Table 2's, result.INDICATORS and the event counts), the same
    values from the same samples, without building the Dataset; the same refusals
    (validity.rigid_after)."""
    _, s, _, _, ind = _run(scene, solver, preset, stats, None)
    validity.rigid_after(scene, s, ind)
    return ind


@dataclass(frozen=True)
class _Loops:
    info: dict
    omega1_0: float
    times: np.ndarray
    warnings: list


def _run(scene: Scene, solver, preset, stats, integrate_with):
    """Both loops (with the scene's backlash and without), the samples and the indicators:
    (_Loops, samples, no-backlash samples, event record, indicators)."""
    preset = PRESETS[scene.accuracy] if preset is None else preset
    solver = SOLVERS[scene.accuracy] if solver is None else solver
    loop = integrate if integrate_with is None else integrate_with
    loop_stats = {} if stats is None else stats
    warnings = validity.check_scene(scene)
    program = scene.program
    model, info = build_model(scene)
    omega1_0 = start_speed(scene, model)
    t_rise = program.rise_angle / omega1_0
    t_loop = _time.perf_counter()
    phases, rows = loop(model, omega1_0, preset, t_rise, solver=solver, stats=loop_stats)
    if model.j > 0.0:
        model0 = model._replace(j=0.0, phi1_end=model.phi1_end + 0.1)
        phases0, _ = loop(model0, omega1_0, preset, t_rise, solver=solver, stats=loop_stats)
    else:
        model0, phases0 = model, phases
    loop_stats["loop_s"] = loop_stats.get("loop_s", 0.0) + _time.perf_counter() - t_loop
    t_end = phases[-1].t1
    n = max(int(preset["samples"] * model.phi1_end / program.rise_angle), 200)
    times = np.linspace(0.0, t_end, n + 1)
    # the last sample just inside the simulated span: at phi1 = rise exactly the dwell begins (the
    # load switches off, as in labtool.models.mechanism.kinematics), which would put a step into every time series
    times[-1] = t_end * (1.0 - 1e-9)
    s = sample(model, phases, times)
    rfj = sample(model0, phases0, times)
    record = events.from_rows(rows, EXTRA_COLUMNS)
    ev = events.within_rise(events.columns(record), program.rise_angle)
    ind = {**empty_indicators(), **indicators(program, s, rfj, ev, model0, phases0)}
    return _Loops(info, omega1_0, times, warnings), s, rfj, record, ind


def indicators(program, s, rfj, ev: dict, model0, phases0) -> dict:
    """The paper's Table 2 indicators over the rise (rcj = with backlash, rfj = the j = 0 run); ``ev``
    the event record of the rise."""
    rise = _in_rise(program, s["phi1"])
    contact = rise & (s["contact"] != FREE)
    mr = s["MR13D"][contact]
    dphi2 = np.abs(s["phi2"] - rfj["phi2"])[rise]
    dw2 = np.abs(s["omega2"] - rfj["omega2"])[rise]
    dw1 = np.abs(s["omega1"] - rfj["omega1"])[rise]
    if ev["event_time"].size:  # the exact states just before and after each event (grid samples miss the jumps)
        ref = sample(model0, phases0, ev["event_time"])
        for when in ("before", "after"):
            dw1 = np.concatenate([dw1, np.abs(ev[f"event_omega1_{when}"] - ref["omega1"])])
            dw2 = np.concatenate([dw2, np.abs(ev[f"event_omega2_{when}"] - ref["omega2"])])
        dphi2 = np.concatenate([dphi2, np.abs(ev["event_phi2"] - ref["phi2"])])
    perc = ev["event_percussion"][events.is_impact(ev)]
    return {
        "MR13D_max_Nm": float(mr.max()) if mr.size else None,
        "MR13D_min_Nm": float(mr.min()) if mr.size else None,
        "dphi2_max_deg": float(np.degrees(dphi2.max())) if dphi2.size else 0.0,
        "domega2_max_rad_s": float(dw2.max()) if dw2.size else 0.0,
        "domega1_max_rad_s": float(dw1.max()) if dw1.size else 0.0,
        "percussion_max_Ns": float(np.max(perc)) if perc.size else 0.0,
        # Table 2's jumps: every flight, by lift-off or by rebound after an impact
        "jumps": events.flights(ev),
        "impacts": events.impacts(ev),
        "liftoffs": events.lift_offs(ev),
        "settles": events.settles(ev),
    }


def _dataset(scene, info, omega1_0, times, s, r, record: dict) -> DatasetParts:
    """The run's Dataset, not built yet (result.DatasetParts)."""
    def var(data, units, long_name, dims=("time",), **extra):
        return (dims, np.asarray(data), {"units": units, "long_name": long_name, **extra})

    aE_t, aE_n = sensor_point.acceleration_at_E(scene.mechanism.DE, s["omega2"], s["epsilon2"])
    data = {
        "phi1": var(s["phi1"], "rad", "cam angle from the start of the rise"),
        "omega1": var(s["omega1"], "rad/s", "cam angular velocity"),
        "epsilon1": var(s["epsilon1"], "rad/s^2", "cam angular acceleration"),
        "phi2": var(s["phi2"], "rad", "follower angle of DC from the x axis"),
        "omega2": var(s["omega2"], "rad/s", "follower angular velocity"),
        "epsilon2": var(s["epsilon2"], "rad/s^2", "follower angular acceleration (impacts excluded: impulsive)"),
        "aE_t": var(aE_t, "m/s^2", "tangential acceleration of E (ideal sensor)"),
        "aE_n": var(aE_n, "m/s^2", "normal acceleration of E, towards D (ideal sensor)"),
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
        **record,
    }
    return DatasetParts(data, coords={"time": ("time", times, {"units": "s", "long_name": "time from the start of the rise"})},
                        attrs={
        "title": "labtool rigid-element dynamic model (paper sec. 2.1.1, eqs 1-11)",
        "omega1_start_rad_s": omega1_0, "no_load_cam_speed_rad_s": no_load_cam_speed(scene.mechanism, scene.omega1_nominal),
        "cam_sense": int(info["sense"]), "transmission_ratio": info["transmission_ratio"],
        "J_cam_kgm2": info["J_cam"], "event_record": events.RECORD_VERSION,
    })
