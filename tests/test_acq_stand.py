"""Simulated stand and measuring chain: truth vs independent facts, chain behaviour, determinism, faults."""
import math

import numpy as np
import pytest
from scipy import signal

from labtool.acquisition import signal_chain as sc
from labtool.acquisition.device import Event, parse_device
from labtool.acquisition.sim_stand import Fault, SimStand, board_rate, parse_fault
from labtool.common.errors import InputError
from labtool.models.mechanism.kinematics import analyze
from labtool.models.mechanism.linkage import linkage_state
from labtool.models.mechanism import Mechanism
from labtool.models.mechanism.motion_laws import CamProgram
from labtool.common.units import RPM


def record(scene=None, params=None, seed=1, duration=2.0, rate=10000.0, faults=()):
    dev = SimStand(scene or sc.StandScene(), params, seed=seed, duration_s=duration, realtime=False, faults=faults)
    dev.configure(rate)
    dev.start()
    blocks = []
    while (b := dev.read_block()) is not None:
        blocks.append(b)
    dev.stop()
    return dev, blocks


def test_truth_without_ripple_is_the_kinematic_analysis():
    scene = sc.StandScene(cam_speed=300 * RPM, ripple=0.0, truth_model="kinematic")
    W = scene.omega1_nominal
    phi1 = np.linspace(0, 2 * math.pi, 721)[:-1]
    ds = analyze(scene.mechanism, scene.program, 300.0, phi1=phi1)
    tr = sc.truth(scene, phi1 / W)
    for name in ("omega2", "epsilon2", "aE_t", "aE_n", "phi2"):
        np.testing.assert_allclose(tr[name], ds[name].values, rtol=1e-9, atol=1e-9)


def test_truth_with_ripple_is_consistent_by_finite_differences():
    scene = sc.StandScene(cam_speed=180 * RPM, ripple=0.02, truth_model="kinematic")
    t = np.linspace(0.0, 0.4, 400001)
    tr = sc.truth(scene, t)
    dt = t[1] - t[0]
    # omega1 = dphi1/dt, omega2 = dphi2/dt, epsilon2 = domega2/dt (central differences, smooth law)
    np.testing.assert_allclose(np.gradient(tr["phi1"], dt)[1:-1], tr["omega1"][1:-1], rtol=1e-6)
    np.testing.assert_allclose(np.gradient(tr["phi2"], dt)[1:-1], tr["omega2"][1:-1], atol=1e-4 * np.abs(tr["omega2"]).max())
    np.testing.assert_allclose(np.gradient(tr["omega2"], dt)[1:-1], tr["epsilon2"][1:-1], atol=2e-3 * np.abs(tr["epsilon2"]).max())
    # the tacho angle phi1 = 2 pi k exactly at t = k T
    T = 2 * math.pi / scene.omega1_nominal
    ph, _, _ = sc.cam_angle(scene, np.arange(5) * T)
    np.testing.assert_allclose(ph, 2 * math.pi * np.arange(5), atol=1e-12)


def test_gravity_component_matches_the_sensor_axes_from_the_linkage():
    mech = Mechanism.default()
    phi2 = np.linspace(1.4, 1.9, 11)
    h = 1e-6
    E0 = linkage_state(mech, phi2, 0.0, 0.0).E
    E1 = linkage_state(mech, phi2 + h, 0.0, 0.0).E
    t_hat = (E1 - E0) / np.linalg.norm(E1 - E0, axis=0)  # direction of increasing psi at E
    n_hat = (mech.D[:, None] - E0) / np.linalg.norm(mech.D[:, None] - E0, axis=0)  # towards D
    f_grav = np.array([0.0, mech.g])  # a resting accelerometer reads -g
    scene = sc.StandScene()
    z = np.zeros_like(phi2)
    f = sc.sensed_acceleration(scene, {"aE_t": z, "aE_n": z, "phi2": phi2})
    np.testing.assert_allclose(f[:, 0], f_grav @ t_hat, atol=1e-4)
    np.testing.assert_allclose(f[:, 1], f_grav @ n_hat, atol=1e-4)


