"""Joint fits: one model's parameters from several measurements, and whether they agree.

``labtool fit a.nc b.nc c.nc --free backlash,restitution --shared backlash`` (docs/identification.md,
"Several measurements"). The backlash is the stand's, the same at every speed; three recordings
at three speeds fitted one by one give three answers, and nothing says whether they agree. Here:

1. each file is fitted alone (labtool.identification.fit.identify): its own estimates and
   intervals, and its model runs, cached, which the joint search reuses;
2. the joint problem: the shared parameters once, the others once per file, the residuals of all
   files together (each file's weighted as in its own fit); it starts from the files' estimates
   combined (``combine``: the shared values weighted by their inverse variances, the others moved
   along their correlation with the shared ones) and is solved by bounded least squares at the
   search preset, then at the requested one; the Jacobian is block-sparse (a file's residuals
   depend on the shared parameters and its own), each block a file's own finite differences;
3. the intervals as a single fit's (labtool.identification.uncertainty: the HAC covariance over
   every file's blocks, the models' numerical resolution, the roughness, the evaluated points,
   the shared parameters' profiles);
4. **the consistency test** (``consistency``): for each shared parameter, the files' own estimates
   against the joint one, chi^2 = sum ((x_f - x_joint) / sd_f)^2 on F - 1 degrees of freedom, on
   the search scale (the logarithm for the backlash), sd_f from each file's own 95 % interval.
   When p < 0.05 the measurements disagree about it beyond their intervals: the model misses
   something that changes with the operating point, and the joint interval is widened by the
   Birge ratio sqrt(chi^2 / (F - 1)) (the spread the files show that their intervals do not
   explain: the model's discrepancy between the operating points).

``combine`` and ``consistency`` work on fit results alone (JSON), so ``campaign report`` tests the
points a campaign has fitted without fitting again.
"""
from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import numpy as np
from scipy import stats

from labtool.common.errors import InputError, SolverError
from labtool.identification import search, uncertainty
from labtool.identification.objective import Scored
from labtool.identification.fit import (FitOutcome, FitRequest, OTHER_PRESET, POLISH_NFEV, SEARCH_PRESET,
                                        identify, _parameter_entry)
from labtool.identification.parameters import CATALOGUE, Space, make_space, parse_free

FORMAT = "labtool.fit.joint"
FORMAT_VERSION = 1
ALPHA = 0.05                   # the consistency test's level
JOINT_NFEV = 20                # least-squares iterations of the joint search (each: the files' Jacobians)


@dataclasses.dataclass
class JointRequest:
    """What to fit jointly: ``measured`` (two or more files), ``shared``: the comma-separated free
    parameters all files share (None: those that are the stand's properties, parameters.FreeParameter.stand);
    the rest as labtool.identification.fit.FitRequest, applied to every file."""

    measured: list
    model: str
    free: str
    shared: str | None = None
    omega1: str = "const"
    accuracy: str = "standard"
    revolutions: int = 3
    bounds: dict = dataclasses.field(default_factory=dict)
    start: object = "scan"
    overrides: dict = dataclasses.field(default_factory=dict)
    chain: dict = dataclasses.field(default_factory=dict)
    max_runs: int = 200
    cond: object = None
    scan: bool = True

    def single(self, path) -> FitRequest:
        return FitRequest(Path(path), self.model, self.free, self.omega1, self.accuracy, self.revolutions,
                          dict(self.bounds), self.start, dict(self.overrides), dict(self.chain), self.max_runs,
                          self.cond, self.scan)


def parse_shared(text: str | None, free: list) -> np.ndarray:
    """The shared mask over the free parameters: ``text`` names them (comma-separated), None
    takes the stand's properties among them."""
    if text is None:
        mask = np.array([p.stand for p in free])
        if not mask.any():
            raise InputError("none of the free parameters is a property of the stand (backlash, contact_length, "
                             "ka_gain, delay); name the shared ones with --shared, e.g. --shared "
                             f"{free[0].name}")
        return mask
    names = [n.strip() for n in str(text).split(",") if n.strip()]
    if not names:
        raise InputError("--shared names no parameter; give e.g. --shared backlash")
    free_names = [p.name for p in free]
    for n in names:
        if n not in free_names:
            hint = "" if n in CATALOGUE else f" (known: {', '.join(CATALOGUE)})"
            raise InputError(f"--shared: '{n}' is not among the free parameters ({', '.join(free_names)}){hint}; "
                             "add it to --free or drop it from --shared")
    return np.array([p.name in names for p in free])


