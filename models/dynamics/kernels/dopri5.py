"""Dormand-Prince 5(4) building blocks for the compiled (numba) integration loops.

The same method, step-size controller and dense output (4th order, Shampine's coefficients) as
scipy's ``RK45``, so the compiled loops and the scipy reference path differ only in the language,
not in the numerics; the independent reference is scipy's DOP853 at the ``reference`` preset.

A model's loop evaluates its own right-hand side at the six stages (numba cannot cache a loop that
receives a function as an argument, so each model writes its ``step`` with these helpers):

    K[0] = f(t, y)   (FSAL: the previous step's K[6])
    K[s] = f(t + C[s] h, y + h * sum_j A[s, j] K[j])        s = 1..5      (``stage_state``)
    y_new = y + h * sum_j B[j] K[j];  K[6] = f(t + h, y_new)            (``stage_state`` with B)
    err = error_norm(K, h, y, y_new, rtol, atol)  (RMS norm, < 1 accepts)
    dense: Q = K.T @ P; y(t + s h) = y + h * (Q[:, 0] s + Q[:, 1] s^2 + Q[:, 2] s^3 + Q[:, 3] s^4)

Time in s, states in the caller's units; tolerances as in scipy (scale = atol + rtol * |y|).
"""
from __future__ import annotations

import numpy as np
from models.dynamics.jit import jit

A = np.array([
    [0.0, 0.0, 0.0, 0.0, 0.0],
    [1 / 5, 0.0, 0.0, 0.0, 0.0],
    [3 / 40, 9 / 40, 0.0, 0.0, 0.0],
    [44 / 45, -56 / 15, 32 / 9, 0.0, 0.0],
    [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0.0],
    [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656],
])
B = np.array([35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84])
C = np.array([0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0])
E = np.array([-71 / 57600, 0.0, 71 / 16695, -71 / 1920, 17253 / 339200, -22 / 525, 1 / 40])
P = np.array([
    [1.0, -8048581381 / 2820520608, 8663915743 / 2820520608, -12715105075 / 11282082432],
    [0.0, 0.0, 0.0, 0.0],
    [0.0, 131558114200 / 32700410799, -68118460800 / 10900136933, 87487479700 / 32700410799],
    [0.0, -1754552775 / 470086768, 14199869525 / 1410260304, -10690763975 / 1880347072],
    [0.0, 127303824393 / 49829197408, -318862633887 / 49829197408, 701980252875 / 199316789632],
    [0.0, -282668133 / 205662961, 2019193451 / 616988883, -1453857185 / 822651844],
    [0.0, 40617522 / 29380423, -110615467 / 29380423, 69997945 / 29380423],
])
SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0
ERROR_EXPONENT = -1.0 / 5.0

# status codes returned by the compiled loops (the Python wrappers turn them into SolverError)
OK, TOO_MANY_STEPS, TOO_MANY_EVENTS, STEP_TOO_SMALL, NOT_FINITE, NO_PROGRESS = 0, 1, 2, 3, 4, 5
STATUS_TEXT = {
    TOO_MANY_STEPS: "the step cap was reached",
    TOO_MANY_EVENTS: "the event cap was reached",
    STEP_TOO_SMALL: "the step size fell below the floating-point resolution of time",
    NOT_FINITE: "the state became non-finite (NaN or infinity)",
    NO_PROGRESS: "the integration stalled in zero-length phases",
}


@jit
def stage_state(y, h, K, coeffs, n_stages, out):
    """out = y + h * sum_{j < n_stages} coeffs[j] K[j]."""
    for i in range(y.size):
        acc = 0.0
        for j in range(n_stages):
            acc += coeffs[j] * K[j, i]
        out[i] = y[i] + h * acc


@jit
def error_norm(K, h, y, y_new, rtol, atol):
    """scipy's RMS error norm of the embedded 4th-order estimate (atol: array per component)."""
    acc = 0.0
    n = y.size
    for i in range(n):
        e = 0.0
        for j in range(7):
            e += E[j] * K[j, i]
        sc = atol[i] + rtol * max(abs(y[i]), abs(y_new[i]))
        r = h * e / sc
        acc += r * r
    return np.sqrt(acc / n)


