"""Compiled integration of the elastic-contact model (paper eqs 12-19; ``models.dynamics.elastic``).

A drop-in for ``models.dynamics.elastic.integrate``: same arguments, same return value (segments as a list
of (phase, run) where ``run.t`` are the step times and ``run.sol(times)`` the dense output, and the
event dicts), so ``models.dynamics.elastic`` keeps its tables, sampling and indicators and only the loop
runs compiled. The equations are those of ``models.dynamics.elastic.rhs`` / ``normal_force`` (read them
there), transcribed:

    M(t) x'' = F(x, x') - drive(t)        x (m) relative displacement along the normal (+ exterior)
    interior flank (phase 0): F = Kc (-x)^(10/9) (1 - c x')^+,  exterior (phase 2):
    F = -Kc (x - j)^(10/9) (1 + c x')^+, flight (phase 1): F = 0; drive and M linear in t on the grid.

Phase changes are terminal events (x = 0, x = j) located on the dense output by bisection to
the resolution of the step fraction (2^-52), then the state restarts a hair inside the new phase,
exactly as the scipy loop does. Caps: ``max_steps`` accepted steps and ``max_segments`` phases per
run; reaching one ends in ``SolverError`` naming it (never a hang).
"""
from __future__ import annotations

import math

import numpy as np
from models.dynamics.jit import jit

from common.errors import SolverError
from models.dynamics.kernels import dopri5 as dp

INTERIOR, FLIGHT, EXTERIOR = 0, 1, 2
N_EXP = 10.0 / 9.0
NUDGE = 1e-13           # m, as models.dynamics.elastic.BOUNDARY_NUDGE
MAX_STEPS = 2_000_000       # accepted steps per run (memory ~100 B a step)
MAX_SEGMENTS = 1_000_000    # phases per run


@jit
def _interp_uniform(t, tg, yg):
    """np.interp on an increasing grid tg (nearly uniform: one guess, then a short walk)."""
    n = tg.size
    if t <= tg[0]:
        return yg[0]
    if t >= tg[n - 1]:
        return yg[n - 1]
    i = int((t - tg[0]) / (tg[n - 1] - tg[0]) * (n - 1))
    i = min(max(i, 0), n - 2)
    while i > 0 and t < tg[i]:
        i -= 1
    while i < n - 2 and t >= tg[i + 1]:
        i += 1
    w = (t - tg[i]) / (tg[i + 1] - tg[i])
    return yg[i] + w * (yg[i + 1] - yg[i])


@jit
def force(x, v, phase, kc, gap, damping):
    """Groove-on-follower normal force along +x (N); models.dynamics.elastic.normal_force."""
    if phase == INTERIOR:
        pen, rate, sign = -x, -v, 1.0
    elif phase == EXTERIOR:
        pen, rate, sign = x - gap, v, -1.0
    else:
        return 0.0
    if pen <= 0.0:
        return 0.0
    f = kc * pen ** N_EXP
    if damping > 0.0:
        f = max(f * (1.0 + damping * rate), 0.0)
    return sign * f


@jit
def rhs(t, y, phase, tg, drive, mg, kc, gap, damping, out):
    d = _interp_uniform(t, tg, drive)
    m = _interp_uniform(t, tg, mg)
    out[0] = y[1]
    out[1] = (force(y[0], y[1], phase, kc, gap, damping) - d) / m


@jit
def _event_value(which, y, gap):
    return y[0] if which == 0 else y[0] - gap


@jit
def _active(g0, g1, direction):
    up = g0 <= 0.0 and g1 >= 0.0
    down = g0 >= 0.0 and g1 <= 0.0
    return (up and direction > 0) or (down and direction < 0)


NSUB = 8    # sign checks per step (models.dynamics.elastic.EVENT_SUBSTEPS)


@jit
def _bisect(which, gap, y0, h, Q, lo, hi, g_lo, tmp):
    """Step fraction in (lo, hi] where the event changes sign, by bisection on the dense output."""
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        dp.dense_eval(y0, h, Q, mid, tmp)
        g = _event_value(which, tmp, gap)
        if (g_lo <= 0.0) == (g <= 0.0) and g != 0.0:
            lo, g_lo = mid, g
        else:
            hi = mid
    return hi


