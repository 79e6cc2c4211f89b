"""Compiled integration of the stand's twin (``labtool.models.dynamics.twin``): state, steps, events, samples.

The equations (read the physics, the sign conventions and the parameters in ``labtool.models.dynamics.twin``):

    state y = (phi1, omega1, q, omega2, u, du, I)
    phi1 (rad, wrapped to [0, 2 pi) with a revolution counter), omega1 (rad/s): cam + motor;
    q = phi2 - phi2_pitch(phi1) (rad): the follower's angle off the pitch curve; omega2 (rad/s);
    u (m), du (m/s): the follower's first bending mode, displacement of the modal mass at E along
    the tangent; I (N s): the contact force integrated since the current contact began.

    g = A2(phi1) q                      normal distance of C from the pitch curve (m; the interior
                                        flank at g = 0, the exterior one at g = j)
    g' = A2 omega2 - G1 omega1,  G1 = A2 psi' - A2' q
    N = hunt_crossley(g, g')            along the normal, > 0 = the interior flank pushes
                                        (labtool.models.dynamics.kernels.elastic_nb.flank_force: the one law)
    J' omega1' = M1(omega1, phi1) + Mc(phi1) - N G1       (drive "motor"; "input": omega1 imposed)
    J_r omega2' + 1/2 J_r' omega2^2 = Mg + ML + N A2 + Mf + DE (k_b u + c_b du)
    m_b (DE omega2' + du') = -(k_b u + c_b du)

with J_r = Jt J0(phi2) - m_b DE^2, M1 = s (W0 (1 + r sin phi1) - omega1) the motor's linear
characteristic (slope s, no-load speed W0, drive ripple r), Mf = -(T_f + r_f |N|) tanh(omega2/w_f)
the pivot friction. Every phi1 and phi2 function is read from the rigid model's Hermite tables
(value and derivative of the same cubic, so the contact forces derive exactly from a potential).

The integrator is Dormand-Prince 5(4) (``labtool.models.dynamics.kernels.dopri5``: the stages, scipy's
controller, the dense output), with absolute tolerances per component (phi1 and omega1 carry no
relative tolerance: the gap depends on phi1's absolute error). Contact phases change at events
(g = 0, g = j) located by bisection on the dense output read at NSUB points of each step, then the
state restarts a hair inside the new phase, as in the elastic model's loop.

Everything a run needs to continue is in arrays the caller keeps (``S`` scalars, ``Y`` state,
``K0`` first stage, ``Y0`` and ``Q`` the last step's dense output): the trajectory does not depend
on where the caller cuts its requests, so a stand can stream it block by block in bounded memory.
"""
from __future__ import annotations

import math

import numpy as np

from labtool.models.dynamics import events as ev_layout
from labtool.models.dynamics.jit import jit
from labtool.models.dynamics.kernels import dopri5 as dp
from labtool.models.dynamics.kernels.elastic_nb import flank_force as contact_force

INTERIOR, FLIGHT, EXTERIOR = 0, 1, 2
NY = 7           # state size; the last component (impulse) is not error-controlled
NERR = 6
NSUB = 8         # event sign checks per step
TWO_PI = 2.0 * math.pi

# parameter vector p
(P_PHI20, P_JT, P_JCAM, P_INPUT, P_W0, P_SLOPE, P_RIPPLE, P_FU, P_GAP, P_KC, P_DAMP, P_MB, P_KB,
 P_CB, P_DE, P_TF, P_RF, P_WF, P_WINDOW, P_NUDGE, P_MAXSTEP, P_ZENO_N, P_ZENO_DT, P_MAXSTEPS) = range(24)
NP = 24
# scalar state S
(S_T, S_H, S_PHASE, S_REV, S_ST0, S_SH, S_SEND, S_SREV, S_HAVE, S_CIDX, S_CT0, S_CQD0, S_NSTEP, S_NFEV,
 S_WRAPT, S_SHORT, S_FSAL, S_PHT0, S_NEV, S_SPHASE) = range(20)