@pytest.mark.slow
@pytest.mark.parametrize("truth_model", ["kinematic", "twin"])
def test_recorded_volts_times_ka_follow_the_truth_in_the_cam_band(truth_model):
    scene = sc.StandScene(cam_speed=180 * RPM, truth_model=truth_model)
    dev, blocks = record(scene, duration=2.0)
    v = np.concatenate([b.data for b in blocks]).astype(float)
    t = np.arange(v.shape[0]) / dev.actual_rate_hz
    tr = sc.truth(scene, t)
    f = sc.sensed_acceleration(scene, tr)
    ka = dev.params.ka_m_s2_per_v[0]
    dc = sc.dc_level(scene, dev.params) * ka
    sos = signal.butter(4, 300.0, fs=dev.actual_rate_hz, output="sos")
    for c in range(2):
        meas = signal.sosfiltfilt(sos, v[:, c] * ka)[2:]
        # the anti-alias filter delays the channels by ~1.8 samples (the twin's impacts fill the band)
        ref = signal.sosfiltfilt(sos, f[:, c] - dc[c])[:-2]
        err = np.sqrt(np.mean((meas - ref) ** 2)) / np.sqrt(np.mean(ref**2))
        assert err < 0.03, (c, err)


def test_tacho_rises_once_per_revolution_at_phi1_zero():
    scene = sc.StandScene(cam_speed=300 * RPM, truth_model="kinematic")
    dev, blocks = record(scene, duration=1.0)
    tach = np.concatenate([b.data for b in blocks])[:, 2]
    rises = np.flatnonzero((tach[1:] > 2.5) & (tach[:-1] <= 2.5)) + 1
    T = 60.0 / 300.0
    expected = np.round(np.arange(1, 5) * T * dev.actual_rate_hz)
    # the anti-alias filter delays every channel alike by a couple of samples
    assert len(rises) == 4
    assert np.all((rises - expected >= 0) & (rises - expected <= 3)), rises - expected
    assert tach[0] > 2.5  # phi1 = 0 at the first sample


def test_tacho_of_the_twin_rises_where_its_cam_completes_a_turn():
    """The twin's cam slips under load: the pulses follow its own phi1, not t = k T."""
    scene = sc.StandScene(cam_speed=300 * RPM)
    dev, blocks = record(scene, duration=1.0)
    tach = np.concatenate([b.data for b in blocks])[:, 2]
    rises = np.flatnonzero((tach[1:] > 2.5) & (tach[:-1] <= 2.5)) + 1
    t = np.arange(tach.size) / dev.actual_rate_hz
    turns = np.floor((sc.truth(scene, t)["phi1"] + sc.TACHO_ANGLE_TOL) / (2 * math.pi))
    expected = np.flatnonzero(np.diff(turns) > 0) + 1
    assert tach[0] > 2.5  # phi1 = 0 at the first sample
    assert len(rises) == len(expected) == 4
    assert np.all((rises - expected >= 0) & (rises - expected <= 3)), rises - expected


def test_chain_passes_the_calibration_frequency_at_unity_and_resonates():
    p = sc.ChainParams()
    h = sc.chain_frequency_response(p, 10000.0, [79.6, p.resonance_hz, 4900.0], resonant=True) * p.ka_m_s2_per_v[0]
    assert abs(abs(h[0]) - 1.0) < 1e-2  # below the mode: transmissibility 1 + (f/f_r)^2
    assert abs(h[1]) > 5.0  # a lightly damped mode (zeta 0.04) amplifies ~1/(2 zeta)
    assert abs(h[2]) < 0.05  # anti-alias near Nyquist
    h_cal = sc.chain_frequency_response(p, 10000.0, [79.6], resonant=False) * p.ka_m_s2_per_v[0]
    assert abs(abs(h_cal[0]) - 1.0) < 1e-4


def test_adc_quantizes_and_flags_clipping():
    p = sc.ChainParams(adc_range_v=10.0, adc_bits=16)
    v = np.array([[0.0, 1.2345678, -20.0], [9.9, 10.5, 3.0]])
    q, clipped = sc.adc(v, p)
    lsb = 20.0 / 2**16
    assert np.allclose(q / lsb, np.round(q / lsb), atol=1e-3)
    assert clipped.tolist() == [[False, False, True], [False, True, False]]
    assert q.max() <= 10.0 - lsb + 1e-6 and q.min() >= -10.0