# --------------------------------------------------------------------------- the joint problem

@dataclasses.dataclass
class JointEvaluation(Scored):
    residuals: np.ndarray
    parts: list                       # each file's Evaluation
    error: str | None = None
    model_run: bool = False


class JointProblem:
    """The joint objective in the joint unit box (the shared parameters, then each file's own),
    with a running best and a budget of model runs over all files; duck-compatible with
    labtool.identification.search.Problem (search.minimize, uncertainty.profile and roughness use it)."""

    def __init__(self, evaluators: list, shared: np.ndarray, preset: str, max_runs: int | None = None,
                 progress=None, phase: str = "joint search", harmonics: int | None = None):
        self.evs, self.shared, self.preset, self.max_runs, self.harmonics = evaluators, shared, preset, max_runs, harmonics
        self.space = evaluators[0].space
        self.p = shared.size
        self.ns = int(shared.sum())
        self.nf = self.p - self.ns
        self.best = search.Best()
        self.say = progress or (lambda msg: None)
        self.phase = phase
        self.visited: dict = {}

    @property
    def size(self) -> int:
        return self.ns + len(self.evs) * self.nf

    @property
    def model_runs(self) -> int:
        return sum(ev.model_runs for ev in self.evs)

    @property
    def exhausted(self) -> bool:
        return self.max_runs is not None and self.model_runs >= self.max_runs

    def split(self, u) -> list[np.ndarray]:
        """Each file's point in its own unit box."""
        u = np.asarray(u, float)
        out = []
        for f in range(len(self.evs)):
            v = np.empty(self.p)
            v[self.shared] = u[:self.ns]
            v[~self.shared] = u[self.ns + f * self.nf: self.ns + (f + 1) * self.nf]
            out.append(v)
        return out

    def join(self, shared_u, own_u: list) -> np.ndarray:
        """The joint point from the shared values and each file's own (unit box)."""
        return np.concatenate([np.asarray(shared_u, float)] + [np.asarray(o, float) for o in own_u])

    def columns(self, f: int) -> np.ndarray:
        """The joint columns of file ``f``'s parameters, in its own order."""
        cols = np.empty(self.p, int)
        cols[self.shared] = np.arange(self.ns)
        cols[~self.shared] = self.ns + f * self.nf + np.arange(self.nf)
        return cols

    def at(self, u) -> JointEvaluation:
        u = np.clip(np.asarray(u, float), 0.0, 1.0)
        parts, new = [], False
        for ev, v in zip(self.evs, self.split(u)):
            x = self.space.from_unit(v)
            if self.exhausted and not ev.cached(x, self.preset):
                raise search.Budget()
            e = ev.evaluate(x, self.preset, self.harmonics)
            parts.append(e)
            new |= e.model_run
        errors = [e.error for e in parts if not e.ok]
        je = JointEvaluation(np.concatenate([e.residuals for e in parts]), parts,
                             errors[0] if errors else None, new)
        self.best.offer(u, je)
        self.visited.setdefault(tuple(np.round(u, 12)), u)
        if new:
            best = "-" if self.best.ev is None else f"{self.best.ev.objective:.4g}"
            self.say(f"{self.phase} ({self.preset}): {self.model_runs} model runs, best objective {best}")
        return je

    def residuals(self, u) -> np.ndarray:
        return self.at(u).residuals

    def jacobian(self, u, step: float = search.FD_STEP, central: bool = False) -> np.ndarray:
        """d residuals / du, block-sparse: each file's residuals by its own parameters only."""
        u = np.asarray(u, float)
        r0 = self.at(u)
        J = np.zeros((r0.residuals.size, self.size))
        row = 0
        for f, part in enumerate(r0.parts):
            n = part.residuals.size
            cols = self.columns(f)
            for c in cols:
                if central and step <= u[c] <= 1.0 - step:
                    up, dn = u.copy(), u.copy()
                    up[c] += step
                    dn[c] -= step
                    d = (self._file(f, up) - self._file(f, dn)) / (2 * step)
                else:
                    h = step if u[c] + step <= 1.0 else -step
                    v = u.copy()
                    v[c] += h
                    d = (self._file(f, v) - part.residuals) / h
                J[row:row + n, c] = d
            row += n
        return J

    def _file(self, f: int, u) -> np.ndarray:
        """File f's residuals at joint point u (the other files' are not needed)."""
        ev = self.evs[f]
        x = self.space.from_unit(self.split(np.clip(u, 0.0, 1.0))[f])
        if self.exhausted and not ev.cached(x, self.preset):
            raise search.Budget()
        return ev.evaluate(x, self.preset, self.harmonics).residuals

    def blocks(self) -> list[tuple[int, int]]:
        """Every file's residual blocks (signals, events), offset into the joint vector."""
        out, off = [], 0
        for ev in self.evs:
            bl = ev.blocks(self.harmonics)
            out += [(a + off, b + off) for a, b in bl]
            off += bl[-1][1]
        return out


