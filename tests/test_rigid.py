"""Rigid-element model (paper sec. 2.1.1): impact law, energy, j = 0 limit, Zeno, omega1 modes."""
import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from labtool.models.dynamics import events, rigid, rigid_tables
from labtool.models.dynamics.contact import contact_stiffness, static_penetration
from labtool.models.mechanism.cam_profile import contact_geometry
from labtool.common.errors import InputError
from labtool.models.dynamics.impact import impact, kinetic_energy, paper_eq10
from labtool.models.mechanism.kinematics import analyze, load_force_x
from labtool.models.mechanism.linkage import reduced_follower
from labtool.models.mechanism.motor import motor_moment_on_cam, no_load_cam_speed
from labtool.models.study.paper import paper_scene
from labtool.common.units import RPM

finite = dict(allow_nan=False, allow_infinity=False)


# --- the impact law, eqs (8)-(11) -------------------------------------------------------------
@settings(max_examples=200, deadline=None)
@given(w1=st.floats(0.1, 50, **finite), w2=st.floats(-20, 20, **finite), A1=st.floats(1e-3, 0.05, **finite),
       A2=st.floats(0.02, 0.07, **finite), Jc=st.floats(1e-3, 1.0, **finite), Jf=st.floats(1e-4, 0.1, **finite),
       k=st.floats(0.0, 1.0, **finite))
def test_impact_law_is_papers_eq10_and_newton(w1, w2, A1, A2, Jc, Jf, k):
    w1a, w2a, P, vb, va = impact(w1, w2, A1, A2, 1.0 / Jc, Jf, k)
    p1, p2, pP = paper_eq10(w1, w2, A1, A2, Jc, Jf, k)
    assert w1a == pytest.approx(p1, rel=1e-9, abs=1e-9)
    assert w2a == pytest.approx(p2, rel=1e-9, abs=1e-9)
    assert -P == pytest.approx(pP, rel=1e-9, abs=1e-12)          # the paper's sign: impulse on the cam
    # Newton's law on the normal velocity of C, recomputed from the speeds after the impact
    assert A2 * w2a - A1 * w1a == pytest.approx(-k * vb, rel=1e-9, abs=1e-12)
    assert va == -k * vb
    # momentum-like balance about each pivot: J dw = moment of the percussion
    assert Jf * (w2a - w2) == pytest.approx(P * A2, rel=1e-9, abs=1e-12)
    assert Jc * (w1a - w1) == pytest.approx(-P * A1, rel=1e-9, abs=1e-12)
    T0, T1 = kinetic_energy(w1, w2, Jc, Jf), kinetic_energy(w1a, w2a, Jc, Jf)
    if k == 1.0:
        assert T1 == pytest.approx(T0, rel=1e-12)
    else:  # loss = (1 - k^2)/2 * v^2 / (A2^2/Jf + A1^2/Jc)
        assert T0 - T1 == pytest.approx(0.5 * (1 - k * k) * vb**2 / (A2**2 / Jf + A1**2 / Jc), rel=1e-6, abs=1e-12)


# --- geometry of the gap: the arms are the paper's Db1/2, Db2/2 --------------------------------
def test_arms_match_contact_geometry_and_kinematics():
    sc = paper_scene()
    P, info = rigid.build_model(sc)
    phi = np.linspace(0.0, sc.program.rise_angle, 301)
    psi, d1, d2, A2, dA2, ddA2, Mc, dirn = rigid.cam_columns(P, phi)
    geo = contact_geometry(sc.mechanism, sc.program, phi)
    np.testing.assert_allclose(A2, geo["Db2"] / 2, rtol=1e-9)                 # A2 = l cos(alpha)
    A2x, A1x = rigid_tables._arms(sc.mechanism, info["sense"], psi, d1)
    np.testing.assert_allclose(A1x, A2 * d1, atol=1e-12)                        # no normal slip in contact
    np.testing.assert_allclose(np.abs(A1x), geo["Db1"] / 2, atol=1e-12)
    # A2' and A2'' of the table against finite differences of the exact A2
    h = 1e-5
    a = lambda x: geo_a2(sc, x)  # noqa: E731
    np.testing.assert_allclose(dA2[1:-1], ((a(phi + h) - a(phi - h)) / (2 * h))[1:-1], atol=1e-7)
    np.testing.assert_allclose(ddA2[5:-5], ((a(phi + h) - 2 * a(phi) + a(phi - h)) / h**2)[5:-5], atol=2e-4)


