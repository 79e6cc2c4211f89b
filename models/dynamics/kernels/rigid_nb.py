"""Compiled integration of the rigid-element model with backlash and impacts (paper eqs 1-11).

A drop-in for ``models.dynamics.rigid.integrate``: same arguments, same return value (phases with a dense
``sol`` and the event dicts), so ``models.dynamics.rigid`` keeps its tables, sampling and indicators and only
the event-driven loop runs compiled. The equations are ``models.dynamics.rigid.contact_terms``,
``free_terms``, ``gap_event`` and the impact law ``models.dynamics.impact.impact``, transcribed line by line
(read the physics and the sign conventions there):

contact (1 DOF, state phi1 rad, omega1 rad/s): the follower rides the inner (+1) or outer (-1)
    flank; eps1 from eq. (1) with the reduced inertia of eq. (2); event: the flank's normal force
    lam = MR13D / A2 (N) changes sign (only with backlash), or phi1 reaches its end.
free (2 DOF, state phi1, omega1, q rad, omega2 rad/s): eqs (4)-(7); events: the gap g = A2 q closes
    on the inner flank (g = 0) or the outer one (g = j); on the flank just left the function is
    divided by (t - t0) so that its trivial root at the start is removed without an offset.
impact: Newton's k on the normal velocity of the roller centre; a grazing or accumulating impact
    (|v| < v_settle) is made plastic and the follower stays on the flank if it is pressed on it.

Integration: Dormand-Prince 5(4) (``models.dynamics.kernels.dopri5``), scipy's controller, events located
by bisection on the dense output. Caps: ``preset["max_events"]`` events and ``MAX_STEPS`` steps
per run, then ``SolverError`` naming the limit.
"""
from __future__ import annotations

import math

import numpy as np
from models.dynamics.jit import jit

from common.errors import SolverError
from models.dynamics.kernels import dopri5 as dp

INNER, OUTER, FREE = 1, -1, 0
CONTACT_MODE, FREE_MODE = 0, 1
LIFTOFF, REBOUND, SETTLE = 1, 2, 3
MAX_STEPS = 2_000_000
ANGLE_TIE = 1e-12      # rad: an event this close to the end of the simulated angle is the end
# parameter vector layout (``_params``)
I_PHI20, I_JT, I_JCAM, I_INVJ, I_CONST, I_M0, I_M1, I_FU, I_J, I_K = range(10)
N_EVCOLS = 14   # time, phi1, kind, flank, v_b, v_a, P, w1b, w1a, w2b, w2a, phi2, Eb, Ea