# --------------------------------------------------------------------------- combining fits

def _unit(p, lo, hi, value) -> float:
    """``value`` (edge units) in the unit box of bounds [lo, hi] on parameter p's search scale."""
    if value is None or not math.isfinite(value):
        return math.nan
    if p.log:
        return math.log(max(value, 1e-300) / lo) / math.log(hi / lo) if value > 0 else -math.inf
    return (value - lo) / (hi - lo)


def _edge(p, lo, hi, u) -> float:
    if not math.isfinite(u):
        return (0.0 if p.log else -math.inf) if u < 0 else math.inf
    return lo * (hi / lo) ** u if p.log else lo + u * (hi - lo)


def file_estimates(summaries: list[dict], key: str) -> tuple[np.ndarray, np.ndarray, list]:
    """Each fit's value and standard deviation of parameter ``key`` on its search scale (unit box
    of its bounds), from its 95 % interval: sd = half its width / 1.96; inf where the fit calls it
    not identifiable or has no interval. Returns (x, sd, the parameter's catalogue entry and bounds)."""
    p = next(q for q in CATALOGUE.values() if q.key == key)
    lo, hi = summaries[0]["parameters"][key]["bounds"]
    x, sd = [], []
    for s in summaries:
        e = s["parameters"][key]
        x.append(_unit(p, lo, hi, e["value"]))
        ci = e.get("ci95_unbounded") or e.get("ci95")      # the spread as computed, not held to the bounds
        if not e.get("identifiable", True) or not ci or None in ci:
            sd.append(math.inf)
            continue
        a, b = _unit(p, lo, hi, ci[0]), _unit(p, lo, hi, ci[1])
        sd.append((b - a) / (2 * 1.959964) if math.isfinite(a) and math.isfinite(b) else math.inf)
    return np.array(x), np.array(sd), (p, lo, hi)


def consistency(x: np.ndarray, sd: np.ndarray, joint: float) -> dict:
    """The files' estimates ``x`` (sd ``sd``, unit box) against the joint value: chi^2 on F - 1
    degrees of freedom (the files that identify the parameter), its p-value, the Birge ratio
    sqrt(chi^2 / dof) (>= 1) and whether they agree at level ALPHA."""
    use = np.isfinite(sd) & (sd > 0) & np.isfinite(x)
    n = int(use.sum())
    if n < 2:
        return {"files_used": n, "chi2": None, "dof": None, "p_value": None, "birge_ratio": 1.0, "consistent": None}
    z = (x[use] - joint) / sd[use]
    chi2 = float(z @ z)
    dof = n - 1
    p = float(stats.chi2.sf(chi2, dof))
    return {"files_used": n, "chi2": chi2, "dof": dof, "p_value": p,
            "birge_ratio": max(1.0, math.sqrt(chi2 / dof)), "consistent": p >= ALPHA}


