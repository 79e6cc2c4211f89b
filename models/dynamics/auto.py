"""``--model auto``: run only as much of the fidelity ladder as the scene needs, and say why.

The ladder (docs/architecture.md): kinematic -> rigid (1 DOF, the motor's speed variation) -> rigid + backlash
(jumps and impacts) -> elastic (contact deformation). ``simulate_auto`` climbs it:

1. Contact outputs requested (x_el, contact force, deformation): the elastic model, the only
   level that has them.
2. Otherwise the kinematic level first (cam as input, kinetostatic MR13D over the rise, read from
   the shared cam-angle table of labtool.models.mechanism.cam_tables; the kinematic dataset is built only when it is
   the answer).
   MR13D keeps its sign (by more than SIGN_MARGIN of its range) and omega1 is constant: the follower
   never leaves the flank, so the rigid model *is* the kinematic model; no dynamic model runs, and
   the jump indicators are exact zeros (no contact loss: the backlash run is the no-backlash run).
   The same holds when the groove has no backlash (j = 0: the follower cannot leave the groove).
3. omega1 variable, or a sign change with backlash: the rigid model, escalated in time. The
   no-backlash run (1 DOF, the reference of the paper's dphi2/domega indicators) is integrated
   first; before the first instant its flank force approaches zero the backlash run is the very
   same ODE on the inner flank, so it is not integrated twice: the 2-DOF model with impacts starts
   there, from the no-backlash run's state (``SharedPrefixLoop``). If the force never approaches
   zero, no backlash run is integrated at all. The ``reference`` preset runs the plain model.

The result says which level ran and why (``SimulationResult.reason``; dataset attributes
``model``, ``model_reason``, ``auto_rhs_evaluations`` = the cost in right-hand-side evaluations of
the compiled loops, ``auto_escalation_phi1_rad`` = where the backlash model took over).
"""
from __future__ import annotations

import math

import numpy as np

from labtool.models.dynamics import elastic, kinematic, rigid
from labtool.models.dynamics.kernels import rigid_nb
from labtool.models.dynamics.scene import Scene

CONTACT_OUTPUTS = frozenset({"x_el", "xel_max_mm", "xel_min_mm", "contact_force", "deformation",
                             "MR13D_contact"})
# a kinematic MR13D minimum closer to zero than this fraction of max |MR13D| counts as a sign
# change: the dynamic levels shift MR13D by the motor's speed variation (< 1 % on Table 1's runs)
SIGN_MARGIN = 0.02
# the backlash run starts this many steps of the no-backlash run before its flank force first
# changes sign (so that the lift-off event is found inside the backlash run, as in the full run)
BACK_STEPS = 3


def _sign_change(mn: float, mx: float) -> bool:
    scale = max(abs(mn), abs(mx), 1e-12)
    return not (mn > SIGN_MARGIN * scale or mx < -SIGN_MARGIN * scale)


def choose_level(scene: Scene, needs_contact_outputs: bool = False, outputs=()) -> tuple[str, str]:
    """(level, reason) from the kinematics alone: 'elastic', 'kinematic' or 'rigid'."""
    level, reason, _ = _choose(scene, needs_contact_outputs or bool(CONTACT_OUTPUTS.intersection(outputs)))
    return level, reason


def _choose(scene: Scene, contact: bool):
    """(level, reason, kinematic result or None)."""
    if contact:
        return "elastic", "contact outputs (x_el, contact force) were requested: only the elastic model has them", None
    mn, mx = rise_moment_range(scene)
    change = _sign_change(mn, mx)
    if scene.omega1_mode == "const" and (not change or scene.backlash == 0.0):
        kin = kinematic.simulate(scene)  # the answer: only now is the kinematic dataset built
        mn, mx = kin.indicators["MR13D_min_Nm"], kin.indicators["MR13D_max_Nm"]
        why = (f"MR13D keeps its sign over the rise ({mn:.3g} to {mx:.3g} N m)" if not change else
               f"MR13D changes sign ({mn:.3g} to {mx:.3g} N m) but the groove has no backlash")
        return "kinematic", (f"{why} and omega1 is constant: the follower never leaves the flank, the "
                             "kinematic level is the rigid model's exact solution"), kin
    if change and scene.backlash > 0.0:
        return "rigid", (f"MR13D changes sign over the rise ({mn:.3g} to {mx:.3g} N m) with backlash "
                         f"{scene.backlash * 1e3:g} mm: jumps and impacts need the rigid model with backlash"), None
    why = (f"MR13D keeps its sign ({mn:.3g} to {mx:.3g} N m)" if not change else
           f"MR13D changes sign ({mn:.3g} to {mx:.3g} N m) but the groove has no backlash")
    return "rigid", f"{why}; omega1 is variable: the motor's speed variation needs the 1-DOF rigid model", None


def rise_moment_range(scene: Scene) -> tuple[float, float]:
    """(min, max) of the kinetostatic MR13D (N m) over the rise at the cam speed the kinematic level
    runs at, from the shared cam-angle table (labtool.models.mechanism.cam_tables: the grid the elastic model uses,
    4001 angles over the rise, computed once per mechanism and law): the decision costs ~0.1 ms
    instead of a whole kinematic analysis."""
    tab = elastic.grid_tables(scene.replace(rise_only=True), scene.program.rise_angle)
    return float(tab.MR13D.min()), float(tab.MR13D.max())


