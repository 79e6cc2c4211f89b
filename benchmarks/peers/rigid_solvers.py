"""Peer solvers of the rigid model with backlash and impacts (paper eqs 1-11, docs/rigid_model.md).

The equations of motion, the events and the impact law are written here from the paper; the
coefficient tables (piecewise-cubic functions of phi1 and phi2: stroke and its derivatives, the
normal's arm A2 and its derivatives, cam gravity, J'', dJ''/dphi2, gravity and load moments) are
the model's own discretisation of the mechanism, taken from labtool's plant (the one place
``rigid_problem`` touches labtool's dynamics), so that every solver integrates the same ODE.

contact (state phi1, omega1): phi2 = phi20 + psi + qc (qc = j/A2 on the outer flank),
    Jred eps1 + 1/2 dJred/dphi1 omega1^2 = M1(omega1) + Mc + (Mg + ML) f'     (eqs 1-3)
    event: the flank's normal force MR13D/A2 changes sign (lift-off), or phi1 reaches its end
free (state phi1, omega1, q, omega2): J' eps1 = M1 + Mc; J'' eps2 + 1/2 dJ'' omega2^2 = Mg + ML
    (eqs 4-7); events: the gap A2 q reaches 0 (inner flank) or j (outer), or the end
impact: P = -(1 + k) v_n / (A2^2/J'' + G1^2/J'), G1 = A2 psi' - A2' q (eqs 8-11); a grazing
    impact (|v| < v_settle) is plastic and the follower stays on a flank that presses it.

numbalsoda (LSODA, DOP853): windows of output instants, events located between two outputs by a
bracketed secant (Illinois) search, each evaluation a short integration from the output before;
solve_ivp (LSODA, DOP853, Radau) with a numba right-hand side and its own terminal events. The
no-backlash companion run (j = 0), which the model's indicators need, is integrated too.
"""
from __future__ import annotations

import time

import numba as nb
import numpy as np

from benchmarks.peers import rigid_problem as rp

try:
    import numbalsoda
    HAVE_NUMBALSODA = True
except ImportError:
    numbalsoda = None
    HAVE_NUMBALSODA = False

INNER, OUTER = 1, -1
CONTACT, FREE = 0, 1
MAX_EVENTS = 20000
ANGLE_TIE = 1e-12
MAX_WINDOW = 64        # output instants per numbalsoda call at most (see numbalsoda_solve)
# s: solve_ivp's own first step after an impact can be so small that the state does not change and
# the flank just left reads as a new contact at once; this one is far below any flight's duration
FIRST_STEP = 1e-7


@nb.njit(cache=True)
def _table(p, which, x, col):
    """Column ``col`` of table ``which`` (0: phi1, 1: phi2) at x: binary search, Hermite cubic."""
    base = 12 + 4 * which
    n, on, oh, oc = int(p[base]), int(p[base + 1]), int(p[base + 2]), int(p[base + 3])
    lo, hi = 0, n - 1
    if x < p[on]:
        hi = 1
    elif x >= p[on + n - 1]:
        lo = n - 2
    else:
        while hi - lo > 1:
            mid = (lo + hi) >> 1
            if p[on + mid] <= x:
                lo = mid
            else:
                hi = mid
    t = (x - p[on + lo]) * p[oh + lo]
    k = oc + (col * (n - 1) + lo) * 4
    return p[k] + t * (p[k + 1] + t * (p[k + 2] + t * p[k + 3]))


@nb.njit(cache=True)
def _contact(p, phi1, omega1, flank):
    """(eps1, phi2, omega2, eps2, MR13D, lam, qc, A2, psi') on a flank."""
    psi, d1, d2 = _table(p, 0, phi1, 0), _table(p, 0, phi1, 1), _table(p, 0, phi1, 2)
    A2, dA2, ddA2 = _table(p, 0, phi1, 3), _table(p, 0, phi1, 4), _table(p, 0, phi1, 5)
    Mc, dirn = _table(p, 0, phi1, 6), _table(p, 0, phi1, 7)
    j, jt = p[10], p[3]
    if flank == OUTER and j > 0.0:
        qc, dqc, ddqc = j / A2, -j * dA2 / (A2 * A2), j * (2.0 * dA2 * dA2 / A2 ** 3 - ddA2 / (A2 * A2))
    else:
        qc, dqc, ddqc = 0.0, 0.0, 0.0
    phi2 = p[2] + psi + qc
    f1, f2 = d1 + dqc, d2 + ddqc
    J, dJ = jt * _table(p, 1, phi2, 0), jt * _table(p, 1, phi2, 1)
    Mg, ML = _table(p, 1, phi2, 2), p[9] * dirn * _table(p, 1, phi2, 3)
    if p[6] > 0.0:
        eps1 = 0.0
    else:
        Jred = p[4] + J * f1 * f1
        dJred = dJ * f1 ** 3 + 2.0 * J * f1 * f2
        eps1 = (p[7] - p[8] * omega1 + Mc + (Mg + ML) * f1 - 0.5 * dJred * omega1 * omega1) / Jred
    omega2 = f1 * omega1
    eps2 = f2 * omega1 * omega1 + f1 * eps1
    MR = J * eps2 + 0.5 * dJ * omega2 * omega2 - Mg - ML
    return eps1, phi2, omega2, eps2, MR, MR / A2, qc, A2, d1


