"""The one compiled Dormand-Prince 5(4) driver of every dynamic model (numba, ``jit``).

The method, step-size controller, first step and dense output (4th order, Shampine's
coefficients) are scipy ``RK45``'s, so the compiled loop and a scipy run of the same equations
differ only in the language; the independent reference is scipy's DOP853 (labtool.models.dynamics.reference).

A model is a ``namedtuple`` of its tables and parameters (the *model struct*) plus six hooks,
registered once with ``register(ModelClass, ...)`` (numba overloads dispatched on the struct's
type, so this driver imports no model and every model shares it):

    rhs(model, ph, t, y, out)                 dy/dt of the phase ``ph`` into ``out``
    event(model, ph, which, t, y) -> g        the phase's event functions, which = 0 .. n - 1
    n_events(model, ph) -> n                  how many the phase has
    direction(model, ph, which) -> +1 | -1    the sign change that fires event ``which``
    state_size(model, ph) -> n                length of the state in this phase (<= Controls.n_state)
    transition(model, ph, which, t, y, ev, nev) -> (code, nev)
                                              what the event does: writes its rows of the event
                                              record into ``ev`` (EV_WIDTH columns,
                                              labtool.models.dynamics.events layout), updates ``ph`` and the
                                              state ``y`` in place; code END ends the run

``ph`` is the phase: a float array of PHASE_WIDTH numbers whose layout the model defines (entry 0
is the mode, also the row of Controls.atol). ``run(model, ctl, ph0, y0, t0)`` integrates phase by
phase: within a phase a smooth right-hand side; an event's sign is read at ``ctl.nsub`` points of
every step's dense output (not at the step's ends only: a micro-bounce inside one step is an event;
for an event that is a state component minus a constant, at points between which no sign change
is possible, and at least every min(max_step) / nsub s) and located by bisection to the resolution
of the step fraction; the earliest event wins (ties within 4 eps of time go to the lower index).
Limits: ``max_steps`` steps, ``max_events`` transitions, ``zeno_n`` consecutive phases shorter than
``zeno_dt`` s (endless switching); each ends the run with its status code, which the model's
wrapper turns into a SolverError.

    K[0] = f(t, y)   (FSAL: the previous step's K[6])
    K[s] = f(t + C[s] h, y + h * sum_j A[s, j] K[j])        s = 1..5
    y_new = y + h * sum_j B[j] K[j];  K[6] = f(t + h, y_new);  err = RMS(h E.K / scale) < 1 accepts
    dense: Q = K.T @ P; y(t + s h) = y + h * (Q[:, 0] s + Q[:, 1] s^2 + Q[:, 2] s^3 + Q[:, 3] s^4)

Time in s, states in the model's units; tolerances as in scipy (scale = atol + rtol * |y|).
"""
from __future__ import annotations

import functools
import math
from collections import namedtuple

import numpy as np
from numba import types
from numba.extending import overload as _overload

from labtool.models.dynamics.jit import jit, kernel

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
TIE = 8.9e-16          # events closer than TIE * (1 + |t|) s are simultaneous: the lower index wins

PHASE_WIDTH = 6        # numbers describing a phase (the model's layout; [0] = mode)
EV_WIDTH = 20          # columns of an event row (labtool.models.dynamics.events: 8 shared, up to 12 the model's own)
MAX_EVENTS_PER_PHASE = 4
CONTINUE, END = 0, 1   # transition codes

# status codes of ``run`` (the model wrappers turn them into SolverError)
OK, TOO_MANY_STEPS, TOO_MANY_EVENTS, STEP_TOO_SMALL, NOT_FINITE, NO_PROGRESS, STALLED = range(7)
STATUS_TEXT = {
    TOO_MANY_STEPS: "the step cap was reached",
    TOO_MANY_EVENTS: "the event cap was reached",
    STEP_TOO_SMALL: "the step size fell below the floating-point resolution of time",
    NOT_FINITE: "the state became non-finite (NaN or infinity)",
    NO_PROGRESS: "the integration stalled in zero-length phases",
    STALLED: "the end of the run was not reached before the time bound",
}

Controls = namedtuple("Controls", [
    "rtol",          # relative tolerance
    "atol",          # absolute tolerances, array (modes, n_state): row ph[0]
    "max_step",      # s, array (modes,): the largest step of a phase in mode ph[0]
    "t_bound",       # s, the integration never goes past it
    "end_at_bound",  # reaching t_bound ends the run (True) or means it stalled (False)
    "max_steps",     # accepted steps per run
    "max_events",    # transitions per run
    "nsub",          # event sign checks per step
    "zeno_n",        # this many consecutive phases ...
    "zeno_dt",       # ... each shorter than this (s) is endless switching
    "n_state",       # largest state size of the model
])