@pytest.mark.slow
def test_same_seed_same_data_other_seed_other_noise():
    a = np.concatenate([b.data for b in record(seed=7, duration=0.5)[1]])
    b = np.concatenate([b.data for b in record(seed=7, duration=0.5)[1]])
    c = np.concatenate([b.data for b in record(seed=8, duration=0.5)[1]])
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    assert np.abs(a - c).max() < 0.1  # same truth, different noise


@pytest.mark.slow
def test_faults_lose_samples_but_keep_the_rest_identical():
    ref = np.concatenate([b.data for b in record(seed=2, duration=3.0)[1]])
    _, blocks = record(seed=2, duration=3.0, faults=[Fault("overrun", 1.0, 0.2), Fault("drop", 2.05)])
    events = [e for b in blocks for e in b.events]
    assert [e.kind for e in events] == ["overrun"]
    assert events[0].index == 10000
    firsts = [b.first_index for b in blocks]
    covered = np.zeros(ref.shape[0], bool)
    for b in blocks:
        covered[b.first_index:b.end_index] = True
        np.testing.assert_array_equal(b.data, ref[b.first_index:b.end_index])
    assert (~covered).sum() == 2000 + 1000  # 0.2 s overrun + one dropped 0.1 s block
    assert firsts == sorted(firsts)


@pytest.mark.slow
def test_clip_fault_and_disconnect():
    _, blocks = record(duration=1.0, faults=[Fault("clip", 0.5)])
    clips = [e for b in blocks for e in b.events if e.kind == "clip"]
    assert clips and clips[0].detail.startswith("aE_t") and 5000 <= clips[0].index < 5100
    from labtool.acquisition.device import DeviceDisconnected
    with pytest.raises(DeviceDisconnected):
        record(duration=1.0, faults=[Fault("disconnect", 0.3)])


def test_calibration_mode_is_a_sine_on_one_channel():
    scene = sc.StandScene(mode="calibration", cal_channel="aE_n", cal_freq=100.0)
    dev, blocks = record(scene, duration=0.5)
    v = np.concatenate([b.data for b in blocks]).astype(float)
    ka = dev.params.ka_m_s2_per_v[0]
    assert np.std(v[:, 1]) * ka == pytest.approx(9.81 / math.sqrt(2), rel=0.01)
    assert np.std(v[:, 0]) * ka < 0.3
    assert np.all(v[:, 2] == 0.0)


def test_realtime_pacing_with_a_fake_clock_and_overrun_when_the_reader_is_late():
    now = [0.0]
    dev = SimStand(seed=1, duration_s=5.0, realtime=True, buffer_s=1.0, clock=lambda: now[0],
                   sleep=lambda s: now.__setitem__(0, now[0] + s))
    dev.configure(10000)
    dev.start()
    b = dev.read_block()
    assert now[0] == pytest.approx(0.1)  # waited for the block's last sample
    now[0] += 2.5  # the reader stalls 2.5 s: more than the 1 s buffer
    b = dev.read_block()
    assert [e.kind for e in b.events] == ["overrun"]
    assert b.first_index > 1000
    dev.stop()


@pytest.mark.parametrize("rate,expected", [(10000, 10000.0), (9999, 10000.0), (25600, 25600.0)])
def test_board_rate(rate, expected):
    assert board_rate(rate) == pytest.approx(expected)


@pytest.mark.parametrize("bad", [0, 999, 60000, float("nan"), -5])
def test_board_rate_refuses_what_the_board_cannot_do(bad):
    with pytest.raises(InputError):
        board_rate(bad)


@pytest.mark.parametrize("spec", ["", "foo", "nidaqmx", "nidaqmx:", "SIM", "sim2", "daq:Dev1/ai0"])
def test_parse_device_bad(spec):
    with pytest.raises(InputError):
        parse_device(spec)


def test_parse_device_and_faults_good():
    assert parse_device("sim") == ("sim", "")
    assert parse_device("nidaqmx:Dev1/ai0:2") == ("nidaqmx", "Dev1/ai0:2")
    assert parse_fault("overrun@1.5") == Fault("overrun", 1.5)
    for bad in ("overrun", "melt@2", "drop@x"):
        with pytest.raises(InputError):
            parse_fault(bad)
    with pytest.raises(ValueError):
        Event(0, "boom")