NS = 20
# event columns
E_T, E_PHI1, E_KIND, E_SIDE, E_VREL, E_DW2, E_P, E_PERS = range(8)
NE = 8
# the event record's codes (labtool.models.dynamics.events), as the row's floats
KIND_SEPARATION, KIND_CONTACT = float(ev_layout.KIND_SEPARATION), float(ev_layout.KIND_CONTACT)
SIDE_INTERIOR, SIDE_EXTERIOR = float(ev_layout.SIDE_INTERIOR), float(ev_layout.SIDE_EXTERIOR)
# sample columns
(O_PHI1, O_W1, O_PHI2, O_W2, O_VE, O_U, O_N, O_G, O_EPS2, O_AET, O_PHASE) = range(11)
NO = 11
# status
OK, BUFFER_FULL = 0, 10
STALLED = 11


@jit
def _cell(nodes, x):
    """Cell index of x in a nearly uniform node array: a proportional guess, then a short walk."""
    n = nodes.size
    if x <= nodes[0]:
        return 0
    if x >= nodes[n - 1]:
        return n - 2
    i = int((x - nodes[0]) / (nodes[n - 1] - nodes[0]) * (n - 1))
    i = min(max(i, 0), n - 2)
    while i > 0 and x < nodes[i]:
        i -= 1
    while i < n - 2 and x >= nodes[i + 1]:
        i += 1
    return i


@jit
def _val(coef, i, c, t):
    return coef[i, c, 0] + t * (coef[i, c, 1] + t * (coef[i, c, 2] + t * coef[i, c, 3]))


@jit
def _der(coef, i, c, t, inv_h):
    return (coef[i, c, 1] + t * (2.0 * coef[i, c, 2] + 3.0 * t * coef[i, c, 3])) * inv_h


@jit
def cam_eval(nodes, inv_h, coef, phi1, out):
    """out = (psi, psi', A2, A2', Mc, direction) at phi1. ``coef`` (ncells, 4, 4) holds the rigid
    model's cam-table cubics of psi, A2, Mc and the direction (``compact_cam``); psi' and A2' are
    the derivatives of the same cubics as psi and A2."""
    i = _cell(nodes, phi1)
    t = (phi1 - nodes[i]) * inv_h[i]
    out[0] = _val(coef, i, 0, t)
    out[1] = _der(coef, i, 0, t, inv_h[i])
    out[2] = _val(coef, i, 1, t)
    out[3] = _der(coef, i, 1, t, inv_h[i])
    out[4] = _val(coef, i, 2, t)
    out[5] = _val(coef, i, 3, t)


@jit
def follower_eval(nodes, inv_h, coef, phi2, out):
    """out = (J0, dJ0/dphi2, M_gravity, M_load per N) at phi2: the rigid model's follower table
    at Jt = 1, ``coef`` (ncells, 4, 4) cell-major (``compact_follower``)."""
    i = _cell(nodes, phi2)
    t = (phi2 - nodes[i]) * inv_h[i]
    out[0] = _val(coef, i, 0, t)
    out[1] = _der(coef, i, 0, t, inv_h[i])
    out[2] = _val(coef, i, 2, t)
    out[3] = _val(coef, i, 3, t)


def compact_cam(table):
    """(nodes, inv_h, coef) of a rigid-model cam Table with its psi, A2, Mc and direction columns
    cell-major (ncells, 4, 4): one cache line run per read."""
    coef = np.ascontiguousarray(np.asarray(table.coef)[[0, 3, 6, 7]].transpose(1, 0, 2))
    return np.ascontiguousarray(table.nodes), np.ascontiguousarray(table.inv_h), coef


def compact_follower(table):
    """(nodes, inv_h, coef) of a rigid-model follower Table, cell-major (ncells, 4, 4)."""
    coef = np.ascontiguousarray(np.asarray(table.coef).transpose(1, 0, 2))
    return np.ascontiguousarray(table.nodes), np.ascontiguousarray(table.inv_h), coef