def combine(summaries: list[dict], shared_keys: list[str]) -> dict:
    """The shared parameters of several single-file fits combined (inverse-variance weighted mean
    on the search scale: the joint estimate of a linear problem whose other parameters are per
    file) with the consistency test, from their JSON results alone. Per key: value, ci95 (widened
    by the Birge ratio when the files disagree), ci95_combined (not widened), the files' values and
    intervals, and the test (``consistency``)."""
    out = {}
    for key in shared_keys:
        x, sd, (p, lo, hi) = file_estimates(summaries, key)
        use = np.isfinite(sd) & (sd > 0) & np.isfinite(x)
        files = [{"file": s["measured"]["file"], "cam_speed_rpm": s["measured"].get("cam_speed_rpm_measured"),
                  "value": s["parameters"][key]["value"], "ci95": s["parameters"][key]["ci95"],
                  "identifiable": s["parameters"][key].get("identifiable", True)} for s in summaries]
        if use.sum() == 0:
            out[key] = {"value": None, "ci95": [None, None], "ci95_combined": [None, None], "files": files,
                        "consistency": consistency(x, sd, math.nan),
                        "verdict": f"no file identifies {key}: nothing to combine"}
            continue
        w = 1.0 / sd[use] ** 2
        xj = float(np.sum(w * x[use]) / w.sum())
        half = 1.959964 / math.sqrt(w.sum())
        test = consistency(x, sd, xj)
        wide = half * test["birge_ratio"]
        out[key] = {"value": _edge(p, lo, hi, xj), "unit": p.unit,
                    # held to the search bounds, as a fit's interval is
                    "ci95": [_edge(p, lo, hi, max(xj - wide, 0.0)), _edge(p, lo, hi, min(xj + wide, 1.0))],
                    "ci95_combined": [_edge(p, lo, hi, max(xj - half, 0.0)), _edge(p, lo, hi, min(xj + half, 1.0))],
                    "files": files, "consistency": test, "verdict": verdict_text(key, test)}
    return out


def verdict_text(key: str, test: dict) -> str:
    if test["consistent"] is None:
        return f"fewer than two measurements identify {key}: no consistency test"
    if test["consistent"]:
        return (f"the measurements agree about {key} within their intervals (chi2 = {test['chi2']:.3g} on "
                f"{test['dof']} degrees of freedom, p = {test['p_value']:.2g})")
    return (f"these measurements disagree about {key} beyond their intervals (chi2 = {test['chi2']:.3g} on "
            f"{test['dof']} degrees of freedom, p = {test['p_value']:.2g}): the model misses something that "
            f"changes with the operating point; the joint interval is widened by {test['birge_ratio']:.3g} (Birge ratio)")


# --------------------------------------------------------------------------- the driver

@dataclasses.dataclass
class JointOutcome:
    """The result (``summary``: the JSON object), the single fits and the joint problem's state."""

    summary: dict
    singles: list
    linear: uncertainty.Linear | None


