"""The search: a coarse scan of the bounds, then bounded least squares (scipy.optimize.least_squares).

Everything works in the unit box u in [0, 1]^p (labtool.identification.parameters.Space). The Jacobian is
a forward difference of step ``FD_STEP`` in u (2 % of each parameter's range, or of its decades on
a log scale), stepping inwards at a bound: the models' outputs move in small steps of their own
(adaptive solvers, an impact more or less), so a finer difference would measure that noise, not the
slope. A chain parameter's difference costs no model run (the run is cached).
"""
from __future__ import annotations

import dataclasses

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import qmc

from labtool.identification.objective import Evaluation, Evaluator

FD_STEP = 0.02


@dataclasses.dataclass
class Best:
    """The best point seen so far (u, its evaluation)."""

    u: np.ndarray | None = None
    ev: Evaluation | None = None

    def offer(self, u, ev: Evaluation) -> None:
        if ev.ok and (self.ev is None or ev.objective < self.ev.objective):
            self.u, self.ev = np.array(u, float), ev


class Budget(Exception):
    """The search used its allowed model runs."""


class Problem:
    """The objective in the unit box at one preset, with a running best and a model-run budget."""

    def __init__(self, evaluator: Evaluator, preset: str, max_runs: int | None = None, progress=None,
                 phase: str = "search", harmonics: int | None = None):
        """``max_runs``: the evaluator's total model runs after which the search stops (Budget);
        ``harmonics``: the resolution the cycles are compared at (objective.Level)."""
        self.ev, self.preset, self.max_runs, self.harmonics = evaluator, preset, max_runs, harmonics
        self.best = Best()
        self.say = progress or (lambda msg: None)
        self.phase = phase

    @property
    def exhausted(self) -> bool:
        return self.max_runs is not None and self.ev.model_runs >= self.max_runs

    def at(self, u) -> Evaluation:
        u = np.clip(np.asarray(u, float), 0.0, 1.0)
        if self.exhausted and not self.ev.cached(self.ev.space.from_unit(u), self.preset):
            raise Budget()
        e = self.ev.evaluate(self.ev.space.from_unit(u), self.preset, self.harmonics)
        self.best.offer(u, e)
        if e.model_run:
            best = "-" if self.best.ev is None else f"{self.best.ev.objective:.4g}"
            self.say(f"{self.phase} ({self.preset}): {self.ev.model_runs} model runs, best objective {best}")
        return e

    def residuals(self, u) -> np.ndarray:
        return self.at(u).residuals

    def jacobian(self, u, step: float = FD_STEP, central: bool = False) -> np.ndarray:
        """d residuals / du (n_residuals, p) by finite differences in the unit box."""
        u = np.asarray(u, float)
        r0 = self.at(u).residuals
        cols = []
        for i in range(u.size):
            if central and step <= u[i] <= 1.0 - step:
                up, dn = u.copy(), u.copy()
                up[i] += step
                dn[i] -= step
                cols.append((self.at(up).residuals - self.at(dn).residuals) / (2 * step))
                continue
            h = step if u[i] + step <= 1.0 else -step
            v = u.copy()
            v[i] += h
            cols.append((self.at(v).residuals - r0) / h)
        return np.column_stack(cols)


def scan_points(space, start_u: np.ndarray, n_points: int = 16, seed: int = 0) -> np.ndarray:
    """Coarse scan of the scene parameters (rows of u), the chain parameters at their start: a
    full grid of cell centres for up to two scene parameters (7 or 4 x 4 points), a scrambled
    Sobol' sample of ``n_points`` beyond (deterministic for ``seed``); the start is the first row."""
    scene = [i for i, p in enumerate(space.params) if p.kind == "scene"]
    k = len(scene)
    if k == 1:
        levels = (np.arange(7) + 0.5) / 7
        grid = levels[:, None]
    elif k == 2:
        levels = (np.arange(4) + 0.5) / 4
        grid = np.array([(a, b) for a in levels for b in levels])
    else:
        m = int(np.ceil(np.log2(max(n_points, 2))))
        grid = qmc.Sobol(k, scramble=True, seed=seed).random_base2(m)[:n_points]
    rows = np.repeat(start_u[None, :], grid.shape[0], axis=0)
    rows[:, scene] = grid
    return np.vstack([start_u[None, :], rows])


def scan(problem: Problem, points: np.ndarray) -> list[tuple[np.ndarray, float]]:
    """The objective at every point (inf where the model failed), in order."""
    out = []
    for u in points:
        e = problem.at(u)
        out.append((np.asarray(u, float), e.objective if e.ok else np.inf))
    return out


def minimize(problem: Problem, u0: np.ndarray, max_nfev: int = 40, xtol: float = 2e-3, ftol: float = 1e-4):
    """Bounded least squares from ``u0``; returns (u, scipy result or None when the budget ended it).

    Tolerances: the models repeat a cycle to about 1 % (objective.MODEL_FLOOR), so a relative
    change of the objective below 1e-4, or a step below 0.2 % of the range, is no progress."""
    u0 = np.clip(np.asarray(u0, float), 0.0, 1.0)

    def stop(intermediate_result):
        if problem.exhausted:
            raise StopIteration

    try:
        res = least_squares(problem.residuals, u0, jac=lambda u: problem.jacobian(u), bounds=(0.0, 1.0),
                            method="trf", x_scale=1.0, xtol=xtol, ftol=ftol, gtol=1e-8, max_nfev=max_nfev,
                            callback=stop)
    except Budget:
        return problem.best.u, None
    u = res.x if problem.best.u is None else problem.best.u
    return u, res


def gauss_newton_step(problem, u: np.ndarray, at_u, jacobian: np.ndarray):
    """One Gauss-Newton step from ``u`` (unit box, clipped to it) with ``jacobian`` (the central
    one the intervals use): the search stops within its tolerance (xtol 2e-3 of the range), which
    can exceed a smooth objective's interval. ``problem.at`` evaluates a point, ``at_u`` is its
    evaluation at ``u``; returns the better of the two points and its evaluation."""
    step = -np.linalg.pinv(jacobian, rcond=1e-10) @ at_u.residuals
    u_gn = np.clip(u + step, 0.0, 1.0)
    if np.max(np.abs(u_gn - u)) > 1e-6:
        e_gn = problem.at(u_gn)
        if e_gn.ok and e_gn.objective < at_u.objective:
            return u_gn, e_gn
    return u, at_u

