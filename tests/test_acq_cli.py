"""``labtool acquire``: the must-show run, scene files, bad input (one line, exit 2), omega2 recovered vs truth."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal

from labtool.acquisition import signal_chain as sc
from labtool.common import recording_format
from labtool.cli import main
from labtool.common.units import RPM


@pytest.mark.slow
def test_must_show_sim_180_rpm_10_s_fast_writes_a_valid_v1_file(tmp_path, capsys):
    out = tmp_path / "r.h5"
    assert main(["acquire", "--device", "sim", "--rpm", "180", "--duration", "10", "--fast", "-o", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out
    rec = recording_format.load(out)
    a = rec["attrs"]
    assert a["format"] == "labtool.recording" and a["format_version"] == 1 and a["complete"]
    assert a["sample_rate_hz"] == 10000.0 and a["cam_speed_rpm"] == 180.0
    assert rec["signals"].shape == (100000, 3) and rec["channel_names"] == ["aE_t", "aE_n", "tacho"]
    assert rec["ka_m_s2_per_v"][0] == 864.3 and math.isnan(rec["ka_m_s2_per_v"][2])  # the 480C02 at gain x1
    assert a["truth_model"].startswith("twin") and a["conditioner_gain"] == pytest.approx(1.0)
    assert a["law"] == "sine" and a["Fu_N"] == 0.0 and a["backlash_mm"] == 0.128 and a["seed"] == 0
    assert [k for _, k, _ in rec["events"]] == ["start", "stop"]


@pytest.mark.slow
def test_recovered_omega2_matches_the_truth(tmp_path):
    """Tacho -> rise start; integrate aE_t * Ka / DE over the rise: the peak omega2 is the truth's."""
    out = tmp_path / "r.h5"
    assert main(["acquire", "--rpm", "300", "--duration", "2", "--fast", "--seed", "5", "-o", str(out)]) == 0
    rec = recording_format.load(out)
    fs = rec["attrs"]["sample_rate_hz"]
    v = rec["signals"]
    scene = sc.scene_from_attrs(rec["attrs"])      # the twin behind the recording
    DE = scene.mechanism.DE
    eps = signal.sosfiltfilt(signal.butter(4, 400, fs=fs, output="sos"), v[:, 0] * rec["ka_m_s2_per_v"][0]) / DE
    rises = np.flatnonzero((v[1:, 2] > 2.5) & (v[:-1, 2] <= 2.5)) + 1
    T_rise = scene.program.rise_angle / scene.omega1_nominal
    n_rise = int(T_rise * fs)
    for r in rises[:3]:
        r = r - 2  # the anti-alias filter's delay, as on the tacho
        omega = np.cumsum(eps[r:r + n_rise]) / fs
        t = (r + np.arange(n_rise)) / fs
        truth = sc.truth(scene, t)["omega2"]
        assert omega.max() == pytest.approx(truth.max(), rel=0.03)
        assert np.sqrt(np.mean((omega - truth) ** 2)) < 0.05 * truth.max()