def identify_joint(req: JointRequest, progress=None) -> JointOutcome:
    """Fit ``req.free`` of ``req.model`` to all of ``req.measured`` at once; see the module's steps."""
    t0 = time.perf_counter()
    say = progress or (lambda msg: None)
    files = _checked_files(req)
    free = parse_free(req.free, req.model, req.overrides.get("elastic_gap") or "physical")
    shared = parse_shared(req.shared, free)
    space = make_space(free, req.bounds)
    singles: list[FitOutcome] = []
    for i, f in enumerate(files):
        tell = (lambda msg, i=i, f=f: say(f"file {i + 1}/{len(files)} ({f.name}): {msg}"))
        singles.append(identify(req.single(f), progress=tell))
    evs = [o.evaluator for o in singles]
    keys = [p.key for p in free]
    shared_keys = [k for k, s in zip(keys, shared) if s]
    own_keys = [k for k, s in zip(keys, shared) if not s]
    summaries = [o.summary for o in singles]
    notes = []
    u, prob = _joint_search(req, evs, shared, _joint_start(space, singles, shared, shared_keys, keys), say, notes)
    final, after, lin, profiles = _joint_uncertainty(req, evs, shared, u, prob.ns, say)

    # the joint space's parameters, named by file
    jparams = [p for p, s in zip(free, shared) if s] + [p for _ in files for p, s in zip(free, shared) if not s]
    jnames = shared_keys + [f"{k}[{i}]" for i in range(len(files)) for k in own_keys]
    jlo = np.concatenate([space.lo[shared]] + [space.lo[~shared]] * len(files))
    jhi = np.concatenate([space.hi[shared]] + [space.hi[~shared]] * len(files))
    jspace = Space(tuple(jparams), jlo, jhi)
    chi2 = after.objective / after.residuals.size
    shared_idx = list(range(prob.ns))
    entries = [_parameter_entry(jspace, i, lin, profiles[i], jnames, chi2, shared_idx if i < prob.ns else None)
               for i in range(lin.u.size)]
    tests = _consistency_tests(shared_keys, summaries, files, lin, jspace, entries, notes)

    fitted = [evs[f].values(space.from_unit(v)) for f, v in enumerate(final.split(lin.u))]
    corr = lin.correlation()
    from labtool.reports.summary import plain_json
    summary = plain_json({
        "format": FORMAT, "format_version": FORMAT_VERSION,
        "model": req.model, "omega1": req.omega1, "accuracy": req.accuracy, "search_accuracy": SEARCH_PRESET,
        "files": [str(f) for f in files],
        "cam_speed_rpm_measured": [s["measured"]["cam_speed_rpm_measured"] for s in summaries],
        "free": [p.name for p in free], "shared": shared_keys, "per_file": own_keys,
        "parameters": {k: entries[i] for i, k in enumerate(shared_keys)},
        "per_file_parameters": [{k: entries[prob.ns + f * prob.nf + j] for j, k in enumerate(own_keys)}
                                for f in range(len(files))],
        "consistency": tests,
        "consistent": all(t["consistent"] is not False for t in tests.values()),
        "objective_after": after.objective,
        "objective_per_file": [float(e.residuals @ e.residuals) for e in after.parts],
        "objective_per_residual": after.objective / after.residuals.size,
        "degrees_of_freedom": lin.dof,
        "correlation": {a: {b: float(corr[i, j]) for j, b in enumerate(jnames)} for i, a in enumerate(jnames)},
        "fitted_operating_points": fitted,
        "single_fits": summaries,
        "evaluations": sum(ev.model_runs for ev in evs),
        "notes": notes,
        "wall_s": time.perf_counter() - t0,
    })
    return JointOutcome(summary, singles, lin)


def _checked_files(req: JointRequest) -> list[Path]:
    """The request's files, each given once and each readable, before the first is fitted (a typo
    in the last must not cost minutes)."""
    files = [Path(m) for m in req.measured]
    if len(files) < 2:
        raise InputError("a joint fit needs two or more measured files")
    if len({f.resolve() for f in files}) != len(files):
        raise InputError("a measured file is given twice; give each measurement once")
    if "cam_speed" in req.overrides:
        raise InputError("--rpm: a joint fit takes each file's measured cam speed; fit a file alone to give its speed")
    from labtool.reports.pipeline import load_measured
    for f in files:
        load_measured(f).close()
    return files


def _joint_start(space, singles, shared, shared_keys, keys) -> tuple:
    """The joint search's start (unit box): each shared parameter the files' estimates weighted by
    their inverse variance; each file's own parameters moved along their correlation with the
    shared ones (its Gauss-Newton ridge). Returns (shared_u, [own_u per file])."""
    summaries = [o.summary for o in singles]
    u_files = [space.to_unit([o.summary["parameters"][k]["value"] for k in keys]) for o in singles]
    shared_u = []
    for k in shared_keys:
        x, sd, _ = file_estimates(summaries, k)
        use = np.isfinite(sd) & (sd > 0)
        shared_u.append(float(np.sum(x[use] / sd[use] ** 2) / np.sum(1 / sd[use] ** 2)) if use.any()
                        else float(np.nanmean(x)))
    shared_u = np.clip(np.array(shared_u), 0.0, 1.0)
    own_u = []
    for o, uf in zip(singles, u_files):
        own = uf[~shared].copy()
        g = o.linear.gn_inv
        if np.all(np.isfinite(g)):
            gss = g[np.ix_(shared, shared)]
            gos = g[np.ix_(~shared, shared)]
            try:
                own = own + gos @ np.linalg.solve(gss, shared_u - uf[shared])
            except np.linalg.LinAlgError:
                pass
        own_u.append(np.clip(own, 0.0, 1.0))
    return shared_u, own_u


