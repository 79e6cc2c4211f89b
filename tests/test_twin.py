"""The stand's twin (labtool.models.dynamics.twin) against independent facts: energy, the bending mode's closed
form, the contact law's static deflection, the elastic and rigid models where they are exact, the
kinematic limit, streaming, and the defaults docs/twin.md promises."""
import math

import numpy as np
import pytest

from labtool.models.dynamics import events as model_events

from labtool.common.errors import InputError, SolverError
from labtool.models.dynamics import elastic, rigid, twin
from labtool.models.dynamics.contact import contact_potential, static_penetration
from labtool.models.dynamics.kernels import twin_nb as nb
from labtool.models.study.paper import paper_scene
from labtool.models.mechanism import Mechanism
from labtool.models.mechanism.cam_profile import cached_sense
from labtool.models.mechanism.kinematics import follower_motion
from labtool.models.mechanism.linkage import linkage_state
from labtool.common.units import RPM

OFF = dict(friction_torque=0.0, friction_radius=0.0)          # no pivot friction
PLAIN = dict(drive="input", ripple=0.0, mode_mass_share=0.0, warmup_revolutions=0, **OFF)


def _potential_energy(mech, sense, phi1, phi2):
    """Gravity potential (J) of the cam and the follower side from the mass centres' heights
    (labtool.models.mechanism.linkage positions): independent of the tabulated gravity moments."""
    st = linkage_state(mech, phi2, np.zeros_like(phi2), np.zeros_like(phi2))
    y = mech.m2 * st.K2[1] + mech.m3 * st.C[1] + mech.m4 * st.K4[1] + mech.m5 * st.K5[1]
    y_cam = mech.m1 * mech.AK1 * np.sin(mech.theta10 + sense * phi1)
    return mech.g * (y + y_cam)


def _energy(run, s):
    """Kinetic + bending + contact + gravity energy (J) of twin samples s."""
    P, mech = run.plant, run.scene.mechanism
    fol = np.zeros(4)
    Jr = np.empty(s["phi2"].size)
    for i, phi2 in enumerate(s["phi2"]):
        nb.follower_eval(*P.follower, phi2, fol)
        Jr[i] = P.p[nb.P_JT] * fol[0] - P.p[nb.P_MB] * mech.DE ** 2
    kc, j = P.p[nb.P_KC], P.p[nb.P_GAP]
    sense = cached_sense(mech, run.scene.program)
    return (0.5 * P.p[nb.P_JCAM] * s["omega1"] ** 2 + 0.5 * Jr * s["omega2"] ** 2 + 0.5 * P.p[nb.P_MB] * s["vE"] ** 2
            + 0.5 * P.p[nb.P_KB] * s["u_bend"] ** 2 + contact_potential(-s["gap"], kc) + contact_potential(s["gap"] - j, kc)
            + _potential_energy(mech, sense, s["phi1"], s["phi2"]))


def test_energy_is_conserved_with_damping_friction_and_motor_off():
    """A free-running cam, the follower bouncing through the 0.128 mm backlash (> 100 contact
    events), gravity on: the total energy stays constant to 1e-5 of the follower's kinetic energy."""
    scene = paper_scene(cam_speed=300 * RPM, backlash=0.128e-3, contact_damping=0.0, accuracy="standard")
    run = twin.TwinRun(scene, twin.TwinPhysics(mode_zeta=0.0, warmup_revolutions=0, **OFF))
    run.plant.p[nb.P_SLOPE] = 0.0                      # the motor off: nothing does work
    s = run.sample(np.arange(0.0, 0.4, 2e-5))
    E = _energy(run, s)
    ke_follower = 0.5 * 7.7e-3 * np.max(s["omega2"]) ** 2
    assert len(run.take_events()["event_time"]) > 100
    assert np.max(np.abs(E - E[0])) < 1e-5 * ke_follower, np.max(np.abs(E - E[0]))