# ------------------------------------------------------------------ the model hooks (overloaded)

def rhs(model, ph, t, y, out):
    raise NotImplementedError("a model registers its hooks with labtool.models.dynamics.kernels.dopri5.register")


def event(model, ph, which, t, y):
    raise NotImplementedError


def n_events(model, ph):
    raise NotImplementedError


def direction(model, ph, which):
    raise NotImplementedError


def state_size(model, ph):
    raise NotImplementedError


def transition(model, ph, which, t, y, ev, nev):
    raise NotImplementedError


def event_offset(model, ph, which):
    """The state component c when event ``which`` is y[c] minus a constant, else -1: then the
    driver skips its sub-step sign checks in a step whose dense output cannot move y[c] by as much
    as the event's distance from zero (an exact bound: no event missed)."""
    raise NotImplementedError


@kernel
def _no_offset(model, ph, which):
    return -1


def register(model_class, rhs_fn, event_fn, n_events_fn, direction_fn, state_size_fn, transition_fn,
             event_offset_fn=None):
    """Make ``model_class`` (a namedtuple class) drivable by ``run``: its structs dispatch the hooks
    above to the model's functions (``jit`` functions with the hooks' parameter names; their Python
    source is compiled in place of the hook, so a hook costs no extra call). ``event_offset_fn``
    (optional): see ``event_offset``."""

    def ours(model):
        return isinstance(model, types.BaseNamedTuple) and model.instance_class is model_class

    # the hooks called at every step allocate nothing: compiled without reference counting
    # (labtool.models.dynamics.jit.kernel); a transition (once an event) may
    overload = functools.partial(_overload, jit_options={"_nrt": False})

    @overload(rhs)
    def _rhs(model, ph, t, y, out):
        if ours(model):
            return rhs_fn.py_func

    @overload(event)
    def _event(model, ph, which, t, y):
        if ours(model):
            return event_fn.py_func

    @overload(n_events)
    def _n_events(model, ph):
        if ours(model):
            return n_events_fn.py_func

    @overload(direction)
    def _direction(model, ph, which):
        if ours(model):
            return direction_fn.py_func

    @overload(state_size)
    def _state_size(model, ph):
        if ours(model):
            return state_size_fn.py_func

    @_overload(transition)
    def _transition(model, ph, which, t, y, ev, nev):
        if ours(model):
            return transition_fn.py_func

    @overload(event_offset)
    def _event_offset(model, ph, which):
        if ours(model):
            return event_offset_fn.py_func if event_offset_fn is not None else _no_offset.py_func


# ------------------------------------------------------------------ Dormand-Prince pieces
#
# The pieces called at every step are inlined into their caller by numba (inline="always"): numba
# calls another compiled function through a pointer, with every array argument (and every array
# inside a struct) spread into seven to nine machine words, and LLVM does not inline across
# them. Inlining these generic pieces takes the elastic loop from ~0.55 to ~0.42 ms (Table 1 run
# 1). The model hooks are not inlined: numba's inlining of an ``overload`` gives
# another 10 % but warns of broken IR assumptions (numba issues 7802, 9489), and a result is not
# worth that risk.

@kernel(inline="always")
def stage_state(y, h, K, coeffs, n_stages, out):
    """out = y + h * sum_{j < n_stages} coeffs[j] K[j]."""
    for i in range(y.size):
        acc = 0.0
        for j in range(n_stages):
            acc += coeffs[j] * K[j, i]
        out[i] = y[i] + h * acc


@kernel(inline="always")
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


@kernel(inline="always")
def dense_coeffs(K, out):
    """out (n, 4) = K.T @ P: the dense-output polynomial of the step just taken."""
    n = out.shape[0]
    for i in range(n):
        for c in range(4):
            acc = 0.0
            for j in range(7):
                acc += K[j, i] * P[j, c]
            out[i, c] = acc


@kernel(inline="always")
def dense_eval(y0, h, Q, s, out):
    """out = y(t0 + s h) from the step's start y0 and coefficients Q (s in [0, 1])."""
    for i in range(y0.size):
        out[i] = y0[i] + h * s * (Q[i, 0] + s * (Q[i, 1] + s * (Q[i, 2] + s * Q[i, 3])))