def _joint_search(req: JointRequest, evs, shared, start, say, notes: list) -> tuple:
    """The joint search from ``start`` at the search preset, polished at the request's; returns the
    optimum (unit box) and the search's problem. Appends a note when the budget stopped it."""
    budget = sum(ev.model_runs for ev in evs) + req.max_runs
    prob = JointProblem(evs, shared, SEARCH_PRESET, budget, say, "joint search")
    u0 = prob.join(*start)
    say("the joint search")
    try:
        prob.at(u0)
        search.minimize(prob, u0, max_nfev=JOINT_NFEV)
    except search.Budget:
        pass
    if prob.best.ev is None:
        raise SolverError(f"the {req.model} model fails at the files' combined estimates: {prob.at(u0).error}")
    if prob.exhausted:
        notes.append(f"the joint search stopped at its budget of {req.max_runs} model runs (--max-runs)")
    u = prob.best.u
    if req.accuracy != SEARCH_PRESET:
        polish = JointProblem(evs, shared, req.accuracy, prob.model_runs + POLISH_NFEV * (u.size + 1), say, "polish")
        try:
            polish.at(u)
            search.minimize(polish, u, max_nfev=POLISH_NFEV)
        except search.Budget:
            pass
        if polish.best.ev is not None:
            u = polish.best.u
    return u, prob


def _joint_uncertainty(req: JointRequest, evs, shared, u, n_shared: int, say) -> tuple:
    """The intervals at the joint optimum ``u``, as a single fit's (uncertainty): the measurement's
    part, the numerical parts, the roughness, the model's discrepancy, the profiles of the shared
    parameters. Returns (the problem, its evaluation at the optimum, the linear theory, profiles)."""
    say(f"joint intervals ({req.accuracy})")
    final = JointProblem(evs, shared, req.accuracy, None, say, "joint intervals")
    after = final.at(u)
    if not after.ok:
        raise SolverError(f"the {req.model} model fails at the joint optimum: {after.error}")
    J = final.jacobian(u, central=True)
    u_j, r_j = u, after.residuals
    u, after = search.gauss_newton_step(final, u, after, J)
    lin = uncertainty.linear(J, after.residuals, u, final.blocks())
    other = JointProblem(evs, shared, OTHER_PRESET[req.accuracy], None, say, "preset check").at(u)
    revs = _revolution_residuals(final, u, after)
    lin.rev_u, lin.preset_u, lin.conv_u = uncertainty.numerical(J, after.residuals, revs,
                                                                other.residuals if other.ok else None)
    lin.rough_u, lin.rough = uncertainty.roughness(final, lin, J, u_j, r_j, search.FD_STEP)
    lin.disc_u, lin.disc_rise, lin.disc_info = uncertainty.discrepancy(J, after.residuals, lin)
    limit = after.objective + lin.acceptance()
    rows = [v for v in final.visited.values() if final.at(v).ok and final.at(v).objective <= limit]
    if rows:
        lin.set_hull(np.array(rows))
    profiles = [uncertainty.profile(final, lin, J, i) if i < n_shared else None for i in range(u.size)]
    return final, after, lin, profiles