def test_energy_lost_is_what_the_contact_damping_takes():
    """With Hunt-Crossley damping (the motor off, no friction, no modal damping) the energy never
    rises, it stays constant while the follower flies through the gap (no force can take it), and
    the impacts take it."""
    scene = paper_scene(cam_speed=300 * RPM, backlash=0.128e-3, contact_damping=40.0, accuracy="standard")
    run = twin.TwinRun(scene, twin.TwinPhysics(mode_zeta=0.0, warmup_revolutions=0, **OFF))
    run.plant.p[nb.P_SLOPE] = 0.0
    t = np.arange(0.0, 0.1, 2e-5)
    s = run.sample(t)
    E = _energy(run, s)
    dE = np.diff(E)
    flight = (s["contact_phase"][1:] == nb.FLIGHT) & (s["contact_phase"][:-1] == nb.FLIGHT)
    assert flight.sum() > 100 and np.max(np.abs(dE[flight])) < 1e-9
    assert np.all(dE < 1e-8)                             # never gains energy
    assert E[0] - E[-1] > 1e-3                           # the impacts took some


def test_bending_mode_frequency_in_flight_is_its_closed_form():
    """The follower floating in a wide gap (cam in a dwell, no gravity): the modal mass m_b on k_b
    against the rest of the follower J_r oscillates at sqrt(k_b kappa - (c_b kappa / 2)^2),
    kappa = 1/m_b + DE^2/J_r."""
    mech = Mechanism.default().replace(g=0.0)
    scene = paper_scene(cam_speed=180 * RPM, backlash=5e-3, contact_damping=0.0, accuracy="standard", mechanism=mech)
    physics = twin.TwinPhysics(drive="input", ripple=0.0, **OFF)
    run = twin.TwinRun(scene, physics, start=dict(phi1=math.radians(120), q=2.5e-3 / 0.06, phase=nb.FLIGHT, u=1e-6))
    t = np.arange(0.0, 0.02, 1e-6)
    s = run.sample(t)
    u = s["u_bend"]
    z = np.flatnonzero((u[:-1] < 0) & (u[1:] >= 0))
    tz = t[z] - u[z] * (t[z + 1] - t[z]) / (u[z + 1] - u[z])
    f_measured = (tz.size - 1) / (tz[-1] - tz[0])
    P = run.plant
    fol = np.zeros(4)
    nb.follower_eval(*P.follower, s["phi2"][0], fol)
    mb, kb, cb = P.p[nb.P_MB], P.p[nb.P_KB], P.p[nb.P_CB]
    Jr = P.p[nb.P_JT] * fol[0] - mb * mech.DE ** 2
    kappa = 1.0 / mb + mech.DE ** 2 / Jr
    f_closed = math.sqrt(kb * kappa - (cb * kappa / 2) ** 2) / (2 * math.pi)
    assert not len(run.take_events()["event_time"])      # it never touched a flank
    assert f_measured == pytest.approx(f_closed, rel=1e-4)
    assert math.sqrt(kb / mb) / (2 * math.pi) == pytest.approx(physics.mode_hz, rel=1e-12)  # the held-root mode


def test_static_deflection_in_the_upper_dwell_is_the_contact_laws():
    """At rest on the exterior flank through the upper dwell, gravity's moment is carried by the
    flank: g - j = (F / Kc)^(9/10) with F = |M_gravity| / A2."""
    scene = paper_scene(cam_speed=180 * RPM, backlash=0.128e-3, contact_damping=40.0, accuracy="standard")
    run = twin.TwinRun(scene, twin.TwinPhysics(ripple=0.0, **OFF))
    T = 60.0 / 180.0
    s = run.sample(np.array([(1 + 150 / 360) * T]), accelerations=True)
    cam, fol = np.zeros(6), np.zeros(4)
    nb.cam_eval(*run.plant.cam, math.radians(150), cam)
    nb.follower_eval(*run.plant.follower, s["phi2"][0], fol)
    force = abs(fol[2]) / cam[2]
    assert s["contact_phase"][0] == nb.EXTERIOR and abs(s["omega2"][0]) < 1e-5
    assert s["gap"][0] - scene.backlash == pytest.approx(static_penetration(force, run.plant.p[nb.P_KC]), rel=1e-3)
    assert -s["contact_force"][0] == pytest.approx(force, rel=1e-3)


