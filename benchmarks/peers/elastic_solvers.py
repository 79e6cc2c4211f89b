"""Peer solvers of the elastic model: numbalsoda LSODA and DOP853, scipy solve_ivp with a numba
right-hand side (LSODA, DOP853, Radau). Same equations (``elastic_problem``), restarted at every
contact change (the phase's right-hand side is smooth; the switch is not).

numbalsoda has no event location: its solvers integrate over a window of output instants (16,
doubling while no contact changes, back to 16 after one); a sign change of the phase's boundary
function between two outputs is located by safeguarded Newton iterations, each a short
integration from the output before it; the solver restarts from the event 1e-13 m inside the new
phase. solve_ivp uses its own events (terminal, with direction), a numba-compiled right-hand side
and analytic Jacobian (LSODA, Radau). Everything a skilled user would do, nothing labtool-specific.
"""
from __future__ import annotations

import time

import numba as nb
import numpy as np

from benchmarks.peers.elastic_problem import EXTERIOR, FLIGHT, INTERIOR, NUDGE

try:
    import numbalsoda
    HAVE_NUMBALSODA = True
except ImportError:          # the optional 'bench' extra
    numbalsoda = None
    HAVE_NUMBALSODA = False

EXPONENT = 10.0 / 9.0
MAX_EVENTS = 20000


@nb.njit(cache=True, inline="always")
def _coefficients(t, p):
    n = int(p[7])
    s = (t - p[5]) / p[6]
    if s <= 0.0:
        return p[8], p[8 + n]
    i = int(s)
    if i >= n - 1:
        return p[8 + n - 1], p[8 + 2 * n - 1]
    f = s - i
    return p[8 + i] + f * (p[9 + i] - p[8 + i]), p[8 + n + i] + f * (p[9 + n + i] - p[8 + n + i])


@nb.njit(cache=True, inline="always")
def _force(phase, x, kc, gap):
    if phase == INTERIOR:
        return kc * (-x) ** EXPONENT if x < 0.0 else 0.0
    if phase == EXTERIOR:
        return -kc * (x - gap) ** EXPONENT if x > gap else 0.0
    return 0.0


@nb.njit(cache=True)
def _derivs(t, u0, u1, p):
    phase, kc, gap, xs, vs = int(p[0]), p[1], p[2], p[3], p[4]
    R, M = _coefficients(t, p)
    return u1 * vs / xs, (_force(phase, u0 * xs, kc, gap) - R) / M / vs


if HAVE_NUMBALSODA:
    @nb.cfunc(numbalsoda.lsoda_sig, cache=True)
    def _rhs_cfunc(t, u, du, p):
        a, b = _derivs(t, u[0], u[1], p)
        du[0] = a
        du[1] = b
    RHS_ADDRESS = _rhs_cfunc.address
else:
    RHS_ADDRESS = 0


@nb.njit(cache=True)
def _boundaries(phase, gap, xs):
    """(boundary u, direction, next phase) x 2 (the second unused outside flight)."""
    if phase == INTERIOR:
        return 0.0, 1.0, (FLIGHT if gap > 0 else EXTERIOR), np.nan, 0.0, -1
    if phase == EXTERIOR:
        return gap / xs, -1.0, (FLIGHT if gap > 0 else INTERIOR), np.nan, 0.0, -1
    return 0.0, -1.0, INTERIOR, gap / xs, 1.0, EXTERIOR


@nb.njit(cache=True)
def _crossed(ga, gb, direction):
    return (ga < 0.0 <= gb) if direction > 0 else (ga > 0.0 >= gb)


@nb.njit(cache=True)
def _restart_u(at_zero, new_phase, gap, xs):
    eps = NUDGE if gap == 0 else min(NUDGE, 0.25 * gap)
    boundary = 0.0 if at_zero else gap
    if new_phase == INTERIOR:
        inward = -1.0
    elif new_phase == EXTERIOR:
        inward = 1.0
    else:
        inward = 1.0 if at_zero else -1.0
    return (boundary + inward * eps) / xs


