"""The independent reference integrator: scipy ``solve_ivp`` (DOP853 by default), phase by phase,
over a model's compiled equations, the same hooks the compiled driver runs
(labtool.models.dynamics.kernels.dopri5: rhs, event, n_events, direction, state_size, transition).

Only the integration differs from ``dopri5.run``: scipy's method, step control and event location
(brentq on the dense output). An event's sign is also read at ``ctl.nsub`` points of every step
(scipy reads it at the step's ends only, so a crossing and its return within one step, a
micro-bounce, would be missed); a crossing found there before solve_ivp's own event is the phase's
real end. The returned tuple has ``dopri5.unpack``'s layout, so a model's wrapper reads both loops
alike.
"""
from __future__ import annotations

import numpy as np
from numba import typeof
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from labtool.common.errors import SolverError
from labtool.models.dynamics.kernels import dopri5 as dp


class ScipyRun:
    """A solve_ivp phase: ``.t`` its step times up to the phase's end, ``.sol(t)`` / ``__call__``
    its dense output (n_state, len(t))."""

    def __init__(self, steps: np.ndarray, dense, t_end: float):
        self.t = np.append(steps[steps < t_end], t_end)
        self._dense = dense

    def __call__(self, times):
        return self._dense(times)

    @property
    def sol(self):
        return self


def _entry(dispatcher, *example):
    """The compiled entry point of ``dispatcher`` for the types of ``example`` (compiled or loaded
    once): calls from Python then skip numba's type resolution, which costs ~10 us for a model
    struct (an array-heavy namedtuple) against ~0.5 us for the call itself. The callers below pass
    arguments of exactly these types (float64 C arrays, float, int)."""
    dispatcher(*example)
    return dispatcher.overloads[tuple(typeof(a) for a in example)].entry_point


class _Calls:
    """The model's hot hooks bound to its struct (their entry points, see ``_entry``)."""

    def __init__(self, eq, model, ph, n):
        y, out = np.zeros(n), np.zeros(n)
        self.model = model
        self.rhs = _entry(eq.rhs, model, ph, 0.0, y, out)
        self.event = _entry(eq.event, model, ph, 0, 0.0, y)


def _event_function(calls, eq, model, ph, which):
    event = calls.event

    def g(t, y):
        return event(model, ph, which, float(t), np.ascontiguousarray(y, dtype=float))
    g.terminal = True
    g.direction = eq.direction(model, ph, which)
    return g


def _hidden_crossing(calls, eq, model, ph, ne: int, sol, nsub: int):
    """(event, t) of the first crossing inside a step that solve_ivp did not see, or None."""
    ts = sol.t
    if nsub <= 1 or ts.size < 2:
        return None
    frac = np.arange(1, nsub + 1) / nsub
    tt = np.concatenate([[ts[0]], (ts[:-1, None] + np.diff(ts)[:, None] * frac).ravel()])
    tt[nsub::nsub] = ts[1:]                                  # the step ends exactly
    Y = np.ascontiguousarray(sol.sol(tt).T)
    best = None
    for which in range(ne):
        g = np.empty(tt.size)
        dp.event_many(model, ph, which, tt, Y, g)
        a, b = g[:-1], g[1:]
        up = eq.direction(model, ph, which) > 0
        cross = np.flatnonzero((a <= 0) & (b >= 0) if up else (a >= 0) & (b <= 0))
        if not cross.size:
            continue
        k = int(cross[0])
        if sol.status == 1 and k + 1 >= tt.size - 1:
            continue          # the last sub-interval ends at solve_ivp's own event: its root stands
        f = lambda t: calls.event(model, ph, which, float(t), np.ascontiguousarray(sol.sol(t), dtype=float))  # noqa: E731
        t_hit = tt[k + 1] if f(tt[k + 1]) == 0 else brentq(f, tt[k], tt[k + 1], xtol=1e-15,
                                                           rtol=4 * np.finfo(float).eps)
        if best is None or t_hit < best[1]:
            best = (which, float(t_hit))
    return best


def _first_event(calls, eq, model, ph, ne, sol, nsub):
    """(event, t) ending the phase: the earliest of solve_ivp's events and the hidden crossings;
    within TIE the lower index wins. None if the phase ran to its time bound."""
    found = [(which, float(te[0])) for which, te in enumerate(sol.t_events or []) if te.size]
    hidden = _hidden_crossing(calls, eq, model, ph, ne, sol, nsub)
    if hidden is not None:
        found.append(hidden)
    if not found:
        return None
    t_min = min(t for _, t in found)
    return min((w, t) for w, t in found if t - t_min <= dp.TIE * (1.0 + abs(t_min)))


def run(model, eq, ctl, ph0, y0, t0: float, method: str = "DOP853", name: str = "model"):
    """Integrate like ``dopri5.run`` with scipy; ``eq`` is the model's kernel module (its compiled
    hooks). Returns (status, t, y, phases, event rows, nfev, n_steps) as ``dopri5.unpack``."""
    ph = np.array(ph0, dtype=float)
    y = np.zeros(ctl.n_state)
    y[: len(y0)] = y0
    ev = np.full((64, dp.EV_WIDTH), np.nan)
    phases, t, nev, ntr, short, nfev, nst, status = [], float(t0), 0, 0, 0, 0, 0, dp.OK
    calls = _Calls(eq, model, ph, ctl.n_state)
    while True:
        if nev + dp.MAX_EVENTS_PER_PHASE > ev.shape[0]:
            ev = np.vstack([ev, np.full(ev.shape, np.nan)])
        frozen = ph.copy()
        n, ne = int(eq.state_size(model, frozen)), int(eq.n_events(model, frozen))
        out = np.empty(n)
        rhs = calls.rhs

        def fun(tt, yy):
            rhs(model, frozen, float(tt), np.ascontiguousarray(yy, dtype=float), out)
            return out.copy()

        sol = solve_ivp(fun, (t, ctl.t_bound), y[:n].copy(), method=method, rtol=ctl.rtol,
                        atol=ctl.atol[int(frozen[0]), :n], max_step=ctl.max_step[int(frozen[0])],
                        dense_output=True,
                        events=[_event_function(calls, eq, model, frozen, e) for e in range(ne)])
        nfev += sol.nfev
        nst += sol.t.size - 1
        if sol.status == -1:
            raise SolverError(f"{name}: scipy {method} failed at t = {sol.t[-1]:.6g} s: {sol.message}")
        hit = _first_event(calls, eq, model, frozen, ne, sol, ctl.nsub)
        if hit is None:
            phases.append(dp.Phase(frozen, t, float(sol.t[-1]), ScipyRun(sol.t, sol.sol, float(sol.t[-1]))))
            t = float(sol.t[-1])
            status = dp.OK if ctl.end_at_bound else dp.STALLED
            break
        which, t_hit = hit
        phases.append(dp.Phase(frozen, t, t_hit, ScipyRun(sol.t, sol.sol, t_hit)))
        short = short + 1 if t_hit - t < ctl.zeno_dt else 0
        y[:n] = sol.sol(t_hit)
        t = t_hit
        code, nev = eq.transition(model, ph, which, t, y, ev, nev)
        ntr += 1
        if code == dp.END:
            break
        if short >= ctl.zeno_n:
            status = dp.NO_PROGRESS
            break
        if ntr > ctl.max_events:
            status = dp.TOO_MANY_EVENTS
            break
    return status, t, y, phases, ev[:nev].copy(), nfev, nst
