"""Uncertainty of a fit: 95 % intervals, correlations, profiles and what is not identifiable.

Linear theory (Bates & Watts, Nonlinear Regression Analysis, ch. 2) at the optimum, with J = d r / d u
(N residuals, p parameters, unit box u): the Gauss-Newton covariance s^2 (J^T J)^-1 with
s^2 = S / (N - p) assumes independent residuals. A model's residuals against a measurement are not:
what a simpler model or the chain leaves unexplained is smooth over the cycle (on a rigid-truth
recording at 180 rpm the residuals' autocorrelation falls to its noise level only after ~8 points of
the residual grid, ~20 deg). So the covariance is the **Newey-West (HAC) sandwich**
(J^T J)^-1 (sum over lags of Bartlett-weighted J^T r r^T J) (J^T J)^-1, within each signal's block
of residuals (statsmodels ``cov_nw_panel``), with ``nlags`` twice the lag at which the residuals'
autocorrelation first falls below its noise level 2 / sqrt(n) (at least Newey-West's rule of
thumb), and never narrower than
s^2 (J^T J)^-1. The measurement's 95 % half-width of u_i is t(0.975, N_eff - p) sqrt(cov[i, i])
(N_eff = N / the mean variance inflation).

The models add a numerical uncertainty of their own (``numerical``): a damped model's revolutions
differ by 0.1-2 % and its cycle by as much between solver presets, so the objective is rough at
that scale and its minimum lies anywhere within it. Both are measured at the optimum with one
Gauss-Newton step: the spread of the steps each of the run's steady revolutions alone asks for,
the step the other preset's residuals ask for, the step still left (the search's convergence), and
how far the objective's roughness (its departure from the Gauss-Newton quadratic at the Jacobian's
points) hides the minimum (``roughness``). The interval's half-width is the measurement's and these
in quadrature, mapped to the parameter through the search scale (additive on a
linear scale, a factor on a log scale); ``sources`` gives each one's share.

The profile checks that: S_i(u_i) = min over the other parameters of S at fixed u_i, on both sides
at the interval's edge (at least ``2 FD_STEP`` away, the models' own resolution) and, when the
interval spans more than a quarter of the bounds, at the bounds.
Linear theory predicts S_i - S = threshold_i (d / (t sd_i))^2 at a distance d, threshold_i =
t^2 cov[i, i] / (J^T J)^-1[i, i]; the ratio rho of the profile's rise to that prediction tells how
far it holds, and the profile's own interval edge is t sd_i / sqrt(rho) from the optimum on that
side. The other parameters follow the ridge of the objective (u_j + G_ji / G_ii (u_i - u_i*),
G = (J^T J)^-1) and take one Gauss-Newton step with the optimum's Jacobian: two model runs a point.

**The model's discrepancy** (``discrepancy``): where the model cannot reproduce the measurement
(the objective S well above the N residuals' noise expectation), the misfit is not noise that
averages out: part of what the model misses lies along the parameters' own directions, where the
fit absorbs it as a bias nobody sees. With no preference for a direction, that part has the size
per direction of the part left over: the discrepancy's variance per degree of freedom is
(S - N) / (K - p), K the number of independent features the misfit is made of, and the bias of
u_i has variance (J^T J)^-1_ii (S - N) / (K - p) (the classical residual-variance estimate, with
the misfit's features in place of the residual points). K is the residuals' participation ratio
(sum r^2)^2 / sum r^4 (the number of points that carry the misfit; for a misfit at a few impacts,
a few) over the residuals' correlation inflation (the points one feature spans), at least
p + MIN_FEATURE_DOF (a variance from one or two features is no estimate: its t quantile reaches
12.7 and 4.3, and the interval the bounds); its 95 % half-width uses t(0.975, K - p). A model that explains the measurement (S ~ N) adds
nothing. The objective's rise at that half-width joins the acceptance threshold (every evaluated
point below it widens the interval, other basins of a misfit objective included).

Not identifiable (the ``notes`` say which): the objective does not depend on the parameter (a zero
column of J), its profile is flat (S_i at both bounds below its threshold), its interval is wider
than the bounds or spans more than half of them (``MOST_OF_BOUNDS``, on the search scale), or it is
correlated with another beyond ``MAX_CORRELATION``.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import stats
from statsmodels.regression.linear_model import OLS
from statsmodels.stats.sandwich_covariance import cov_nw_panel

from labtool.identification.search import FD_STEP

MAX_CORRELATION = 0.95
PROFILE_AGREES = (0.5, 2.0)     # rho within this: the linear interval's edge is within ~30 % of the profile's
BOUND_TOL = 1e-3                # u this close to 0 or 1 is at the bound
BOUNDS_CHECK = 0.25             # the profile visits the bounds when the interval spans more than this of them
MOST_OF_BOUNDS = 0.5            # an interval spanning more than this of the bounds identifies nothing
MIN_FEATURE_DOF = 3             # the discrepancy's degrees of freedom, at least (t(0.975, 3) = 3.18)


@dataclasses.dataclass
class Linear:
    """The linear-theory uncertainty at the optimum (unit box)."""

    u: np.ndarray
    objective: float
    dof: float
    s2: float
    t: float
    cov_u: np.ndarray             # (p, p) HAC covariance; inf on the diagonal where J has no column
    gn_inv: np.ndarray            # (p, p) (J^T J)^-1, the objective's curvature (ridges of the profile)
    sensitive: np.ndarray         # (p,) bool: the objective depends on the parameter
    nlags: int = 0
    rev_u: np.ndarray | None = None     # (p,) half-width from the model's revolution-to-revolution variation
    preset_u: np.ndarray | None = None  # (p,) the optimum's shift to the other solver preset
    conv_u: np.ndarray | None = None    # (p,) the Gauss-Newton step still left at the optimum (convergence)
    rough_u: np.ndarray | None = None   # (p,) where the objective's roughness hides the minimum (roughness)
    rough: float = 0.0                  # the roughness R itself (objective units)
    disc_u: np.ndarray | None = None    # (p,) the model's discrepancy: the bias its misfit may hide (unit box)
    disc_rise: float = 0.0              # the objective's rise at the discrepancy's half-width (objective units)
    disc_info: dict | None = None       # what the discrepancy is estimated from (``discrepancy``)
    hull_lo: np.ndarray | None = None   # (p,) range of the points evaluated within R + threshold of the optimum
    hull_hi: np.ndarray | None = None

    @property
    def sd_u(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov_u))

    @property
    def inflation(self) -> np.ndarray:
        """cov / (s^2 (J^T J)^-1) on the diagonal: how much the residuals' correlation widens the intervals."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.diag(self.cov_u) / (self.s2 * np.diag(self.gn_inv))

    def threshold(self, i: int) -> float:
        """The objective's rise at the edge of parameter i's 95 % interval (linear theory)."""
        g = self.gn_inv[i, i]
        return float(self.t ** 2 * self.cov_u[i, i] / g) if g > 0 and math.isfinite(self.cov_u[i, i]) else math.inf

    def correlation(self) -> np.ndarray:
        sd = self.sd_u
        with np.errstate(invalid="ignore", divide="ignore"):
            c = self.cov_u / np.outer(sd, sd)
        c[~np.isfinite(c)] = np.nan
        np.fill_diagonal(c, 1.0)
        return c

    @property
    def numerical_u(self) -> np.ndarray:
        """The numerical half-width (unit box): revolution variation and preset shift combined."""
        parts = [v for v in (self.rev_u, self.preset_u, self.conv_u, self.rough_u) if v is not None]
        return np.sqrt(sum(v ** 2 for v in parts)) if parts else np.zeros(self.u.size)

    @property
    def added_u(self) -> np.ndarray:
        """What widens the measurement's half-width (unit box): the numerical resolution and the
        model's discrepancy in quadrature."""
        disc = np.zeros(self.u.size) if self.disc_u is None else self.disc_u
        return np.sqrt(self.numerical_u ** 2 + disc ** 2)

    def half_u(self) -> np.ndarray:
        """The 95 % half-width (unit box): the measurement's (t sd), the numerical one and the
        model's discrepancy in quadrature."""
        return np.sqrt((self.t * self.sd_u) ** 2 + self.added_u ** 2)

    def interval_u(self) -> tuple[np.ndarray, np.ndarray]:
        """The 95 % interval (unit box): u +- half_u, widened to every point evaluated whose
        objective lies within the roughness and the threshold of the optimum (``hull``)."""
        half = self.half_u()
        lo, hi = self.u - half, self.u + half
        if self.hull_lo is not None:
            lo, hi = np.minimum(lo, self.hull_lo), np.maximum(hi, self.hull_hi)
        return lo, hi

    def rough_ratio(self, i: int) -> float:
        """The roughness over parameter i's 95 % threshold."""
        thr = self.threshold(i)
        return self.rough / thr if math.isfinite(thr) and thr > 0 else math.nan

    def set_hull(self, rows_u: np.ndarray) -> None:
        """The acceptable points (unit box rows) that widen the interval."""
        if rows_u.size:
            self.hull_lo, self.hull_hi = rows_u.min(axis=0), rows_u.max(axis=0)

    def acceptance(self) -> float:
        """The objective's margin above the optimum that counts as acceptable: R + the largest finite threshold."""
        thr = [self.threshold(i) for i in range(self.u.size)]
        thr = [t for t in thr if math.isfinite(t)]
        return self.rough + (max(thr) if thr else 0.0) + self.disc_rise

    def sources(self, i: int) -> dict:
        """Shares of parameter i's interval variance: measurement, model revolutions, solver preset,
        convergence, roughness, the model's discrepancy."""
        parts = {"measurement": float((self.t * self.sd_u[i]) ** 2),
                 "model_revolutions": 0.0 if self.rev_u is None else float(self.rev_u[i] ** 2),
                 "solver_preset": 0.0 if self.preset_u is None else float(self.preset_u[i] ** 2),
                 "convergence": 0.0 if self.conv_u is None else float(self.conv_u[i] ** 2),
                 "roughness": 0.0 if self.rough_u is None else float(self.rough_u[i] ** 2),
                 "model_discrepancy": 0.0 if self.disc_u is None else float(self.disc_u[i] ** 2)}
        total = sum(parts.values())
        return {k: (v / total if total > 0 and math.isfinite(total) else None) for k, v in parts.items()}