def _make_driver(solve):
    @nb.njit
    def drive(funcptr, p, t_out, t_start, u0, w0, phase0, rtol, atol):
        n_out = t_out.size
        U = np.empty((n_out, 2))
        PH = np.empty(n_out, np.int64)
        ev_t = np.empty(MAX_EVENTS)
        ev_from = np.empty(MAX_EVENTS, np.int64)
        ev_to = np.empty(MAX_EVENTS, np.int64)
        n_ev = 0
        gap, xs = p[2], p[3]
        y = np.array([u0, w0])
        phase = phase0
        t0 = t_start
        k = 0
        while k < n_out and t_out[k] <= t0:
            U[k, 0], U[k, 1], PH[k] = y[0], y[1], phase
            k += 1
        window = 16
        ok_all = True
        while k < n_out:
            W = min(window, n_out - k)
            tev = np.empty(W + 1)
            tev[0] = t0
            tev[1:] = t_out[k:k + W]
            p[0] = phase
            usol, ok = solve(funcptr, y, tev, p, rtol, atol, 500000)
            ok_all = ok_all and ok
            b1, d1, n1, b2, d2, n2 = _boundaries(phase, gap, xs)
            hit, which = -1, 0
            for j in range(1, W + 1):
                if _crossed(usol[j - 1, 0] - b1, usol[j, 0] - b1, d1):
                    hit, which = j, 1
                    break
                if n2 >= 0 and _crossed(usol[j - 1, 0] - b2, usol[j, 0] - b2, d2):
                    hit, which = j, 2
                    break
            if hit < 0:
                for j in range(W):
                    U[k + j, 0], U[k + j, 1], PH[k + j] = usol[j + 1, 0], usol[j + 1, 1], phase
                t0 = tev[W]
                y = usol[W].copy()
                k += W
                window = min(2 * window, 4096)
                continue
            for j in range(1, hit):
                U[k + j - 1, 0], U[k + j - 1, 1], PH[k + j - 1] = usol[j, 0], usol[j, 1], phase
            b, new, d = (b1, n1, d1) if which == 1 else (b2, n2, d2)
            ta, ya, tb = tev[hit - 1], usol[hit - 1].copy(), tev[hit]
            lo, hi = ta, tb
            tc, yc = ta, ya.copy()
            for _ in range(60):                         # safeguarded Newton on x(t) = boundary
                g, gp = yc[0] - b, yc[1] * p[4] / xs
                tn = tc - g / gp if gp != 0.0 else 0.5 * (lo + hi)
                if not (lo < tn < hi):
                    tn = 0.5 * (lo + hi)
                seg = np.array([ta, tn])
                ys, ok = solve(funcptr, ya, seg, p, rtol, atol, 500000)
                yc = ys[1].copy()
                done = abs(tn - tc) <= 1e-15 + 4e-16 * tn
                tc = tn
                if _crossed(ya[0] - b, yc[0] - b, d):
                    hi = tn
                else:
                    lo = tn
                if done or hi - lo < 1e-15:
                    break
            if n_ev >= MAX_EVENTS:
                raise RuntimeError("too many contact events")
            ev_t[n_ev], ev_from[n_ev], ev_to[n_ev] = tc, phase, new
            n_ev += 1
            k += hit - 1
            y = yc
            y[0] = _restart_u(b == 0.0, new, gap, xs)
            phase = new
            t0 = tc
            while k < n_out and t_out[k] <= t0:
                U[k, 0], U[k, 1], PH[k] = y[0], y[1], phase
                k += 1
            window = 16
        return U, PH, ev_t[:n_ev].copy(), ev_from[:n_ev].copy(), ev_to[:n_ev].copy(), ok_all
    return drive


if HAVE_NUMBALSODA:
    _drive_lsoda = _make_driver(numbalsoda.lsoda)
    _drive_dop853 = _make_driver(numbalsoda.dop853)


def numbalsoda_solve(prob, method: str, rtol: float, atol: float):
    """(U, PH, event times, loop_s) with numbalsoda's LSODA or DOP853."""
    drive = {"LSODA": _drive_lsoda, "DOP853": _drive_dop853}[method]
    t_start, u0, w0, phase = prob.initial_state()
    p = prob.data()
    t0 = time.perf_counter()
    U, PH, ev_t, _, _, ok = drive(RHS_ADDRESS, p, prob.t_out, t_start, u0, w0, phase, rtol, atol)
    loop = time.perf_counter() - t0
    if not ok:
        raise RuntimeError(f"numbalsoda {method} failed")
    return U, PH, ev_t, loop


# ------------------------------------------------------------------------- scipy, numba RHS
@nb.njit(cache=True)
def _rhs_nb(t, y, p):
    a, b = _derivs(t, y[0], y[1], p)
    return np.array([a, b])


