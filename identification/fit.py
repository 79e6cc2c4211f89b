"""``identify``: a model's parameters from a measurement, with their uncertainty (labtool fit).

The steps (docs/identification.md):

1. the measurement side once (labtool.identification.objective.load_target);
2. *before*: the model at the scene's values (what ``labtool report`` would simulate);
3. the search at the ``fast`` preset: a coarse scan of the bounds, bounded least squares on
   smoothed cycles from its best points (and a given start), then at full resolution from the best
   (labtool.identification.search);
4. for another requested preset, a few least-squares iterations at that preset from there;
5. the Jacobian at the optimum (central differences) at the requested preset: 95 % intervals and
   correlations; a profile of the objective per parameter checks them and finds what this
   measurement cannot identify (labtool.identification.uncertainty);
6. *after*: metrics of the fitted model against the measurement, as the report computes them.
"""
from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import numpy as np

from labtool.common.operating_point import BY_ATTR, FIELD, STATED
from labtool.common.errors import InputError, SolverError
from labtool.common.names import shown
from labtool.identification import search, uncertainty
from labtool.identification.objective import SIGNALS, Evaluation, Evaluator, load_target
from labtool.identification.parameters import check_start, make_space, parse_free
from labtool.reports import align, pipeline

FORMAT = "labtool.fit"
FORMAT_VERSION = 1
SEARCH_PRESET = "fast"
OTHER_PRESET = {"fast": "standard", "standard": "fast"}   # the optimum's shift between them is a numerical error
ACCURACIES = ("fast", "standard")
OMEGA1_MODES = ("const", "var")
DEFAULT_REVOLUTIONS = 3       # the first is the start-up transient; the last two judge periodicity
POLISH_NFEV = 6               # least-squares iterations at the requested preset after the fast search
RESTARTS = 1                  # searches again from a deeper point the profiles find
UNEXPLAINED = 10.0            # objective per residual beyond which the model is said not to explain the measurement
# objective per residual beyond which an impact-law parameter (not a stand property: restitution,
# contact damping) is the closest model's effective value, its interval no bound on the stand's: a
# model's own truth fits at 1-2; on the twin and the foreign stand (5-200) the rigid k came out
# biased by +0.2 with nothing in the measurement to show it (docs/identification.md, coverage)
MISFIT = 3.0
# |correlation| with a parameter judged misfit from which a parameter is judged misfit too: the
# misfit parameter's bias (what the model misses, which it stands in for) moves this one's estimate
# by r x its own bias in units of the intervals, and at |r| = 0.5 a quarter of its variance is shared
MISFIT_CORRELATION = 0.5
METRIC_KEYS = ("iso_rating", "iso_grade", "sg_magnitude", "sg_phase", "sg_comprehensive", "nrmse", "band_overlap")


@dataclasses.dataclass
class FitRequest:
    """What to fit. ``free``: the --free text; ``bounds``/``start`` in edge units by parameter name
    (``start``: "scan" (default), "scene", or {name: value}: a given start is searched from first,
    beside the scan's best points unless ``scan`` is False); ``overrides``: the operating point as
    ``labtool report`` takes it (SI values by operating-point field); ``chain``: fixed
    values of the chain parameters that are not free (ka_gain, delay_ms)."""

    measured: Path
    model: str
    free: str
    omega1: str = "const"
    accuracy: str = "standard"
    revolutions: int = DEFAULT_REVOLUTIONS
    bounds: dict = dataclasses.field(default_factory=dict)
    start: object = "scan"
    overrides: dict = dataclasses.field(default_factory=dict)
    chain: dict = dataclasses.field(default_factory=dict)
    max_runs: int = 200
    cond: align.Conditioning | None = None
    scan: bool = True

    def check(self) -> None:
        if self.accuracy not in ACCURACIES:
            raise InputError(f"--accuracy must be one of {', '.join(ACCURACIES)} for a fit, got '{self.accuracy}' "
                             "(check a fitted model at the reference preset with 'labtool report --fit')")
        if self.omega1 not in OMEGA1_MODES:
            raise InputError(f"--omega1 must be one of {', '.join(OMEGA1_MODES)}, got '{self.omega1}'")
        if not (isinstance(self.revolutions, int) and 2 <= self.revolutions <= 20):
            raise InputError(f"--revolutions must be a whole number in [2, 20], got {self.revolutions}")
        if not (isinstance(self.max_runs, int) and self.max_runs >= 4):
            raise InputError(f"--max-runs must be a whole number >= 4, got {self.max_runs}")


