"""The next experiment: the operating point whose recording would narrow the fit's intervals most
(``labtool suggest --goal identify``), or tell the candidate models apart (``--goal discriminate``;
docs/identification.md, "The next experiment").

D-optimal design on the fit's own Jacobian (Atkinson, Donev & Tobias, Optimum Experimental
Designs, ch. 10-11): the measurements so far are fitted (one file alone, several jointly), which
gives the parameters' estimates and their information matrix M0 = cov^-1 (on the search scale,
the fit's covariance: measurement, residual correlation and misfit included). A candidate
operating point c (cam speed, load) is simulated at the estimates through the report's path, and
its residuals' Jacobian J_c (central differences on the search scale, each point over the noise a
recording at c would have) gives the information a recording there would add,
M_c = J_c^T J_c / (s^2 x inflation), with the current fit's misfit s^2 and correlation inflation.
The parameters a joint fit shares (``--shared``: the backlash, by default) persist; the others are
each recording's own, so a new recording brings a new one of those (a nuisance parameter): the
criterion is the Ds one, the determinant of the shared parameters' information with every other
parameter profiled out (the Schur complement), and the expected gain is the ratio of its value
after to before, with each shared parameter's expected interval (its square root's ratio).

The noise a recording at c would have: each signal's measured scatter from revolution to
revolution relative to its rms (the measurements' median), over the square root of the
revolutions a recording of the same duration holds at c, and the fit's 1 % floor
(labtool.identification.objective.MODEL_FLOOR).

Candidates: cam speeds on ``rpm_range`` (within the models' range, Mechanism.check_cam_speed) at
the loads given (default the measured ones: the criterion takes the model's misfit at a candidate
to be the measurements', which holds near them; at a load never measured it can be many times
larger, for the model's own truth too, benchmarks/suggest_loop.py); a candidate whose model run
fails or warns about its own validity is left out and listed with the reason.

``--goal discriminate``: the candidate models (``models``, at the first measurement's operating
point and model options) are simulated at every candidate speed and load by the report's
discrimination (labtool.reports.discrimination.discriminate): their omega2 and epsilon2 cycles'
rms difference in units of the measurement's scatter (scaled with the speed as the signals are);
the point is where the closest pair's epsilon2 lies furthest apart.
"""
from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import numpy as np

from labtool.common.errors import InputError, LabtoolError
from labtool.identification import search
from labtool.identification.objective import MODEL_FLOOR, SIGNALS
from labtool.identification.parameters import parse_free
from labtool.processing.cycles import cycle_statistics
from labtool.reports import align, pipeline

FORMAT = "labtool.suggest"
FORMAT_VERSION = 1
GOALS = ("identify", "discriminate")
DEFAULT_RPM_RANGE = (120.0, 600.0, 20.0)


@dataclasses.dataclass
class SuggestRequest:
    """What to suggest from: ``measured`` files, the model and free parameters the fit uses,
    ``shared`` (as labtool.identification.joint), the candidates (``rpm_range`` = lo, hi, step in
    rpm; ``loads`` in N, None: the measured ones), the preset of the fit and of the
    candidates' runs, and the fit's other options (``fit``: keyword arguments of FitRequest)."""

    measured: list
    model: str = "rigid"
    free: str = "backlash,restitution"
    goal: str = "identify"
    shared: str | None = None
    rpm_range: tuple = DEFAULT_RPM_RANGE
    loads: tuple | None = None
    accuracy: str = "fast"
    revolutions: int = 3
    fit: dict = dataclasses.field(default_factory=dict)
    models: tuple = ("rigid", "elastic")     # --goal discriminate: the candidate models

    def check(self) -> None:
        if self.goal not in GOALS:
            raise InputError(f"--goal must be one of {', '.join(GOALS)}, got '{self.goal}'")
        if self.goal == "discriminate":
            bad = [m for m in self.models if m not in pipeline.MODELS]
            if bad or len(set(self.models)) < 2:
                raise InputError(f"--models: --goal discriminate needs two or more of {', '.join(pipeline.MODELS)}, got "
                                 f"{','.join(self.models) or 'none'}")
        lo, hi, step = self.rpm_range
        if not (all(math.isfinite(v) for v in (lo, hi, step)) and 0 < lo <= hi and step > 0):
            raise InputError(f"--rpm-range must be lo:hi:step with 0 < lo <= hi and step > 0 rpm, got "
                             f"{lo:g}:{hi:g}:{step:g}")
        if (hi - lo) / step > 200:
            raise InputError(f"--rpm-range {lo:g}:{hi:g}:{step:g} makes {int((hi - lo) / step) + 1} speeds; at most 201 "
                             "(each costs model runs): take a larger step")
        for f in self.loads or ():
            if not (math.isfinite(f) and f >= 0):
                raise InputError(f"--loads: a load must be a finite force >= 0 N, got {f:g}")