@kernel
def new_step_factor(err, rejected):
    """Step-size factor after a step with error norm ``err`` (scipy's controller).

    err^(-1/5) as exp(-ln(err) / 5): libm's pow with that exponent took ~40 ns a call, ~5 % of the
    elastic loop (one call an attempt); exp and log agree with it to a few ulps."""
    if err < 1.0:
        if err == 0.0:
            f = MAX_FACTOR
        else:
            f = min(MAX_FACTOR, SAFETY * math.exp(ERROR_EXPONENT * math.log(err)))
        if rejected:
            f = min(1.0, f)
        return f
    return max(MIN_FACTOR, SAFETY * math.exp(ERROR_EXPONENT * math.log(err)))


@jit(internal=True)
def grow(a, n_new):
    """A copy of ``a`` (C-contiguous) with its first axis enlarged to n_new (the stores double as
    they fill); the new rows are zero. Copied element by element over the flat arrays: a slice
    assignment compiles numba's broadcasting checks and their error message (~2 s of the first
    compile, four array types, for a copy that happens once in a long run)."""
    b = np.zeros((n_new,) + a.shape[1:], dtype=a.dtype)
    fa, fb = a.ravel(), b.ravel()
    for i in range(fa.size):
        fb[i] = fa[i]
    return b


@kernel(internal=True)
def rms(v, atol, y0, rtol):
    """RMS of v / scale, scale = atol + |y0| rtol (scipy's, element by element: no array made)."""
    acc = 0.0
    for i in range(v.size):
        r = v[i] / (atol[i] + abs(y0[i]) * rtol)
        acc += r * r
    return np.sqrt(acc / v.size)


@kernel(internal=True)
def first_step(model, ph, t0, y0, f0, t_bound, max_step, rtol, atol, y1, f1):
    """scipy's initial step (Hairer, Norsett & Wanner II.4, order 4); y1, f1 are work arrays."""
    d0 = rms(y0, atol, y0, rtol)
    d1 = rms(f0, atol, y0, rtol)
    h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
    h0 = min(h0, t_bound - t0)
    for i in range(y0.size):
        y1[i] = y0[i] + h0 * f0[i]
    rhs(model, ph, t0 + h0, y1, f1)
    for i in range(y0.size):
        f1[i] -= f0[i]
    d2 = rms(f1, atol, y0, rtol) / h0
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** 0.2
    return min(100.0 * h0, h1, t_bound - t0, max_step)


@kernel(internal=True)
def _phase_size(model, ph):
    """(state size, number of events) of the phase ``ph``. The model's hooks are called from
    functions compiled without reference counting only (``kernel``): numba compiles an overload
    once per set of its caller's compile flags, so a hook called from ``run`` as well would be
    compiled twice."""
    return state_size(model, ph), n_events(model, ph)


@kernel(internal=True)
def _phase_start(model, ph, t, yv, K, tmp, y_new, t_bound, max_step, rtol, atol, ne, g):
    """A phase's start at (t, yv): K[0] = f(t, yv), the first step's size (returned, s) and the
    events' values g[0] (``_phase_size``: why here)."""
    rhs(model, ph, t, yv, K[0])
    for e in range(ne):
        g[0, e] = event(model, ph, e, t, yv)
    return first_step(model, ph, t, yv, K[0], t_bound, max_step, rtol, atol, tmp, y_new)


@kernel(inline="always")
def attempt(model, ph, t, y, h_abs, rtol, t_bound, atol, max_step, K, y_new, tmp):
    """One accepted step from (t, y) with K[0] = f(t, y), at most max_step (s) long: (status, t_new,
    h, next h_abs, rhs calls).

    Rejects and shrinks as scipy does; a non-finite state shrinks by MIN_FACTOR down to the
    floating-point resolution of time, then is NOT_FINITE."""
    min_step = 10.0 * abs(np.nextafter(t, np.inf) - t)
    h_abs = min(max(h_abs, min_step), max_step)
    rejected = False
    nfev = 0
    while True:
        if h_abs < min_step:
            return STEP_TOO_SMALL, t, 0.0, h_abs, nfev
        t_new = min(t + h_abs, t_bound)
        h = t_new - t
        for s in range(1, 6):
            stage_state(y, h, K, A[s], s, tmp)
            rhs(model, ph, t + C[s] * h, tmp, K[s])
        stage_state(y, h, K, B, 6, y_new)
        rhs(model, ph, t_new, y_new, K[6])
        nfev += 6
        err = error_norm(K, h, y, y_new, rtol, atol)
        finite = np.isfinite(err)
        for i in range(y.size):
            finite = finite and np.isfinite(y_new[i])
        if not finite:
            if h_abs <= min_step:
                return NOT_FINITE, t, 0.0, h_abs, nfev
            h_abs *= MIN_FACTOR
            rejected = True
            continue
        f = new_step_factor(err, rejected)
        h_abs *= f
        if err < 1.0:
            return OK, t_new, h, h_abs, nfev
        rejected = True