@jit
def rhs(t, y, phase, cn, ch, cc, fn, fh, fc, p, out, aux, cam, fol):
    """dy/dt into ``out``; ``aux`` receives (N, g, g', phi2, eps1, eps2, A2, q', aE_t) in SI;
    ``cam`` (6) and ``fol`` (4) are the scratch of the table reads."""
    cam_eval(cn, ch, cc, y[0], cam)
    psi, dpsi, A2, dA2, Mc, dirn = cam[0], cam[1], cam[2], cam[3], cam[4], cam[5]
    w1, q, w2, u, du = y[1], y[2], y[3], y[4], y[5]
    phi2 = p[P_PHI20] + psi + q
    follower_eval(fn, fh, fc, phi2, fol)
    G1 = A2 * dpsi - dA2 * q
    g = A2 * q
    gd = A2 * w2 - G1 * w1
    N = contact_force(phase, g, gd, p[P_KC], p[P_GAP], p[P_DAMP])
    if p[P_INPUT] > 0.0:
        W = p[P_W0]
        eps1 = p[P_RIPPLE] * W * W * math.cos(W * t)
    else:
        M1 = p[P_SLOPE] * (p[P_W0] * (1.0 + p[P_RIPPLE] * math.sin(y[0])) - w1)
        eps1 = (M1 + Mc - N * G1) / p[P_JCAM]
    jt = p[P_JT]
    mb, DE = p[P_MB], p[P_DE]
    Jr = jt * fol[0] - mb * DE * DE
    fb = p[P_KB] * u + p[P_CB] * du if mb > 0.0 else 0.0
    fric = -(p[P_TF] + p[P_RF] * abs(N)) * math.tanh(w2 / p[P_WF]) if p[P_WF] > 0.0 else 0.0
    eps2 = (fol[2] + p[P_FU] * dirn * fol[3] + N * A2 + fric + DE * fb - 0.5 * jt * fol[1] * w2 * w2) / Jr
    ddu = -fb / mb - DE * eps2 if mb > 0.0 else 0.0
    out[0] = w1
    out[1] = eps1
    out[2] = w2 - dpsi * w1
    out[3] = eps2
    out[4] = du
    out[5] = ddu
    out[6] = N
    aux[0] = N
    aux[1] = g
    aux[2] = gd
    aux[3] = phi2
    aux[4] = eps1
    aux[5] = eps2
    aux[6] = A2
    aux[7] = w2 - dpsi * w1
    aux[8] = DE * eps2 + ddu     # sensor_point.acceleration_at_E's aE_t plus the mode's u'': compiled loop


@jit
def _gap_of(y, cn, ch, cc, cam):
    cam_eval(cn, ch, cc, y[0], cam)
    return cam[2] * y[2]


@jit
def _error_norm(K, h, y, y_new, atol, rtol):
    acc = 0.0
    for i in range(NERR):
        e = 0.0
        for j in range(7):
            e += dp.E[j] * K[j, i]
        sc = atol[i] + rtol[i] * max(abs(y[i]), abs(y_new[i]))
        r = h * e / sc
        acc += r * r
    return math.sqrt(acc / NERR)


@jit
def _dense_q(y0, h, Q, s):
    """q (component 2) of the dense output at step fraction s."""
    return y0[2] + h * s * (Q[2, 0] + s * (Q[2, 1] + s * (Q[2, 2] + s * Q[2, 3])))


@jit
def _crossing(target, direction, y0, h, Q, g0, g1, a2_0, a2_1, cn, ch, cc, tmp, cam):
    """First step fraction in (0, 1] where g - target changes sign in ``direction``; 2.0 if none.

    The sign is read at NSUB points of the dense output (with A2 > 0 interpolated linearly over
    the step: it moves by ~1e-5 of itself in a step), then the crossing is bisected to 2^-52 on
    the exact g = A2(phi1) q.
    """
    s_prev, v_prev = 0.0, g0 - target
    for k in range(1, NSUB + 1):
        s = k / NSUB
        if k == NSUB:
            v = g1 - target
        else:
            v = (a2_0 + s * (a2_1 - a2_0)) * _dense_q(y0, h, Q, s) - target
        up = v_prev <= 0.0 and v >= 0.0
        down = v_prev >= 0.0 and v <= 0.0
        if (up and direction > 0) or (down and direction < 0):
            lo, hi, v_lo = s_prev, s, v_prev
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                if mid <= lo or mid >= hi:
                    break
                dp.dense_eval(y0, h, Q, mid, tmp)
                vm = _gap_of(tmp, cn, ch, cc, cam) - target
                if (v_lo <= 0.0) == (vm <= 0.0) and vm != 0.0:
                    lo, v_lo = mid, vm
                else:
                    hi = mid
            return hi
        s_prev, v_prev = s, v
    return 2.0