@nb.njit(cache=True)
def _free(p, phi1, omega1, q, omega2):
    """(eps1, dq/dt, eps2, gap g m, phi2, A2, psi', A2')."""
    psi, d1 = _table(p, 0, phi1, 0), _table(p, 0, phi1, 1)
    A2, dA2, Mc, dirn = _table(p, 0, phi1, 3), _table(p, 0, phi1, 4), _table(p, 0, phi1, 6), _table(p, 0, phi1, 7)
    phi2 = p[2] + psi + q
    jt = p[3]
    J, dJ = _table(p, 1, phi2, 0), _table(p, 1, phi2, 1)
    Mg, MLu = _table(p, 1, phi2, 2), _table(p, 1, phi2, 3)
    eps1 = 0.0 if p[6] > 0.0 else (p[7] - p[8] * omega1 + Mc) * p[5]
    eps2 = (Mg + p[9] * dirn * MLu - 0.5 * jt * dJ * omega2 * omega2) / (jt * J)
    return eps1, omega2 - d1 * omega1, eps2, A2 * q, phi2, A2, d1, dA2


@nb.njit(cache=True)
def _derivs(p, u, du):
    if p[0] == CONTACT:
        du[0] = u[1]
        du[1] = _contact(p, u[0], u[1], int(p[1]))[0]
    else:
        r = _free(p, u[0], u[1], u[2], u[3])
        du[0], du[1], du[2], du[3] = u[1], r[0], r[1], r[2]


if HAVE_NUMBALSODA:
    @nb.cfunc(numbalsoda.lsoda_sig, cache=True)
    def _rhs_cfunc(t, u, du, p):
        _derivs(p, u, du)
    RHS_ADDRESS = _rhs_cfunc.address
else:
    RHS_ADDRESS = 0


@nb.njit(cache=True)
def _events(p, y, mode, flank, end):
    """Event functions, each crossing zero upwards: (lift-off or inner flank, outer flank, end)."""
    if mode == CONTACT:
        lift = -flank * _contact(p, y[0], y[1], flank)[5] if p[10] > 0.0 else -1.0
        return lift, -1.0, y[0] - end
    g = _free(p, y[0], y[1], y[2], y[3])[3]
    return -g, g - p[10], y[0] - end