@kernel(internal=True)
def _fires(g0, g1, dirn):
    return (g0 <= 0.0 and g1 >= 0.0 and dirn > 0) or (g0 >= 0.0 and g1 <= 0.0 and dirn < 0)


@kernel(inline="always")
def _event_at(model, ph, which, t, y0, h, Q, s, tmp):
    """Event ``which`` at the fraction s of the step (its dense output; tmp receives the state)."""
    dense_eval(y0, h, Q, s, tmp)
    return event(model, ph, which, t + s * h, tmp)


@kernel(internal=True)
def bisect(model, ph, which, t, y0, h, Q, lo, hi, g_lo, tmp):
    """Step fraction in (lo, hi] where event ``which`` changes sign (bisection on the dense output)."""
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        g = _event_at(model, ph, which, t, y0, h, Q, mid, tmp)
        if (g_lo <= 0.0) == (g <= 0.0) and g != 0.0:
            lo, g_lo = mid, g
        else:
            hi = mid
    return hi


@kernel(internal=True)
def crossing(model, ph, which, t, y0, h, Q, g0, g1, nsub, tmp):
    """First step fraction s in (0, 1] where event ``which`` changes sign in its direction, 2.0 if
    none; the sign is read at ``nsub`` points of the step (its end value g1 given)."""
    dirn = direction(model, ph, which)
    s_prev, g_prev = 0.0, g0
    for k in range(1, nsub + 1):
        s = k / nsub
        g = g1 if k == nsub else _event_at(model, ph, which, t, y0, h, Q, s, tmp)
        if _fires(g_prev, g, dirn):
            return bisect(model, ph, which, t, y0, h, Q, s_prev, s, g_prev, tmp)
        s_prev, g_prev = s, g
    return 2.0


@kernel(internal=True)
def crossing_bounded(model, ph, which, t, y0, h, Q, g0, g1, c, ds_min, tmp):
    """``crossing`` for an event g = y[c] - const (``event_offset``): the sign is read at points
    no sign change can lie between, since |dg/ds| <= |h| (|Q0| + 2|Q1| + 3|Q2| + 4|Q3|) = D over
    the step: from a point where g is read, the next is |g| / D further (less a rounding margin),
    and never more than ``ds_min`` closer. So a crossing is missed only where g stays within
    D ds_min of zero (a dip narrower than ds_min, as between ``crossing``'s points), and far from
    zero a long step costs a few reads."""
    dirn = direction(model, ph, which)
    d = abs(h) * (abs(Q[c, 0]) + 2.0 * abs(Q[c, 1]) + 3.0 * abs(Q[c, 2]) + 4.0 * abs(Q[c, 3]))
    margin = 1e-12 * (abs(y0[c]) + abs(g0 - y0[c])) + 1e-9 * d
    s_prev, g_prev = 0.0, g0
    while s_prev < 1.0:
        free = (abs(g_prev) - margin) / d if d > 0.0 else 2.0
        s = min(s_prev + max(free, ds_min), 1.0)
        g = g1 if s >= 1.0 else _event_at(model, ph, which, t, y0, h, Q, s, tmp)
        if _fires(g_prev, g, dirn):
            return bisect(model, ph, which, t, y0, h, Q, s_prev, s, g_prev, tmp)
        s_prev, g_prev = s, g
    return 2.0


@kernel(inline="always")
def _out_of_reach(g0, g1, y0c, h, Q, c):
    """Can the dense output of the step (y0c + h s (Q0 + s (Q1 + s (Q2 + s Q3))), s in [0, 1])
    not bring an event g = y[c] - const from g0 to zero? |y(s) - y0c| <= |h| sum |Q_k|; the margin
    covers the rounding of the dense evaluation (~1e-16 relative) a millionfold."""
    reach = abs(h) * (abs(Q[c, 0]) + abs(Q[c, 1]) + abs(Q[c, 2]) + abs(Q[c, 3]))
    margin = 1e-12 * (abs(y0c) + abs(g0 - y0c)) + 1e-9 * reach
    return g0 != 0.0 and (g0 > 0.0) == (g1 > 0.0) and abs(g0) > reach + margin