@jit
def _crossing(which, direction, gap, y0, h, Q, g0, g1, nsub, tmp):
    """First step fraction s in (0, 1] where the event changes sign in its direction, 2.0 if none.

    The sign is read at ``nsub`` points of the step's dense output, not at its two ends only: a
    brief separation that leaves the flank and comes back within one step (a micro-bounce) is an
    event too, not a contact phase with x outside the contact range.
    """
    s_prev, g_prev = 0.0, g0
    for k in range(1, nsub + 1):
        s = k / nsub
        if k == nsub:
            g = g1
        else:
            dp.dense_eval(y0, h, Q, s, tmp)
            g = _event_value(which, tmp, gap)
        if _active(g_prev, g, direction):
            return _bisect(which, gap, y0, h, Q, s_prev, s, g_prev, tmp)
        s_prev, g_prev = s, g
    return 2.0


@jit
def _first_step(t0, y0, f0, t_bound, max_step, rtol, atol, phase, tg, drive, mg, kc, gap, damping):
    """scipy's initial step selection (Hairer, Norsett & Wanner II.4), order 4."""
    n = y0.size
    scale = atol + np.abs(y0) * rtol
    d0 = dp.rms(y0, scale)
    d1 = dp.rms(f0, scale)
    h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
    h0 = min(h0, t_bound - t0)
    y1 = y0 + h0 * f0
    f1 = np.empty(n)
    rhs(t0 + h0, y1, phase, tg, drive, mg, kc, gap, damping, f1)
    d2 = dp.rms(f1 - f0, scale) / h0
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** 0.2
    return min(100.0 * h0, h1, t_bound - t0, max_step)