@dataclasses.dataclass
class FitOutcome:
    """The result (``summary``: the JSON object) and what the figures need."""

    summary: dict
    target: object
    space: object
    before: Evaluation
    after: Evaluation
    profiles: list
    linear: uncertainty.Linear
    evaluator: Evaluator | None = None     # its cached model runs (a joint fit reuses them)


def identify(req: FitRequest, progress=None) -> FitOutcome:
    """Fit ``req.free`` of ``req.model`` to ``req.measured``; see the module's steps."""
    t0 = time.perf_counter()
    say = progress or (lambda msg: None)
    req.check()
    # the options first: a wrong parameter name must not wait for the measurement to be read
    free = parse_free(req.free, req.model, req.overrides.get("elastic_gap") or "physical")
    space = make_space(free, req.bounds)
    if isinstance(req.start, dict):
        _start(req.start, space, space.from_unit(np.full(len(free), 0.5)))
    say("reading and aligning the measured revolutions")
    target = load_target(req.measured, req.cond, req.overrides)
    fixed = {**target.op, "ka_gain": 1.0, "delay_ms": 0.0, **req.chain}
    x_scene = np.array([fixed.get(p.op_key, p.start) for p in free], float)
    x_start, start_note = _start(req.start, space, x_scene)
    ev = Evaluator(target, req.model, req.omega1, req.revolutions, space, fixed)
    notes = list(target.notes) + ([start_note] if start_note else [])

    say(f"the model at the scene's values ({req.accuracy})")
    before = ev.evaluate(x_scene, req.accuracy)
    if not before.ok:
        notes.append(f"the {req.model} model fails at the scene's values: {before.error}")
    u_best = _search(ev, space, req, x_start, say, notes)
    if req.accuracy != SEARCH_PRESET:
        polish = search.Problem(ev, req.accuracy, ev.model_runs + POLISH_NFEV * (len(free) + 1), say, "polish")
        search.minimize(polish, u_best, max_nfev=POLISH_NFEV)
        if polish.best.ev is not None:
            u_best = polish.best.u
    for attempt in range(RESTARTS + 1):
        say(f"intervals and profiles ({req.accuracy})")
        after, lin, profiles, deeper = _uncertainty(ev, space, req, u_best, say)
        if deeper is None:
            break
        where = ", ".join(f"{n} = {v:.4g}" for n, v in space.as_dict(space.from_unit(deeper[0])).items())
        found = f"a point checked for the intervals has a lower objective ({deeper[1]:.4g} < {after.objective:.4g}) at {where}"
        if attempt == RESTARTS:
            notes.append(f"{found}, again after a restart: the objective is rough or has several minima here; "
                         "the result is the best point found; try --start there or narrower --bounds")
            break
        notes.append(f"{found}: the search restarted from there")
        u_best = _restart(ev, req, deeper[0], say)
    chi2 = after.objective / after.residuals.size
    if chi2 > UNEXPLAINED:
        notes.append(f"the {req.model} model leaves {chi2:.3g} x the measurement's variance (its scatter and a 1 % "
                     "floor) unexplained: the values are those of the closest {req.model} model, which is not the "
                     "stand's physics here; the intervals include a term for the bias that misfit may hide "
                     "(model_discrepancy)".replace("{req.model}", req.model))
    summary = _summary(req, target, space, ev, x_scene, x_start, before, after, lin, profiles, notes,
                       time.perf_counter() - t0)
    return FitOutcome(summary, target, space, before, after, profiles, lin, ev)


