"""The one compiled driver (labtool.models.dynamics.kernels.dopri5) and the scipy reference loop over the same
compiled equations: closed forms, the same numerics, the same events, caching."""
import math

import numpy as np
import pytest

from labtool.models.dynamics import elastic, events, rigid
from labtool.models.dynamics.contact import contact_potential, contact_stiffness
from labtool.models.dynamics.kernels import dopri5
from labtool.models.study.paper import paper_scene
from labtool.models.study.paper import table1_runs
from labtool.common.units import RPM

T, KIND, SIDE = events.COL_TIME, events.COL_KIND, events.COL_SIDE


def _scene(run, **kw):
    r = table1_runs().iloc[run - 1]
    return paper_scene(cam_speed=r.n1_rpm * RPM, Fu=r.Fu_N, backlash=r.j_mm * 1e-3, jt_factor=r.Jt_factor, **kw)


def test_tableau_is_dormand_prince():
    # row sums of A are the nodes C; B and the embedded weights integrate polynomials exactly
    np.testing.assert_allclose(dopri5.A.sum(axis=1), dopri5.C, atol=1e-15)
    assert dopri5.B.sum() == pytest.approx(1.0, abs=1e-15)
    assert dopri5.E.sum() == pytest.approx(0.0, abs=1e-15)          # difference of two quadratures
    for q in range(1, 5):                                             # order conditions b.c^(q-1) = 1/q
        assert np.dot(dopri5.B, dopri5.C ** (q - 1)) == pytest.approx(1.0 / q, abs=1e-14)
    # the dense output at s = 1 is the step's end: sum over P's columns equals B (with 0 for K7)
    np.testing.assert_allclose(dopri5.P.sum(axis=1)[:6], dopri5.B, atol=1e-14)


def test_step_factor_is_scipys_controller_to_a_few_ulps():
    """new_step_factor forms err^(-1/5) by exp and log (cheaper than pow in the loop): it must be
    scipy RK45's factor (numpy's power, an independent libm call) at every error norm."""
    from scipy.integrate._ivp.rk import MAX_FACTOR, MIN_FACTOR, SAFETY
    for err in np.geomspace(1e-12, 1e3, 4001):
        for rejected in (False, True):
            want = SAFETY * np.power(err, -0.2)
            want = (min(1.0, min(MAX_FACTOR, want)) if rejected else min(MAX_FACTOR, want)) if err < 1 \
                else max(MIN_FACTOR, want)
            assert dopri5.new_step_factor(err, rejected) == pytest.approx(want, rel=1e-14, abs=0)
    assert dopri5.new_step_factor(0.0, False) == MAX_FACTOR


@pytest.mark.slow
def test_grid_lookup_is_np_interp_on_a_nonuniform_grid():
    """The right-hand side's table lookup (a guess from the mean rate, then a walk) is np.interp on
    grids far from uniform, at and between the nodes and outside the grid."""
    from labtool.models.dynamics.kernels import elastic_nb as eq
    rng = np.random.default_rng(7)
    for _ in range(20):
        tg = np.cumsum(rng.uniform(0.05, 3.0, 200)) * 1e-5
        tab = np.vstack([tg, rng.normal(size=200), rng.uniform(0.5, 2.0, 200)])
        ts = np.concatenate([rng.uniform(tg[0] - 1e-4, tg[-1] + 1e-4, 500), tg])
        for t in ts:
            a, b = eq.interp_rows(t, tab, eq.DRIVE, eq.MASS, eq.grid_rate(tg))
            assert a == pytest.approx(np.interp(t, tg, tab[eq.DRIVE]), rel=1e-13, abs=1e-15)
            assert b == pytest.approx(np.interp(t, tg, tab[eq.MASS]), rel=1e-13, abs=1e-15)


@pytest.mark.parametrize("solver", ["compiled", "scipy"])
def test_free_flight_is_exact_parabola(solver):
    # flight phase, constant drive d and mass m: x = x0 + v0 t - d t^2 / (2 m): 5th order is exact
    t = np.linspace(0.0, 1e-2, 5)
    d, m, gap = 2.0, 0.5, 1.0
    segments, rows = elastic.integrate(t, np.full(5, d), np.full(5, m), 1e9, gap, y0=(0.5, 3.0, 1),
                                       rtol=1e-10, atol=(1e-14, 1e-12), max_step=1e-3, solver=solver)
    assert rows.shape[0] == 0
    (phase, run), = segments
    tt = np.linspace(0.0, 1e-2, 37)
    x, v = run(tt)
    np.testing.assert_allclose(x, 0.5 + 3.0 * tt - d * tt**2 / (2 * m), rtol=0, atol=1e-13)
    np.testing.assert_allclose(v, 3.0 - d * tt / m, rtol=0, atol=1e-12)