def geo_a2(sc, phi):
    return contact_geometry(sc.mechanism, sc.program, phi)["Db2"] / 2


# --- the 1-DOF model (j = 0) -------------------------------------------------------------------
def test_const_speed_contact_is_the_kinetostatic_model():
    """omega1 const, j = 0: the follower follows the law and MR13D is labtool.models.mechanism.kinematics' value."""
    sc = paper_scene(omega1_mode="const", backlash=0.0, Fu=65.0, jt_factor=4.0, cam_speed=300 * RPM)
    ds = rigid.simulate(sc).dataset
    assert np.all(ds["contact"].values != 0) and ds.sizes["event"] == 0
    np.testing.assert_allclose(ds["omega1"], sc.omega1_nominal, rtol=1e-12)
    phi1 = ds["phi1"].values[:-1]     # the rise's end belongs to the dwell in labtool.models.mechanism.kinematics
    kin = analyze(sc.mechanism, sc.program, 300, 65.0, 4.0, phi1=phi1)
    np.testing.assert_allclose(ds["phi2"].values[:-1], kin["phi2"], atol=1e-10)
    np.testing.assert_allclose(ds["omega2"].values[:-1], kin["omega2"], atol=1e-8)
    np.testing.assert_allclose(ds["MR13D"].values[:-1], kin["MR13D"], atol=1e-6 * abs(kin["MR13D"]).max().item())


@pytest.mark.slow
def test_variable_speed_power_balance():
    """omega1 var, j = 0: d/dt(1/2 J' w1^2 + 1/2 J'' w2^2) = motor + cam gravity + gravity + load power,
    each term from labtool.models.mechanism.motor / labtool.models.mechanism.linkage (not from the model's tables)."""
    sc = paper_scene(backlash=0.0, Fu=65.0, jt_factor=4.0, cam_speed=300 * RPM, accuracy="reference")
    ds = rigid.simulate(sc).dataset
    mech = sc.mechanism
    t, w1, w2 = ds["time"].values, ds["omega1"].values, ds["omega2"].values
    phi1, phi2 = ds["phi1"].values, ds["phi2"].values
    red = reduced_follower(mech, phi2, load_force_x(mech, sc.program, phi1, phi2, sc.Fu), sc.jt_factor)
    T = 0.5 * ds.attrs["J_cam_kgm2"] * w1**2 + 0.5 * red.J * w2**2
    M1 = motor_moment_on_cam(mech, w1, ds.attrs["transmission_ratio"])
    Mc = -mech.m1 * mech.g * mech.AK1 * ds.attrs["cam_sense"] * np.cos(mech.theta10 + ds.attrs["cam_sense"] * phi1)
    power = (M1 + Mc) * w1 + (red.M_gravity + red.M_load) * w2
    work = np.concatenate([[0.0], np.cumsum(0.5 * (power[1:] + power[:-1]) * np.diff(t))])
    scale = np.trapezoid(np.abs(power), t)
    assert np.max(np.abs((T - T[0]) - work)[:-1]) < 1e-4 * scale
    # and MR13D is the reaction that moves elements 2-5: J'' eps2 + 1/2 dJ'' w2^2 - Mg - ML
    mr = red.J * ds["epsilon2"].values + 0.5 * red.dJ * w2**2 - red.M_gravity - red.M_load
    np.testing.assert_allclose(ds["MR13D"].values[:-1], mr[:-1], atol=1e-6 * np.abs(mr).max())