def _make_driver(solve):
    @nb.njit
    def drive(fp, p, t_out, y0, end, rtol, atol, v_settle, max_events):
        n_out = t_out.size
        U = np.zeros((n_out, 4))
        MODE = np.zeros(n_out, np.int64)
        FL = np.zeros(n_out, np.int64)
        ev_t = np.empty(max_events)
        n_ev = 0
        phi1, omega1 = y0[0], y0[1]
        lam = _contact(p, phi1, omega1, INNER)[5]
        mode, flank = CONTACT, (INNER if (lam >= 0 or p[10] == 0.0) else OUTER)
        y = np.array([phi1, omega1])
        t0, k, window = 0.0, 0, 16
        U[0, 0], U[0, 1], MODE[0], FL[0] = y[0], y[1], mode, flank
        k = 1
        t_end = t_out[n_out - 1]
        while True:
            p[0], p[1] = mode, flank
            W = max(0, min(window, n_out - k))
            tev = np.empty(W + 1)
            tev[0] = t0
            tev[1:] = t_out[k:k + W]
            if W == 0:                                  # past the last output: run on to the end event
                tev = np.array([t0, t0 + 10.0 * (t_out[1] - t_out[0])])
                W = 1
            usol, ok = solve(fp, y, tev, p, rtol, atol, 500000)
            if not ok:
                raise RuntimeError("the solver failed")
            hit, which = -1, -1
            for jj in range(1, W + 1):
                a = _events(p, usol[jj - 1], mode, flank, end)
                b = _events(p, usol[jj], mode, flank, end)
                for e in range(3):
                    if a[e] < 0.0 <= b[e]:
                        hit, which = jj, e
                        break
                if hit > 0:
                    break
            if hit < 0:
                for jj in range(W):
                    if k + jj < n_out:
                        U[k + jj, :y.size] = usol[jj + 1]
                        MODE[k + jj], FL[k + jj] = mode, flank
                t0, y = tev[W], usol[W].copy()
                k += W
                window = min(2 * window, MAX_WINDOW)
                continue
            for jj in range(1, hit):
                U[k + jj - 1, :y.size] = usol[jj]
                MODE[k + jj - 1], FL[k + jj - 1] = mode, flank
            ta, ya, tb = tev[hit - 1], usol[hit - 1].copy(), tev[hit]
            ga = _events(p, ya, mode, flank, end)[which]
            gb = _events(p, usol[hit], mode, flank, end)[which]
            lo, hi, glo, ghi = ta, tb, ga, gb
            tc, yc = tb, usol[hit].copy()
            side = 0
            for _ in range(80):                         # Illinois: bracketed secant
                tn = (lo * ghi - hi * glo) / (ghi - glo) if ghi != glo else 0.5 * (lo + hi)
                if not (lo < tn < hi):
                    tn = 0.5 * (lo + hi)
                ys, ok = solve(fp, ya, np.array([ta, tn]), p, rtol, atol, 500000)
                yn = ys[1].copy()
                gn = _events(p, yn, mode, flank, end)[which]
                if gn >= 0.0:
                    hi, ghi, tc, yc = tn, gn, tn, yn
                    if side == 1:
                        glo *= 0.5
                    side = 1
                else:
                    lo, glo = tn, gn
                    if side == -1:
                        ghi *= 0.5
                    side = -1
                if hi - lo <= 1e-15 + 4e-16 * hi:
                    break
            k += hit - 1
            t0 = tc
            if which == 2 or yc[0] >= end - ANGLE_TIE:             # the end of the simulated angle
                return U, MODE, FL, ev_t[:n_ev].copy(), tc
            if n_ev >= max_events:
                raise RuntimeError("too many contact events")
            ev_t[n_ev] = tc
            n_ev += 1
            mode, flank, y = _after_event(p, yc, mode, flank, which, v_settle)
            while k < n_out and t_out[k] <= t0:
                U[k, :y.size] = y
                MODE[k], FL[k] = mode, flank
                k += 1
            window = 16
    return drive


if HAVE_NUMBALSODA:
    _drive_lsoda = _make_driver(numbalsoda.lsoda)
    _drive_dop853 = _make_driver(numbalsoda.dop853)


@nb.njit(cache=True)
def _omega2_mr(p, U, MODE, FL):
    n = U.shape[0]
    w2, mr = np.empty(n), np.empty(n)
    for i in range(n):
        if MODE[i] == CONTACT:
            r = _contact(p, U[i, 0], U[i, 1], FL[i])
            w2[i], mr[i] = r[2], r[4]
        else:
            w2[i], mr[i] = U[i, 3], 0.0
    return w2, mr


def numbalsoda_solve(prob, method, rtol):
    drive = {"LSODA": _drive_lsoda, "DOP853": _drive_dop853}[method]
    t0 = time.perf_counter()
    runs = []
    for p in (prob.data(prob.j), prob.data(0.0)):          # with backlash, and the j = 0 companion
        runs.append(drive(RHS_ADDRESS, p, prob.t_out, np.array([0.0, prob.omega1_0]), prob.phi1_end,
                          rtol, rtol * 1e-3, prob.v_settle, MAX_EVENTS) + (p,))
    loop = time.perf_counter() - t0
    U, MODE, FL, ev, _, p = runs[0]
    return U, MODE, FL, ev, p, loop


# ------------------------------------------------------------------------- scipy, numba RHS
@nb.njit(cache=True)
def _rhs_nb(t, y, p):
    du = np.empty(y.size)
    _derivs(p, y, du)
    return du