@pytest.mark.parametrize("step", [2e-6, 1e-6])
def test_contact_energy_is_conserved_and_converges(step):
    # interior contact under a constant drive: E = m v^2/2 + U(-x) + d x is an invariant
    kc, m, d = contact_stiffness(6e-3), 0.3, 200.0
    t = np.linspace(0.0, 5e-3, 3)
    segments, rows = elastic.integrate(t, np.full(3, d), np.full(3, m), kc, 1e-3, y0=(-1e-7, 0.0, 0),
                                       rtol=1e-12, atol=(1e-18, 1e-14), max_step=step)
    assert rows.shape[0] == 0               # a loaded contact oscillates about its static deflection
    (_, run), = segments
    tt = np.linspace(0.0, 5e-3, 400)
    x, v = run(tt)
    E = 0.5 * m * v**2 + contact_potential(-x, kc) + d * x
    assert np.max(np.abs(E - E[0])) < 1e-9 * (abs(d) * 1e-6)


@pytest.mark.parametrize("run", [1, 6, 11])
def test_elastic_compiled_loop_is_scipy_rk45_on_the_same_equations(run):
    s = _scene(run)
    tab = elastic.build_tables(s, s.program.rise_angle / elastic.cam_speed(s))
    kc = contact_stiffness(s.contact_length)
    kw = dict(rtol=1e-8, atol=(1e-13, 1e-9), max_step=5e-5)
    seg_a, ev_a = elastic.integrate(tab.t, tab.R31, tab.M, kc, s.backlash, solver="scipy", method="RK45", **kw)
    seg_b, ev_b = elastic.integrate(tab.t, tab.R31, tab.M, kc, s.backlash, **kw)
    np.testing.assert_array_equal(ev_a[:, [KIND, SIDE]], ev_b[:, [KIND, SIDE]])
    # equal to rounding: brentq and the bisection locate the events to 1e-15 s, and the step
    # sequences then carry the last bits forward (1e-10 s << the solver's own error, 1e-7 s)
    np.testing.assert_allclose(ev_a[:, T], ev_b[:, T], rtol=0, atol=1e-10)
    # the same steps (same controller) and the same dense output
    for (pa, sa), (pb, sb) in zip(seg_a, seg_b):
        assert pa == pb
        assert sa.t.size == sb.t.size
        np.testing.assert_allclose(sa.t, sb.t, rtol=0, atol=1e-10)
        tt = np.linspace(sa.t[0], sa.t[-1], 50)
        np.testing.assert_allclose(sa(tt)[0], sb(tt)[0], rtol=0, atol=1e-12)


@pytest.mark.parametrize("run", [1, 12, 16])
@pytest.mark.slow
def test_rigid_compiled_loop_is_scipy_rk45_on_the_same_equations(run):
    s = _scene(run)
    model, _ = rigid.build_model(s)
    w0 = rigid.start_speed(s, model)
    preset = rigid.PRESETS["fast"]
    ph_a, ev_a = rigid.integrate(model, w0, preset, s.program.rise_angle / w0, solver="scipy")
    ph_b, ev_b = rigid.integrate(model, w0, preset, s.program.rise_angle / w0)
    np.testing.assert_array_equal(ev_a[:, [KIND, SIDE]], ev_b[:, [KIND, SIDE]])
    for col, atol in ((T, 1e-12), (events.COL_PERCUSSION, 1e-9), (rigid.eq.COL_OMEGA2_AFTER, 1e-8)):
        np.testing.assert_allclose(ev_a[:, col], ev_b[:, col], rtol=0, atol=atol)
    assert [(p.kind, p.flank) for p in ph_a] == [(p.kind, p.flank) for p in ph_b]
    tt = np.linspace(ph_a[-1].t0, ph_a[-1].t1, 20)
    np.testing.assert_allclose(ph_a[-1].sol(tt), ph_b[-1].sol(tt), rtol=1e-10, atol=1e-12)


def _event_list(result):
    ev = events.read(result.dataset)
    return list(zip(ev["event_kind"].values, ev["event_side"].values)), ev["event_time"].values


MICRO_BOUNCE = dict(law="sine", cam_speed=408.0 * RPM, Fu=124.0, backlash=1.6e-05, jt_factor=4.9375,
                    contact_length=0.009765625, contact_damping=1.0)


@pytest.mark.slow
@pytest.mark.parametrize("model, kw", [
    ("elastic", MICRO_BOUNCE),                       # tests/test_elastic.py: the micro-bounce case
    ("elastic", dict(run=1)), ("elastic", dict(run=6)), ("elastic", dict(run=11)),
    ("rigid", dict(run=1)), ("rigid", dict(run=12)), ("rigid", dict(run=16)),
])
def test_compiled_and_reference_loops_give_the_same_events(model, kw):
    """The compiled loop (standard) and the independent reference (scipy DOP853 at the reference
    preset) on the same compiled equations: the same events, at times within the standard preset's
    measured error (labtool.models.dynamics.accuracy) times 10."""
    from labtool.models.dynamics import accuracy
    from labtool.models.dynamics.simulate import simulate

    kw = dict(kw)
    scene = _scene(kw.pop("run")) if "run" in kw else paper_scene(**kw)
    a = _event_list(simulate(scene.replace(accuracy="standard"), model))
    b = _event_list(simulate(scene.replace(accuracy="reference"), model))
    assert a[0] == b[0] and len(a[0]) > 0
    tol = 10 * accuracy.MEASURED[model]["standard"]["err_event_time"]
    np.testing.assert_allclose(a[1], b[1], rtol=0, atol=max(tol, 1e-9))