def _elastic_and_twin(rpm, backlash, damping, accuracy="standard"):
    # the cam as input in both (the elastic model's reduced mass with an immovable cam: M = M2)
    mech = Mechanism.default().replace(Jm=1e3)
    scene = paper_scene(cam_speed=rpm * RPM, backlash=backlash, contact_damping=damping, accuracy=accuracy,
                  omega1_mode="const", mechanism=mech, rise_only=True)
    ds = elastic.simulate(scene).dataset
    run = twin.TwinRun(scene, twin.TwinPhysics(**PLAIN))
    return ds, run.sample(ds["time"].values), run.take_events()


@pytest.mark.parametrize("rpm", [180, 300])
def test_converges_to_the_elastic_model_where_its_linearisation_is_exact(rpm):
    """The twin with its extra effects off (no bending mode, friction, drive, ripple; the cam as
    input) and the gap closed is the elastic model's system: the same event (the interior flank
    let go for the exterior one at mid-rise, within 2 us) and omega2 within the standard preset's
    stated 1e-4."""
    ds, s, ev = _elastic_and_twin(rpm, 0.0, 20.0)
    el = model_events.read(ds)
    t_el = el["event_time"].values
    assert list(el["event_kind"].values) == ["separation"] and list(el["event_side"].values) == ["interior"]
    # with j = 0 a change of flank is a separation only (labtool.models.dynamics.events), as the elastic model's
    assert list(ev["event_kind"]) == ["separation"] and list(ev["event_side"]) == ["interior"]
    assert ev["event_time"][0] == pytest.approx(t_el[0], abs=2e-6)
    w = ds["omega2"].values
    assert np.max(np.abs(s["omega2"] - w)) / np.max(np.abs(w)) < 1e-4


def test_the_flight_across_the_gap_converges_to_the_rigid_models():
    """Across the 0.128 mm backlash the twin's free flight is the rigid model's (the same geometry
    g = A2 q, eqs 4-7): as the contact stiffens the lift-off and the landing converge to the rigid
    model's instants. (The elastic model lands 87 us = 1.5 % of the flight later than both: its
    relative equation M x'' = -R31 leaves out the transport terms of x = A2(phi1) q, docs/twin.md.)"""
    scene = paper_scene(cam_speed=180 * RPM, backlash=0.128e-3, restitution=0.5, accuracy="standard", omega1_mode="const",
                  rise_only=True)
    tr = rigid.simulate(scene).dataset["event_time"].values
    errors = []
    for kc in (1.0, 100.0, 1e4):
        run = twin.TwinRun(scene.replace(kc_factor=kc, contact_damping=20.0 / math.sqrt(kc)), twin.TwinPhysics(**PLAIN))
        run.sample(np.linspace(0.0, 0.034, 200))
        t = run.take_events()["event_time"]
        errors.append((abs(t[0] - tr[0]), abs(t[1] - tr[1])))
    assert errors[-1][0] < 5e-6 and errors[-1][1] < 1e-6
    assert errors[0][1] > errors[1][1] > errors[2][1] or errors[2][1] < 1e-7
    _, _, ev = _elastic_and_twin(180, 0.128e-3, 20.0)
    assert abs(ev["event_time"][1] - tr[1]) < 2e-5