class SharedPrefixLoop:
    """An integration loop for ``labtool.models.dynamics.rigid.simulate`` (compiled) that integrates the prefix the
    backlash run and the no-backlash run share only once.

    First call (the backlash model, j > 0): integrate the no-backlash run (j = 0) over the span,
    find the first of its steps where its flank force is <= 0, and start the backlash run (contact
    on the inner flank, free to lift off) BACK_STEPS steps earlier from its state; the prefix phase
    is the no-backlash run's. Second call (j = 0): return the run already made.
    """

    def __init__(self):
        self.rfj = None            # (phi1_end, omega1_0, phases, event rows)
        self.escalation_phi1 = None

    def __call__(self, model, omega1_0, preset, t_rise, start=None, t_start=0.0, solver="compiled", stats=None):
        run = lambda m, **kw: rigid.integrate(m, omega1_0, preset, t_rise, solver=solver, stats=stats, **kw)  # noqa: E731
        if start is not None:
            return run(model, start=start, t_start=t_start)
        if model.j == 0.0:
            if self.rfj is not None and self.rfj[1] == omega1_0 and self.rfj[0] >= model.phi1_end:
                return self.rfj[2], self.rfj[3]
            return run(model)
        # the backlash run: the no-backlash run first (a little longer: rigid.simulate samples it
        # up to the end of the backlash run, which may overshoot by an event's resolution)
        model0 = model._replace(j=0.0, phi1_end=model.phi1_end + 0.1)
        phases0, rows0 = run(model0)
        self.rfj = (model0.phi1_end, omega1_0, phases0, rows0)
        if len(phases0) != 1 or phases0[0].kind != "contact":
            return run(model)
        ph = phases0[0]
        ts = ph.sol.t
        y = np.ascontiguousarray(ph.sol(ts))
        terms = np.empty((len(rigid.SAMPLED), ts.size))
        rigid_nb.derived(model0, np.full(ts.size, rigid.CONTACT, dtype=np.int64),
                         np.full(ts.size, rigid.INNER, dtype=np.int64), y, terms)
        lam = np.where(y[0] <= model.phi1_end, terms[rigid.SAMPLED.index("R13n")], np.inf)   # inside the span
        low = np.flatnonzero(lam <= 0.0)
        if not low.size:
            # the flank force never vanishes: the backlash run is the no-backlash run; cut it at
            # the end of the backlash run's span
            self.escalation_phi1 = None
            return [rigid.Phase("contact", rigid.INNER, ph.t0, _time_at_phi1(ph, model.phi1_end), ph.sol)], rows0[:0]
        k = int(low[0]) - BACK_STEPS
        if k <= 0:                                            # at (or near) the start: the full run
            self.escalation_phi1 = 0.0
            return run(model)
        t_a = float(ts[k])
        phi1_a, omega1_a = float(y[0, k]), float(y[1, k])
        prefix = rigid.Phase("contact", rigid.INNER, ph.t0, t_a, ph.sol)
        self.escalation_phi1 = phi1_a
        phases, rows = run(model, start=("contact", phi1_a, omega1_a, rigid.INNER), t_start=t_a)
        return [prefix] + phases, rows


def _time_at_phi1(phase, phi1_end: float) -> float:
    """Time (s) at which a contact phase's phi1 reaches phi1_end (bisection on its dense output)."""
    lo, hi = phase.t0, phase.t1
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        if float(phase.sol(mid)[0]) < phi1_end:
            lo = mid
        else:
            hi = mid
    return hi


def simulate_auto(scene: Scene, outputs=()):
    """Run the cheapest level the scene needs (module doc). Returns labtool.models.dynamics.result.SimulationResult."""
    level, reason, kin = _choose(scene, bool(CONTACT_OUTPUTS.intersection(outputs)))
    stats: dict = {}
    escalation = None
    if level == "kinematic":
        result = kin
        result.indicators.update(dphi2_max_deg=0.0, domega2_max_rad_s=0.0, domega1_max_rad_s=0.0,
                                 percussion_max_Ns=0.0, jumps=0, impacts=0)
    elif level == "elastic":
        result = elastic.simulate(scene, stats=stats)
    elif rigid.SOLVERS[scene.accuracy] == "compiled":
        loop = SharedPrefixLoop()
        result = rigid.simulate(scene, stats=stats, integrate_with=loop)
        escalation = loop.escalation_phi1
        if escalation is None:
            reason += ("; the flank force of the 1-DOF run never vanishes: no backlash model was needed "
                       "(no contact loss)")
        elif escalation > 0.0:
            reason += (f"; the 1-DOF run (no backlash) up to phi1 = {math.degrees(escalation):.2f} deg, "
                       "just before its flank force changes sign, then the 2-DOF model with impacts")
    else:
        result = rigid.simulate(scene, stats=stats)
        reason += "; the reference preset runs the full scipy model (no escalation in time)"
    result.model = level
    result.reason = reason
    result.attrs.update(auto_rhs_evaluations=int(stats.get("nfev", 0)),
                        auto_escalation_phi1_rad=float("nan") if escalation is None else float(escalation))
    return result