@jit
def _phase_events(phase, gap):
    """(n, target0, dir0, next0, target1, dir1, next1): the contact boundaries of a phase."""
    if phase == INTERIOR:
        return 1, 0.0, 1.0, (FLIGHT if gap > 0.0 else EXTERIOR), 0.0, 0.0, 0
    if phase == EXTERIOR:
        return 1, gap, -1.0, (FLIGHT if gap > 0.0 else INTERIOR), 0.0, 0.0, 0
    return 2, 0.0, -1.0, INTERIOR, gap, 1.0, EXTERIOR


@jit
def _push_event(ev, S, t, phi1u, kind, side, vrel, dw2, P, pers):
    n = int(S[S_NEV])
    ev[n, E_T] = t
    ev[n, E_PHI1] = phi1u
    ev[n, E_KIND] = kind
    ev[n, E_SIDE] = side
    ev[n, E_VREL] = vrel
    ev[n, E_DW2] = dw2
    ev[n, E_P] = P
    ev[n, E_PERS] = pers
    S[S_NEV] = n + 1
    return n


@jit
def _finalize_contact(ev, S, P, qd, t_end, window):
    """Close the pending contact record: impulse (>= 0) and change of q' over the contact or its
    first ``window`` seconds, persistent if it lasted the window."""
    k = int(S[S_CIDX])
    if k >= 0:
        ev[k, E_P] = abs(P)
        ev[k, E_DW2] = qd - S[S_CQD0]
        ev[k, E_PERS] = 1.0 if t_end - S[S_CT0] >= window else 0.0
        S[S_CIDX] = -1.0


def new_workspace():
    """Scratch arrays of one run: the stages K (7, NY), the dense coefficients Qs, and rows for
    trial states, rhs outputs and table reads (``take_step``, ``advance``)."""
    return np.empty((7, NY)), np.empty((NY, 4)), np.empty((4, 19))