def _consistency_tests(shared_keys, summaries, files, lin, jspace, entries, notes: list) -> dict:
    """The consistency test of every shared parameter: the files' own fits against the joint value.
    Where they disagree, the joint interval is widened by the Birge ratio (``ci95_joint`` keeps it
    as fitted) and the verdict said in the entry's and the fit's notes."""
    tests = {}
    for i, k in enumerate(shared_keys):
        x, sd, _ = file_estimates(summaries, k)
        test = consistency(x, sd, float(lin.u[i]))
        e = entries[i]
        e["ci95_joint"] = list(e["ci95"])
        if test["consistent"] is False:
            c = float(lin.u[i])
            a = -math.inf if e["ci95"][0] is None else _to_unit_one(jspace, i, e["ci95"][0])
            b = math.inf if e["ci95"][1] is None else _to_unit_one(jspace, i, e["ci95"][1])
            wa, wb = c - (c - a) * test["birge_ratio"], c + (b - c) * test["birge_ratio"]
            # held to the search bounds as a single fit's is (a backlash of 0.0003 mm is no
            # answer); ci95_unbounded keeps the widened one as computed
            e["ci95_unbounded"] = [jspace.value(i, wa), jspace.value(i, wb)]
            e["ci95"] = [jspace.value(i, max(wa, 0.0)), jspace.value(i, min(wb, 1.0))]
            e["notes"] = e["notes"] + [verdict_text(k, test)]
            if wb - wa > uncertainty.MOST_OF_BOUNDS:
                e["identifiable"] = False
                e["verdict"] = "not identifiable"
                e["notes"].append("widened, its 95 % interval spans more than half the bounds")
        tests[k] = {**test, "verdict": verdict_text(k, test),
                    "files": [{"file": str(f), "cam_speed_rpm": s["measured"]["cam_speed_rpm_measured"],
                               "value": s["parameters"][k]["value"], "ci95": s["parameters"][k]["ci95"],
                               "identifiable": s["parameters"][k]["identifiable"]} for f, s in zip(files, summaries)]}
        if test["consistent"] is False:
            notes.append(verdict_text(k, test))
    return tests


def _to_unit_one(space, i: int, value: float) -> float:
    p, lo, hi = space.params[i], float(space.lo[i]), float(space.hi[i])
    return _unit(p, lo, hi, value)


def _revolution_residuals(problem: JointProblem, u, e: JointEvaluation) -> list[np.ndarray]:
    """The joint residuals with every file's model cycle replaced by its k-th steady revolution
    (the same runs): the models' own revolution-to-revolution variation."""
    per = [ev.revolution_residuals(problem.space.from_unit(v), part)
           for ev, v, part in zip(problem.evs, problem.split(u), e.parts)]
    k = min((len(p) for p in per), default=0)
    return [np.concatenate([p[i] for p in per]) for i in range(k)]


# --------------------------------------------------------------------------- a campaign's points

def campaign_identification(point_fits: list, joint_doc: dict | None = None, joint_source: str = "") -> dict | None:
    """What a campaign's page says about its points' fits (``labtool campaign report``): from a
    joint fit of its measurements (``joint_doc``, a labtool.fit.joint result) when there is one,
    else the points' own fits (``point_fits``: (point name, labtool.fit result) pairs) combined
    (``combine``) for every group of two or more fitted with the same model and free parameters,
    their stand properties shared. None when neither is there. Plain JSON, no wall time."""
    if joint_doc is not None and joint_doc.get("format") == FORMAT:
        params = {}
        for k in joint_doc.get("shared", []):
            e, test = joint_doc["parameters"][k], joint_doc["consistency"][k]
            params[k] = {"value": e["value"], "unit": e.get("unit"), "ci95": e["ci95"], "ci95_combined": e["ci95_joint"],
                         "identifiable": e.get("identifiable", True), "files": test["files"],
                         "consistency": {x: test.get(x) for x in ("chi2", "dof", "p_value", "birge_ratio", "consistent",
                                                                  "files_used")},
                         "verdict": test["verdict"]}
        return {"source": f"joint fit {joint_source}".strip(), "groups": [
            {"model": joint_doc["model"], "free": joint_doc["free"], "points": joint_doc["files"], "parameters": params}]}
    groups: dict = {}
    for name, doc in point_fits:
        if not (isinstance(doc, dict) and doc.get("format") == "labtool.fit" and isinstance(doc.get("parameters"), dict)):
            continue
        groups.setdefault((doc.get("model"), tuple(doc.get("free", []))), []).append((name, doc))
    out = []
    for (model, free), members in groups.items():
        if len(members) < 2:
            continue
        try:
            keys = [p.key for p in parse_free(",".join(free), model) if p.stand]
        except InputError:
            continue
        if not keys:
            continue
        summaries = [doc for _, doc in members]
        params = combine(summaries, keys)
        for k, e in params.items():
            for f, (name, _) in zip(e["files"], members):
                f["point"] = name
        out.append({"model": model, "free": list(free), "points": [n for n, _ in members], "parameters": params})
    if not out:
        return None
    return {"source": "the points' own fits (fit.json in each point's folder), combined", "groups": out}