def _uncertainty(ev: Evaluator, space, req: FitRequest, u_best, say):
    """At the optimum and the requested preset: the Jacobian (central differences), the HAC
    covariance, the numerical spread (revolutions, the other preset, convergence, roughness) and
    one profile a parameter; ``deeper`` = (u, objective) of a point these visited lower than the
    optimum by more than a threshold and the roughness (the search missed a deeper minimum), else None."""
    final = search.Problem(ev, req.accuracy, None, say, "intervals")
    after = final.at(u_best)
    if not after.ok:
        raise SolverError(f"the {req.model} model fails at the fitted point {space.as_dict(space.from_unit(u_best))}: "
                          f"{after.error}")
    J = final.jacobian(u_best, central=True)
    u_j, r_j = u_best, after.residuals
    u_best, after = search.gauss_newton_step(final, u_best, after, J)
    lin = uncertainty.linear(J, after.residuals, u_best, ev.blocks(None))
    other = search.Problem(ev, OTHER_PRESET[req.accuracy], None, say, "preset check").at(u_best)
    lin.rev_u, lin.preset_u, lin.conv_u = uncertainty.numerical(J, after.residuals,
                                                                 ev.revolution_residuals(space.from_unit(u_best), after),
                                                                 other.residuals if other.ok else None)
    lin.rough_u, lin.rough = uncertainty.roughness(final, lin, J, u_j, r_j, search.FD_STEP)
    lin.disc_u, lin.disc_rise, lin.disc_info = uncertainty.discrepancy(J, after.residuals, lin)
    # every point evaluated (cached) within the roughness and the threshold of the optimum widens the
    # interval, at the requested preset and, measured from its own value at the optimum, the search's
    rows = [ev.acceptable(req.accuracy, after.objective + lin.acceptance())]
    if req.accuracy != SEARCH_PRESET and other.ok:
        rows.append(ev.acceptable(SEARCH_PRESET, other.objective + lin.acceptance()))
    lin.set_hull(space.to_unit(np.vstack(rows)))
    profiles = [uncertainty.profile(final, lin, J, i) for i in range(len(space.params))]
    # a point visited here lower than the optimum by more than the threshold and the roughness:
    # the search stopped in a shallower minimum
    margin = max(min(lin.threshold(i) for i in range(len(space.params))), lin.rough)
    best = final.best
    deeper = (best.u, best.ev.objective) if best.ev is not None and best.ev.objective < after.objective - margin else None
    return after, lin, profiles, deeper