@jit
def take_step(cn, ch, cc, fn, fh, fc, p, atol, rtol, S, Y, K0, Y0, Q, ev, K, Qs, wk):
    """One accepted step from (S[S_T], Y), ended early at a contact event. Returns a status."""
    tmp = wk[0, :NY]
    y_new = wk[1, :NY]
    aux = wk[2]
    cam = wk[3, :6]
    fol = wk[3, 6:10]
    phase = int(S[S_PHASE])
    t = S[S_T]
    if S[S_FSAL] == 0.0:
        rhs(t, Y, phase, cn, ch, cc, fn, fh, fc, p, K0, aux, cam, fol)
        S[S_NFEV] += 1
        S[S_FSAL] = 1.0
    for i in range(NY):
        K[0, i] = K0[i]
    max_step = p[P_MAXSTEP]
    h_abs = S[S_H]
    if h_abs <= 0.0:
        h_abs = max_step
    min_step = 10.0 * abs(np.nextafter(t, np.inf) - t)
    h_abs = min(max(h_abs, min_step), max_step)
    rejected = False
    while True:
        if h_abs < min_step:
            return dp.STEP_TOO_SMALL
        h = h_abs
        for s in range(1, 6):
            dp.stage_state(Y, h, K, dp.A[s], s, tmp)
            rhs(t + dp.C[s] * h, tmp, phase, cn, ch, cc, fn, fh, fc, p, K[s], aux, cam, fol)
        dp.stage_state(Y, h, K, dp.B, 6, y_new)
        rhs(t + h, y_new, phase, cn, ch, cc, fn, fh, fc, p, K[6], aux, cam, fol)
        S[S_NFEV] += 6
        err = _error_norm(K, h, Y, y_new, atol, rtol)
        finite = np.isfinite(err)
        for i in range(NY):
            finite = finite and np.isfinite(y_new[i])
        if not finite:
            if h_abs <= min_step:
                return dp.NOT_FINITE
            h_abs *= dp.MIN_FACTOR
            rejected = True
            continue
        f = dp.new_step_factor(err, rejected)
        if err < 1.0:
            S[S_H] = h_abs * f
            break
        h_abs *= f
        rejected = True
    if y_new[1] <= 0.0:
        return STALLED
    dp.dense_coeffs(K, Qs)
    for i in range(NY):
        Y0[i] = Y[i]
        for c in range(4):
            Q[i, c] = Qs[i, c]
    S[S_ST0] = t
    S[S_SH] = h
    S[S_SREV] = S[S_REV]
    S[S_SPHASE] = phase
    S[S_HAVE] = 1.0
    S[S_NSTEP] += 1
    # contact boundaries of this phase inside the step
    gap = p[P_GAP]
    ne, tg0, d0, n0, tg1, d1, n1 = _phase_events(phase, gap)
    g_start = _gap_of(Y, cn, ch, cc, cam)
    a2_0 = cam[2]
    g_end = _gap_of(y_new, cn, ch, cc, cam)
    a2_1 = cam[2]
    sa = _crossing(tg0, d0, Y, h, Q, g_start, g_end, a2_0, a2_1, cn, ch, cc, tmp, cam)
    sb = _crossing(tg1, d1, Y, h, Q, g_start, g_end, a2_0, a2_1, cn, ch, cc, tmp, cam) if ne == 2 else 2.0
    hit = sa <= 1.0 or sb <= 1.0
    s_end = min(sa, sb) if hit else 1.0
    t_end = t + s_end * h
    S[S_SEND] = t_end
    window = p[P_WINDOW]
    # a pending contact that lasts the window is persistent: close its record at the window's end
    if S[S_CIDX] >= 0.0 and S[S_CT0] + window <= t_end:
        t_w = max(S[S_CT0] + window, t)
        dp.dense_eval(Y0, h, Q, (t_w - t) / h, tmp)
        rhs(t_w, tmp, phase, cn, ch, cc, fn, fh, fc, p, K[1], aux, cam, fol)
        S[S_NFEV] += 1
        _finalize_contact(ev, S, tmp[6], aux[7], t_w, window)
    if hit:
        first = 0 if sa <= sb else 1
        new_phase = n0 if first == 0 else n1
        boundary = tg0 if first == 0 else tg1
        dp.dense_eval(Y0, h, Q, s_end, tmp)
        rhs(t_end, tmp, phase, cn, ch, cc, fn, fh, fc, p, K[1], aux, cam, fol)
        S[S_NFEV] += 1
        gd, qd, A2 = aux[2], aux[7], aux[6]
        phi1u = S[S_SREV] * TWO_PI + tmp[0]
        if phase != FLIGHT:                   # a contact ends: separation (domega2 0 for a lift-off)
            _finalize_contact(ev, S, tmp[6], qd, t_end, window)
            side = SIDE_INTERIOR if phase == INTERIOR else SIDE_EXTERIOR
            pers = 1.0 if t_end - S[S_CT0] >= window else 0.0
            _push_event(ev, S, t_end, phi1u, KIND_SEPARATION, side, abs(gd), 0.0 if pers > 0.0 else np.nan, np.nan, pers)
        if new_phase != FLIGHT:               # a contact begins (with j = 0 a change of flank: no landing row)
            if phase == FLIGHT:
                side = SIDE_INTERIOR if new_phase == INTERIOR else SIDE_EXTERIOR
                S[S_CIDX] = _push_event(ev, S, t_end, phi1u, KIND_CONTACT, side, abs(gd), np.nan, np.nan, 0.0)
            S[S_CT0] = t_end
            S[S_CQD0] = qd
            tmp[6] = 0.0
        # restart a hair inside the new phase (labtool.models.dynamics.elastic._restart_position)
        eps = p[P_NUDGE] if gap == 0.0 else min(p[P_NUDGE], 0.25 * gap)
        if new_phase == INTERIOR:
            inward = -1.0
        elif new_phase == EXTERIOR:
            inward = 1.0
        else:
            inward = 1.0 if boundary == 0.0 else -1.0
        tmp[2] = (boundary + inward * eps) / A2
        S[S_SHORT] = S[S_SHORT] + 1.0 if t_end - S[S_PHT0] < p[P_ZENO_DT] else 0.0
        S[S_PHT0] = t_end
        for i in range(NY):
            Y[i] = tmp[i]
        S[S_PHASE] = new_phase
        S[S_FSAL] = 0.0
    else:
        for i in range(NY):
            Y[i] = y_new[i]
            K0[i] = K[6, i]
    S[S_T] = t_end
    # the cam completes a revolution: wrap phi1, remember when (bisection on the dense output)
    if Y[0] >= TWO_PI:
        lo, hi = 0.0, s_end
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if mid <= lo or mid >= hi:
                break
            dp.dense_eval(Y0, h, Q, mid, tmp)
            if tmp[0] < TWO_PI:
                lo = mid
            else:
                hi = mid
        S[S_WRAPT] = t + hi * h
        Y[0] -= TWO_PI
        S[S_REV] += 1.0
    if hit and S[S_SHORT] >= p[P_ZENO_N]:
        return dp.NO_PROGRESS
    return OK