@jit
def run(tg, drive, mg, kc, gap, damping, t_end, x0, v0, phase0, rtol, atol, max_step,
        max_steps, max_segments, zeno_segments, zeno_dt, nudge, nsub):
    """The phase-by-phase loop. Returns (status, t_fail, n_steps, n_seg, nfev, step arrays,
    segment arrays, event arrays); see ``integrate`` for their layout."""
    cap = min(max_steps, 4096)
    st_t = np.empty(cap)
    st_h = np.empty(cap)
    st_y = np.empty((cap, 2))
    st_Q = np.empty((cap, 2, 4))
    scap = 256
    seg_phase = np.empty(scap, dtype=np.int64)
    seg_first = np.empty(scap, dtype=np.int64)
    seg_end = np.empty(scap)
    ev_t = np.empty(scap)
    ev_v = np.empty(scap)
    ev_from = np.empty(scap, dtype=np.int64)
    ev_to = np.empty(scap, dtype=np.int64)
    K = np.empty((7, 2))
    y = np.array([x0, v0])
    y_new = np.empty(2)
    tmp = np.empty(2)
    Q = np.empty((2, 4))
    t = 0.0
    phase = phase0
    nst, nseg, nev, nfev = 0, 0, 0, 0
    short = 0                       # consecutive phases shorter than zeno_dt (models.dynamics.elastic)
    while t < t_end:
        if short >= zeno_segments:
            return dp.NO_PROGRESS, t, nst, nseg, nev, nfev, st_t, st_h, st_y, st_Q, seg_phase, seg_first, seg_end, ev_t, ev_v, ev_from, ev_to
        if nseg >= max_segments:
            return dp.TOO_MANY_EVENTS, t, nst, nseg, nev, nfev, st_t, st_h, st_y, st_Q, seg_phase, seg_first, seg_end, ev_t, ev_v, ev_from, ev_to
        if nseg == scap:
            scap *= 2
            seg_phase = dp.grow(seg_phase, scap)
            seg_first = dp.grow(seg_first, scap)
            seg_end = dp.grow(seg_end, scap)
            ev_t = dp.grow(ev_t, scap)
            ev_v = dp.grow(ev_v, scap)
            ev_from = dp.grow(ev_from, scap)
            ev_to = dp.grow(ev_to, scap)
        seg_phase[nseg] = phase
        seg_first[nseg] = nst
        t_seg0 = t
        # events of this phase: (which, direction, next phase); which 0: x, 1: x - gap
        if phase == INTERIOR:
            ne, w0, d0, n0, w1, d1, n1 = 1, 0, 1.0, (FLIGHT if gap > 0 else EXTERIOR), 0, 0.0, 0
        elif phase == EXTERIOR:
            ne, w0, d0, n0, w1, d1, n1 = 1, 1, -1.0, (FLIGHT if gap > 0 else INTERIOR), 0, 0.0, 0
        else:
            ne, w0, d0, n0, w1, d1, n1 = 2, 0, -1.0, INTERIOR, 1, 1.0, EXTERIOR
        rhs(t, y, phase, tg, drive, mg, kc, gap, damping, K[0])
        nfev += 1
        h_abs = _first_step(t, y, K[0], t_end, max_step, rtol, atol, phase, tg, drive, mg, kc, gap, damping)
        nfev += 1
        g0a = _event_value(w0, y, gap)
        g0b = _event_value(w1, y, gap)
        hit = -1
        while t < t_end:
            if nst >= max_steps:
                return dp.TOO_MANY_STEPS, t, nst, nseg, nev, nfev, st_t, st_h, st_y, st_Q, seg_phase, seg_first, seg_end, ev_t, ev_v, ev_from, ev_to
            min_step = 10.0 * abs(np.nextafter(t, np.inf) - t)
            h_abs = min(max(h_abs, min_step), max_step)
            rejected = False
            while True:
                if h_abs < min_step:
                    return dp.STEP_TOO_SMALL, t, nst, nseg, nev, nfev, st_t, st_h, st_y, st_Q, seg_phase, seg_first, seg_end, ev_t, ev_v, ev_from, ev_to
                t_new = min(t + h_abs, t_end)
                h = t_new - t
                for s in range(1, 6):
                    dp.stage_state(y, h, K, dp.A[s], s, tmp)
                    rhs(t + dp.C[s] * h, tmp, phase, tg, drive, mg, kc, gap, damping, K[s])
                dp.stage_state(y, h, K, dp.B, 6, y_new)
                rhs(t_new, y_new, phase, tg, drive, mg, kc, gap, damping, K[6])
                nfev += 6
                err = dp.error_norm(K, h, y, y_new, rtol, atol)
                if not (np.isfinite(y_new[0]) and np.isfinite(y_new[1])) or not np.isfinite(err):
                    if h_abs <= min_step:
                        return dp.NOT_FINITE, t, nst, nseg, nev, nfev, st_t, st_h, st_y, st_Q, seg_phase, seg_first, seg_end, ev_t, ev_v, ev_from, ev_to
                    h_abs *= dp.MIN_FACTOR
                    rejected = True
                    continue
                f = dp.new_step_factor(err, rejected)
                if err < 1.0:
                    h_abs *= f
                    break
                h_abs *= f
                rejected = True
            dp.dense_coeffs(K, Q)
            if nst == cap:
                cap = min(2 * cap, max_steps)
                st_t = dp.grow(st_t, cap)
                st_h = dp.grow(st_h, cap)
                st_y = dp.grow(st_y, cap)
                st_Q = dp.grow(st_Q, cap)
            st_t[nst] = t
            st_h[nst] = h
            st_y[nst, 0] = y[0]
            st_y[nst, 1] = y[1]
            st_Q[nst] = Q
            nst += 1
            g1a = _event_value(w0, y_new, gap)
            g1b = _event_value(w1, y_new, gap) if ne == 2 else 0.0
            sa = _crossing(w0, d0, gap, y, h, Q, g0a, g1a, nsub, tmp)
            sb = _crossing(w1, d1, gap, y, h, Q, g0b, g1b, nsub, tmp) if ne == 2 else 2.0
            if sa <= 1.0 or sb <= 1.0:
                hit = 0 if sa <= sb else 1
                s_hit = sa if hit == 0 else sb
                t_hit = t + s_hit * h
                dp.dense_eval(y, h, Q, s_hit, tmp)
                seg_end[nseg] = t_hit
                nseg += 1
                short = short + 1 if t_hit - t_seg0 < zeno_dt else 0
                new_phase = n0 if hit == 0 else n1
                at_zero = (w0 if hit == 0 else w1) == 0
                ev_t[nev] = t_hit
                ev_v[nev] = tmp[1]
                ev_from[nev] = phase
                ev_to[nev] = new_phase
                nev += 1
                # restart a hair inside the new phase (models.dynamics.elastic._restart_position)
                eps = nudge if gap == 0.0 else min(nudge, 0.25 * gap)
                boundary = 0.0 if at_zero else gap
                if new_phase == INTERIOR:
                    inward = -1.0
                elif new_phase == EXTERIOR:
                    inward = 1.0
                else:
                    inward = 1.0 if at_zero else -1.0
                y[0] = boundary + inward * eps
                y[1] = tmp[1]
                t = t_hit
                phase = new_phase
                break
            t = t_new
            y[0] = y_new[0]
            y[1] = y_new[1]
            K[0, 0] = K[6, 0]
            K[0, 1] = K[6, 1]
            g0a, g0b = g1a, g1b
        if hit < 0:
            seg_end[nseg] = t
            nseg += 1
    return dp.OK, t, nst, nseg, nev, nfev, st_t, st_h, st_y, st_Q, seg_phase, seg_first, seg_end, ev_t, ev_v, ev_from, ev_to


