"""The next experiment: the operating point whose recording would narrow the fit's intervals most
(``labtool suggest --goal identify``), or tell the candidate models apart (``--goal discriminate``;
docs/identification.md, "The next experiment").

The measurements so far are fitted (one file alone, several jointly); a candidate operating point
c (cam speed, load) is simulated at the estimates through the report's path, and the criterion is
the shared parameters' expected 95 % interval after a recording at c, as a share of today's
(labtool.identification.expected: the parts a fit's interval is made of, each as a recording at c
would change it):

* the measurement's part: Ds-optimal design (Atkinson, Donev & Tobias, Optimum Experimental
  Designs, ch. 10-11) on a **secant** Jacobian J_c: each column the normalised residuals'
  difference across today's 95 % interval of that parameter (at least the fit's own step
  search.FD_STEP), what a recording there can tell apart over the range still in doubt; a
  tiny-step derivative of an objective made rough by impacts promises more than that. The
  information M_c = J_c^T J_c / (s^2 x inflation), the current fit's misfit and correlation
  inflation, joins the fit's M0 = cov^-1 (on the search scale); the parameters a joint fit shares
  (``--shared``: the backlash, by default) persist, the others are each recording's own, so a new
  recording brings a new one of those (a nuisance parameter, profiled out: the Schur complement);
* the model's discrepancy: the misfit beyond the noise expected of a recording at c is the
  measured one, grown as the candidate models' predictions grow apart (``models``: the first other
  than ``model``; their normalised difference at c over at the measured points); a point where the
  model misses much more than at the measured speeds widens the interval however much
  information it carries;
* the roughness and the numerical parts: today's, as the information changes them, and the new
  recording's own: its residuals' change to the other solver preset at c, its model revolutions'
  change at c (the fit's ``model_revolutions`` part, from the same run), and its objective's
  roughness as the fit would measure it at c: the residuals at u +- FD_STEP e_i (the fit's own
  central-difference points; the secant's runs where its step is the fit's), whose second
  difference s makes the objective depart from its Gauss-Newton quadratic by +-m.s + |s|^2 / 4 +
  r0.s (m the half-difference, r0 the recording's expected misfit and noise).

The noise a recording at c would have: each signal's measured scatter from revolution to
revolution relative to its rms (the measurements' median), over the square root of the
revolutions a recording of the same duration holds at c, and the fit's 1 % floor
(labtool.identification.objective.MODEL_FLOOR).

Candidates: cam speeds on ``rpm_range`` (within the models' range, Mechanism.check_cam_speed) at
the loads given (default the measured ones: at a load never measured the misfit can be many times
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

from labtool.common import recording_attrs
from labtool.common.errors import InputError, LabtoolError
from labtool.identification import expected, search
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


# How a recording's peak over the chain's input range grows with the cam speed n: as n^HEADROOM_EXPONENT
# above a measured speed, as n below it. The impacts make the peak, and their acceleration grows
# about as the approach speed, so as n (the kinematic part grows as n^2 but is the smaller); on the
# simulated stand (the twin and the rigid truth, 20 stands, 124 recordings at 200-600 rpm against
# each one's 180 rpm recording, `benchmarks/suggest_loop.py --headroom`) the exponent was 0.98
# (median), 1.14 (90th percentile) and at most 1.20 above the measured speed: the largest is taken,
# so a point is left out before its recording would clip, not after (docs/identification.md).
HEADROOM_EXPONENT = 1.2


def headroom(targets: list) -> list[tuple[float, float]]:
    """(measured cam speed [rpm], the accelerometer channels' largest peak over their input range)
    of each measurement whose recording stated its headroom (recording format v1, measured.nc's
    ``peak_fraction_of_range_aE_t``/``_aE_n``); files from other software state none."""
    out = []
    for t in targets:
        attrs = getattr(t.dataset, "attrs", {}) or {}
        fr = [float(attrs[k]) for k in recording_attrs.ACCELEROMETER_HEADROOM if k in attrs]
        fr = [f for f in fr if math.isfinite(f) and f >= 0]
        if fr:
            out.append((float(t.cycles.cam_speed_rpm), max(fr)))
    return out


def _scaled(measurement: tuple[float, float], rpm: float) -> float:
    """One measurement's (rpm, peak) peak scaled to ``rpm`` (HEADROOM_EXPONENT above its speed)."""
    n, f = measurement
    return f * (rpm / n) ** (HEADROOM_EXPONENT if rpm > n else 1.0)


def expected_peak(measured: list[tuple[float, float]], rpm: float) -> float:
    """The peak over the input range a recording at ``rpm`` is expected to reach (NaN: no
    measurement stated its headroom): each measurement's scaled to ``rpm`` (HEADROOM_EXPONENT), the
    largest."""
    return max((_scaled(m, rpm) for m in measured), default=math.nan)


def clips(measured: list[tuple[float, float]], rpm: float) -> str | None:
    """Why a recording at ``rpm`` is expected to clip the measuring chain (None: it is not, or the
    headroom is unknown)."""
    peak = expected_peak(measured, rpm)
    if not (math.isfinite(peak) and peak >= 1.0):
        return None
    n, f = max(measured, key=lambda m: _scaled(m, rpm))     # the measurement that predicts it
    return (f"its recording is expected to clip the measuring chain: the accelerometer's peak at about "
            f"{100 * peak:.0f} % of its input range ({100 * f:.0f} % at the measured {n:.0f} rpm)")


@dataclasses.dataclass
class Candidate:
    rpm: float
    Fu: float
    criterion: float = math.nan         # -sum ln(expected 95 % width after / today's) of the shared parameters
    shrink: dict = dataclasses.field(default_factory=dict)   # key -> expected interval width after / before
    log_det: float = math.nan           # the measurement's part alone: log det of the shared information after / before
    misfit: float = math.nan            # the misfit beyond the noise expected of a recording there
    parts: dict = dataclasses.field(default_factory=dict)   # the expected half-widths' parts (unit box)
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


def _today(lin, order, M0, nf: int, ns: int, F: int, half_now: np.ndarray) -> "expected.Today":
    """The fit's interval in parts (labtool.identification.expected), in the joint layout."""
    A = information(lin.gn_inv[np.ix_(order, order)])
    A = np.pad(A, ((0, nf), (0, nf)))
    info = lin.disc_info or {}
    infl = lin.inflation[np.isfinite(lin.inflation) & (lin.inflation > 0)]
    other = [v for v in (lin.rev_u, lin.preset_u, lin.conv_u) if v is not None]
    other = np.sqrt(sum(v[order][:ns] ** 2 for v in other)) if other else np.zeros(ns)
    return expected.Today(M=M0, A=A, t=float(lin.t), half=half_now[:ns], other=other,
                          excess=float(info.get("objective_beyond_noise", 0.0)), objective=float(lin.objective),
                          features=float(info.get("features", lin.objective)),
                          inflation=max(float(np.mean(infl)) if infl.size else 1.0, 1.0), rough=float(lin.rough),
                          n_files=F, ns=ns)


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
    if len(files) > 1:
        order = np.arange(lin.u.size)
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
    # the secant's half-steps: today's 95 % half-width of each parameter (the per-file ones' mean),
    # what a recording must tell apart; at least the fit's own finite-difference step
    half_now = lin.half_u()[order]
    steps = np.empty(len(free))
    steps[shared] = half_now[:ns]
    steps[~shared] = half_now[ns:].reshape(F, nf).mean(axis=0) if nf else []
    steps = np.clip(np.nan_to_num(steps, nan=search.FD_STEP, posinf=0.5), search.FD_STEP, 0.5)
    today = _today(lin, order, M0, nf, ns, F, half_now)
    targets = [o.target for o in singles]
    noise = noise_model(targets)
    base = dict(singles[0].evaluator.fixed)
    proxy = next((m for m in req.models if m != req.model), None)
    # the measured misfit beyond the noise per unit of the candidate models' disagreement, at the
    # measured points: a candidate's misfit is expected to grow as their disagreement does
    per_disagreement = 0.0
    if proxy and today.excess > 0:
        try:
            at_measured = sum(float(d @ d) for d in (
                _candidate_runs(req, space, free, u_c, base, t, noise, t.cycles.cam_speed_rpm,
                                float(t.op.get("Fu_N", 0.0)), None, proxy)[1] for t in targets))
        except (LabtoolError, ArithmeticError, ValueError) as exc:
            raise InputError(f"the {proxy} model, whose disagreement with the {req.model} model scales the misfit "
                             f"expected at each candidate, fails at a measured point ({str(exc).splitlines()[0]}); "
                             f"--models {req.model} rates the candidates without it") from exc
        per_disagreement = today.excess / at_measured if at_measured > 0 else 0.0
    loads = sorted(set(req.loads) if req.loads is not None else {float(t.op.get("Fu_N", 0.0)) for t in targets})
    cands = []
    total = len(rpms) * len(loads)
    pos = np.empty(len(free), int)
    pos[shared] = np.arange(ns)
    pos[~shared] = M0.shape[0] - nf + np.arange(nf)
    keys = [p.key for p, s in zip(free, shared) if s]
    measured_headroom = headroom(targets)
    for i, (Fu, rpm) in enumerate((f, r) for f in loads for r in rpms):
        say(f"candidate {i + 1}/{total}: {rpm:g} rpm, Fu = {Fu:g} N")
        c = Candidate(float(rpm), float(Fu))
        c.error = clips(measured_headroom, float(rpm))
        if c.error:
            cands.append(c)
            continue
        try:
            J, d, n_c, shift, rev, gaps = _candidate_runs(req, space, free, u_c, base, targets[0], noise, rpm, Fu, steps, proxy)
        except (LabtoolError, ArithmeticError, ValueError) as exc:
            c.error = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
            cands.append(c)
            continue
        M = M0.copy()
        M[np.ix_(pos, pos)] += J.T @ J / scale
        M_s = _schur(M, keep)
        c.log_det = _logdet(M_s) - _logdet(M0_s) if _logdet(M0_s) > -math.inf else _logdet(M_s)
        e = math.sqrt(per_disagreement) * d if d is not None else np.zeros(n_c)
        rough_c = roughness_at(gaps, e)
        after = expected.combine(today, pos, J.T @ J / scale, J.T @ J, float(e @ e), n_c, J.T @ shift,
                                 J.T @ rev.T if rev.shape[0] >= 2 else None, rough_c)
        ratio = after["total"] / today.half
        c.parts = {k: [float(x) for x in v] for k, v in after.items()}
        c.criterion = -float(np.sum(np.log(ratio))) if np.all(np.isfinite(ratio) & (ratio > 0)) else math.nan
        c.misfit = float(e @ e)
        c.shrink = {k: float(v) if math.isfinite(v) else None for k, v in zip(keys, ratio)}
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


def _candidate_runs(req, space, free, u_c, base, target, noise, rpm, Fu, steps, proxy):
    """At (rpm, Fu): the normalised residuals' secant Jacobian a recording there would have (unit box,
    each column across ``steps`` either side of the estimate), the candidate models' disagreement
    there (``proxy`` against ``req.model``, normalised alike; None without a proxy model), the
    number of residuals, the residuals' change to the other solver preset (the model's numerical
    resolution there), their change from revolution to revolution (revolutions, residuals) and the
    objective's departures from its quadratic at the fit's points (``_rough_gaps``, per parameter
    and side). ``steps`` None: the disagreement alone."""
    cond = target.cond
    tf = _time_filter(target.time_filter, target.cycles.cam_speed_rpm, rpm)
    n_rev = max(noise["minutes"] * rpm, 2.0)
    lev = target.level(None)

    def cycle(u, model, accuracy=req.accuracy, revolutions=False):
        op = {**base, "cam_speed_rpm": float(rpm), "Fu_N": float(Fu)}
        for p, v in zip(space.params, space.from_unit(np.clip(u, 0.0, 1.0))):
            op[p.op_key] = float(v)
        scene = {k: v for k, v in op.items() if k not in pipeline.CHAIN_KEYS}
        run = pipeline.run_simulation(scene, model, "const", accuracy, req.revolutions, cond, tf)
        if run.dataset is not None:
            warnings = run.dataset.attrs.get("validity_warnings", "[]")
            if warnings not in ("[]", "", None):
                raise ValueError(f"the {model} model doubts its validity here: {warnings}")
        shown = pipeline.chain_view(run.cycle, op)
        out = {s: np.asarray(shown.signals[s], float) for s in SIGNALS}
        if not revolutions:
            return out
        revs = getattr(shown, "revolutions", None)
        k = next(iter(revs.values())).shape[0] if revs else 0
        # each steady revolution (after the first, as the fit takes them) as the cycle
        return out, [{s: np.asarray(revs[s][i], float) for s in SIGNALS} for i in range(1, k)]

    centre, revolutions = cycle(u_c, req.model, revolutions=True)
    sigma = {}
    for s in SIGNALS:
        rms = float(np.sqrt(np.mean(centre[s] ** 2)))
        sigma[s] = math.hypot(noise["scatter"][s] * rms / math.sqrt(n_rev), MODEL_FLOOR * rms) or 1.0

    def normalised(a, b):
        return np.concatenate([(a[s] - b[s])[lev.sub] / sigma[s] for s in SIGNALS])

    if steps is None:
        return None, normalised(cycle(u_c, proxy), centre), None, None, None, None
    # the share of each normalised residual's variance that is the recording's noise (the rest: the floor)
    noise_var = np.concatenate([np.full(lev.sub.size, min((noise["scatter"][s] * math.sqrt(np.mean(centre[s] ** 2))
                                                            / math.sqrt(n_rev) / sigma[s]) ** 2, 1.0)) for s in SIGNALS])
    cols, gaps = [], []
    for i in range(len(free)):
        up, dn = u_c.copy(), u_c.copy()
        up[i] = min(u_c[i] + steps[i], 1.0)
        dn[i] = max(u_c[i] - steps[i], 0.0)
        c_up, c_dn = cycle(up, req.model), cycle(dn, req.model)
        cols.append(normalised(c_up, c_dn) / (up[i] - dn[i]))
        gaps += _rough_gaps(lambda v: cycle(v, req.model), normalised, centre, u_c, i, steps[i], c_up, c_dn, noise_var)
    d = normalised(cycle(u_c, proxy), centre) if proxy else None
    # the model's numerical resolution there: its residuals' change to the other solver preset
    from labtool.identification.fit import OTHER_PRESET
    shift = normalised(cycle(u_c, req.model, OTHER_PRESET[req.accuracy]), centre)
    # and its own revolution-to-revolution change there (the same run, no new one)
    rev = np.array([normalised(r, centre) for r in revolutions]).reshape(len(revolutions), -1)
    return np.column_stack(cols), d, cols[0].size, shift, rev, gaps


def roughness_at(gaps: list, misfit: np.ndarray) -> float:
    """The roughness R a fit would measure on a recording at c (objective units): the rms of the
    departures ``gaps`` (``_rough_gaps``) with the recording's expected ``misfit`` in r0 (its
    noise's part in expectation)."""
    if not gaps:
        return 0.0
    return math.sqrt(float(np.mean([(g + float(misfit @ sec)) ** 2 + var for g, var, sec in gaps])))


def _rough_gaps(run, normalised, centre, u_c, i, step_i, c_up, c_dn, noise_var) -> list:
    """What a recording's objective at c departs by from its Gauss-Newton quadratic at the fit's
    own points u +- FD_STEP e_i, as the fit measures its roughness
    (labtool.identification.uncertainty.roughness, central differences): with the residuals'
    changes d+, d- there, m = (d+ - d-) / 2 and the second difference s = d+ + d-, the departure is
    +-m.s + |s|^2 / 4 + r0.s, r0 the recording's residuals at c (its misfit and its noise; the
    noise's part has variance sum noise_var s^2). Returns (the departures without r0.s, that
    variance, s) for each side: zero where the residuals are linear in u_i. The secant's runs are
    reused when its step is the fit's."""
    h = search.FD_STEP
    if not (h <= u_c[i] <= 1.0 - h):
        return []                     # the fit takes no gap there either (a forward difference)
    if abs(step_i - h) > 1e-12:
        up, dn = u_c.copy(), u_c.copy()
        up[i] += h
        dn[i] -= h
        c_up, c_dn = run(up), run(dn)
    d_up, d_dn = normalised(c_up, centre), normalised(c_dn, centre)
    m, sec = 0.5 * (d_up - d_dn), d_up + d_dn
    ms, ss, var = float(m @ sec), float(sec @ sec), float(noise_var @ sec ** 2)
    return [(ms + 0.25 * ss, var, sec), (-ms + 0.25 * ss, var, sec)]


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
        "expected": {"interval_width_ratio": best.shrink, "criterion": best.criterion, "log_det_gain": best.log_det,
                     "misfit_beyond_noise": best.misfit,
                     "sentence": f"a recording at {best.rpm:g} rpm, Fu = {best.Fu:g} N is expected to narrow "
                                 f"the 95 % interval of {shrink} of its width now: the measurement's part by linear "
                                 "theory on a secant across today's interval, the model's discrepancy with the misfit "
                                 "expected there (the measured one, grown as the candidate models' predictions "
                                 "grow apart), the objective's roughness, the model's revolution-to-revolution "
                                 "change and its solver preset's error as a fit would measure them there; not in "
                                 "it: the joint fit's consistency test, and a misfit the candidate models do not "
                                 "foresee"},
        "noise_model": noise,
        "candidates": [{"cam_speed_rpm": c.rpm, "Fu_N": c.Fu,
                        "criterion": c.criterion if c.error is None and math.isfinite(c.criterion) else None,
                        "log_det_gain": c.log_det if c.error is None and math.isfinite(c.log_det) else None,
                        "misfit_beyond_noise": c.misfit if c.error is None and math.isfinite(c.misfit) else None,
                        "expected_half_width_parts": c.parts or None,
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
    measured_headroom = headroom([target])
    for r in rows:
        r["clips"] = clips(measured_headroom, r["cam_speed_rpm"])
    good = [r for r in rows if r["epsilon2_distance"] is not None and not r["clips"]]
    if not good and any(r["epsilon2_distance"] is not None for r in rows):
        raise InputError(f"every candidate speed's recording is expected to clip the measuring chain "
                         f"({next(r['clips'] for r in rows if r['clips'])}); give --rpm-range lower speeds")
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
