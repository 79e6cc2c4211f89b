"""labtool.models.mechanism.cam_tables: the speed-independent terms reproduce labtool.models.mechanism.kinematics and the cam geometry,
the stroke spline reproduces the exact linkage, the grid cache is shared and read-only; and the
batched dense output of the compiled loop equals the per-run one."""
import math

import numpy as np
import pytest

from labtool.models.mechanism import cam_tables, memo
from labtool.models.dynamics import elastic
from labtool.models.mechanism.cam_profile import contact_geometry
from labtool.models.mechanism.kinematics import follower_motion, kinetostatic_moment, load_force_x
from labtool.models.study.paper import paper_scene
from labtool.models.dynamics.simulate import simulate
from labtool.common.units import RPM


def _reference(scene, phi1, omega1):
    """The operating point's kinematics the way labtool.models.mechanism.kinematics computes them."""
    mech, prog = scene.mechanism, scene.program
    phi2, omega2, epsilon2, _ = follower_motion(prog, mech, phi1, omega1)
    load_x = load_force_x(mech, prog, phi1, phi2, scene.Fu)
    MR13D, red = kinetostatic_moment(mech, phi2, omega2, epsilon2, load_x, scene.jt_factor)
    return phi2, omega2, epsilon2, MR13D, red.J


@pytest.mark.parametrize("law", ["sine", "cosine", "modtrap"])
@pytest.mark.parametrize("rpm,Fu,jt", [(180.0, 0.0, 1.0), (300.0, 65.0, 4.0), (60.0, 500.0, 0.25)])
def test_terms_at_speed_equal_the_kinematic_analysis(law, rpm, Fu, jt):
    scene = paper_scene(law=law, cam_speed=rpm * RPM, Fu=Fu, jt_factor=jt)
    phi1 = np.linspace(0.0, 2.0 * math.pi, 1441)            # rise, dwell, return, dwell
    omega1 = scene.omega1_nominal
    terms = cam_tables.angle_terms(scene.mechanism, scene.program, phi1)
    op = terms.at_speed(omega1, Fu, jt)
    phi2, omega2, epsilon2, MR13D, J = _reference(scene, phi1, omega1)
    np.testing.assert_allclose(terms.phi2, phi2, rtol=0, atol=1e-15)
    np.testing.assert_allclose(op["omega2"], omega2, rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(op["epsilon2"], epsilon2, rtol=1e-14, atol=1e-12)
    scale = np.abs(MR13D).max()
    np.testing.assert_allclose(op["MR13D"], MR13D, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(op["J_follower"], J, rtol=1e-14)
    geo = contact_geometry(scene.mechanism, scene.program, phi1)
    np.testing.assert_array_equal(terms.alpha, geo["pressure_angle"])
    np.testing.assert_array_equal(terms.Db1, geo["Db1"])
    np.testing.assert_array_equal(terms.Db2, geo["Db2"])


def test_until_holds_the_rise_at_its_last_instant():
    """At phi1 = rise exactly the dwell begins; with ``until`` just below it the last instant keeps
    the rise's load and motion (the cosine law's acceleration does not vanish there)."""
    scene = paper_scene(Fu=65.0, law="cosine")
    rise = scene.program.rise_angle
    phi1 = np.array([0.5 * rise, np.nextafter(rise, 0.0), rise, rise + 0.01])
    free = cam_tables.angle_terms(scene.mechanism, scene.program, phi1)
    held = cam_tables.angle_terms(scene.mechanism, scene.program, phi1, until=np.nextafter(rise, 0.0))
    assert free.m_load[2] == 0.0 and free.m_load[3] == 0.0 and free.ddpsi[2] == 0.0   # the dwell
    for name in ("m_load", "ddpsi", "alpha"):
        assert getattr(held, name)[2] == getattr(held, name)[1] == getattr(free, name)[1] != 0.0
    np.testing.assert_array_equal(held.phi1, phi1)


def test_stroke_spline_reproduces_the_exact_linkage():
    scene = paper_scene(Fu=65.0, jt_factor=4.0)
    rng = np.random.default_rng(7)
    phi1 = np.sort(rng.uniform(0.0, 2.0 * math.pi, 4000))
    exact = cam_tables.angle_terms(scene.mechanism, scene.program, phi1)
    spl = cam_tables.angle_terms(scene.mechanism, scene.program, phi1, linkage="spline")
    for name, tol in (("J0", 1e-11), ("dJ0", 1e-9), ("M_gravity", 1e-11), ("m_load", 1e-11)):
        a, b = getattr(exact, name), getattr(spl, name)
        assert np.abs(a - b).max() <= tol * np.abs(a).max(), name
    # the motion law and the contact geometry are exact in both
    np.testing.assert_array_equal(exact.alpha, spl.alpha)
    np.testing.assert_array_equal(exact.ddpsi, spl.ddpsi)


def test_spline_falls_back_to_the_exact_linkage_outside_the_stroke():
    mech = paper_scene().mechanism
    sp = cam_tables.stroke_spline(mech)
    prog = paper_scene(law="sine").program.__class__.rise_dwell_return_dwell("sine", stroke=2.0 * mech.psi_a)
    phi1 = np.linspace(0.0, prog.rise_angle, 50)       # a stroke twice the tabulated one
    assert mech.phiD + mech.psi0 + prog(phi1)[0].max() > sp.x[-1]
    a = cam_tables.angle_terms(mech, prog, phi1)
    b = cam_tables.angle_terms(mech, prog, phi1, linkage="spline")
    np.testing.assert_array_equal(a.J0, b.J0)


def test_one_cached_grid_serves_every_speed_load_and_inertia():
    memo.clear_cache()
    runs = [paper_scene(cam_speed=n * RPM, Fu=f, jt_factor=j) for n, f, j in ((180, 0, 1), (300, 65, 4), (500, 0, 1))]
    span = runs[0].program.rise_angle
    tabs = [elastic.grid_tables(s, span) for s in runs]
    key_terms = cam_tables.grid_terms(runs[0].mechanism, runs[0].program, span, elastic.GRID_POINTS,
                                      float(np.nextafter(span, 0.0)))
    assert all(t.phi1 is key_terms.phi1 for t in tabs)           # the same arrays, not copies
    assert not key_terms.J0.flags.writeable
    with pytest.raises(ValueError):
        key_terms.J0[0] = 0.0
    # each run's tables equal an uncached exact evaluation at its own speed
    for s, tab in zip(runs, tabs):
        fresh = elastic.build_tables(s, span / elastic.cam_speed(s), t=tab.t)
        np.testing.assert_allclose(tab.R31, fresh.R31, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(tab.M, fresh.M, rtol=1e-12)


def test_cache_is_bounded():
    memo.clear_cache()
    s = paper_scene()
    for n in range(memo.CACHE_SIZE + 3):
        cam_tables.grid_terms(s.mechanism, s.program, s.program.rise_angle, 101 + n)
    assert len(memo._cache) == memo.CACHE_SIZE


@pytest.mark.slow
def test_batched_dense_output_equals_each_run_including_a_shared_boundary():
    from labtool.models.dynamics.elastic import integrate
    from labtool.models.dynamics.kernels.dopri5 import evaluate_runs

    s = paper_scene(backlash=0.016e-3, omega1_mode="var")           # run 1: several phases
    tab = elastic.build_tables(s, s.program.rise_angle / elastic.cam_speed(s))
    kc = 8.53e8
    segs, events = integrate(tab.t, tab.R31, tab.M, kc, s.backlash, rtol=1e-8, atol=(1e-13, 1e-9), max_step=5e-5)
    assert len(segs) >= 3 and events.shape[0]
    runs = [sol for _, sol in segs]
    times = [np.concatenate([np.linspace(r.t[0], r.t[-1], 17), [r.t[-1]]]) for r in runs]
    batched = evaluate_runs(runs, times)
    each = np.concatenate([r(tt) for r, tt in zip(runs, times)], axis=1)
    np.testing.assert_array_equal(batched, each)
    # read in place on the integration's store, a subset of the runs too (the landings of
    # complete_events), and the same as runs that are copies with no store (joined first)
    from labtool.models.dynamics.kernels.dopri5 import DenseRun, evaluate_at_runs
    assert all(r.store is runs[0].store for r in runs)
    subset = runs[1::2]
    which = np.repeat(np.arange(len(subset)), [tt.size for tt in times[1::2]])[::-1].copy()
    tt_subset = np.concatenate(times[1::2])[::-1].copy()
    in_place = evaluate_at_runs(subset, which, tt_subset)
    each_subset = np.concatenate([subset[w](np.array([tt])) for w, tt in zip(which, tt_subset)], axis=1)
    np.testing.assert_array_equal(in_place, each_subset)
    copies = [DenseRun(r.t0s.copy(), r.hs.copy(), r.y0s.copy(), r.Qs.copy(), float(r.t[-1])) for r in subset]
    np.testing.assert_array_equal(evaluate_at_runs(copies, which, tt_subset), each_subset)
    # the merged output instants read the store in place too, and equal those of copies
    from labtool.models.dynamics.kernels.dopri5 import shared_store
    copied = [(ph, DenseRun(r.t0s.copy(), r.hs.copy(), r.y0s.copy(), r.Qs.copy(), float(r.t[-1]))) for ph, r in segs]
    assert shared_store(runs) is not None and shared_store([r for _, r in copied]) is None
    for in_store, joined in zip(elastic._outputs(tab, segs), elastic._outputs(tab, copied)):
        np.testing.assert_array_equal(in_store, joined)
    # the boundary instant belongs to both runs, each with its own state (the restart is nudged)
    end0 = runs[0](np.array([runs[0].t[-1]]))[0, 0]
    start1 = runs[1](np.array([runs[1].t[0]]))[0, 0]
    assert runs[0].t[-1] == runs[1].t[0] and end0 != start1


def test_elastic_dataset_static_moment_is_the_kinetostatic_moment():
    scene = paper_scene(cam_speed=300 * RPM, Fu=65.0, jt_factor=4.0, backlash=0.016e-3, omega1_mode="var")
    ds = simulate(scene, "elastic").dataset
    phi1 = ds["phi1"].values
    *_, MR13D, _ = _reference(scene, np.minimum(phi1, np.nextafter(scene.program.rise_angle, 0.0)),
                              elastic.cam_speed(scene))
    np.testing.assert_allclose(ds["MR13D_static"].values, MR13D, rtol=0, atol=1e-10 * np.abs(MR13D).max())


def test_rigid_plant_tables_are_shared_and_a_warm_run_equals_a_cold_one():
    from labtool.models.dynamics import rigid

    a = paper_scene(cam_speed=180 * RPM, Fu=0.0, jt_factor=1.0, backlash=0.016e-3)
    b = paper_scene(cam_speed=300 * RPM, Fu=65.0, jt_factor=4.0, backlash=0.128e-3)
    memo.clear_cache()
    cold = simulate(b, "rigid").indicators
    pa, _ = rigid.build_model(a)
    pb, _ = rigid.build_model(b)
    assert pa.cam is pb.cam and pa.fol is pb.fol              # one table for every operating point
    assert not pa.cam.flags.writeable and not pa.fol.flags.writeable
    warm = simulate(b, "rigid").indicators
    assert warm == cold                                        # bit for bit


@pytest.mark.parametrize("law,rise_only", [("sine", True), ("modtrap", True), ("cosine", False)])
def test_compiled_step_terms_equal_angle_terms_with_the_stroke_spline(law, rise_only):
    # output_terms' compiled pass (the spline in scipy's order of operations, pitch_geometry
    # compiled) against cam_tables.angle_terms(linkage="spline") at the solver's step instants
    # and the cached grid at the others; the pressure angle through libm's atan2, not numpy's
    s = paper_scene(law=law, backlash=0.016e-3, omega1_mode="var", rise_only=rise_only, revolutions=1)
    run = elastic._solve(s, "consistent", None, None, None, raw=True)
    t, _, _, _, grid_index = elastic._raw_outputs(run.tab, run.raw)
    steps = grid_index < 0
    assert steps.sum() > 100 and (~steps).sum() > 100
    got, arm, factors = elastic.output_terms(s, run.tab, t, grid_index)
    want = cam_tables.angle_terms(s.mechanism, s.program, run.tab.omega1 * t[steps], elastic._until(s),
                                  linkage="spline")
    grid = elastic._grid_terms(s, run.tab.omega1, float(run.tab.t[-1]))
    for name in elastic._TERMS:
        a, b = getattr(got, name), getattr(want, name)
        if name == "alpha":
            np.testing.assert_allclose(a[steps], b, rtol=0, atol=1e-15)   # rad; libm vs numpy
        else:
            np.testing.assert_array_equal(a[steps], b, err_msg=name)
        np.testing.assert_array_equal(a[~steps], getattr(grid, name)[grid_index[~steps]], err_msg=name)
    # the arm l cos(alpha) and eq. (16)'s factors from the block's own alpha, Db1, Db2, in numpy
    want_arm = s.mechanism.l * np.cos(got.alpha)
    np.testing.assert_allclose(arm, want_arm, rtol=2.3e-16, atol=0)
    Db1, Db2 = got.Db1, got.Db2
    through_a = ~(Db1 > 0)
    with np.errstate(divide="ignore"):
        np.testing.assert_array_equal(factors[0], np.where(through_a, np.inf, 4.0 / Db1**2))
    np.testing.assert_array_equal(factors[1], 4.0 / Db2**2)
    np.testing.assert_array_equal(factors[2], np.where(through_a, 0.0, Db1**2 / Db2**2))
    np.testing.assert_allclose(factors[3], 1.0 / want_arm, rtol=4.5e-16, atol=0)


@pytest.mark.slow
def test_compiled_step_terms_refuse_a_stroke_beyond_the_spline():
    s = paper_scene()
    sp = cam_tables.stroke_spline(s.mechanism)
    phi2_0 = s.mechanism.phiD + s.mechanism.psi0
    psi = np.array([0.0, sp.x[-1] - phi2_0 + 1e-9])          # the second angle just past the last knot
    out = np.empty((elastic._BLOCK_ROWS, 2))
    args = (np.empty((elastic._BLOCK_ROWS, 1)), np.array([-1, -1]), psi, np.zeros(2), np.zeros(2), np.ones(2), phi2_0,
            sp.x, sp.c, float(s.mechanism.xD), float(s.mechanism.yD), float(s.mechanism.l), 1.0, out)
    assert not elastic._step_terms(*args)
    psi[1] = sp.x[-1] - phi2_0                                 # on the last knot: inside, scipy's last interval
    assert elastic._step_terms(*args)
    np.testing.assert_array_equal(out[4:7, 1], sp(sp.x[-1])[:3])
    with pytest.raises(ValueError, match="rows"):                # a block too small is refused, not overrun
        elastic._step_terms(*args[:-1], np.empty((len(elastic._TERMS), 2)))