_KIND = {(INTERIOR, FLIGHT): "leave_interior", (INTERIOR, EXTERIOR): "leave_interior",
         (EXTERIOR, FLIGHT): "leave_exterior", (EXTERIOR, INTERIOR): "leave_exterior",
         (FLIGHT, INTERIOR): "land_interior", (FLIGHT, EXTERIOR): "land_exterior"}
_NAMES = ("interior", "flight", "exterior")


def integrate(t_grid, drive_grid, m_grid, kc, gap, damping=0.0, t_end=None, y0=None,
              rtol=1e-8, atol=(1e-13, 1e-9), max_step=np.inf, method="RK45",
              max_steps=MAX_STEPS, max_segments=MAX_SEGMENTS, stats=None):
    """Compiled twin of ``models.dynamics.elastic.integrate`` (same arguments and return value).

    ``method`` is accepted for compatibility and must be RK45 (Dormand-Prince 5(4)). Limits: the
    model's chatter guard (ZENO_SEGMENTS consecutive phases shorter than ZENO_DT), ``max_steps``
    steps and ``max_segments`` phases per run. ``stats`` (dict, optional) receives nfev and
    n_steps: the cost measure of the benchmarks.
    """
    from models.dynamics import elastic

    if method != "RK45":
        raise ValueError("the compiled loop is Dormand-Prince 5(4) (RK45) only")
    zeno_n = int(getattr(elastic, "ZENO_SEGMENTS", 200))
    zeno_dt = float(getattr(elastic, "ZENO_DT", 1e-9))
    tg = np.ascontiguousarray(t_grid, dtype=float)
    drive_grid = np.ascontiguousarray(drive_grid, dtype=float)
    t_end = float(tg[-1] if t_end is None else t_end)
    if y0 is None:
        # the start of models.dynamics.elastic.integrate: static equilibrium; at rest with no load, against
        # the flank the first non-zero drive will load
        x0, v0, phase = elastic.initial_state(float(drive_grid[0]), kc, gap)
        nonzero = np.flatnonzero(drive_grid)
        if drive_grid[0] == 0 and nonzero.size:
            phase = INTERIOR if drive_grid[nonzero[0]] > 0 else EXTERIOR
            x0 = elastic._restart_position(phase == INTERIOR, phase, gap)
    else:
        x0, v0, phase = y0
    max_step = float(min(max_step, t_end)) if math.isfinite(max_step) else float(t_end)
    out = run(tg, drive_grid, np.ascontiguousarray(m_grid, dtype=float),
              float(kc), float(gap), float(damping), t_end, float(x0), float(v0), int(phase),
              float(rtol), np.asarray(atol, dtype=float), max_step, int(max_steps), int(max_segments),
              zeno_n, zeno_dt, float(getattr(elastic, "BOUNDARY_NUDGE", NUDGE)),
              int(getattr(elastic, "EVENT_SUBSTEPS", NSUB)))
    status, t_fail, nst, nseg, nev, nfev, st_t, st_h, st_y, st_Q, sph, sfirst, send, ev_t, ev_v, ev_from, ev_to = out
    if stats is not None:
        stats["nfev"] = stats.get("nfev", 0) + int(nfev)
        stats["n_steps"] = stats.get("n_steps", 0) + int(nst)
    if status == dp.NO_PROGRESS:
        raise SolverError(f"elastic model: {zeno_n} contact switches within {zeno_n * zeno_dt:.1g} s at "
                          f"t = {t_fail:.6g} s (endless chatter); add contact damping or check the scene")
    if status == dp.TOO_MANY_EVENTS:
        raise SolverError(f"elastic model (compiled): more than {max_segments} contact phases before "
                          f"t = {t_fail:.4g} s (the phase cap per run)")
    if status != dp.OK:
        raise SolverError(f"elastic model (compiled): {dp.STATUS_TEXT[status]} at t = {t_fail:.6g} s "
                          f"(limits: {max_steps} steps, {max_segments} phases per run)")
    segments = []
    for k in range(nseg):
        a = sfirst[k]
        b = sfirst[k + 1] if k + 1 < nseg else nst
        segments.append((int(sph[k]), dp.DenseRun(st_t[a:b], st_h[a:b], st_y[a:b], st_Q[a:b], float(send[k]))))
    events = [{"t": float(ev_t[i]), "kind": _KIND[(int(ev_from[i]), int(ev_to[i]))], "v": float(ev_v[i]),
               "from": _NAMES[int(ev_from[i])], "to": _NAMES[int(ev_to[i])]} for i in range(nev)]
    return segments, events