def speeds(rpm_range: tuple) -> np.ndarray:
    """The candidate cam speeds (rpm) within the models' range."""
    from labtool.models.mechanism import Mechanism

    lo, hi, step = rpm_range
    mech = Mechanism.default()
    out = np.arange(lo, hi + 0.5 * step, step)
    out = out[(out >= mech.min_cam_speed_rpm) & (out <= mech.max_cam_speed_rpm)]
    if out.size == 0:
        raise InputError(f"--rpm-range {lo:g}:{hi:g}:{step:g} holds no speed the models take "
                         f"({mech.min_cam_speed_rpm:.4g}-{mech.max_cam_speed_rpm:.4g} rpm)")
    return out


@dataclasses.dataclass
class Candidate:
    rpm: float
    Fu: float
    criterion: float = math.nan         # log det of the shared information after over before
    shrink: dict = dataclasses.field(default_factory=dict)   # key -> expected interval width after / before
    error: str | None = None


@dataclasses.dataclass
class SuggestOutcome:
    summary: dict
    candidates: list
    fit: object


def noise_model(targets: list) -> dict:
    """Per signal: the measured scatter between revolutions relative to the cycle's rms (median
    over the grid and the measurements), and the recordings' mean duration in cam revolutions per
    rpm (to scale the revolutions a recording at another speed holds)."""
    rel = {s: [] for s in SIGNALS}
    minutes = []
    for t in targets:
        for s in SIGNALS:
            stats = cycle_statistics(align.harmonic_lowpass(t.cycles.signals[s], t.cond.n_harmonics))
            rms = float(np.sqrt(np.mean(stats.mean ** 2)))
            if rms > 0:
                rel[s].append(float(np.median(stats.std)) / rms)
        minutes.append(t.n_revolutions / t.cycles.cam_speed_rpm)
    return {"scatter": {s: float(np.median(v)) if v else 0.0 for s, v in rel.items()},
            "minutes": float(np.mean(minutes))}


def _time_filter(tf, rpm_measured: float, rpm: float):
    """The processing's low-pass at another speed: its cutoff scales with the cam frequency, at most 0.4 fs."""
    if tf is None:
        return None
    return align.TimeFilter(tf.fs, min(tf.cutoff_hz * rpm / rpm_measured, 0.4 * tf.fs), tf.order)