@pytest.mark.parametrize("solver", ["compiled", "scipy"])
def test_unloaded_start_gives_no_events_in_either_loop(solver):
    """R31(0) = 0 (zero, then a ramp): both loops start at rest against the flank the ramp loads and
    record no event (the compiled copy once lacked the at-rest prefix: 2 events at 0.41 and 1.01 ms)."""
    t = np.linspace(0.0, 5e-3, 11)
    kc = contact_stiffness(6e-3)
    for sign in (1.0, -1.0):
        drive = sign * np.maximum(t - 1e-3, 0.0) * 1e4
        segs, rows = elastic.integrate(t, drive, np.full(11, 2.0), kc, gap=16e-6, rtol=1e-9, atol=(1e-15, 1e-11),
                                       max_step=2e-5, solver=solver, method="DOP853" if solver == "scipy" else "RK45")
        assert rows.shape[0] == 0
        assert segs[0][0] == (elastic.INTERIOR if sign > 0 else elastic.EXTERIOR)
        assert isinstance(segs[0][1], elastic.AtRest) and segs[0][1].t[-1] == pytest.approx(1e-3)   # the last instant before the drive departs from 0


def test_dense_output_is_continuous_across_steps():
    s = _scene(5)
    tab = elastic.build_tables(s, s.program.rise_angle / elastic.cam_speed(s))
    segs, _ = elastic.integrate(tab.t, tab.R31, tab.M, contact_stiffness(s.contact_length), s.backlash, max_step=5e-5)
    for _, run in segs:
        if not isinstance(run, dopri5.DenseRun) or run.t0s.size < 2:
            continue
        # each step's polynomial at s = 1 is the next step's start, to the rounding of its terms
        ends = run.y0s[:-1] + run.hs[:-1, None] * run.Qs[:-1].sum(axis=2)
        terms = np.abs(run.y0s[:-1]) + np.abs(run.hs[:-1, None]) * np.abs(run.Qs[:-1]).sum(axis=2)
        assert np.all(np.abs(ends - run.y0s[1:]) <= 16 * np.finfo(float).eps * terms)


def test_kernels_are_compiled_with_an_on_disk_cache():
    from numba.core.caching import FunctionCache

    from labtool.models.dynamics.jit import CACHING
    assert CACHING
    for fn in (dopri5.run, dopri5.error_norm, rigid.eq.contact_terms, elastic.eq.rhs):
        assert isinstance(fn._cache, FunctionCache), fn     # numba's, read tolerantly (jit._TolerantCache)


def test_start_on_a_flank_at_a_later_time_continues_the_run():
    # the escalation in time of labtool.models.dynamics.auto: restarting the contact run from its own state later
    # gives the same run
    s = _scene(1)
    model, _ = rigid.build_model(s)
    model0 = model._replace(j=0.0, phi1_end=0.9)
    w0 = rigid.start_speed(s, model)
    tr = s.program.rise_angle / w0
    preset = rigid.PRESETS["standard"]
    ph, _ = rigid.integrate(model0, w0, preset, tr)
    t_a = 0.3 * ph[0].t1
    phi1, omega1 = ph[0].sol(t_a)
    ph2, _ = rigid.integrate(model0, w0, preset, tr, start=("contact", phi1, omega1, rigid.INNER), t_start=t_a)
    # the end event is located on another sequence of steps: to the dense output's accuracy (2.3e-12 s
    # apart at the standard preset's rise/20 step cap; the preset's event times are good to 1e-9 s)
    assert ph2[0].t0 == t_a and ph2[-1].t1 == pytest.approx(ph[0].t1, abs=1e-10)
    tt = np.linspace(t_a, ph[0].t1, 30)
    # two solutions at rtol 1e-9 on different step sequences: 2.3e-9 apart (relative) at rise/20
    np.testing.assert_allclose(ph2[0].sol(tt), ph[0].sol(tt), rtol=1e-8)
    assert math.isfinite(ph2[0].sol(tt).sum())


@pytest.mark.slow
def test_a_function_compiled_for_compiled_callers_only_refuses_a_python_call():
    """``jit(internal=True)``: no CPython wrapper is compiled; a call from Python is one TypeError,
    before and after its compiled callers compiled it (not a call into a missing wrapper)."""
    from labtool.models.dynamics import elastic as E

    for _ in range(2):
        with pytest.raises(TypeError, match=r"elastic\.bounce_time is called from compiled code only"):
            E._bounce_time(8.05e4, 1.0, 0.1)
        elastic.simulate(_scene(1))                     # compiles it for its compiled callers