@pytest.mark.parametrize("kw", [dict(mode="x"), dict(cam_speed=0 * RPM), dict(Fu=-1), dict(backlash=-1e-3),
                                dict(law="nope"), dict(ripple=0.7), dict(cal_freq=0), dict(cal_channel="tacho")])
def test_stand_scene_bad_input(kw):
    with pytest.raises(InputError):
        sc.StandScene(**kw)


@pytest.fixture(scope="module")
def rigid_scene():
    return sc.StandScene(cam_speed=300 * RPM, truth_model="rigid", truth_revolutions=3, ripple=0.0)


@pytest.mark.slow
def test_model_truth_is_the_models_steady_turn_repeated(rigid_scene):
    """The rigid model (k = 0.2) repeats its events turn after turn: the truth is its last turn,
    from t = 0 and for as long as a recording lasts."""
    tab = sc.model_table(rigid_scene)
    assert tab["periodic"] and tab["time"][-1] == pytest.approx(3 * 0.2, rel=1e-6)  # three turns at 300 rpm
    T = tab["period"]
    t = tab["time"][(tab["time"] >= 2 * T) & (tab["time"] < 3 * T)][::50]
    tr = sc.truth(rigid_scene, t - 2 * T + 7 * T)  # the eighth turn of a recording
    sel = (tab["time"] >= 2 * T) & (tab["time"] < 3 * T)
    # atol: in the dwell omega2 is 0 to rounding (1.2e-16 rad/s against an exact 0.0 with the rigid
    # the models' step cap), where a relative tolerance alone cannot hold
    np.testing.assert_allclose(tr["omega2"], tab["omega2"][sel][::50], atol=1e-12)
    np.testing.assert_allclose(tr["aE_n"], tab["omega2"][sel][::50] ** 2 * rigid_scene.mechanism.DE, atol=1e-12)
    np.testing.assert_allclose(tr["phi1"], rigid_scene.omega1_nominal * (t - 2 * T + 7 * T))
    ev = sc.truth_events(rigid_scene, 10 * T)
    per_turn = np.bincount(np.floor(ev["event_time"] / T).astype(int), minlength=10)
    assert per_turn[:10].min() == per_turn[:10].max() > 0


def test_boxcar_epsilon2_keeps_every_velocity_step(rigid_scene):
    """Summing the interval means gives back omega2 exactly (telescoping), impacts and the turn
    boundaries of the repeated turn included."""
    dt = 1 / 20000
    t = np.arange(dt / 2, 2.0, dt)               # ten repeated turns
    eps = sc.boxcar_epsilon2(rigid_scene, t, dt)
    w = sc.truth(rigid_scene, t + dt / 2)["omega2"]
    w0 = sc.truth(rigid_scene, np.array([0.0]))["omega2"][0]
    np.testing.assert_allclose(np.cumsum(eps) * dt + w0, w, atol=1e-9)
    # away from impacts it is the model's epsilon2
    smooth = np.abs(eps - sc.truth(rigid_scene, t)["epsilon2"]) < 1.0
    assert smooth.mean() > 0.9


def test_a_model_truth_that_never_settles_is_served_over_its_run_only():
    scene = sc.StandScene(cam_speed=300 * RPM, truth_model="rigid", restitution=1.0, truth_revolutions=3, ripple=0.0)
    tab = sc.model_table(scene)
    assert not tab["periodic"]                   # k = 1 keeps bouncing: no steady turn to repeat
    assert sc.model_truth_span(scene) < 0.6
    with pytest.raises(InputError):
        sc.truth(scene, np.array([0.7]))


def test_model_truth_scene_rules():
    with pytest.raises(InputError):
        sc.StandScene(truth_model="elastic")  # default ripple 0.005: the model's cam has none
    with pytest.raises(InputError):
        sc.StandScene(truth_model="fem", ripple=0.0)
    for bad in (-1, 500, 2.5):
        with pytest.raises(InputError):
            sc.StandScene(truth_model="rigid", ripple=0.0, truth_revolutions=bad)