@jit
def _sample(cn, ch, cc, fn, fh, fc, p, S, Y0, Q, t, accel, row, tmp, dy, aux, cam, fol):
    """One output row at time t inside the last step (in its phase)."""
    h = S[S_SH]
    s = (t - S[S_ST0]) / h if h > 0.0 else 0.0
    dp.dense_eval(Y0, h, Q, s, tmp)
    phase = int(S[S_SPHASE])
    cam_eval(cn, ch, cc, tmp[0], cam)
    row[O_PHI1] = S[S_SREV] * TWO_PI + tmp[0]
    row[O_W1] = tmp[1]
    row[O_PHI2] = p[P_PHI20] + cam[0] + tmp[2]
    row[O_W2] = tmp[3]
    row[O_VE] = p[P_DE] * tmp[3] + tmp[5]
    row[O_U] = tmp[4]
    row[O_G] = cam[2] * tmp[2]
    if accel:
        rhs(t, tmp, phase, cn, ch, cc, fn, fh, fc, p, dy, aux, cam, fol)
        row[O_N] = aux[0]
        row[O_EPS2] = aux[5]
        row[O_AET] = aux[8]
    else:
        row[O_N] = np.nan
        row[O_EPS2] = np.nan
        row[O_AET] = np.nan
    row[O_PHASE] = phase


@jit
def advance(cn, ch, cc, fn, fh, fc, p, atol, rtol, S, Y, K0, Y0, Q, ev, K, Qs, wk, times, out, accel):
    """Sample the trajectory at ``times`` (kernel time, s, non-decreasing, >= the last request),
    integrating as far as they need. Returns (status, rows filled). BUFFER_FULL: the event buffer
    is nearly full; drain it and call again with the remaining times."""
    tmp = wk[0, :NY]
    dy = wk[1, :NY]
    aux = wk[2, :9]
    cam = wk[2, 9:15]
    fol = wk[2, 15:19]
    row = wk[3, :NO]
    cap = ev.shape[0]
    n = times.size
    i = 0
    while i < n:
        tt = times[i]
        if S[S_HAVE] > 0.0 and tt <= S[S_SEND]:
            _sample(cn, ch, cc, fn, fh, fc, p, S, Y0, Q, tt, accel, row, tmp, dy, aux, cam, fol)
            for c in range(NO):
                out[i, c] = row[c]
            i += 1
            continue
        if S[S_NEV] >= cap - 4:
            return BUFFER_FULL, i
        if S[S_NSTEP] >= p[P_MAXSTEPS]:
            return dp.TOO_MANY_STEPS, i
        status = take_step(cn, ch, cc, fn, fh, fc, p, atol, rtol, S, Y, K0, Y0, Q, ev, K, Qs, wk)
        if status != OK:
            return status, i
    return OK, i


@jit
def run_until_rev(cn, ch, cc, fn, fh, fc, p, atol, rtol, S, Y, K0, Y0, Q, ev, K, Qs, wk, rev):
    """Integrate until the revolution counter reaches ``rev`` (the warm-up). Returns a status."""
    cap = ev.shape[0]
    while S[S_REV] < rev:
        if S[S_NEV] >= cap - 4:
            return BUFFER_FULL
        if S[S_NSTEP] >= p[P_MAXSTEPS]:
            return dp.TOO_MANY_STEPS
        status = take_step(cn, ch, cc, fn, fh, fc, p, atol, rtol, S, Y, K0, Y0, Q, ev, K, Qs, wk)
        if status != OK:
            return status
    return OK