def test_backlash_without_sign_change_is_the_no_backlash_run():
    """Run 9 of Table 1 (MR13D > 0 over the rise): no jump, the j > 0 run equals the j = 0 one."""
    res = rigid.simulate(paper_scene(Fu=65.0, backlash=0.128e-3))
    ind = res.indicators
    assert ind["jumps"] == 0 and ind["impacts"] == 0
    assert ind["dphi2_max_deg"] == 0.0 and ind["domega2_max_rad_s"] == 0.0 and ind["domega1_max_rad_s"] == 0.0
    assert ind["MR13D_min_Nm"] > 0


def test_j0_never_jumps_even_when_MR13D_changes_sign():
    ind = rigid.simulate(paper_scene(backlash=0.0)).indicators
    assert ind["MR13D_max_Nm"] > 0 > ind["MR13D_min_Nm"]
    assert ind["jumps"] == 0 and ind["impacts"] == 0


# --- impacts in the simulation ------------------------------------------------------------------
@pytest.mark.parametrize("backlash_mm,jt", [(0.016, 1.0), (0.128, 4.0)])
def test_k1_conserves_energy_and_reverses_normal_velocity(backlash_mm, jt):
    sc = paper_scene(backlash=backlash_mm * 1e-3, jt_factor=jt, restitution=1.0)
    res = rigid.simulate(sc)
    ds = res.dataset
    P, _ = rigid.build_model(sc)
    impacts = np.nonzero(events.is_impact(ds) & ~ds["event_persistent"].values)[0]     # the rebounds
    assert impacts.size >= 3
    for i in impacts:
        Tb, Ta = ds["event_energy_before"].values[i], ds["event_energy_after"].values[i]
        assert Ta == pytest.approx(Tb, rel=1e-12)
        # recompute v_n before/after from the speeds and the flank's arms (not from the record)
        phi1 = ds["event_phi1"].values[i]
        flank = rigid.INNER if ds["event_side"].values[i] == events.INTERIOR else rigid.OUTER
        psi, d1, d2, A2, dA2, ddA2, *_ = rigid.cam_columns(P, phi1)[:, 0]
        q = 0.0 if flank == rigid.INNER else sc.backlash / A2
        G1 = A2 * d1 - dA2 * q
        vb = A2 * ds["event_omega2_before"].values[i] - G1 * ds["event_omega1_before"].values[i]
        va = A2 * ds["event_omega2_after"].values[i] - G1 * ds["event_omega1_after"].values[i]
        assert va == pytest.approx(-vb, rel=1e-9)
        assert vb * flank < 0        # closing on that flank
    # every impact happens exactly on a flank: the gap just before is 0 or j
    assert res.indicators["jumps"] >= res.indicators["impacts"]


@pytest.mark.parametrize("kw", [dict(backlash=0.128e-3, jt_factor=4.0),
                                dict(Fu=65.0, backlash=0.016e-3, jt_factor=4.0, restitution=0.5),
                                dict(Fu=65.0, backlash=0.128e-3, cam_speed=300 * RPM, restitution=0.8)])
def test_energy_balance_through_flights_and_impacts(kw):
    """Whole hybrid run (contact, flights, impacts): T(t) - T(0) = work of motor, cam gravity,
    follower gravity and load - the impacts' losses, all recomputed from labtool.models.mechanism.motor/linkage."""
    sc = paper_scene(**kw)
    ds = rigid.simulate(sc).dataset
    mech = sc.mechanism
    t, w1, w2 = ds["time"].values, ds["omega1"].values, ds["omega2"].values
    phi1, phi2 = ds["phi1"].values, ds["phi2"].values
    red = reduced_follower(mech, phi2, load_force_x(mech, sc.program, phi1, phi2, sc.Fu), sc.jt_factor)
    T = 0.5 * ds.attrs["J_cam_kgm2"] * w1**2 + 0.5 * red.J * w2**2
    s = ds.attrs["cam_sense"]
    M1 = motor_moment_on_cam(mech, w1, ds.attrs["transmission_ratio"])
    Mc = -mech.m1 * mech.g * mech.AK1 * s * np.cos(mech.theta10 + s * phi1)
    power = (M1 + Mc) * w1 + (red.M_gravity + red.M_load) * w2
    work = np.concatenate([[0.0], np.cumsum(0.5 * (power[1:] + power[:-1]) * np.diff(t))])
    ev_t = ds["event_time"].values
    loss = np.nan_to_num(ds["event_energy_before"].values - ds["event_energy_after"].values)
    lost = np.array([loss[ev_t <= ti].sum() for ti in t])
    assert ds.sizes["event"] >= 3
    scale = np.trapezoid(np.abs(power), t)
    tol = 5e-4 * scale                 # trapezoidal rule across the velocity jumps
    if sc.restitution < 1:
        assert lost[-1] > 2 * tol      # the losses are resolved by the check
    assert np.max(np.abs((T - T[0]) - (work - lost))) < tol