@pytest.mark.slow
@pytest.mark.parametrize("drive", ["input", "motor"])
def test_kinematic_limit_at_low_speed_without_backlash(drive):
    """10 rpm, no backlash, every twin effect on: the follower follows the cam. omega2 equals the
    kinematics (labtool.models.mechanism.kinematics.follower_motion) at the twin's own cam motion to 2e-5,
    phi2 to 1e-6 rad; with the cam as input phi1 is the kinematic truth's ripple law."""
    scene = paper_scene(cam_speed=10 * RPM, backlash=0.0, contact_damping=40.0, accuracy="fast")
    run = twin.TwinRun(scene, twin.TwinPhysics(drive=drive, ripple=0.005))
    T = 6.0
    t = np.linspace(0.0, T, 4001)
    s = run.sample(t)
    eps1 = np.gradient(s["omega1"], t)
    phi2, omega2, _, _ = follower_motion(scene.program, scene.mechanism, s["phi1"], s["omega1"], eps1)
    assert np.max(np.abs(s["omega2"] - omega2)) / np.max(np.abs(omega2)) < 2e-5
    assert np.max(np.abs(s["phi2"] - phi2)) < 1e-6
    W = scene.omega1_nominal
    ripple_law = W * t + 0.005 * (1 - np.cos(W * t))
    assert np.max(np.abs(s["phi1"] - ripple_law)) < (1e-9 if drive == "input" else 5e-4)


def test_streaming_does_not_depend_on_the_blocks():
    """The same trajectory and events whether sampled at once or in uneven blocks."""
    scene = paper_scene(cam_speed=500 * RPM, backlash=0.128e-3, contact_damping=40.0, accuracy="fast")
    t = np.arange(0.0, 0.3, 5e-5)
    a = twin.TwinRun(scene)
    sa = a.sample(t)
    b = twin.TwinRun(scene)
    cuts = [0, 1, 7, 1000, 1001, 2500, 4999, t.size]
    parts = [b.sample(t[i:j]) for i, j in zip(cuts[:-1], cuts[1:])]
    for key in ("phi1", "omega2", "vE", "gap"):
        np.testing.assert_array_equal(np.concatenate([p[key] for p in parts]), sa[key])
    ea, eb = a.take_events(), b.take_events()
    np.testing.assert_array_equal(ea["event_time"], eb["event_time"])
    with pytest.raises(ValueError):
        b.sample(np.array([0.1]))                           # requests may not go back in time


def test_default_stand_jumps_in_the_rise_second_half_and_rests_in_the_upper_dwell():
    """docs/twin.md's promise at 180 rpm: lift-off from the interior flank in the second half of the
    rise, the first impact on the exterior flank a few degrees later, a few visible impacts, rest
    (one lasting contact, no impact above 1 mm/s) through the upper dwell; the same every turn."""
    scene = paper_scene(cam_speed=180 * RPM, backlash=0.128e-3, contact_damping=40.0, accuracy="fast")
    run = twin.TwinRun(scene)
    T = 60.0 / 180.0
    run.sample(np.linspace(0.0, 3 * T, 31))
    ev = run.take_events()
    ang = np.degrees(ev["event_phi1"]) % 360.0
    turn = np.floor(ev["event_time"] / T)
    for k in range(3):
        e = turn == k
        lift = e & (ev["event_kind"] == "separation") & ev["event_persistent"] & (ang < 58.0)
        hits = e & (ev["event_kind"] == "contact") & (ev["event_side"] == "exterior") & (ang < 58.0)
        assert lift.sum() == 1 and 27.0 <= ang[lift][0] < 58.0   # where the inertia moment changes sign (29 deg, gravity a hair earlier)
        assert 30.0 < ang[hits].min() < 40.0 and ev["event_v_rel"][hits].max() > 0.03
        visible = e & (ev["event_kind"] == "contact") & (np.abs(ev["event_domega2"]) > 0.05)
        assert 2 <= visible.sum() <= 10
        dwell = e & (ev["event_kind"] == "contact") & (ang > 70.0) & (ang < 180.0)
        assert not np.any(ev["event_v_rel"][dwell] > 1e-3)