@jit
def event_many(model, ph, which, ts, Y, out):
    """Event ``which`` at many instants ts (s), states Y (len(ts), n): for the scipy reference loop."""
    for i in range(ts.size):
        out[i] = event(model, ph, which, ts[i], Y[i])


@kernel(internal=True)
def _steps(model, ph, n, ne, rtol, t_bound, max_steps, nsub, atol, max_step, span, t, yv, y_new, tmp, Q, K,
           h_abs, g, st_t, st_h, st_y, st_Q, nst):
    """Steps of one phase from (t, yv) (K[0] = f(t, yv), g[0] its event values; g[1] receives
    those at a step's end) until an event fires (yv is then the state at it), the time bound, a
    failure or the step cap, storing each step; it returns early, ``full``, when the step store is
    full (``run`` enlarges it and calls again: the state, K[0], g[0] and h_abs carry over).
    Allocates nothing (no reference counts
    in the per-step work). ``span`` (s): the finest step cap of the run's modes; an offset event's
    sign is read at least every span / nsub s, so a mode whose steps may be longer (the elastic
    flight) is checked as finely as the others. Returns (status, full, t, h_abs, nst, rhs calls,
    event hit or -1).

    The controls come as scalars, not as the ``Controls`` tuple: a tuple that holds arrays,
    passed into the per-step functions, made the elastic loop 35-40 % slower (an unused extra
    array in it measured so once; perhaps a slow episode of the VM); the events' old and new values
    are one array (2 % of the elastic loop)."""
    nfev = 0
    while t < t_bound:
        if nst >= max_steps:
            return TOO_MANY_STEPS, False, t, h_abs, nst, nfev, -1
        if nst == st_t.size:
            return OK, True, t, h_abs, nst, nfev, -1
        status, t_new, h, h_abs, calls = attempt(model, ph, t, yv, h_abs, rtol, t_bound, atol, max_step, K, y_new,
                                                 tmp)
        nfev += calls
        if status != OK:
            return status, False, t, h_abs, nst, nfev, -1
        dense_coeffs(K, Q)
        st_t[nst] = t
        st_h[nst] = h
        for i in range(n):            # element loops: numba's slice copies cost more per step
            st_y[nst, i] = yv[i]
            for c in range(4):
                st_Q[nst, i, c] = Q[i, c]
        nst += 1
        best = 2.0
        hit = -1
        for e in range(ne):
            g[1, e] = event(model, ph, e, t_new, y_new)
            c = event_offset(model, ph, e)
            if c < 0:
                s = crossing(model, ph, e, t, yv, h, Q, g[0, e], g[1, e], nsub, tmp)
            elif _out_of_reach(g[0, e], g[1, e], yv[c], h, Q, c):
                continue                               # no sign change is possible in this step
            else:
                s = crossing_bounded(model, ph, e, t, yv, h, Q, g[0, e], g[1, e], c,
                                     min(1.0, span / h) / nsub, tmp)
            if s <= 1.0 and (best - s) * h > TIE * (1.0 + abs(t)):
                best = s
                hit = e
        if hit >= 0:
            dense_eval(yv, h, Q, best, tmp)
            for i in range(n):
                yv[i] = tmp[i]
            return OK, False, t + best * h, h_abs, nst, nfev, hit
        t = t_new
        for i in range(n):
            yv[i] = y_new[i]
            K[0, i] = K[6, i]
        for e in range(ne):
            g[0, e] = g[1, e]
    return OK, False, t, h_abs, nst, nfev, -1