def scipy_solve(prob, method, rtol):
    from scipy.integrate import solve_ivp

    t0c = time.perf_counter()
    result = None
    for p in (prob.data(prob.j), prob.data(0.0)):
        t_out, end, n = prob.t_out, prob.phi1_end, prob.t_out.size
        U, MODE, FL = np.zeros((n, 4)), np.zeros(n, np.int64), np.zeros(n, np.int64)
        ev = []
        lam = _contact(p, 0.0, prob.omega1_0, INNER)[5]
        mode, flank = CONTACT, (INNER if (lam >= 0 or p[10] == 0.0) else OUTER)
        y, t0, k = np.array([0.0, prob.omega1_0]), 0.0, 0
        while True:
            p[0], p[1] = mode, flank
            evs = []
            for e in range(3):
                f = (lambda e, mode, flank: lambda t, yy: _events(p, yy, mode, flank, end)[e])(e, mode, flank)
                f.terminal, f.direction = True, 1.0
                evs.append(f)
            sol = solve_ivp(lambda t, yy: _rhs_nb(t, yy, p), (t0, 4.0 * t_out[-1] + 1.0), y, method=method,
                            t_eval=t_out[k:] if k < n else [], events=evs, rtol=rtol, atol=rtol * 1e-3,
                            first_step=FIRST_STEP)
            m = len(sol.t) if k < n else 0
            if m:
                U[k:k + m, :y.size], MODE[k:k + m], FL[k:k + m] = np.asarray(sol.y).T, mode, flank
            k += m
            hits = [i for i in range(3) if sol.t_events[i].size]
            if sol.status != 1 or not hits:
                raise RuntimeError(f"solve_ivp {method}: {sol.message}")
            which = min(hits, key=lambda i: sol.t_events[i][0])
            t0, yc = float(sol.t_events[which][0]), sol.y_events[which][0]
            if which == 2 or yc[0] >= end - ANGLE_TIE:
                break
            ev.append(t0)
            mode, flank, y = _after_event(p, yc, mode, flank, which, prob.v_settle)
            while k < n and t_out[k] <= t0:
                U[k, :y.size], MODE[k], FL[k] = y, mode, flank
                k += 1
        if result is None:
            result = (U, MODE, FL, np.array(ev), p)
    U, MODE, FL, ev, p = result
    return U, MODE, FL, ev, p, time.perf_counter() - t0c


@nb.njit(cache=True)
def _after_event(p, yc, mode, flank, which, v_settle):
    """(mode, flank, state) after a lift-off (contact mode) or an impact on the inner (which 0) or
    outer (which 1) flank: q projected onto the flank, Newton's k on the normal velocity of C, a
    grazing impact (|v| < v_settle) made plastic when the flank then presses the follower."""
    if mode == CONTACT:
        r = _contact(p, yc[0], yc[1], flank)
        return FREE, flank, np.array([yc[0], yc[1], r[6], r[2]])
    hit_flank = INNER if which == 0 else OUTER
    phi1, omega1, q, omega2 = yc[0], yc[1], yc[2], yc[3]
    r = _free(p, phi1, omega1, q, omega2)
    phi2, A2, d1, dA2 = r[4], r[5], r[6], r[7]
    q = 0.0 if hit_flank == INNER else p[10] / A2
    G1 = A2 * d1 - dA2 * q
    J2 = _table(p, 1, phi2, 0) * p[3]
    kk = p[11]
    v_before = A2 * omega2 - G1 * omega1
    denominator = A2 * A2 / J2 + G1 * G1 * p[5]
    if min(-v_before * hit_flank, -kk * v_before * hit_flank) < v_settle:
        w1_plastic = omega1 + v_before / denominator * G1 * p[5]
        if hit_flank * _contact(p, phi1, w1_plastic, hit_flank)[5] > 0.0:
            kk = -1.0                       # settle: a plastic impact, then stay on the flank
    settle = kk < 0.0
    P = -(1.0 + max(kk, 0.0)) * v_before / denominator
    omega1, omega2 = omega1 - P * G1 * p[5], omega2 + P * A2 / J2
    if settle:
        return CONTACT, hit_flank, np.array([phi1, omega1])
    return FREE, hit_flank, np.array([phi1, omega1, q, omega2])


SOLVERS = {
    "numbalsoda-LSODA": lambda prob, rtol: numbalsoda_solve(prob, "LSODA", rtol),
    "numbalsoda-DOP853": lambda prob, rtol: numbalsoda_solve(prob, "DOP853", rtol),
    "scipy+numba-LSODA": lambda prob, rtol: scipy_solve(prob, "LSODA", rtol),
    "scipy+numba-DOP853": lambda prob, rtol: scipy_solve(prob, "DOP853", rtol),
    "scipy+numba-Radau": lambda prob, rtol: scipy_solve(prob, "Radau", rtol),
}


def available() -> list[str]:
    return [k for k in SOLVERS if HAVE_NUMBALSODA or not k.startswith("numbalsoda")]


def solve(scene, solver: str, rtol: float, t_out=None):
    """Whole call: the plant, both integrations, omega2 and MR13D at the output instants."""
    t0 = time.perf_counter()
    prob = rp.build(scene, t_out)
    U, MODE, FL, ev, p, loop = SOLVERS[solver](prob, rtol)
    w2, mr = _omega2_mr(p, U, MODE, FL)
    out = {"omega2": w2, "MR13D": mr, "event_times": ev, "time": prob.t_out}
    return out, loop, time.perf_counter() - t0
