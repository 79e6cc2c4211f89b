"""Compiled loops (models.dynamics.kernels): the same numerics as the scipy path, closed forms, caching."""
import math

import numpy as np
import pytest

from models.dynamics import elastic, rigid
from models.dynamics.contact import contact_potential, contact_stiffness
from models.dynamics.kernels import dopri5, elastic_nb, rigid_nb
from models.study.paper import table1_runs
from models.dynamics.scene import Scene


def _scene(run, **kw):
    r = table1_runs().iloc[run - 1]
    return Scene(cam_speed_rpm=r.n1_rpm, Fu=r.Fu_N, backlash=r.j_mm * 1e-3, jt_factor=r.Jt_factor, **kw)


def test_tableau_is_dormand_prince():
    # row sums of A are the nodes C; B and the embedded weights integrate polynomials exactly
    np.testing.assert_allclose(dopri5.A.sum(axis=1), dopri5.C, atol=1e-15)
    assert dopri5.B.sum() == pytest.approx(1.0, abs=1e-15)
    assert dopri5.E.sum() == pytest.approx(0.0, abs=1e-15)          # difference of two quadratures
    for q in range(1, 5):                                             # order conditions b.c^(q-1) = 1/q
        assert np.dot(dopri5.B, dopri5.C ** (q - 1)) == pytest.approx(1.0 / q, abs=1e-14)
    # the dense output at s = 1 is the step's end: sum over P's columns equals B (with 0 for K7)
    np.testing.assert_allclose(dopri5.P.sum(axis=1)[:6], dopri5.B, atol=1e-14)


def test_free_flight_is_exact_parabola():
    # flight phase, constant drive d and mass m: x = x0 + v0 t - d t^2 / (2 m): 5th order is exact
    t = np.linspace(0.0, 1e-2, 5)
    d, m, gap = 2.0, 0.5, 1.0
    segments, events = elastic_nb.integrate(t, np.full(5, d), np.full(5, m), 1e9, gap, y0=(0.5, 3.0, 1),
                                            rtol=1e-10, atol=(1e-14, 1e-12), max_step=1e-3)
    assert events == []
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
    segments, events = elastic_nb.integrate(t, np.full(3, d), np.full(3, m), kc, 1e-3, y0=(-1e-7, 0.0, 0),
                                            rtol=1e-12, atol=(1e-18, 1e-14), max_step=step)
    assert events == []                     # a loaded contact oscillates about its static deflection
    (_, run), = segments
    tt = np.linspace(0.0, 5e-3, 400)
    x, v = run(tt)
    E = 0.5 * m * v**2 + contact_potential(-x, kc) + d * x
    assert np.max(np.abs(E - E[0])) < 1e-9 * (abs(d) * 1e-6)


@pytest.mark.parametrize("run", [1, 6, 11])
def test_elastic_kernel_is_the_scipy_loop(run):
    s = _scene(run)
    tab = elastic.build_tables(s, s.program.rise_angle / elastic.cam_speed(s))
    kc = contact_stiffness(s.contact_length)
    kw = dict(rtol=1e-8, atol=(1e-13, 1e-9), max_step=5e-5)
    seg_a, ev_a = elastic.integrate(tab.t, tab.R31, tab.M, kc, s.backlash, **kw)
    seg_b, ev_b = elastic_nb.integrate(tab.t, tab.R31, tab.M, kc, s.backlash, **kw)
    assert [e["kind"] for e in ev_a] == [e["kind"] for e in ev_b]
    # equal to rounding: np.interp vs the compiled interpolation differ in the last bits, which
    # the event locations and step sizes carry forward (1e-10 s << the solver's own error, 1e-7 s)
    np.testing.assert_allclose([e["t"] for e in ev_a], [e["t"] for e in ev_b], rtol=0, atol=1e-10)
    # the same steps (same controller) and the same dense output
    for (pa, sa), (pb, sb) in zip(seg_a, seg_b):
        assert pa == pb
        assert sa.t.size == sb.t.size
        np.testing.assert_allclose(sa.t, sb.t, rtol=0, atol=1e-10)
        tt = np.linspace(sa.t[0], sa.t[-1], 50)
        np.testing.assert_allclose(sa.sol(tt)[0], sb.sol(tt)[0], rtol=0, atol=1e-12)