@jit
def dense_coeffs(K, out):
    """out (n, 4) = K.T @ P: the dense-output polynomial of the step just taken."""
    n = out.shape[0]
    for i in range(n):
        for c in range(4):
            acc = 0.0
            for j in range(7):
                acc += K[j, i] * P[j, c]
            out[i, c] = acc


@jit
def dense_eval(y0, h, Q, s, out):
    """out = y(t0 + s h) from the step's start y0 and coefficients Q (s in [0, 1])."""
    for i in range(y0.size):
        out[i] = y0[i] + h * s * (Q[i, 0] + s * (Q[i, 1] + s * (Q[i, 2] + s * Q[i, 3])))


@jit
def new_step_factor(err, rejected):
    """Step-size factor after a step with error norm ``err`` (scipy's controller)."""
    if err < 1.0:
        if err == 0.0:
            f = MAX_FACTOR
        else:
            f = min(MAX_FACTOR, SAFETY * err ** ERROR_EXPONENT)
        if rejected:
            f = min(1.0, f)
        return f
    return max(MIN_FACTOR, SAFETY * err ** ERROR_EXPONENT)


@jit
def grow(a, n_new):
    """A copy of ``a`` with its first axis enlarged to n_new (the step store doubles as it fills)."""
    b = np.empty((n_new,) + a.shape[1:], dtype=a.dtype)
    b[: a.shape[0]] = a
    return b


@jit
def rms(v, scale):
    acc = 0.0
    for i in range(v.size):
        r = v[i] / scale[i]
        acc += r * r
    return np.sqrt(acc / v.size)


def evaluate_steps(t0s, hs, y0s, Qs, times, first=0, last=None):
    """Dense output of a run of steps at ``times`` (numpy, vectorised): array (n_state, n_times).

    t0s, hs (n_steps,), y0s (n_steps, n), Qs (n_steps, n, 4); times inside [t0s[0], t0s[-1] + hs[-1]].
    ``first``, ``last`` (int or one per time): the step index each time is clipped to, so that a
    time is read on the steps of its own run only (``evaluate_runs``).
    """
    times = np.atleast_1d(np.asarray(times, dtype=float))
    last = t0s.size - 1 if last is None else last
    i = np.clip(np.searchsorted(t0s, times, side="right") - 1, first, last)
    h = hs[i]
    s = np.where(h > 0, (times - t0s[i]) / np.where(h > 0, h, 1.0), 0.0)
    Q = Qs[i]                                            # (m, n, 4)
    poly = s[:, None] * (Q[:, :, 0] + s[:, None] * (Q[:, :, 1] + s[:, None] * (Q[:, :, 2] + s[:, None] * Q[:, :, 3])))
    return (y0s[i] + h[:, None] * poly).T


def evaluate_runs(runs, times):
    """Dense output of several ``DenseRun``s in one vectorised pass: ``times[k]`` on ``runs[k]``.

    The runs must follow each other in time (the phases of one integration). A time is evaluated
    on a step of its own run only, so an instant shared by two runs (a phase boundary) takes each
    run's own value. Returns an array (n_state, sum of len(times[k])) in the order given.
    """
    counts = np.array([np.size(tk) for tk in times])
    sizes = np.array([r.t0s.size for r in runs])
    first = np.concatenate(([0], np.cumsum(sizes)[:-1]))
    tt = np.concatenate([np.atleast_1d(np.asarray(tk, dtype=float)) for tk in times])
    return evaluate_steps(np.concatenate([r.t0s for r in runs]), np.concatenate([r.hs for r in runs]),
                          np.concatenate([r.y0s for r in runs]), np.concatenate([r.Qs for r in runs]), tt,
                          np.repeat(first, counts), np.repeat(first + sizes - 1, counts))


class DenseRun:
    """A stretch of steps with the interface the models read from scipy: ``.t`` (step times, s) and
    ``.sol(times)`` / ``__call__`` -> array (n_state, n_times), ``.nfev``."""

    def __init__(self, t0s, hs, y0s, Qs, t_end, nfev=0):
        self.t0s, self.hs, self.y0s, self.Qs = t0s, hs, y0s, Qs
        self.t = np.append(t0s, t_end)      # the last step may end early, at an event
        self.nfev = nfev

    def __call__(self, times):
        out = evaluate_steps(self.t0s, self.hs, self.y0s, self.Qs, times)
        return out[:, 0] if np.ndim(times) == 0 else out

    @property
    def sol(self):
        return self