@jit
def run(model, ctl, ph0, y0, t0):
    """Integrate phase by phase from (t0, y0) in phase ph0 (module doc). Returns
    (status, t, y, n_steps, n_phases, n_events, nfev, step t0s, hs, y0s, Qs, phase rows, phase
    t0s, t1s, first step of each phase, event rows)."""
    nmax = ctl.n_state
    cap = min(ctl.max_steps, 4096)
    # not zeroed: only the first n_steps rows are ever read, and zeroing the rest (~300 kB) would
    # pull it through the cache at every call
    st_t = np.empty(cap)
    st_h = np.empty(cap)
    st_y = np.empty((cap, nmax))
    st_Q = np.empty((cap, nmax, 4))
    pcap = 64
    ph_row = np.zeros((pcap, PHASE_WIDTH))
    ph_t0 = np.zeros(pcap)
    ph_t1 = np.zeros(pcap)
    ph_first = np.zeros(pcap, dtype=np.int64)
    ev = np.empty((pcap, EV_WIDTH))
    ev[:] = np.nan
    ynew_all = np.empty(nmax)
    tmp_all = np.empty(nmax)
    Q_all = np.empty((nmax, 4))
    g = np.empty((2, MAX_EVENTS_PER_PHASE))
    y = np.zeros(nmax)
    for i in range(y0.size):
        y[i] = y0[i]
    span = np.inf                          # ctl.max_step.min(), NaN if one is (numpy's)
    for i in range(ctl.max_step.size):
        cap = ctl.max_step[i]
        if cap != cap:
            span = cap
            break
        span = min(span, cap)
    ph = np.empty(PHASE_WIDTH)
    for i in range(PHASE_WIDTH):
        ph[i] = ph0[i]
    t = t0
    # counters start as int64, not as the literal 0: a literal argument compiles a callee (_steps)
    # once for it and once more for int64 (~2 s of the first compile)
    nst = nph = nev = ntr = nfev = short = np.int64(0)
    status = OK
    while True:
        if nph == ph_t0.size:
            pcap = 2 * ph_t0.size
            ph_row, ph_t0, ph_t1, ph_first = grow(ph_row, pcap), grow(ph_t0, pcap), grow(ph_t1, pcap), grow(ph_first, pcap)
        if nev + MAX_EVENTS_PER_PHASE > ev.shape[0]:
            old = ev.shape[0]
            ev = grow(ev, 2 * old)
            ev[old:] = np.nan
        n, ne = _phase_size(model, ph)
        atol = ctl.atol[int(ph[0]), :n]
        max_step = ctl.max_step[int(ph[0])]
        yv, y_new, tmp, Q = y[:n], ynew_all[:n], tmp_all[:n], Q_all[:n]
        K = np.empty((7, n))          # contiguous: the stages' inner loops run over it
        for i in range(PHASE_WIDTH):
            ph_row[nph, i] = ph[i]
        ph_t0[nph] = t
        ph_first[nph] = nst
        t_ph0 = t
        h_abs = _phase_start(model, ph, t, yv, K, tmp, y_new, ctl.t_bound, max_step, ctl.rtol, atol, ne, g)
        nfev += 2
        hit = -1
        while True:
            status, full, t, h_abs, nst, calls, hit = _steps(model, ph, n, ne, ctl.rtol, ctl.t_bound, ctl.max_steps,
                                                            ctl.nsub, atol, max_step, span, t, yv, y_new, tmp, Q,
                                                            K, h_abs, g, st_t, st_h, st_y, st_Q, nst)
            nfev += calls
            if not full:
                break
            cap = min(2 * st_t.size, ctl.max_steps)     # the step store is full: double it, go on
            st_t, st_h, st_y, st_Q = grow(st_t, cap), grow(st_h, cap), grow(st_y, cap), grow(st_Q, cap)
        if status != OK:
            break
        ph_t1[nph] = t
        nph += 1
        if hit < 0:                                    # the time bound, without an end event
            if not ctl.end_at_bound:
                status = STALLED
            break
        short = short + 1 if t - t_ph0 < ctl.zeno_dt else 0
        code, nev = transition(model, ph, hit, t, y, ev, nev)
        ntr += 1
        if code == END:
            break
        if short >= ctl.zeno_n:
            status = NO_PROGRESS
            break
        if ntr > ctl.max_events:
            status = TOO_MANY_EVENTS
            break
    return (status, t, y, nst, nph, nev, nfev, st_t, st_h, st_y, st_Q, ph_row, ph_t0, ph_t1, ph_first, ev)


# ------------------------------------------------------------------ the Python side of a run

class DenseRun:
    """A stretch of steps with the interface the models read from scipy: ``.t`` (step times, s),
    ``.sol(times)`` / ``__call__`` -> array (n_state, n_times), ``.nfev``."""

    def __init__(self, t0s, hs, y0s, Qs, t_end, nfev=0, store=None, first=0):
        self.t0s, self.hs, self.y0s, self.Qs = t0s, hs, y0s, Qs
        # the whole integration's steps (t0s, hs, y0s, Qs; the state at the loop's full width,
        # of which this run's first y0s.shape[1] components are its own) that these are rows
        # first.. of, when they are (``unpack``): several runs are then read in place, not copied
        self.store, self.first = store, first
        self.t = np.empty(t0s.size + 1)     # the step times; the last step may end early, at an event
        self.t[:-1] = t0s
        self.t[-1] = t_end
        self.nfev = nfev

    def __call__(self, times):
        out = evaluate_steps(self.t0s, self.hs, self.y0s, self.Qs, times)
        return out[:, 0] if np.ndim(times) == 0 else out

    @property
    def sol(self):
        return self