def test_restitution_law_exact_for_k_below_one():
    ds = rigid.simulate(paper_scene(restitution=0.6, backlash=0.128e-3)).dataset
    vb, va = ds["event_v_before"].values, ds["event_v_after"].values
    reb = events.is_impact(ds) & ~ds["event_persistent"].values
    assert reb.sum() >= 2
    np.testing.assert_array_equal(va[reb], -0.6 * vb[reb])


def _toy_model(a2=0.05, J=0.01, M=-0.5, k=0.5, j=1e-3, phi1_end=100.0):
    """A follower with constant inertia J and a constant moment M against the inner flank of a
    motionless groove (psi = 0, cam as input at 1 rad/s): the bouncing ball in angular form."""
    zeros = np.zeros((8, 1))
    v1 = zeros.copy()
    v1[3] = a2
    cam = rigid_tables.make_table([-1.0, 200.0], v1, v1, zeros, zeros).packed()
    v2 = np.array([[J], [0.0], [M], [0.0]])
    fol = rigid_tables.make_table([0.0, 10.0], v2, v2, np.zeros((4, 1)), np.zeros((4, 1))).packed()
    cam.flags.writeable = fol.flags.writeable = False      # as the model's shared tables: one compiled type
    return rigid.eq.RigidModel(cam, fol, 1.0, 1.0, 1.0, 0.0, True, 0.0, 0.0, 0.0, j, k, phi1_end,
                               contact_stiffness(6e-3))


@pytest.mark.parametrize("k", [0.3, 0.5, 0.8])
def test_zeno_accumulation_time_and_switch_to_contact(k):
    """Dropped from height h0: impacts at t1 = sqrt(2 h0/a), intervals 2 v0 k^n / a (ratio k), the
    accumulation point T = t1 + 2 k v0 / (a (1 - k)); the settle rule (labtool.models.dynamics.kernels.rigid_nb)
    ends the series at the first rebound whose apex v^2 / (2 a) lies below the contact deformation
    under the flank's force, delta = (|lam| / Kc)^(9/10): no later than T and no earlier than the
    flights the rule skips, 2 v_crit / (a (1 - k)) with v_crit = sqrt(2 a delta); then persistent
    contact on the flank."""
    a2, J, M, h0 = 0.05, 0.01, -0.5, 2e-4
    a = a2 * abs(M) / J                      # m/s^2 along the normal
    v0 = math.sqrt(2 * a * h0)
    t1 = math.sqrt(2 * h0 / a)
    T_acc = t1 + 2 * k * v0 / (a * (1 - k))
    P = _toy_model(a2, J, M, k, phi1_end=1.2 * T_acc)
    preset = dict(rigid.PRESETS["standard"])
    phases, rows = rigid.integrate(P, 1.0, preset, T_acc, start=("free", 0.0, 1.0, h0 / a2, 0.0))
    contact = rows[rows[:, events.COL_KIND] == events.KIND_CONTACT]
    times = contact[:, events.COL_TIME]
    assert contact[0, rigid.eq.COL_V_BEFORE] == pytest.approx(-v0, rel=1e-7)
    assert times[0] == pytest.approx(t1, rel=1e-7)
    gaps = np.diff(times)                    # every interval is a whole flight, the settle's included
    n = min(5, gaps.size - 1)
    assert n >= 1
    np.testing.assert_allclose(gaps[1:n + 1] / gaps[:n], k, rtol=1e-5)
    settle = contact[contact[:, events.COL_PERSISTENT] > 0]
    assert len(settle) == 1 and settle[0, events.COL_TIME] == rows[-1, events.COL_TIME]
    lam = abs(M) / a2                                            # the flank's force at rest (N)
    v_crit = math.sqrt(2 * a * static_penetration(lam, P.kc))
    bound = 2 * v_crit / (a * (1 - k))
    assert T_acc - bound - 1e-9 <= settle[0, events.COL_TIME] <= T_acc + 1e-9
    # the last rebound speed before the settle is above v_crit, the settling one's below it
    assert k * contact[-1, events.COL_V_REL] < v_crit < k * contact[-2, events.COL_V_REL]
    assert phases[-1].kind == "contact" and phases[-1].flank == rigid.INNER
    assert len(contact) < 60