@pytest.mark.slow
def test_scene_file_and_overrides(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text('[stand]\ncam_speed_rpm = 500\nseed = 9\nduration_s = 0.5\nlaw = "sine"\nbacklash_mm = 0.128\n')
    out = tmp_path / "r.h5"
    assert main(["acquire", "--scene", str(scene), "--fast", "--rpm", "300", "-o", str(out)]) == 0
    a = recording_format.load(out)["attrs"]
    assert a["cam_speed_rpm"] == 300.0 and a["seed"] == 9 and recording_format.load(out)["signals"].shape[0] == 5000


@pytest.mark.slow
def test_clipping_warns(tmp_path, capsys):
    out = tmp_path / "c.h5"
    assert main(["acquire", "--fast", "--duration", "1", "--fault", "clip@0.5", "-o", str(out)]) == 0
    assert "clipping on aE_t" in capsys.readouterr().err
    assert any(k == "clip" for _, k, _ in recording_format.load(out)["events"])


@pytest.mark.slow
def test_bad_input_one_line_exit_2(tmp_path, capsys):
    (tmp_path / "exists.h5").write_text("x")
    (tmp_path / "afile").write_text("x")
    (tmp_path / "bad.toml").write_text("[stand]\nrpm_typo = 3\n")
    o = str(tmp_path / "o.h5")
    cases = [
        ["acquire", "--device", "usb6009", "-o", o],
        ["acquire", "--device", "nidaqmx", "-o", o],
        ["acquire", "--rate", "200000", "--fast", "-o", o],
        ["acquire", "--rate", "-5", "--fast", "-o", o],
        ["acquire", "--fast", "-o", str(tmp_path / "exists.h5")],
        ["acquire", "--fast", "-o", str(tmp_path / "afile" / "r.h5")],
        ["acquire", "--fast", "-o", str(tmp_path / "nofolder" / "r.h5")],
        ["acquire", "--fast", "-o", str(tmp_path)],
        ["acquire", "--fast", "--duration", "0", "-o", o],
        ["acquire", "--fast", "--duration", "inf", "-o", o],
        ["acquire", "--fast", "--law", "zigzag", "-o", o],
        ["acquire", "--fast", "--rpm", "0", "-o", o],
        ["acquire", "--fast", "--fault", "melt@1", "-o", o],
        ["acquire", "--fast", "--scene", str(tmp_path / "bad.toml"), "-o", o],
        ["acquire", "--fast", "--scene", str(tmp_path / "none.toml"), "-o", o],
        ["acquire", "--fast", "--mode", "shake", "-o", o],
        ["acquire", "--device", "nidaqmx:Dev1/ai0:2", "--fault", "drop@1", "-o", o],
        ["acquire", "--device", "nidaqmx:Dev1/ai0:2", "--fast", "-o", o],
        ["acquire", "--device", "nidaqmx:Dev1/ai0:2", "-o", o],  # no NI-DAQmx runtime here
        ["acquire", "--fast", "--fu", "500000", "-o", o],          # the twin's motor stalls: a solver error
        ["acquire", "--fast", "--truth", "rigid", "--restitution", "1.5", "-o", o],
        ["acquire", "--fast", "--contact-damping", "nan", "-o", o],
    ]
    for argv in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("labtool: error: "), (argv, err)
    assert (tmp_path / "exists.h5").read_text() == "x"
    assert not (tmp_path / "o.h5").exists()


def test_force_overwrites(tmp_path):
    out = tmp_path / "r.h5"
    out.write_text("old")
    assert main(["acquire", "--fast", "--duration", "0.2", "--force", "-o", str(out)]) == 0
    assert recording_format.load(out)["signals"].shape[0] == 2000


@pytest.mark.slow
@settings(max_examples=30, deadline=None)
@given(st.text(max_size=30).filter(lambda s: s.strip() != "sim" and not s.strip().startswith("nidaqmx:")))
def test_any_other_device_name_is_refused(tmp_path_factory, spec):
    out = tmp_path_factory.mktemp("d") / "r.h5"
    assert main(["acquire", "--device", spec, "--fast", "-o", str(out)]) == 2
    assert not out.exists()


SAMPLE = __import__("pathlib").Path(__file__).resolve().parents[1] / "sample_data"


@pytest.mark.parametrize("name", ["run_180rpm", "run_300rpm", "run_500rpm", "calibration_79p6Hz",
                                  "calibration_79p6Hz_aE_n"])
@pytest.mark.slow
def test_sample_data_is_what_its_scene_makes(tmp_path, name):
    out = tmp_path / f"{name}.h5"
    assert main(["acquire", "--scene", str(SAMPLE / "scenes" / f"{name}.toml"), "--fast", "-o", str(out)]) == 0
    kept, fresh = recording_format.load(SAMPLE / f"{name}.h5"), recording_format.load(out)
    np.testing.assert_array_equal(kept["signals"], fresh["signals"])
    assert kept["attrs"]["complete"] and not any(k in ("clip", "gap", "overrun") for _, k, _ in kept["events"])
    assert (SAMPLE / f"{name}.h5").stat().st_size < 1_000_000


def test_sample_calibration_gives_the_chains_ka():
    """The sample recordings use the 480C02 at gain x1 (Ka = 864.3 m/s^2/V), calibration included."""
    from labtool.processing.calibration_file import read_calibration
    cal = read_calibration(SAMPLE / "calibration.toml")
    assert cal["aE_t"].ka_m_s2_per_v == pytest.approx(864.3, rel=0.005)
    assert cal["aE_n"].ka_m_s2_per_v == pytest.approx(864.3, rel=0.005)


def test_truth_from_a_recordings_attributes(tmp_path):
    out = tmp_path / "r.h5"
    assert main(["acquire", "--fast", "--rpm", "500", "--ripple", "0.01", "--duration", "0.3", "-o", str(out)]) == 0
    rec = recording_format.load(out)
    scene = sc.scene_from_attrs(rec["attrs"])
    assert scene.cam_speed_rpm == 500 and scene.ripple == 0.01 and scene.backlash == pytest.approx(0.128e-3)
    t = np.arange(rec["signals"].shape[0]) / rec["attrs"]["sample_rate_hz"]
    np.testing.assert_array_equal(sc.truth(scene, t)["omega2"], sc.truth(sc.StandScene(cam_speed=500 * RPM, ripple=0.01), t)["omega2"])
    with pytest.raises(sc.InputError):
        sc.scene_from_attrs({"device": "nidaqmx"})


@pytest.mark.slow
def test_elastic_truth_run_records_the_models_motion(tmp_path):
    out = tmp_path / "el.h5"
    assert main(["acquire", "--truth", "elastic", "--rpm", "300", "--duration", "0.6", "--fast", "--ka", "864.3",
                 "-o", str(out)]) == 0
    rec = recording_format.load(out)
    assert rec["attrs"]["truth_model"].startswith("elastic") and rec["attrs"]["truth_revolutions"] == 0  # the default 8, periodic
    scene = sc.scene_from_attrs(rec["attrs"])
    assert scene.truth_model == "elastic" and scene.ripple == 0.0 and scene.contact_damping == 40.0
    assert sc.model_table(scene)["periodic"]
    fs = rec["attrs"]["sample_rate_hz"]
    t = np.arange(rec["signals"].shape[0]) / fs
    truth = sc.truth(scene, t)
    # the normal channel is omega2^2 DE: compare in the cam band, where the chain is flat
    sos = signal.butter(4, 100, fs=fs, output="sos")
    meas = signal.sosfiltfilt(sos, rec["signals"][:, 1] * 864.3)
    ref = signal.sosfiltfilt(sos, truth["aE_n"] - scene.mechanism.g * np.sin(truth["phi2"]))
    meas, ref = meas - meas.mean(), ref - ref.mean()
    assert np.sqrt(np.mean((meas - ref) ** 2)) < 0.1 * np.abs(ref).max()
    for argv in (["--ripple", "0.01"], ["--truth", "fem"], ["--contact-damping", "0", "--duration", "100"],
                 ["--contact-damping", "-1"]):
        base = ["acquire", "--truth", "elastic", "--fast", "--duration", "0.5", "-o", str(tmp_path / "x.h5")]
        assert main(base + argv) == 2
    assert not (tmp_path / "x.h5").exists()


@pytest.mark.slow
def test_scene_file_truth_table(tmp_path, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text('[stand]\ncam_speed_rpm = 300\nduration_s = 0.3\n\n[truth]\ncontact_damping_s_per_m = 25.0\n'
                     'mode_hz = 1500\nfriction_radius_mm = 0.02\npersistence_ms = 3\n')
    out = tmp_path / "r.h5"
    assert main(["acquire", "--scene", str(scene), "--fast", "--restitution", "0.4", "-o", str(out)]) == 0
    a = recording_format.load(out)["attrs"]
    assert a["truth_contact_damping_s_per_m"] == 25.0 and a["truth_mode_hz"] == 1500.0 and a["resonance_hz"] == 1500.0
    assert a["truth_friction_radius_m"] == pytest.approx(2e-5) and a["truth_persistence_s"] == pytest.approx(3e-3)
    assert a["truth_restitution"] == 0.4
    o = str(tmp_path / "o.h5")
    for body in ('[truth]\nmode_hz = "fast"\n', '[truth]\nfrction_torque_Nm = 1\n', '[truth]\ndrive = "belt"\n',
                 '[truth]\nmodel = "fem"\n', 'truth = 3\n', '[truth]\nrevolutions = 1.5\n'):
        bad = tmp_path / "bad.toml"
        bad.write_text("[stand]\nduration_s = 0.2\n" + body if body.startswith("[") else body + "[stand]\n")
        capsys.readouterr()
        assert main(["acquire", "--scene", str(bad), "--fast", "-o", o]) == 2, body
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("labtool: error: "), (body, err)
    assert not (tmp_path / "o.h5").exists()