@nb.njit(cache=True)
def _jac_nb(t, y, p):
    phase, kc, gap, xs, vs = int(p[0]), p[1], p[2], p[3], p[4]
    _, M = _coefficients(t, p)
    x = y[0] * xs
    if phase == INTERIOR and x < 0.0:
        dF = kc * EXPONENT * (-x) ** (EXPONENT - 1.0)     # d/dx of Kc (-x)^n is -n Kc (-x)^(n-1): F' = -...
        dF = -dF
    elif phase == EXTERIOR and x > gap:
        dF = -kc * EXPONENT * (x - gap) ** (EXPONENT - 1.0)
    else:
        dF = 0.0
    return np.array([[0.0, vs / xs], [dF * xs / M / vs, 0.0]])


def scipy_solve(prob, method: str, rtol: float, atol: float):
    """(U, PH, event times, loop_s) with scipy solve_ivp and the numba right-hand side."""
    from scipy.integrate import solve_ivp

    t_start, u0, w0, phase = prob.initial_state()
    p = prob.data()
    gap, xs = prob.gap, prob.xs
    t_out = prob.t_out
    n = t_out.size
    U, PH = np.empty((n, 2)), np.empty(n, np.int64)
    ev = []
    jac = (lambda t, y: _jac_nb(t, y, p)) if method in ("LSODA", "Radau") else None
    t0c = time.perf_counter()
    y, t0, k = np.array([u0, w0]), t_start, 0
    while k < n and t_out[k] <= t0:
        U[k], PH[k] = y, phase
        k += 1
    while k < n:
        p[0] = phase
        b1, d1, n1, b2, d2, n2 = _boundaries(phase, gap, xs)
        specs = [(b1, d1, n1)] + ([(b2, d2, n2)] if n2 >= 0 else [])
        events = []
        for b, d, _ in specs:
            f = (lambda b: lambda t, y: y[0] - b)(b)
            f.terminal, f.direction = True, d
            events.append(f)
        sol = solve_ivp(lambda t, y: _rhs_nb(t, y, p), (t0, prob.t_end), y, method=method, t_eval=t_out[k:],
                        events=events, rtol=rtol, atol=atol, jac=jac)
        if sol.status == -1:
            raise RuntimeError(f"solve_ivp {method}: {sol.message}")
        m = sol.t.size
        U[k:k + m], PH[k:k + m] = sol.y.T, phase
        k += m
        if sol.status != 1:
            break
        hit = min((i for i in range(len(specs)) if sol.t_events[i].size), key=lambda i: sol.t_events[i][0])
        t0, y = float(sol.t_events[hit][0]), sol.y_events[hit][0].copy()
        b, _, new = specs[hit]
        ev.append(t0)
        y[0] = _restart_u(b == 0.0, new, gap, xs)
        phase = new
        while k < n and t_out[k] <= t0:
            U[k], PH[k] = y, phase
            k += 1
    loop = time.perf_counter() - t0c
    return U, PH, np.array(ev), loop


SOLVERS = {
    "numbalsoda-LSODA": lambda prob, rtol: numbalsoda_solve(prob, "LSODA", rtol, 10 * rtol),
    "numbalsoda-DOP853": lambda prob, rtol: numbalsoda_solve(prob, "DOP853", rtol, 10 * rtol),
    "scipy+numba-LSODA": lambda prob, rtol: scipy_solve(prob, "LSODA", rtol, 10 * rtol),
    "scipy+numba-DOP853": lambda prob, rtol: scipy_solve(prob, "DOP853", rtol, 10 * rtol),
    "scipy+numba-Radau": lambda prob, rtol: scipy_solve(prob, "Radau", rtol, 10 * rtol),
}


def available() -> list[str]:
    return [k for k in SOLVERS if HAVE_NUMBALSODA or not k.startswith("numbalsoda")]


def solve(scene, solver: str, rtol: float):
    """The whole call of a peer: the problem from the mechanism, the loop, the outputs at the
    output instants. Returns (outputs dict with omega2, MR13D, event_times; loop_s; wall_s)."""
    from benchmarks.peers import elastic_problem
    t0 = time.perf_counter()
    prob = elastic_problem.build(scene)
    U, PH, ev, loop = SOLVERS[solver](prob, rtol)
    out = elastic_problem.outputs(prob, U[:, 0], U[:, 1], PH)
    out["event_times"] = ev
    out["time"] = prob.t_out
    return out, loop, time.perf_counter() - t0