def numerical(J: np.ndarray, r: np.ndarray, rev_residuals: list, r_other: np.ndarray | None):
    """The optimum's numerical uncertainty (unit box, per parameter) from Gauss-Newton steps with
    the optimum's Jacobian: ``rev`` = 2 x the standard deviation of the steps that each of the model
    run's steady revolutions alone would ask for (its own revolution-to-revolution variation: the
    objective is rough at that scale, the optimum anywhere inside), ``pre`` = |the step the other
    solver preset's residuals ``r_other`` ask for| (the preset's error), ``conv`` = |the step the
    residuals ``r`` still ask for| (the search's convergence)."""
    p = J.shape[1]
    pinv = np.linalg.pinv(J, rcond=1e-10)
    steps = np.array([-pinv @ rk for rk in rev_residuals]) if rev_residuals else np.zeros((0, p))
    rev = 2.0 * steps.std(axis=0, ddof=1) if steps.shape[0] >= 2 else np.zeros(p)
    pre = np.abs(pinv @ (r_other - r)) if r_other is not None else np.zeros(p)
    conv = np.abs(pinv @ r)
    return rev, pre, conv


def roughness(problem, lin: "Linear", J: np.ndarray, u0: np.ndarray, r: np.ndarray, step: float) -> np.ndarray:
    """Where the objective's roughness hides its minimum (unit box, per parameter).

    At the central Jacobian's points u* +- h e_i (cached runs, no new one) the objective is compared
    with the Gauss-Newton quadratic ||r + J (u - u*)||^2: a smooth objective differs from it by its
    curvature's second order only, a rough one (a rebound more or less, an impact on the other
    flank: the models change in small discrete steps) by the size of its steps, R (rms over the
    points). The minimum then lies anywhere the quadratic rises by less than R: sqrt(R (J^T J)^-1_ii)
    along parameter i. ``u0``, ``r``: the Jacobian's centre and its residuals. Returns the
    half-widths and R."""
    u0 = np.asarray(u0, float)
    gaps = []
    for i in range(u0.size):
        if not (step <= u0[i] <= 1.0 - step):
            continue                      # a forward difference fits its point exactly: no information
        for sign in (1.0, -1.0):
            v = u0.copy()
            v[i] += sign * step
            e = problem.at(v)
            if e.ok:
                pred = r + J[:, i] * sign * step
                gaps.append(e.objective - float(pred @ pred))
    if not gaps:
        return np.zeros(u0.size), 0.0
    R = float(np.sqrt(np.mean(np.square(gaps))))
    g = np.diag(lin.gn_inv)
    return np.where(np.isfinite(g) & (g > 0), np.sqrt(R * np.where(np.isfinite(g), g, 0.0)), 0.0), R