@jit
def _cell(nodes, x):
    """Index of the cell [nodes[i], nodes[i+1]) that holds x, clipped to the table (binary search)."""
    n = nodes.size
    lo, hi = 0, n - 1
    if x < nodes[0]:
        return 0
    if x >= nodes[n - 1]:
        return n - 2
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if nodes[mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo


@jit
def interp(nodes, inv_h, coef, x, out):
    """All columns of a piecewise-cubic table at x (models.dynamics.rigid.interp)."""
    i = _cell(nodes, x)
    t = (x - nodes[i]) * inv_h[i]
    for c in range(coef.shape[0]):
        out[c] = coef[c, i, 0] + t * (coef[c, i, 1] + t * (coef[c, i, 2] + t * coef[c, i, 3]))


@jit
def contact_terms(n1, h1, c1, n2, h2, c2, p, phi1, omega1, flank, w1, w2, res):
    """res = (eps1, phi2, omega2, eps2, MR13D, lam, qc, A2, psi') on ``flank`` (models.dynamics.rigid.contact_terms)."""
    interp(n1, h1, c1, phi1, w1)
    psi, d1, d2, A2, dA2, ddA2, Mc, dirn = w1[0], w1[1], w1[2], w1[3], w1[4], w1[5], w1[6], w1[7]
    j = p[I_J]
    if flank == OUTER and j > 0.0:
        qc = j / A2
        dqc = -j * dA2 / (A2 * A2)
        ddqc = j * (2.0 * dA2 * dA2 / A2 ** 3 - ddA2 / (A2 * A2))
    else:
        qc, dqc, ddqc = 0.0, 0.0, 0.0
    phi2 = p[I_PHI20] + psi + qc
    f1, f2 = d1 + dqc, d2 + ddqc
    interp(n2, h2, c2, phi2, w2)
    J, dJ = w2[0] * p[I_JT], w2[1] * p[I_JT]
    Mg, ML = w2[2], p[I_FU] * dirn * w2[3]
    if p[I_CONST] != 0.0:
        eps1 = 0.0
    else:
        Jred = p[I_JCAM] + J * f1 * f1                                   # eq. (2)
        dJred = dJ * f1 ** 3 + 2.0 * J * f1 * f2
        eps1 = (p[I_M0] - p[I_M1] * omega1 + Mc + (Mg + ML) * f1 - 0.5 * dJred * omega1 * omega1) / Jred   # eq. (1)
    omega2 = f1 * omega1
    eps2 = f2 * omega1 * omega1 + f1 * eps1
    MR = J * eps2 + 0.5 * dJ * omega2 * omega2 - Mg - ML
    res[0], res[1], res[2], res[3], res[4] = eps1, phi2, omega2, eps2, MR
    res[5], res[6], res[7], res[8] = MR / A2, qc, A2, d1


@jit
def free_terms(n1, h1, c1, n2, h2, c2, p, phi1, omega1, q, omega2, w1, w2, res):
    """res = (eps1, dq/dt, eps2, g, phi2, A2, psi', A2') in the gap (models.dynamics.rigid.free_terms)."""
    interp(n1, h1, c1, phi1, w1)
    psi, d1, A2, dA2, Mc, dirn = w1[0], w1[1], w1[3], w1[4], w1[6], w1[7]
    phi2 = p[I_PHI20] + psi + q
    interp(n2, h2, c2, phi2, w2)
    J, dJ, Mg, MLu = w2[0], w2[1], w2[2], w2[3]
    eps1 = 0.0 if p[I_CONST] != 0.0 else (p[I_M0] - p[I_M1] * omega1 + Mc) * p[I_INVJ]   # eq. (4)
    eps2 = (Mg + p[I_FU] * dirn * MLu - 0.5 * p[I_JT] * dJ * omega2 * omega2) / (p[I_JT] * J)   # eq. (6)
    res[0], res[1], res[2], res[3] = eps1, omega2 - d1 * omega1, eps2, A2 * q
    res[4], res[5], res[6], res[7] = phi2, A2, d1, dA2


@jit
def _rhs(mode, flank, y, out, n1, h1, c1, n2, h2, c2, p, w1, w2, res):
    if mode == CONTACT_MODE:
        contact_terms(n1, h1, c1, n2, h2, c2, p, y[0], y[1], flank, w1, w2, res)
        out[0] = y[1]
        out[1] = res[0]
    else:
        free_terms(n1, h1, c1, n2, h2, c2, p, y[0], y[1], y[2], y[3], w1, w2, res)
        out[0] = y[1]
        out[1] = res[0]
        out[2] = res[1]
        out[3] = res[2]


@jit
def _event(which, mode, flank, left, t, t0, v0, y, phi1_end, n1, h1, c1, n2, h2, c2, p, w1, w2, res):
    """Event functions. which 0: end of the cam angle; contact 1: flank force; free 1: inner gap,
    free 2: outer gap (divided by t - t0 on the flank just left)."""
    if which == 0:
        return y[0] - phi1_end
    if mode == CONTACT_MODE:
        contact_terms(n1, h1, c1, n2, h2, c2, p, y[0], y[1], flank, w1, w2, res)
        return flank * res[5]
    free_terms(n1, h1, c1, n2, h2, c2, p, y[0], y[1], y[2], y[3], w1, w2, res)
    target_flank = INNER if which == 1 else OUTER
    g = res[3] - (0.0 if which == 1 else p[I_J])
    if target_flank != left:
        return g
    return g / (t - t0) if t > t0 else v0


@jit
def _impact(omega1, omega2, G1, G2, inv_Jcam, Jf, k):
    """models.dynamics.impact.impact: (omega1+, omega2+, P N s, v_n- m/s, v_n+ m/s)."""
    vb = G2 * omega2 - G1 * omega1
    P = -(1.0 + k) * vb / (G2 * G2 / Jf + G1 * G1 * inv_Jcam)
    return omega1 - P * G1 * inv_Jcam, omega2 + P * G2 / Jf, P, vb, -k * vb


@jit
def run(n1, h1, c1, n2, h2, c2, p, phi1_end, omega1_0, rtol, max_step, t_max, v_settle, max_events,
        max_steps, start_mode, start_flank, s_phi1, s_omega1, s_q, s_omega2, t_start):
    """The event-driven loop (models.dynamics.rigid.integrate). Returns status, t at failure, counts, steps,
    phases and events (see ``integrate``)."""
    cap = min(max_steps, 4096)
    st_t = np.empty(cap)
    st_h = np.empty(cap)
    st_y = np.zeros((cap, 4))
    st_Q = np.zeros((cap, 4, 4))
    pcap = 256
    ph_mode = np.empty(pcap, dtype=np.int64)
    ph_flank = np.empty(pcap, dtype=np.int64)
    ph_t0 = np.empty(pcap)
    ph_t1 = np.empty(pcap)
    ph_first = np.empty(pcap, dtype=np.int64)
    ev = np.empty((pcap, N_EVCOLS))
    w1 = np.empty(8)
    w2 = np.empty(4)
    res = np.empty(9)
    K4 = np.empty((7, 4))
    ynew4 = np.empty(4)
    tmp4 = np.empty(4)
    Q4 = np.empty((4, 4))
    atol_c = np.array([rtol * 1e-3, rtol * 1e-2])
    atol_f = np.array([rtol * 1e-3, rtol * 1e-2, rtol * 1e-6, rtol * 1e-3])
    j, kres = p[I_J], p[I_K]

    t = t_start
    if start_mode == CONTACT_MODE:
        phi1, omega1 = s_phi1, s_omega1
        flank = start_flank
        if flank == FREE:   # default start: the flank whose force is compressive
            contact_terms(n1, h1, c1, n2, h2, c2, p, phi1, omega1, INNER, w1, w2, res)
            flank = INNER if (res[5] >= 0.0 or j == 0.0) else OUTER
        q, omega2 = 0.0, 0.0
    else:
        phi1, omega1, q, omega2 = s_phi1, s_omega1, s_q, s_omega2
        flank = FREE
    mode = start_mode
    left, v_left = FREE, 0.0
    short = 0
    nst, nph, nev, nfev = 0, 0, 0, 0
    status = dp.OK
    while True:
        if nev > max_events:
            status = dp.TOO_MANY_EVENTS
            break
        if nph == pcap or nev == pcap:
            pcap *= 2
            ph_mode = dp.grow(ph_mode, pcap)
            ph_flank = dp.grow(ph_flank, pcap)
            ph_t0 = dp.grow(ph_t0, pcap)
            ph_t1 = dp.grow(ph_t1, pcap)
            ph_first = dp.grow(ph_first, pcap)
            ev = dp.grow(ev, pcap)
        n = 2 if mode == CONTACT_MODE else 4
        y = np.empty(n)
        if mode == CONTACT_MODE:
            y[0], y[1] = phi1, omega1
            atol = atol_c
            n_ev = 2 if j > 0.0 else 1
            dirs = (1.0, -1.0, 0.0)
        else:
            y[0], y[1], y[2], y[3] = phi1, omega1, q, omega2
            atol = atol_f
            n_ev = 3
            dirs = (1.0, -1.0, 1.0)
        K = K4[:, :n]
        y_new = ynew4[:n]
        tmp = tmp4[:n]
        Q = Q4[:n]
        ph_mode[nph] = mode
        ph_flank[nph] = flank if mode == CONTACT_MODE else FREE
        ph_t0[nph] = t
        ph_first[nph] = nst
        t_ph0 = t
        _rhs(mode, flank, y, K[0], n1, h1, c1, n2, h2, c2, p, w1, w2, res)
        # initial step (scipy's select_initial_step, order 4)
        scale = atol + np.abs(y) * rtol
        d0 = dp.rms(y, scale)
        d1 = dp.rms(K[0], scale)
        h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
        h0 = min(h0, t_max - t)
        for i in range(n):
            tmp[i] = y[i] + h0 * K[0, i]
        _rhs(mode, flank, tmp, y_new, n1, h1, c1, n2, h2, c2, p, w1, w2, res)
        nfev += 2
        d2 = dp.rms(y_new - K[0], scale) / h0
        h1s = max(1e-6, h0 * 1e-3) if (d1 <= 1e-15 and d2 <= 1e-15) else (0.01 / max(d1, d2)) ** 0.2
        h_abs = min(100.0 * h0, h1s, t_max - t, max_step)
        g_old = np.empty(3)
        g_new = np.empty(3)
        for e in range(n_ev):
            g_old[e] = _event(e, mode, flank, left, t, t_ph0, v_left, y, phi1_end, n1, h1, c1, n2, h2, c2, p, w1, w2, res)
        hit = -1
        t_hit = t
        while t < t_max:
            if nst >= max_steps:
                status = dp.TOO_MANY_STEPS
                break
            min_step = 10.0 * abs(np.nextafter(t, np.inf) - t)
            h_abs = min(max(h_abs, min_step), max_step)
            rejected = False
            bad = False
            while True:
                if h_abs < min_step:
                    bad = True
                    status = dp.STEP_TOO_SMALL
                    break
                t_new = min(t + h_abs, t_max)
                h = t_new - t
                for s in range(1, 6):
                    dp.stage_state(y, h, K, dp.A[s], s, tmp)
                    _rhs(mode, flank, tmp, K[s], n1, h1, c1, n2, h2, c2, p, w1, w2, res)
                dp.stage_state(y, h, K, dp.B, 6, y_new)
                _rhs(mode, flank, y_new, K[6], n1, h1, c1, n2, h2, c2, p, w1, w2, res)
                nfev += 6
                err = dp.error_norm(K, h, y, y_new, rtol, atol)
                if not np.isfinite(err):
                    if h_abs <= min_step:
                        bad = True
                        status = dp.NOT_FINITE
                        break
                    h_abs *= dp.MIN_FACTOR
                    rejected = True
                    continue
                f = dp.new_step_factor(err, rejected)
                h_abs *= f
                if err < 1.0:
                    break
                rejected = True
            if bad:
                break
            dp.dense_coeffs(K, Q)
            if nst == cap:
                cap = min(2 * cap, max_steps)
                st_t = dp.grow(st_t, cap)
                st_h = dp.grow(st_h, cap)
                st_y = dp.grow(st_y, cap)
                st_Q = dp.grow(st_Q, cap)
            st_t[nst] = t
            st_h[nst] = h
            st_y[nst, :n] = y
            st_Q[nst, :n] = Q
            nst += 1
            best = 2.0
            for e in range(n_ev):
                g_new[e] = _event(e, mode, flank, left, t_new, t_ph0, v_left, y_new, phi1_end, n1, h1, c1, n2, h2, c2, p, w1, w2, res)
                g0, g1 = g_old[e], g_new[e]
                up = g0 <= 0.0 and g1 >= 0.0
                down = g0 >= 0.0 and g1 <= 0.0
                if not ((up and dirs[e] > 0) or (down and dirs[e] < 0)):
                    continue
                # bisection on the dense output for the step fraction of the sign change
                lo, hi, g_lo = 0.0, 1.0, g0
                for _ in range(60):
                    mid = 0.5 * (lo + hi)
                    if mid <= lo or mid >= hi:
                        break
                    dp.dense_eval(y, h, Q, mid, tmp)
                    gm = _event(e, mode, flank, left, t + mid * h, t_ph0, v_left, tmp, phi1_end, n1, h1, c1, n2, h2, c2, p, w1, w2, res)
                    if (g_lo <= 0.0) == (gm <= 0.0) and gm != 0.0:
                        lo, g_lo = mid, gm
                    else:
                        hi = mid
                # ties (within scipy's root tolerance in time, 4 eps absolute and relative) go to the
                # lower index: the end of the simulated angle wins over a force jump at that same
                # angle (the end of the rise, where the load is removed)
                if (best - hi) * h > 8.9e-16 * (1.0 + abs(t)):
                    best = hi
                    hit = e
            if hit >= 0:
                t_hit = t + best * h
                dp.dense_eval(y, h, Q, best, tmp)
                if hit != 0 and tmp[0] >= phi1_end - ANGLE_TIE:
                    # a force jump at the very end of the span (the end of the rise, where the
                    # load is removed) ends the run: it is not a lift-off inside the span
                    hit = 0
                for i in range(n):
                    y_new[i] = tmp[i]
                break
            t = t_new
            for i in range(n):
                y[i] = y_new[i]
                K[0, i] = K[6, i]
            for e in range(n_ev):
                g_old[e] = g_new[e]
        if status != dp.OK:
            break
        if hit < 0:
            status = dp.NO_PROGRESS + 1      # reached t_max without the end event: stalled cam
            break
        ph_t1[nph] = t_hit
        nph += 1
        short = short + 1 if t_hit - t_ph0 < 1e-13 else 0
        if short > 100:
            status = dp.NO_PROGRESS
            break
        t = t_hit
        if hit == 0:
            break
        if mode == CONTACT_MODE:                 # contact loss: the flank's force changed sign
            phi1, omega1 = y_new[0], y_new[1]
            contact_terms(n1, h1, c1, n2, h2, c2, p, phi1, omega1, flank, w1, w2, res)
            omega2, q = res[2], res[6]
            r = ev[nev]
            r[0], r[1], r[2], r[3], r[4], r[5], r[6] = t, phi1, LIFTOFF, flank, 0.0, 0.0, 0.0
            r[7], r[8], r[9], r[10], r[11], r[12], r[13] = omega1, omega1, omega2, omega2, res[1], np.nan, np.nan
            nev += 1
            mode, left, v_left = FREE_MODE, flank, 0.0
            continue
        phi1, omega1, q, omega2 = y_new[0], y_new[1], y_new[2], y_new[3]
        hit_flank = INNER if hit == 1 else OUTER
        free_terms(n1, h1, c1, n2, h2, c2, p, phi1, omega1, q, omega2, w1, w2, res)
        phi2, A2, d1_, dA2 = res[4], res[5], res[6], res[7]
        q = 0.0 if hit_flank == INNER else j / A2            # project onto the flank
        G1 = A2 * d1_ - dA2 * q
        interp(n2, h2, c2, phi2, w2)
        J2 = w2[0] * p[I_JT]
        approach = (A2 * omega2 - G1 * omega1) * hit_flank
        k = kres
        settle = False
        if min(-approach, -k * approach) < v_settle:
            a1, a2, _, _, _ = _impact(omega1, omega2, G1, A2, p[I_INVJ], J2, 0.0)
            contact_terms(n1, h1, c1, n2, h2, c2, p, phi1, a1, hit_flank, w1, w2, res)
            settle = hit_flank * res[5] > 0.0
            if settle:
                k = 0.0
        a1, a2, Pimp, vb, va = _impact(omega1, omega2, G1, A2, p[I_INVJ], J2, k)
        Jc = p[I_JCAM]
        r = ev[nev]
        r[0], r[1], r[2], r[3], r[4], r[5], r[6] = t, phi1, SETTLE if settle else REBOUND, hit_flank, vb, va, Pimp
        r[7], r[8], r[9], r[10], r[11] = omega1, a1, omega2, a2, phi2
        r[12] = 0.5 * Jc * omega1 * omega1 + 0.5 * J2 * omega2 * omega2
        r[13] = 0.5 * Jc * a1 * a1 + 0.5 * J2 * a2 * a2
        nev += 1
        omega1, omega2 = a1, a2
        if settle:
            mode, flank = CONTACT_MODE, hit_flank
        else:
            mode, left, v_left = FREE_MODE, hit_flank, va
    return (status, t, phi1, nst, nph, nev, nfev, st_t, st_h, st_y, st_Q, ph_mode, ph_flank, ph_t0, ph_t1,
            ph_first, ev)


STALLED = dp.NO_PROGRESS + 1
_EV_KEYS = ("time", "phi1", "kind", "flank", "v_before", "v_after", "percussion", "omega1_before",
            "omega1_after", "omega2_before", "omega2_after", "phi2", "energy_before", "energy_after")


def _params(P) -> np.ndarray:
    return np.array([P.phi20, P.jt, P.Jcam, P.inv_Jcam, 1.0 if P.const else 0.0, P.m0, P.m1, P.Fu, P.j, P.k])


def integrate(P, phi1_end: float, omega1_0: float, preset: dict, t_rise: float, start: tuple | None = None,
              stats: dict | None = None, t_start: float = 0.0, max_steps: int = MAX_STEPS):
    """Compiled twin of ``models.dynamics.rigid.integrate`` (same arguments and return value).

    Extra: ``start`` may also be ("contact", phi1, omega1, flank) to start on a flank at
    ``t_start`` (s) (models.dynamics.auto escalates from the kinematic level this way); ``stats`` receives
    nfev and n_steps, the cost measure of the benchmarks.
    """
    from models.dynamics.rigid import Phase

    rtol = float(preset["rtol"])
    max_step = float(preset["max_step"] * t_rise)
    t_max = t_start + 4.0 * phi1_end / max(omega1_0, 1e-9) + 1.0
    if start is None:
        smode, sflank, s = CONTACT_MODE, FREE, (0.0, float(omega1_0), 0.0, 0.0)
    elif start[0] == "contact":
        smode, sflank, s = CONTACT_MODE, int(start[3]), (float(start[1]), float(start[2]), 0.0, 0.0)
    else:
        smode, sflank, s = FREE_MODE, FREE, tuple(float(v) for v in start[1:5])
    # the tables are shared read-only arrays (models.mechanism.cam_tables.cached); numba would compile a
    # second specialisation for read-only arrays, so the loop gets writeable copies (~1 MB)
    rw = lambda a: np.require(a, dtype=np.float64, requirements=["C", "W"])  # noqa: E731
    out = run(rw(P.tab1.nodes), rw(P.tab1.inv_h), rw(P.tab1.coef), rw(P.tab2.nodes), rw(P.tab2.inv_h),
              rw(P.tab2.coef), _params(P), float(phi1_end), float(omega1_0), rtol, max_step,
              float(t_max), float(preset["v_settle"]), int(preset["max_events"]), int(max_steps),
              smode, sflank, s[0], s[1], s[2], s[3], float(t_start))
    (status, t, phi1, nst, nph, nev, nfev, st_t, st_h, st_y, st_Q, ph_mode, ph_flank, ph_t0, ph_t1,
     ph_first, ev) = out
    if stats is not None:
        stats["nfev"] = stats.get("nfev", 0) + int(nfev)
        stats["n_steps"] = stats.get("n_steps", 0) + int(nst)
    where = f"phi1 = {math.degrees(phi1):.3f} deg (t = {t:.6g} s)"
    if status == dp.TOO_MANY_EVENTS:
        raise SolverError(f"rigid model: more than {preset['max_events']} contact events before {where}: "
                          "the impacts do not settle; try another restitution k or accuracy preset")
    if status == STALLED:
        raise SolverError(f"rigid model: the cam did not reach phi1 = {math.degrees(phi1_end):.2f} deg "
                          f"within {t_max - t_start:.3g} s (motor stalled?)")
    if status == dp.NO_PROGRESS:
        raise SolverError(f"rigid model: stalled in zero-length phases at {where}")
    if status == dp.TOO_MANY_STEPS:
        raise SolverError(f"rigid model (compiled): the step cap of {max_steps} steps per run was reached at {where}")
    if status != dp.OK:
        raise SolverError(f"rigid model (compiled): {dp.STATUS_TEXT[status]} at {where}")
    phases = []
    for i in range(nph):
        a = ph_first[i]
        b = ph_first[i + 1] if i + 1 < nph else nst
        n = 2 if ph_mode[i] == CONTACT_MODE else 4
        run_ = dp.DenseRun(st_t[a:b], st_h[a:b], st_y[a:b, :n], st_Q[a:b, :n], float(ph_t1[i]))
        phases.append(Phase("contact" if ph_mode[i] == CONTACT_MODE else "free", int(ph_flank[i]),
                            float(ph_t0[i]), float(ph_t1[i]), run_))
    events = []
    for r in ev[:nev]:
        d = dict(zip(_EV_KEYS, (float(v) for v in r)))
        d["kind"], d["flank"] = int(r[2]), int(r[3])
        events.append(d)
    return phases, events