def _schur(M: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """The information of the ``keep`` parameters with the others profiled out."""
    a = M[np.ix_(keep, keep)]
    if keep.all():
        return a
    b = M[np.ix_(keep, ~keep)]
    c = M[np.ix_(~keep, ~keep)]
    return a - b @ np.linalg.pinv(c, rcond=1e-12, hermitian=True) @ b.T


def _logdet(M: np.ndarray) -> float:
    sign, v = np.linalg.slogdet(M)
    return v if sign > 0 else -math.inf


def information(cov: np.ndarray) -> np.ndarray:
    """The information matrix of a fit's covariance (unit box); a parameter the fit does not see
    (an infinite variance) carries none."""
    cov = np.array(cov, float)
    ok = np.isfinite(np.diag(cov)) & (np.diag(cov) > 0)
    M = np.zeros_like(cov)
    if ok.any():
        sub = cov[np.ix_(ok, ok)]
        sub = np.where(np.isfinite(sub), sub, 0.0)
        M[np.ix_(ok, ok)] = np.linalg.pinv(sub, rcond=1e-12, hermitian=True)
    return M


def suggest(req: SuggestRequest, progress=None) -> SuggestOutcome:
    """Fit the measurements, then rate every candidate operating point (module doc)."""
    t0 = time.perf_counter()
    say = progress or (lambda msg: None)
    req.check()
    files = [Path(m) for m in req.measured]
    if not files:
        raise InputError("give at least one measured file")
    if req.goal == "discriminate":
        return _discriminate(req, files, say, t0)
    free = parse_free(req.free, req.model, (req.fit.get("overrides") or {}).get("elastic_gap") or "physical")
    from labtool.identification.joint import parse_shared
    shared = parse_shared(req.shared, free)
    rpms = speeds(req.rpm_range)
    fit_kw = dict(req.fit)
    fit_kw.setdefault("accuracy", req.accuracy)
    if len(files) == 1:
        from labtool.identification.fit import FitRequest, identify
        outcome = identify(FitRequest(files[0], req.model, req.free, **fit_kw), progress=lambda m: say(f"fit: {m}"))
        singles, lin = [outcome], outcome.linear
        order = np.r_[np.flatnonzero(shared), np.flatnonzero(~shared)]      # to the joint layout
        cov = lin.cov_u[np.ix_(order, order)]
        summary_fit = outcome.summary
        current = {k: summary_fit["parameters"][k] for k in (p.key for p in free)}
    else:
        from labtool.identification.joint import JointRequest, identify_joint
        outcome = identify_joint(JointRequest(files, req.model, req.free, req.shared, **fit_kw),
                                 progress=lambda m: say(f"fit: {m}"))
        singles, lin = outcome.singles, outcome.linear
        cov = lin.cov_u
        summary_fit = outcome.summary
        current = dict(summary_fit["parameters"])
    space = singles[0].space
    ns, nf, F = int(shared.sum()), int((~shared).sum()), len(files)
    M0 = information(cov)
    # the new recording's own parameters join as nuisance ones (no information yet)
    M0 = np.pad(M0, ((0, nf), (0, nf)))
    keep = np.zeros(M0.shape[0], bool)
    keep[:ns] = True
    M0_s = _schur(M0, keep)
    scale = lin.s2 * max(float(np.nanmean(lin.inflation[np.isfinite(lin.inflation)])) if np.isfinite(lin.inflation).any()
                         else 1.0, 1.0)
    # the estimates: the shared ones, and the per-file ones' mean on the search scale
    u_lin = np.asarray(lin.u, float)
    u_shared = u_lin[:ns] if len(files) > 1 else u_lin[shared]
    if len(files) > 1:
        own = u_lin[ns:].reshape(F, nf) if nf else np.zeros((F, 0))
    else:
        own = u_lin[~shared][None, :]
    u_c = np.empty(len(free))
    u_c[shared] = u_shared
    u_c[~shared] = own.mean(axis=0) if nf else []
    targets = [o.target for o in singles]
    noise = noise_model(targets)
    base = dict(singles[0].evaluator.fixed)
    loads = sorted(set(req.loads) if req.loads is not None else {float(t.op.get("Fu_N", 0.0)) for t in targets})
    cands = []
    total = len(rpms) * len(loads)
    for i, (Fu, rpm) in enumerate((f, r) for f in loads for r in rpms):
        say(f"candidate {i + 1}/{total}: {rpm:g} rpm, Fu = {Fu:g} N")
        c = Candidate(float(rpm), float(Fu))
        try:
            J = _candidate_jacobian(req, space, free, u_c, base, targets[0], noise, rpm, Fu)
        except (LabtoolError, ArithmeticError, ValueError) as exc:
            c.error = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
            cands.append(c)
            continue
        Mc = J.T @ J / scale
        # place it: the shared columns, then the new recording's own (the last nf)
        pos = np.empty(len(free), int)
        pos[shared] = np.arange(ns)
        pos[~shared] = M0.shape[0] - nf + np.arange(nf)
        M = M0.copy()
        M[np.ix_(pos, pos)] += Mc
        M_s = _schur(M, keep)
        c.criterion = _logdet(M_s) - _logdet(M0_s) if _logdet(M0_s) > -math.inf else _logdet(M_s)
        try:
            before = np.diag(np.linalg.pinv(M0_s, rcond=1e-12, hermitian=True))
            after = np.diag(np.linalg.pinv(M_s, rcond=1e-12, hermitian=True))
        except np.linalg.LinAlgError:
            before = after = np.full(ns, np.nan)
        keys = [p.key for p, s in zip(free, shared) if s]
        c.shrink = {k: float(math.sqrt(a / b)) if b > 0 and a >= 0 else None for k, a, b in zip(keys, after, before)}
        cands.append(c)
    good = [c for c in cands if c.error is None and math.isfinite(c.criterion)]
    if not good:
        first = cands[0].error if cands else "no candidate"
        raise InputError(f"no candidate operating point could be rated (first: {first}); widen --rpm-range or "
                         "check the model at these points with 'labtool simulate'")
    best = max(good, key=lambda c: c.criterion)
    summary = _summary(req, files, free, shared, summary_fit, current, noise, cands, best, targets,
                       time.perf_counter() - t0)
    return SuggestOutcome(summary, cands, outcome)


def _candidate_jacobian(req, space, free, u_c, base, target, noise, rpm, Fu) -> np.ndarray:
    """The normalised residuals' Jacobian a recording at (rpm, Fu) would have (unit box)."""
    cond = target.cond
    tf = _time_filter(target.time_filter, target.cycles.cam_speed_rpm, rpm)
    n_rev = max(noise["minutes"] * rpm, 2.0)
    h = search.FD_STEP
    lev = target.level(None)

    def cycle(u):
        op = {**base, "cam_speed_rpm": float(rpm), "Fu_N": float(Fu)}
        for p, v in zip(space.params, space.from_unit(np.clip(u, 0.0, 1.0))):
            op[p.op_key] = float(v)
        scene = {k: v for k, v in op.items() if k not in pipeline.CHAIN_KEYS}
        run = pipeline.run_simulation(scene, req.model, "const", req.accuracy, req.revolutions, cond, tf)
        if run.dataset is not None:
            warnings = run.dataset.attrs.get("validity_warnings", "[]")
            if warnings not in ("[]", "", None):
                raise ValueError(f"the {req.model} model doubts its validity here: {warnings}")
        shown = pipeline.chain_view(run.cycle, op)
        return {s: np.asarray(shown.signals[s], float) for s in SIGNALS}

    centre = cycle(u_c)
    sigma = {}
    for s in SIGNALS:
        rms = float(np.sqrt(np.mean(centre[s] ** 2)))
        sigma[s] = math.hypot(noise["scatter"][s] * rms / math.sqrt(n_rev), MODEL_FLOOR * rms) or 1.0
    cols = []
    for i in range(len(free)):
        up, dn = u_c.copy(), u_c.copy()
        up[i] = min(u_c[i] + h, 1.0)
        dn[i] = max(u_c[i] - h, 0.0)
        a, b = cycle(up), cycle(dn)
        cols.append(np.concatenate([(a[s] - b[s])[lev.sub] / sigma[s] for s in SIGNALS]) / (up[i] - dn[i]))
    return np.column_stack(cols)


def _summary(req, files, free, shared, fit, current, noise, cands, best, targets, wall) -> dict:
    from labtool.reports.summary import plain_json

    keys = [p.key for p, s in zip(free, shared) if s]
    point = {"cam_speed_rpm": best.rpm, "Fu_N": best.Fu, "law": targets[0].op.get("law"),
             "jt_factor": targets[0].op.get("jt_factor")}
    shrink = ", ".join(f"{k} to {100 * v:.0f} %" for k, v in best.shrink.items() if v is not None)
    snippet = (f"[[points]]\nname = \"next_{best.rpm:g}rpm\"\nrpm = {best.rpm:g}\nFu_N = {best.Fu:g}\n")
    return plain_json({
        "format": FORMAT, "format_version": FORMAT_VERSION, "goal": req.goal, "model": req.model,
        "free": [p.name for p in free], "shared": keys,
        "measured": [{"file": str(f), "cam_speed_rpm": t.cycles.cam_speed_rpm, "Fu_N": t.op.get("Fu_N")}
                     for f, t in zip(files, targets)],
        "current": {k: {"value": current[k]["value"], "ci95": current[k]["ci95"]} for k in keys if k in current},
        "point": point,
        "expected": {"log_det_gain": best.criterion, "interval_width_ratio": best.shrink,
                     "sentence": f"a recording at {best.rpm:g} rpm, Fu = {best.Fu:g} N is expected to narrow "
                                 f"the 95 % interval of {shrink} of its width now, by linear theory of the "
                                 "measurement's part (the model's discrepancy and the objective's roughness at that "
                                 "speed are not in it; on the simulated stand the paper's 300 and 500 rpm did as well: "
                                 "docs/identification.md)"},
        "noise_model": noise,
        "candidates": [{"cam_speed_rpm": c.rpm, "Fu_N": c.Fu,
                        "log_det_gain": c.criterion if c.error is None else None,
                        "interval_width_ratio": c.shrink or None, "error": c.error} for c in cands],
        "plan_points_toml": snippet,
        "fit": fit,
        "wall_s": wall,
    })


def _discriminate(req: SuggestRequest, files: list, say, t0: float) -> SuggestOutcome:
    """--goal discriminate: where the candidate models' predictions lie furthest apart against the
    first measurement's scatter (labtool.reports.discrimination), over the candidate speeds and loads."""
    from labtool.identification.objective import load_target
    from labtool.reports.discrimination import TELLS_APART, discriminate
    from labtool.reports.summary import plain_json

    rpms = speeds(req.rpm_range)
    say(f"reading {files[0].name}")
    target = load_target(files[0], None, (req.fit.get("overrides") or {}))
    scatter = {s: target.cycles.std(s) for s in SIGNALS}
    measured_rpm = float(target.cycles.cam_speed_rpm)
    loads = sorted(set(req.loads) if req.loads is not None else {float(target.op.get("Fu_N", 0.0))})
    cands = [(m, m, "const") for m in req.models]
    per_load, rows, failed = {}, [], {}
    for n, Fu in enumerate(loads):
        say(f"the models at {len(rpms)} speeds, Fu = {Fu:g} N ({n + 1}/{len(loads)})")
        op = {**{k: v for k, v in target.op.items() if k not in pipeline.CHAIN_KEYS}, "Fu_N": float(Fu)}
        d = discriminate(op, cands, scatter, measured_rpm, speeds_rpm=list(rpms) + [measured_rpm],
                         accuracy=req.accuracy, revolutions=req.revolutions, cond=target.cond)
        per_load[Fu] = d
        failed.update({f"{k} (Fu = {Fu:g} N)": v for k, v in d.failed.items()})
        worst = d.worst_pair("epsilon2")
        for rpm, dist, w2 in zip(d.speeds_rpm, worst, d.worst_pair("omega2")):
            rows.append({"cam_speed_rpm": float(rpm), "Fu_N": float(Fu),
                         "epsilon2_distance": float(dist) if math.isfinite(dist) else None,
                         "omega2_distance": float(w2) if math.isfinite(w2) else None,
                         "measured_speed": bool(abs(rpm - measured_rpm) < 1e-6)})
    good = [r for r in rows if r["epsilon2_distance"] is not None]
    if not good:
        raise InputError(f"the models could not be compared at any candidate point (first failure: "
                         f"{next(iter(failed.values()), 'none')}); check them with 'labtool simulate'")
    best = max(good, key=lambda r: r["epsilon2_distance"])
    here = next((r for r in good if r["measured_speed"] and r["Fu_N"] == float(target.op.get("Fu_N", 0.0))), None)
    d_best = per_load[best["Fu_N"]]
    sentence = (f"a recording at {best['cam_speed_rpm']:g} rpm, Fu = {best['Fu_N']:g} N is where the closest pair of "
                f"{', '.join(req.models)} differs most: epsilon2 by {best['epsilon2_distance']:.3g} x the measured scatter"
                + (f" ({here['epsilon2_distance']:.3g} x at the measured {measured_rpm:.0f} rpm)" if here else "")
                + ("" if best["epsilon2_distance"] >= TELLS_APART else
                   f"; below {TELLS_APART:g}: no candidate point tells them apart"))
    snippet = (f"[[points]]\nname = \"next_{best['cam_speed_rpm']:g}rpm\"\nrpm = {best['cam_speed_rpm']:g}\n"
               f"Fu_N = {best['Fu_N']:g}\n")
    summary = plain_json({
        "format": FORMAT, "format_version": FORMAT_VERSION, "goal": "discriminate", "models": list(req.models),
        "measured": [{"file": str(files[0]), "cam_speed_rpm": measured_rpm, "Fu_N": target.op.get("Fu_N")}],
        "point": {"cam_speed_rpm": best["cam_speed_rpm"], "Fu_N": best["Fu_N"], "law": target.op.get("law"),
                  "jt_factor": target.op.get("jt_factor")},
        "expected": {"epsilon2_distance": best["epsilon2_distance"], "omega2_distance": best["omega2_distance"],
                     "at_measured": here["epsilon2_distance"] if here else None, "tells_apart": TELLS_APART,
                     "sentence": sentence},
        "candidates": rows, "pairs": [list(p) for p in d_best.pairs], "failed": failed,
        "plan_points_toml": snippet, "wall_s": time.perf_counter() - t0})
    return SuggestOutcome(summary, rows, None)