def test_simulate_dataset_carries_the_event_record():
    scene = paper_scene(cam_speed=300 * RPM, backlash=0.128e-3, contact_damping=40.0, accuracy="fast", revolutions=1.0)
    ds = twin.simulate(scene, duration=0.2, output_step=1e-4)
    for name in ("event_time", "event_phi1", "event_kind", "event_side", "event_v_rel", "event_domega2",
                 "event_percussion", "event_persistent"):
        assert ds[name].dims == ("event",) and "units" in ds[name].attrs
    kinds = set(ds["event_kind"].values)
    assert kinds <= {"separation", "contact"} and len(kinds) == 2
    contact = ds["event_kind"].values == "contact"
    persistent = ds["event_persistent"].values
    assert np.isnan(ds["event_percussion"].values[~contact]).all() and (ds["event_percussion"].values[contact] >= 0).all()
    assert (ds["event_v_rel"].values >= 0).all()
    # labtool.models.dynamics.events: a lift-off changes nothing (domega2 0), a rebound's separation has none
    assert (ds["event_domega2"].values[~contact & persistent] == 0).all()
    assert np.isnan(ds["event_domega2"].values[~contact & ~persistent]).all()
    # a separation is persistent exactly when the contact it ends was
    rows = list(zip(ds["event_kind"].values, persistent))
    for (k0, p0), (k1, p1) in zip(rows[:-1], rows[1:]):
        if k0 == "contact" and k1 == "separation":
            assert p0 == p1
    # the sensor's acceleration integrates to its speed: aE_t is d(vE)/dt
    dt = ds["time"].values[1] - ds["time"].values[0]
    vE = ds["vE"].values
    np.testing.assert_allclose(np.cumsum(ds["aE_t"].values[1:] + ds["aE_t"].values[:-1]) * dt / 2 + vE[0], vE[1:],
                               atol=0.02 * np.abs(vE).max())
    assert ds.attrs["truth_mode_hz"] == 1200.0 and ds.attrs["twin_Kc_SI"] > 0


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("kw", [dict(drive="belt"), dict(ripple=0.6), dict(mode_hz=0), dict(mode_zeta=1.0),
                                dict(mode_mass_share=0.95), dict(friction_torque=-1), dict(friction_radius=float("nan")),
                                dict(friction_speed=0), dict(persistence_s=0), dict(warmup_revolutions=2.5),
                                dict(warmup_revolutions=-1)])
def test_impossible_physics_is_refused(kw):
    with pytest.raises(InputError):
        twin.TwinPhysics(**kw)


@pytest.mark.hostile("hang")
def test_a_motor_that_cannot_drive_the_load_ends_in_a_solver_error():
    scene = paper_scene(cam_speed=180 * RPM, Fu=5e5, backlash=0.128e-3, contact_damping=40.0, accuracy="fast")
    with pytest.raises(SolverError, match="stalled|twin"):
        run = twin.TwinRun(scene)
        run.sample(np.linspace(0.0, 2.0, 50))


@pytest.mark.slow
@pytest.mark.parametrize("rpm", [180, 500])
def test_the_stands_fast_preset_against_the_reference(rpm):
    """The truth's own accuracy (docs/twin.md): the 'fast' preset the stand
    uses has the reference preset's events, one for one, within 5e-5 s, and omega2 within 1e-4 away
    from them (measured 1.2e-5 / 4.2e-5 s and 1.4e-5 / 3.3e-5 at 180 / 500 rpm)."""
    T = 60.0 / rpm
    t = np.arange(0.0, 2 * T, 2e-5)
    out = {}
    for acc in ("fast", "reference"):
        run = twin.TwinRun(paper_scene(cam_speed=rpm * RPM, backlash=0.128e-3, contact_damping=40.0, accuracy=acc))
        out[acc] = (run.sample(t), run.take_events())
    (s, e), (sr, er) = out["fast"], out["reference"]
    assert list(e["event_kind"]) == list(er["event_kind"]) and list(e["event_side"]) == list(er["event_side"])
    assert np.max(np.abs(e["event_time"] - er["event_time"])) < 5e-5
    away = np.ones(t.size, bool)
    for x in np.concatenate([e["event_time"], er["event_time"]]):
        away &= np.abs(t - x) > 2e-4
    assert np.max(np.abs(s["omega2"] - sr["omega2"])[away]) < 1e-4 * np.max(np.abs(sr["omega2"]))