def discrepancy(J: np.ndarray, r: np.ndarray, lin: "Linear") -> tuple[np.ndarray, float, dict]:
    """The model's discrepancy at the optimum (module doc): the 95 % half-widths (unit box, per
    parameter), the objective's rise at them, and the figures behind them (the misfit beyond the
    noise S - N, the misfit's independent features K, the t quantile)."""
    n, p = J.shape
    S = float(r @ r)
    excess = max(S - n, 0.0)
    r4 = float(np.sum(np.asarray(r, float) ** 4))
    ratio = S * S / r4 if r4 > 0 else float(n)
    infl = lin.inflation
    infl = infl[np.isfinite(infl) & (infl > 0)]
    features = max(ratio / max(float(np.mean(infl)) if infl.size else 1.0, 1.0), p + MIN_FEATURE_DOF)
    dof = features - p
    t = float(stats.t.ppf(0.975, dof))
    per = excess / dof
    g = np.diag(lin.gn_inv)
    half = np.where(np.isfinite(g) & (g > 0), t * np.sqrt(per * np.where(np.isfinite(g), g, 0.0)), 0.0)
    half = np.where(lin.sensitive, half, 0.0)
    info = {"objective_beyond_noise": excess, "features": features, "t": t, "per_feature": per}
    return half, t * t * per, info