def _restart(ev: Evaluator, req: FitRequest, u0, say) -> np.ndarray:
    """Least squares again from a deeper point a profile found (search preset, then a polish)."""
    prob = search.Problem(ev, SEARCH_PRESET, ev.model_runs + req.max_runs // 2, say, "search again")
    try:
        search.minimize(prob, u0)
    except search.Budget:
        pass
    u = prob.best.u if prob.best.ev is not None else u0
    if req.accuracy != SEARCH_PRESET:
        polish = search.Problem(ev, req.accuracy, ev.model_runs + POLISH_NFEV * (u.size + 1), say, "polish")
        search.minimize(polish, u, max_nfev=POLISH_NFEV)
        if polish.best.ev is not None:
            u = polish.best.u
    return u


def _start(start, space, x_scene) -> tuple[np.ndarray, str]:
    """The starting point (edge units) and a note, from "scan", "scene" or {name: value}."""
    if isinstance(start, dict):
        extra = set(start) - set(space.names)
        if extra:
            raise InputError(f"--start: {', '.join(sorted(extra))} is not free (add it to --free, or set its "
                             "fixed value with its own option)")
        vals = {**space.as_dict(x_scene), **start}
        return check_start(space, vals), ""
    if start == "scene":
        return check_start(space, space.as_dict(x_scene)), ""
    if start != "scan":
        raise InputError(f"--start must be 'scan', 'scene' or name=value,..., got '{start}'")
    inside = np.all((x_scene >= space.lo) & (x_scene <= space.hi))
    if inside:
        return x_scene, ""
    centre = space.from_unit(np.full(len(space.params), 0.5))
    return centre, ("the scene's values lie outside the bounds: the scan starts from the bounds' centre "
                    f"({', '.join(f'{n} = {v:.4g}' for n, v in space.as_dict(centre).items())})")


def coarse_harmonics(cond: align.Conditioning) -> int:
    """The resolution of the search's first stage: a third of the harmonics (at least 8). The
    impacts' pulses and rebounds are smoothed there, so the objective has one wide basin where the
    full resolution has narrow ones (docs/identification.md, the landscape at 180 rpm)."""
    return max(8, cond.n_harmonics // 3)


SCAN_STARTS = 2       # least-squares starts on the smoothed cycles: the scan's best points


def _search(ev: Evaluator, space, req: FitRequest, x_start, say, notes) -> np.ndarray:
    """Scan, least squares on the smoothed cycles from the given start (if any) and the scan's best
    ``SCAN_STARTS`` points, then least squares at full resolution from the best of those, all at
    the search preset; the best u. ``req.scan`` False with a given start: that start only."""
    prob = search.Problem(ev, SEARCH_PRESET, req.max_runs, say, "scan", harmonics=coarse_harmonics(ev.target.cond))
    given = req.start != "scan"
    try:
        starts = [space.to_unit(x_start)] if given else []
        if req.scan or not given:
            results = sorted(search.scan(prob, search.scan_points(space, space.to_unit(x_start))), key=lambda r: r[1])
            starts += [u for u, obj in results[:SCAN_STARTS] if np.isfinite(obj)]
        prob.phase = "search, smoothed"
        for u0 in starts:
            search.minimize(prob, u0)
    except search.Budget:
        pass
    fine = search.Problem(ev, SEARCH_PRESET, req.max_runs, say, "search", harmonics=None)
    try:
        if prob.best.u is not None:
            fine.at(prob.best.u)
            search.minimize(fine, prob.best.u)
    except search.Budget:
        pass
    if fine.best.ev is None:
        first = ev.failures[0] if ev.failures else {"error": "no point evaluated"}
        raise SolverError(f"the {req.model} model failed at every point the search tried ({len(ev.failures)} runs; "
                          f"first: {first['error']}); check the operating point or narrow --bounds")
    if fine.exhausted:
        notes.append(f"the search stopped at its budget of {req.max_runs} model runs (--max-runs): the optimum "
                     "may not be reached")
    if ev.failures:
        notes.append(f"the model failed at {len(ev.failures)} trial point(s) (first: {ev.failures[0]['error']} at "
                     f"{ev.failures[0]['at']}); the search went around them")
    return fine.best.u


# --------------------------------------------------------------------------- the JSON

def metrics(target, e: Evaluation, delay_deg: float = 0.0) -> dict | None:
    """The report's overall metrics of a model cycle against the measured cycle average, and its
    events beside the measured ones; None when the model failed."""
    if not e.ok:
        return None
    out = {}
    for sig in SIGNALS:
        o, _ = pipeline.compare_signal(target.cycles, e.cycle, sig, per_revolution=False)
        out[sig] = {k: o.get(k) for k in METRIC_KEYS}
    m = target.events or {}
    p = e.events or {}
    first = p.get("first_impact_deg")
    out["events"] = {"first_impact_deg": None if first is None else first + delay_deg,
                     "impacts_per_rev": p.get("detectable_impacts_per_rev"),
                     "measured_first_impact_deg": m.get("first_impact_deg"),
                     "measured_impacts_per_rev": m.get("impacts_per_rev")}
    out["periodic"] = bool(getattr(e.cycle, "periodic", True))
    return out


def _parameter(space, i: int, lin, prof, x_start, x_scene, chi2: float) -> dict:
    """One parameter's entry of the JSON (edge units)."""
    out = _parameter_entry(space, i, lin, prof, space.keys, chi2)
    out["start"] = float(x_start[i])
    out["scene_value"] = float(x_scene[i])
    return out


def _parameter_entry(space, i: int, lin, prof, names: list[str], chi2: float, others: list[int] | None = None) -> dict:
    """Parameter i's value, intervals and verdict (edge units); ``prof`` None: no profile was
    computed (the linear interval stands); ``names``: every parameter's, for the verdicts;
    ``chi2``: the objective per residual (the misfit verdict); ``others``: the parameters whose
    correlation with it makes it not identifiable (uncertainty.verdict; default all).

    ``verdict``: "identified"; "not identifiable" (``notes`` say why); or "misfit": an impact-law
    parameter fitted where the model leaves more than MISFIT x the measurement's variance, whose
    interval understates how far the stand's value may lie (and, after ``inherit_misfit``, a
    parameter whose estimate moves with such a one's)."""
    p = space.params[i]
    lo, hi, sides = uncertainty.interval(lin, prof, i)
    lin_lo, lin_hi = lin.interval_u()
    plo, phi = prof.interval_u(lin) if prof is not None else (math.nan, math.nan)
    why = uncertainty.verdict(lin, prof, i, names, lo, hi, others)
    bound = uncertainty.at_bound(float(lin.u[i]))
    sources = lin.sources(i)
    misfit = bool(not p.stand and chi2 > MISFIT)
    if misfit and not why:
        sides = sides + [f"misfit: the model leaves {chi2:.3g} x the measurement's variance unexplained, and an "
                         "impact-law parameter then stands in for what the model misses (the flanks' compliance, the "
                         "follower's bending): the value is the closest model's effective one, its interval "
                         "understates how far the stand's may lie"]
    if (sources.get("model_discrepancy") or 0.0) > 0.5:
        sides = sides + ["its interval is mostly the model's discrepancy: the model misses something this parameter "
                         "could make up for, so the value is the closest model's and may be biased by that much"]
    return {
        "value": space.value(i, float(lin.u[i])),
        # held to the search bounds (a restitution of -4 is no answer); the verdict says when the
        # interval reached past them, and ci95_unbounded keeps it as computed
        "ci95": [space.value(i, max(lo, 0.0)), space.value(i, min(hi, 1.0))],
        "ci95_unbounded": [space.value(i, lo), space.value(i, hi)],
        "ci95_linear": [space.value(i, lin_lo[i]), space.value(i, lin_hi[i])],
        "bound_hit": bound is not None,
        "bound": bound,
        "unit": p.unit,
        "bounds": [float(space.lo[i]), float(space.hi[i])],
        "ci95_profile": [space.value(i, plo), space.value(i, phi)],
        "profile_agrees": prof is not None and all(r is None or PROFILE_LOW <= r <= PROFILE_HIGH
                                                   for r in (prof.rho_low, prof.rho_high)),
        "interval_sources": sources,
        "roughness_over_threshold": lin.rough_ratio(i),
        "identifiable": not why,
        "misfit": misfit,
        "verdict": "not identifiable" if why else ("misfit" if misfit else "identified"),
        "notes": why + sides,
    }


def inherit_misfit(entries: dict, corr: np.ndarray) -> dict:
    """Judge misfit a parameter ``identified`` whose estimate moves with a misfit one's
    (|correlation| >= MISFIT_CORRELATION): the misfit one stands in for what the model misses, and
    a bias with a direction in the parameters' space is what the discrepancy term, which assumes
    none, does not cover (docs/identification.md, coverage). ``entries``: by key, in the order of
    ``corr``'s rows; changed in place and returned."""
    keys = list(entries)
    for i, a in enumerate(keys):
        if entries[a]["verdict"] != "identified":
            continue
        for j, b in enumerate(keys):
            r = float(corr[i, j])
            if j != i and entries[b]["verdict"] == "misfit" and math.isfinite(r) and abs(r) >= MISFIT_CORRELATION:
                entries[a].update(verdict="misfit", misfit=True)
                entries[a]["notes"] = entries[a]["notes"] + [
                    f"misfit: its estimate moves with {b}'s (r = {r:+.2f}), which stands in for what the model "
                    "misses: its interval understates how far the stand's value may lie"]
                break
    return entries


def _summary(req, target, space, ev, x_scene, x_start, before, after, lin, profiles, notes, wall) -> dict:
    from labtool.reports.summary import plain_json

    names = space.keys
    corr = lin.correlation()
    fitted_op = ev.values(space.from_unit(lin.u))
    out = {
        "format": FORMAT, "format_version": FORMAT_VERSION,
        "model": req.model, "omega1": req.omega1, "accuracy": req.accuracy, "search_accuracy": SEARCH_PRESET,
        "revolutions": req.revolutions,
        "measured": {"file": str(req.measured), "whole_revolutions": target.n_revolutions,
                     "cam_speed_rpm_measured": target.cycles.cam_speed_rpm, "events": _events_info(target.events)},
        "free": space.names,
        "parameters": inherit_misfit({p.key: _parameter(space, i, lin, profiles[i], x_start, x_scene,
                                                        after.objective / after.residuals.size)
                                      for i, p in enumerate(space.params)}, corr),
        "correlation": {a: {b: float(corr[i, j]) for j, b in enumerate(names)} for i, a in enumerate(names)},
        "objective_before": before.objective if before.ok else None,
        "objective_after": after.objective,
        "degrees_of_freedom": lin.dof,
        "objective_per_residual": after.objective / after.residuals.size,
        "residual_scale": math.sqrt(lin.s2),
        "interval_inflation": {p.key: float(v) for p, v in zip(space.params, lin.inflation)},
        "newey_west_lags": lin.nlags,
        "roughness": lin.rough,
        "model_discrepancy": lin.disc_info,
        "metrics_before": metrics(target, before, _delay_deg(ev.values(x_scene))),
        "metrics_after": metrics(target, after, _delay_deg(fitted_op)),
        "profiles": {p.key: {"values": [space.value(i, u) for u in profiles[i].u], "objective": profiles[i].objective,
                             "threshold": after.objective + lin.threshold(i)}
                     for i, p in enumerate(space.params)},
        "operating_point": dict(ev.fixed),
        "fitted_operating_point": fitted_op,
        "failures": ev.failures,
        "evaluations": ev.model_runs,
        "objective_evaluations": ev.evaluations,
        "model_time_s": ev.run_s,
        "notes": notes,
        "wall_s": wall,
    }
    return plain_json(out)


PROFILE_LOW, PROFILE_HIGH = uncertainty.PROFILE_AGREES


def _delay_deg(op: dict) -> float:
    """The chain delay of an operating point as cam angle (deg): delay_ms x the cam's deg per ms."""
    return op.get("delay_ms", 0.0) * 1e-3 * op["cam_speed_rpm"] * 6.0


def _events_info(m: dict | None) -> dict | None:
    if m is None:
        return None
    return {k: m.get(k) for k in ("impacts_per_rev", "jumps_per_rev", "first_impact_deg", "impact_angles_deg",
                                  "threshold_rad_s")}



def _is_number(v) -> bool:
    """A finite JSON number (not a boolean): what a fit file holds for a value."""
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def load_fit(path: Path) -> dict:
    """A ``labtool fit`` result as ``labtool.reports.pipeline.build_report``'s ``fitted`` entry: the model,
    its omega1 mode, the fitted operating point and a note; InputError for a file that is not one."""
    import json

    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"fit file {path} not found") from None
    except (UnicodeDecodeError, ValueError) as exc:
        raise InputError(f"fit file {path} is not JSON ({exc})") from None
    if isinstance(doc, dict) and doc.get("format") == "labtool.fit.joint":
        n = len(doc.get("files") or [])
        raise InputError(f"{path} is a joint fit of {n} measurements; --fit draws one measurement's fit: fit that "
                         "file alone (labtool fit FILE --model ... --free ... -o fit.json) and give that")
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise InputError(f"{path} is not a 'labtool fit' result (no format = {FORMAT!r})")
    if doc.get("format_version") != FORMAT_VERSION:
        raise InputError(f"{path}: fit format version {doc.get('format_version')!r}, this labtool reads {FORMAT_VERSION}")
    op = doc.get("fitted_operating_point")
    if doc.get("model") not in ("rigid", "elastic") or doc.get("omega1") not in OMEGA1_MODES or not isinstance(op, dict):
        raise InputError(f"{path}: incomplete fit result (model, omega1 or fitted_operating_point missing)")
    for name in STATED:
        if FIELD[name].attr not in op:
            raise InputError(f"{path}: fitted_operating_point has no {FIELD[name].attr}")
    # a hand-edited file: a value of the wrong type was an internal error (TypeError, KeyError, ...)
    for key, value in op.items():
        if key in BY_ATTR:
            BY_ATTR[key].check_edge(value, f"{path}: fitted_operating_point")
        elif key in ("omega1_var_n1_rpm", "ka_gain", "delay_ms") and not _is_number(value):
            raise InputError(f"{path}: fitted_operating_point {key} = {shown(json.dumps(value))} is not a number")
    params = doc.get("parameters", {})
    if not (isinstance(params, dict) and all(
            isinstance(v, dict) and _is_number(v.get("value"))
            and (v.get("ci95") is None or (isinstance(v["ci95"], list) and len(v["ci95"]) == 2
                                           and all(c is None or _is_number(c) for c in v["ci95"])))
            for v in params.values())):
        raise InputError(f"{path}: parameters must map each name to its value and ci95 (two numbers)")
    if not isinstance(doc.get("measured", {}), dict):
        raise InputError(f"{path}: measured must be a table (its file, revolutions, ...)")
    vals = ", ".join(f"{k} = {v['value']:.4g} [{v['ci95'][0]:.4g}, {v['ci95'][1]:.4g}]"
                     if v.get("ci95") and None not in v["ci95"] else f"{k} = {v['value']:.4g}"
                     for k, v in doc.get("parameters", {}).items())
    note = (f"{doc['model']} (fitted): identified by labtool fit from {doc.get('measured', {}).get('file', '?')} "
            f"({path}): {vals}")
    return {"model": doc["model"], "omega1": doc["omega1"], "operating_point": op, "note": note}