def test_the_twins_bending_mode_is_not_applied_twice():
    """The twin carries the follower's mode as a degree of freedom: the chain's resonance filter
    then shapes the roughness noise only, so with that noise off the chain's resonance setting
    does not change a sample."""
    scene = sc.StandScene(cam_speed=300 * RPM)
    quiet = dict(mech_noise_m_s2=0.0)
    a = np.concatenate([b.data for b in record(scene, sc.ChainParams(resonance_hz=1200.0, **quiet), duration=0.5)[1]])
    b = np.concatenate([b.data for b in record(scene, sc.ChainParams(resonance_hz=2500.0, resonance_zeta=0.2, **quiet), duration=0.5)[1]])
    np.testing.assert_array_equal(a, b)
    kin = sc.StandScene(cam_speed=300 * RPM, truth_model="kinematic")   # the kinematic truth has no mode of its own
    c = np.concatenate([b.data for b in record(kin, sc.ChainParams(resonance_hz=1200.0, **quiet), duration=0.5)[1]])
    d = np.concatenate([b.data for b in record(kin, sc.ChainParams(resonance_hz=2500.0, resonance_zeta=0.2, **quiet), duration=0.5)[1]])
    assert not np.array_equal(c, d)


def test_every_truth_parameter_survives_the_recordings_attributes():
    from labtool.models.dynamics.twin import TwinPhysics

    physics = TwinPhysics(drive="input", mode_hz=1500.0, mode_zeta=0.03, mode_mass_share=0.2, friction_torque=0.01,
                          friction_radius=2e-5, friction_speed=2e-3, persistence_s=3e-3, warmup_revolutions=2)
    scene = sc.StandScene(cam_speed=250 * RPM, Fu=5.0, backlash=0.1e-3, jt_factor=1.5, ripple=0.01, restitution=0.4,
                          contact_damping=25.0, contact_length=7e-3, kc_factor=1.2, accuracy="standard", twin=physics)
    again = sc.scene_from_attrs({"device": "sim", **scene.attrs()})
    assert again == scene
    t = np.linspace(0.0, 0.3, 301)
    np.testing.assert_array_equal(sc.truth(again, t)["omega2"], sc.truth(scene, t)["omega2"])


def test_the_recordings_truth_events_are_the_stands():
    """truth_events rebuilds the twin from the scene: the first impact after each lift-off is where
    the recorded aE_t, quiet during the flight before it, jumps."""
    scene = sc.StandScene(cam_speed=300 * RPM)
    dev, blocks = record(scene, duration=1.0)
    v = np.concatenate([b.data for b in blocks]).astype(float)[:, 0] * dev.params.ka_m_s2_per_v[0]
    ev = sc.truth_events(scene, 1.0)
    lift = np.r_[False, (ev["event_kind"][:-1] == "separation") & ev["event_persistent"][:-1]]
    big = (ev["event_kind"] == "contact") & (np.abs(ev["event_domega2"]) > 0.5) & lift
    assert big.sum() >= 8                               # two landings a turn, five turns
    fs = dev.actual_rate_hz
    for t0 in ev["event_time"][big]:
        i = int(round(t0 * fs))
        window = np.abs(v[i:i + 15]).max()              # the impact's pulse, within the anti-alias delay
        quiet = np.abs(v[max(0, i - 60):i - 10]).max()
        assert window > 3 * quiet, (t0, window, quiet)


@pytest.mark.parametrize("rpm", [180, 300, 500])
def test_the_default_chain_has_room_for_the_twins_impacts(rpm):
    dev, blocks = record(sc.StandScene(cam_speed=rpm * RPM), duration=1.0)
    v = np.concatenate([b.data for b in blocks])
    assert not [e for b in blocks for e in b.events if e.kind == "clip"]
    assert 1.0 < np.abs(v[:, 0]).max() < 8.0            # used, with headroom below the 10 V rails


@pytest.mark.hostile("silent_wrong")
def test_a_sensitive_range_clips_and_says_so():
    """The paper's x10 chain (Ka = 86.43) cannot hold the twin's impacts at 300 rpm: clip events."""
    dev, blocks = record(sc.StandScene(cam_speed=300 * RPM), sc.ChainParams(ka_m_s2_per_v=(86.43, 86.43)), duration=1.0)
    clips = [e for b in blocks for e in b.events if e.kind == "clip"]
    assert clips and clips[0].detail.startswith("aE_t")
    assert dev.params.conditioner_gain == pytest.approx(10.0)