def autocorrelation_lags(r: np.ndarray, groups: list[tuple[int, int]]) -> int:
    """The Newey-West window: twice the largest lag (over the blocks) at which the residuals'
    circular autocorrelation first falls below 2 / sqrt(n), at least Newey and West's rule of
    thumb 4 (n / 100)^(2/9), at most half a block."""
    lags = []
    for a, b in groups:
        x = np.asarray(r[a:b], float)
        n = x.size
        if n < 8:
            continue
        x = x - x.mean()
        ac = np.fft.irfft(np.abs(np.fft.rfft(x)) ** 2, n=n)
        if ac[0] <= 0:
            continue
        ac = ac / ac[0]
        below = np.flatnonzero(ac[1:n // 2] < 2.0 / math.sqrt(n))
        lag = int(below[0]) + 1 if below.size else n // 2
        rule = int(4 * (n / 100.0) ** (2.0 / 9.0))        # Newey & West's rule of thumb, as a floor
        lags.append(min(max(2 * lag, rule), n // 2))
    return max(lags) if lags else 0


def linear(J: np.ndarray, r: np.ndarray, u: np.ndarray, groups: list[tuple[int, int]] | None = None) -> Linear:
    """HAC covariance of the unit-box parameters from the Jacobian ``J`` (N, p) and the residuals
    ``r`` at the optimum; ``groups``: (start, end) of each signal's block of residuals."""
    n, p = J.shape
    groups = groups or [(0, n)]
    S = float(r @ r)
    s2 = S / max(n - p, 1)
    scale = np.linalg.norm(J, axis=0)
    sensitive = scale > 1e-9 * max(float(scale.max()), 1e-300)
    cov = np.full((p, p), np.nan)
    gn = np.full((p, p), np.nan)
    np.fill_diagonal(cov, np.inf)
    np.fill_diagonal(gn, np.inf)
    idx = np.flatnonzero(sensitive)
    nlags = autocorrelation_lags(r, groups)
    if idx.size:
        Js = J[:, idx] / scale[idx]
        # a direction J does not see (a combination of parameters) gets a huge variance, not an error
        g = np.linalg.pinv(Js.T @ Js, rcond=1e-12, hermitian=True)
        res = OLS(r, Js).fit()
        # at the optimum J^T r ~ 0: the OLS residuals are r itself (up to the last Gauss-Newton step)
        c = cov_nw_panel(res, nlags, groups) if nlags > 0 else s2 * g
        # never narrower than the independent-residual intervals (negative autocorrelation at
        # some lags can make the sandwich smaller; that is not evidence of a better estimate)
        if np.mean(np.diag(c) / (s2 * np.diag(g))) < 1.0:
            c = s2 * g
        den = np.outer(scale[idx], scale[idx])
        cov[np.ix_(idx, idx)] = c / den
        gn[np.ix_(idx, idx)] = g / den
    with np.errstate(invalid="ignore", divide="ignore"):
        infl = np.diag(cov)[idx] / (s2 * np.diag(gn)[idx]) if idx.size else np.ones(1)
    infl = infl[np.isfinite(infl) & (infl > 0)]
    n_eff = n / max(float(np.mean(infl)) if infl.size else 1.0, 1.0)
    dof = max(n_eff - p, 1.0)
    return Linear(np.asarray(u, float), S, dof, s2, float(stats.t.ppf(0.975, dof)), cov, gn, sensitive, nlags)


@dataclasses.dataclass
class Profile:
    """One parameter's profile: values in the unit box and the profiled objective there; for each
    side, rho = the profile's rise over linear theory's at the checked distance."""

    index: int
    u: list
    objective: list
    rho_low: float | None = None
    rho_high: float | None = None

    def interval_u(self, lin: Linear) -> tuple[float, float]:
        """The profile's 95 % interval (unit box): quadratic on each side through the checked point."""
        i = self.index
        u0, half = float(lin.u[i]), float(lin.t * lin.sd_u[i])
        num = float(lin.added_u[i])
        out = []
        for sign, rho in ((-1, self.rho_low), (1, self.rho_high)):
            if rho is None or not math.isfinite(half):
                out.append(math.nan)
            elif rho <= 0:
                out.append(sign * math.inf)
            else:
                out.append(u0 + sign * math.hypot(half / math.sqrt(rho), num))
        return out[0], out[1]


def profile(problem, lin: Linear, J: np.ndarray, i: int) -> Profile:
    """Profile of parameter ``i`` at the interval's edges and the bounds (problem: search.Problem
    at the final preset; ``J`` the Jacobian at the optimum)."""
    u_opt, S = lin.u, lin.objective
    half = lin.t * lin.sd_u[i]
    d = max(half, 2 * FD_STEP) if math.isfinite(half) else 0.5
    checks = {"low": max(u_opt[i] - d, 0.0), "high": min(u_opt[i] + d, 1.0)}
    # the bounds only where the flat-profile check could matter: an interval over a quarter of them
    wide = float(lin.half_u()[i]) > BOUNDS_CHECK / 2 if math.isfinite(float(lin.half_u()[i])) else True
    points = sorted({round(v, 9) for v in (checks["low"], checks["high"]) + ((0.0, 1.0) if wide else ())
                     if abs(v - u_opt[i]) > 1e-6})
    prof = Profile(i, [float(u_opt[i])], [S])
    for v in points:
        prof.u.append(float(v))
        prof.objective.append(_profiled(problem, lin, J, i, v))
    order = np.argsort(prof.u)
    prof.u = [prof.u[k] for k in order]
    prof.objective = [prof.objective[k] for k in order]
    thr = lin.threshold(i)
    for side, v in checks.items():
        dist = abs(v - u_opt[i])
        if dist <= 1e-6 or not (math.isfinite(thr) and thr > 0 and half > 0):
            continue
        k = int(np.argmin(np.abs(np.asarray(prof.u) - v)))
        predicted = thr * (dist / half) ** 2
        setattr(prof, f"rho_{side}", float((prof.objective[k] - S) / predicted))
    return prof


def _profiled(problem, lin: Linear, J: np.ndarray, i: int, v: float) -> float:
    """min over the other parameters of the objective at u_i = v (ridge start, one Gauss-Newton step)."""
    u = lin.u.copy()
    others = [j for j in range(u.size) if j != i]
    g = lin.gn_inv
    if others and math.isfinite(g[i, i]) and g[i, i] > 0:
        ridge = np.nan_to_num(g[others, i] / g[i, i])
        u[others] = u[others] + ridge * (v - lin.u[i])
    u[i] = v
    u = np.clip(u, 0.0, 1.0)
    e = problem.at(u)
    best = e.objective
    if others and e.ok:
        step, *_ = np.linalg.lstsq(J[:, others], -e.residuals, rcond=None)
        u2 = u.copy()
        u2[others] = np.clip(u[others] + step, 0.0, 1.0)
        if np.max(np.abs(u2 - u)) > 1e-6:
            e2 = problem.at(u2)
            if e2.ok:
                best = min(best, e2.objective)
    return float(best)


def interval(lin: Linear, prof: Profile | None, i: int) -> tuple[float, float, list[str]]:
    """Parameter i's 95 % interval (unit box): the linear one (with the numerical parts and the
    acceptable points), widened to the profile's where the profile rises more slowly than linear
    theory says; a side where the profile does not rise at all reaches the bound. Returns
    (lo, hi, notes)."""
    lo_all, hi_all = lin.interval_u()
    lo, hi = float(lo_all[i]), float(hi_all[i])
    notes = []
    if prof is not None:
        plo, phi = prof.interval_u(lin)
        if plo == -math.inf:
            lo = min(lo, 0.0)
            notes.append("its profile does not rise towards the lower bound")
        elif math.isfinite(plo):
            lo = min(lo, plo)
        if phi == math.inf:
            hi = max(hi, 1.0)
            notes.append("its profile does not rise towards the upper bound")
        elif math.isfinite(phi):
            hi = max(hi, phi)
    return lo, hi, notes


def verdict(lin: Linear, prof: Profile | None, i: int, names: list[str], lo: float, hi: float,
            others: list[int] | None = None) -> list[str]:
    """Why parameter ``i`` is not identifiable from this measurement (empty: it is); ``lo``, ``hi``:
    its interval (unit box, ``interval``); ``others``: the parameters whose correlation with it
    counts (default all; a joint fit's shared parameter: the other shared ones, its correlation
    with one file's own parameters being in its marginal interval already)."""
    notes = []
    if not lin.sensitive[i]:
        return ["the objective does not depend on it at the optimum (no jump or contact it changes)"]

    width = float(hi - lo)
    if width > 1.0:
        notes.append("its 95 % interval is wider than the bounds")
    elif width > MOST_OF_BOUNDS:
        notes.append(f"its 95 % interval spans {100 * width:.0f} % of the bounds (on the search scale)")
    if prof is not None and len(prof.u) >= 3:
        S = lin.objective
        at_bounds = [o for u, o in zip(prof.u, prof.objective) if u <= BOUND_TOL or u >= 1 - BOUND_TOL]
        if len(at_bounds) == 2 and max(at_bounds) - S < lin.threshold(i):
            notes.append("flat profile: the objective rises less than its 95 % threshold over the whole bounds")
    c = lin.correlation()
    for j, name in enumerate(names):
        if others is not None and j not in others:
            continue
        if j != i and np.isfinite(c[i, j]) and abs(c[i, j]) > MAX_CORRELATION:
            notes.append(f"correlated with {name} (r = {c[i, j]:+.3f}): only a combination of the two is identified")
    return notes


def at_bound(u: float) -> str | None:
    if u <= BOUND_TOL:
        return "lower"
    if u >= 1.0 - BOUND_TOL:
        return "upper"
    return None