def test_event_cap_raises_solver_error():
    P = _toy_model(k=0.999)
    preset = dict(rigid.PRESETS["standard"], max_events=50)
    with pytest.raises(rigid.SolverError, match="more than 50 contact events"):
        rigid.integrate(P, 1.0, preset, 1.0, start=("free", 0.0, 1.0, 2e-4 / 0.05, 0.0))


# --- omega1 constant vs variable ----------------------------------------------------------------
def test_omega1_const_vs_var_differ_by_what_the_motor_allows():
    sc = paper_scene(backlash=0.0, cam_speed=300 * RPM, jt_factor=4.0)
    var = rigid.simulate(sc).dataset
    const = rigid.simulate(sc.replace(omega1_mode="const")).dataset
    mech = sc.mechanism
    np.testing.assert_array_equal(const["omega1"].values, sc.omega1_nominal)
    w_nl = no_load_cam_speed(mech, sc.omega1_nominal)
    w1 = var["omega1"].values
    # var: the motor holds the cam near its no-load speed n1 * 1000/920 ...
    assert abs(np.mean(w1) - w_nl) < 0.1 * (w_nl - sc.omega1_nominal)
    # ... and gives way by at most the follower's torque on the cam over the characteristic's slope
    slope = (motor_moment_on_cam(mech, 0.0, var.attrs["transmission_ratio"]) - motor_moment_on_cam(mech, 1.0, var.attrs["transmission_ratio"]))
    torque_on_cam = np.abs(var["MR13D"].values * var["omega2"].values / w1)
    dev = np.abs(w1 - w1[0])
    assert 0 < dev.max() <= torque_on_cam.max() / slope + 1e-3
    # MR13D scales with the square of the cam speed: (1000/920)^2 between the modes when the
    # follower's torque is small; a heavy follower at 300 rpm makes the motor slip and the ratio drop
    def ratio(scene):
        return (rigid.simulate(scene).indicators["MR13D_max_Nm"]
                / rigid.simulate(scene.replace(omega1_mode="const")).indicators["MR13D_max_Nm"])
    light = ratio(paper_scene(backlash=0.0, cam_speed=180 * RPM, jt_factor=1.0))
    assert light == pytest.approx((mech.omega_sync_motor / mech.omega_nominal_motor) ** 2, rel=0.01)
    assert ratio(sc) < light - 0.02


# --- bad input ------------------------------------------------------------------------------------
@pytest.mark.parametrize("kw", [dict(backlash=-1e-6), dict(restitution=1.5), dict(restitution=-0.1),
                                dict(jt_factor=0.0)])
def test_bad_scene_is_input_error(kw):
    with pytest.raises(InputError):
        rigid.simulate(paper_scene(**kw))


def test_zero_follower_inertia_is_input_error():
    mech = paper_scene().mechanism
    zero = dataclasses.replace(mech, m2=0.0, J2=0.0, m3=0.0, m4=0.0, J4=0.0, m5=0.0, J5=0.0)
    with pytest.raises(InputError, match="inertia"):
        rigid.simulate(paper_scene(mechanism=zero))