@pytest.mark.parametrize("run", [1, 12, 16])
def test_rigid_kernel_is_the_scipy_loop(run):
    s = _scene(run)
    P, _ = rigid.build_plant(s)
    span = rigid.simulated_span(s)
    w0 = (P.m0 + float(rigid.interp(P.tab1, 0.0)[6])) / P.m1
    preset = rigid.PRESETS["fast"]
    ph_a, ev_a = rigid.integrate(P, span, w0, preset, s.program.rise_angle / w0)
    ph_b, ev_b = rigid_nb.integrate(P, span, w0, preset, s.program.rise_angle / w0)
    assert [(e["kind"], e["flank"]) for e in ev_a] == [(e["kind"], e["flank"]) for e in ev_b]
    for key, atol in (("time", 1e-12), ("percussion", 1e-9), ("omega2_after", 1e-8)):
        np.testing.assert_allclose([e[key] for e in ev_a], [e[key] for e in ev_b], rtol=0, atol=atol)
    assert [(p.kind, p.flank) for p in ph_a] == [(p.kind, p.flank) for p in ph_b]
    tt = np.linspace(ph_a[-1].t0, ph_a[-1].t1, 20)
    np.testing.assert_allclose(ph_a[-1].sol(tt), ph_b[-1].sol(tt), rtol=1e-10, atol=1e-12)


def test_dense_output_is_continuous_across_steps():
    s = _scene(5)
    tab = elastic.build_tables(s, s.program.rise_angle / elastic.cam_speed(s))
    segs, _ = elastic_nb.integrate(tab.t, tab.R31, tab.M, contact_stiffness(s.contact_length), s.backlash,
                                   max_step=5e-5)
    for _, run in segs:
        if run.t0s.size < 2:
            continue
        # each step's polynomial at s = 1 is the next step's start
        ends = run.y0s[:-1] + run.hs[:-1, None] * run.Qs[:-1].sum(axis=2)
        np.testing.assert_allclose(ends, run.y0s[1:], rtol=1e-12, atol=1e-18)


def test_kernels_are_compiled_with_an_on_disk_cache():
    for fn in (rigid_nb.run, elastic_nb.run, dopri5.error_norm):
        assert fn._cache.__class__.__name__ == "FunctionCache", fn


def test_start_on_a_flank_at_a_later_time_continues_the_run():
    # the escalation in time of models.dynamics.auto: restarting the contact run from its own state later
    # gives the same run
    s = _scene(1)
    P, _ = rigid.build_plant(s)
    P0 = rigid.dataclasses.replace(P, j=0.0)
    w0 = (P.m0 + float(rigid.interp(P.tab1, 0.0)[6])) / P.m1
    tr = s.program.rise_angle / w0
    preset = rigid.PRESETS["standard"]
    ph, _ = rigid_nb.integrate(P0, 0.9, w0, preset, tr)
    t_a = 0.3 * ph[0].t1
    phi1, omega1 = ph[0].sol(t_a)
    ph2, _ = rigid_nb.integrate(P0, 0.9, w0, preset, tr, start=("contact", phi1, omega1, rigid.INNER), t_start=t_a)
    assert ph2[0].t0 == t_a and ph2[-1].t1 == pytest.approx(ph[0].t1, abs=1e-12)
    tt = np.linspace(t_a, ph[0].t1, 30)
    np.testing.assert_allclose(ph2[0].sol(tt), ph[0].sol(tt), rtol=1e-9)
    assert math.isfinite(ph2[0].sol(tt).sum())