Phase = namedtuple("Phase", "row t0 t1 sol")      # row: the phase array; sol: dense output over [t0, t1]


def unpack(out, width):
    """``run``'s return value -> (status, t, y, phases, event rows, nfev, n_steps); ``width(row)``
    is the state size of a phase (its dense output keeps that many components)."""
    (status, t, y, nst, nph, nev, nfev, st_t, st_h, st_y, st_Q, ph_row, ph_t0, ph_t1, ph_first, ev) = out
    phases = []
    store = (st_t[:nst], st_h[:nst], st_y[:nst], st_Q[:nst])     # every phase's steps, in order
    for i in range(nph):
        a = ph_first[i]
        b = ph_first[i + 1] if i + 1 < nph else nst
        n = width(ph_row[i])
        sol = DenseRun(st_t[a:b], st_h[a:b], st_y[a:b, :n], st_Q[a:b, :n], float(ph_t1[i]), store=store, first=int(a))
        phases.append(Phase(ph_row[i].copy(), float(ph_t0[i]), float(ph_t1[i]), sol))
    return int(status), float(t), y, phases, ev[:nev].copy(), int(nfev), int(nst)


def shared_store(runs):
    """The one step store that every run of ``runs`` (``DenseRun``s) is rows of (``unpack``), and
    each run's first row there: (store (t0s, hs, y0s, Qs), first (int64 array)), or None when they
    are not (a run built otherwise, from another loop, or without steps). Reading the store in
    place gives the values a joined copy would: each run's rows are its own steps."""
    store = getattr(runs[0], "store", None) if runs else None
    if store is None or not all(isinstance(r, DenseRun) and r.store is store and r.t0s.size for r in runs):
        return None
    return store, np.array([r.first for r in runs], dtype=np.int64)


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

    The runs must follow each other in time (the phases of one integration) and have the same
    state width. A time is evaluated on a step of its own run only, so an instant shared by two
    runs (a phase boundary) takes each run's own value. Returns (n_state, sum of len(times[k])).
    """
    counts = [np.size(tk) for tk in times]
    tt = np.concatenate([np.atleast_1d(np.asarray(tk, dtype=float)) for tk in times])
    return evaluate_at_runs(runs, np.repeat(np.arange(len(runs)), counts), tt)


def evaluate_at_runs(runs, which, times):
    """Dense output at ``times[i]`` (s) on ``runs[which[i]]``, ``which`` an integer array:
    array (n_state, len(times)), each value the one ``runs[which[i]](times[i])`` gives.

    ``runs``: ``DenseRun``s of one integration in time order, of one state width. A time is read
    on the steps of its own run only (``evaluate_steps``' first and last), so an instant shared by
    two runs takes each run's own value. Runs that are rows of one store (``unpack``) are read in
    place; others are joined first; a run that is not a ``DenseRun`` (a phase at rest, scipy's)
    is called at each of its times."""
    times = np.asarray(times, dtype=float)
    which = np.asarray(which, dtype=np.int64)
    if not all(isinstance(r, DenseRun) for r in runs):
        return np.concatenate([np.asarray(runs[w](times[i:i + 1]), dtype=float).reshape(-1, 1)
                               for i, w in enumerate(which)], axis=1)
    sizes = np.array([r.t0s.size for r in runs], dtype=np.int64)
    shared, n = shared_store(runs), runs[0].y0s.shape[1]
    if shared is not None and all(r.y0s.shape[1] == n for r in runs):
        store, first = shared
        store = (store[0], store[1], store[2][:, :n], store[3][:, :n])
    else:
        first = np.concatenate(([0], np.cumsum(sizes)[:-1]))
        store = tuple(np.concatenate([getattr(r, a) for r in runs]) for a in ("t0s", "hs", "y0s", "Qs"))
    return evaluate_steps(*store, times, first[which], (first + sizes - 1)[which])


@jit(internal=True)
def merge_outputs(grid, starts, ends, first, last, t0s, hs, y0s, Qs, out_t, out_y, out_seg, out_grid):
    """The samples of consecutive phases on a time grid plus each phase's own step times, in time
    order, in one pass: what ``evaluate_runs`` on (the grid points of each phase, its steps),
    a stable sort and the removal of repeated instants give, value for value (the same arithmetic).

    Phase k covers [starts[k], ends[k]] (ends[k] == starts[k + 1]) and takes the grid points from
    starts[k] on, up to but excluding ends[k] (including it for the last phase); its steps are
    first[k] .. last[k] (>= first[k]) of (t0s, hs, y0s, Qs), the concatenated ``DenseRun``
    arrays; its own times are those steps' starts and ends[k]. At a repeated instant (a grid point
    on a step time, a phase boundary) the first in order is kept: the grid's, and the value of the
    phase that ends. Writes out_t (s), out_y (n_state, m), out_seg (phase index), out_grid (grid
    index, -1 at a step time); returns m.
    """
    n_state = y0s.shape[1]
    m = 0
    for k in range(starts.size):
        lo, hi = starts[k], ends[k]
        a = np.searchsorted(grid, lo, side="left")
        b = np.searchsorted(grid, hi, side="right") if k == starts.size - 1 else np.searchsorted(grid, hi, side="left")
        f, l = first[k], last[k]
        n_times = l - f + 2                # the steps' starts and the phase's end
        iu, js = a, 0                      # next grid point, next own time
        i_step = f
        ts = hi
        while iu < b or js < n_times:
            if js < n_times:
                ts = t0s[f + js] if js < n_times - 1 else hi
            if js >= n_times or (iu < b and grid[iu] <= ts):
                tau, gidx = grid[iu], iu
                iu += 1
            else:
                tau, gidx = ts, -1
                js += 1
            if m > 0 and tau == out_t[m - 1]:
                continue
            out_t[m] = tau
            out_seg[m] = k
            out_grid[m] = gidx
            while i_step < l and t0s[i_step + 1] <= tau:   # the last step starting at or before tau
                i_step += 1
            _dense_at(t0s, hs, y0s, Qs, i_step, tau, n_state, out_y, m)
            m += 1
    return m


@jit
def merged(grid, starts, ends, first, last, t0s, hs, y0s, Qs, n_steps):
    """``merge_outputs`` of phases (starts, ends, their steps first..last of t0s, hs, y0s, Qs; n_steps
    of them) with the grid, into arrays of their own: (t, y (n_state, m), phase index, grid index
    or -1)."""
    size = grid.size + n_steps + starts.size
    out_t, out_y = np.empty(size), np.empty((y0s.shape[1], size))
    out_seg, out_grid = np.empty(size, dtype=np.int64), np.empty(size, dtype=np.int64)
    m = merge_outputs(grid, starts, ends, first, last, t0s, hs, y0s, Qs, out_t, out_y, out_seg, out_grid)
    return out_t[:m], out_y[:, :m], out_seg[:m], out_grid[:m]


@jit
def merge_run(grid, out, width):
    """``merged`` of a run from ``run``'s own return value ``out`` (its step store and phase
    table), without a Python object per phase, for the first ``width`` state components (the
    others are not evaluated)."""
    nst, nph = out[3], out[4]
    first = out[14][:nph]
    last = np.empty(nph, dtype=np.int64)
    for k in range(nph - 1):                # element by element: a slice assignment would compile
        last[k] = first[k + 1] - 1          # numba's shape check and its message (~1 s once)
    last[nph - 1] = nst - 1
    return merged(grid, out[12][:nph], out[13][:nph], first, last, out[7], out[8], out[9][:, :width],
                  out[10][:, :width], nst)


@kernel(inline="always")
def _dense_at(t0s, hs, y0s, Qs, i, tau, n_state, out, m):
    """out[:n_state, m] = the dense output of step i at tau: ``evaluate_steps``' arithmetic."""
    h = hs[i]
    s = (tau - t0s[i]) / h if h > 0 else 0.0
    for c in range(n_state):
        poly = s * (Qs[i, c, 0] + s * (Qs[i, c, 1] + s * (Qs[i, c, 2] + s * Qs[i, c, 3])))
        out[c, m] = y0s[i, c] + h * poly


@kernel
def evaluate_at(times, first, last, width, t0s, hs, y0s, Qs, out):
    """``evaluate_steps`` for many runs in one compiled pass: times[m] on the steps first[m] ..
    last[m] of the concatenated (t0s, hs, y0s, Qs) (the state padded to Qs.shape[1]), its first
    width[m] components into out[:, m] (the same arithmetic, value for value)."""
    for m in range(times.size):
        f, l, tau = first[m], last[m], times[m]
        lo, hi = f, l                       # the last step of [f, l] starting at or before tau, else f
        if t0s[l] <= tau:
            lo = l
        else:
            while hi - lo > 1:
                mid = (lo + hi) >> 1
                if t0s[mid] <= tau:
                    lo = mid
                else:
                    hi = mid
        _dense_at(t0s, hs, y0s, Qs, lo, tau, width[m], out, m)
