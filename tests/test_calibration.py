"""Calibration: Ka recovered from simulated reference recordings; the fit and its uncertainty; bad input."""
import math
import tomllib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from labtool.acquisition import session
from labtool.acquisition import signal_chain as sc
from labtool.processing.calibration import fit_sine, ka_from_fit
from labtool.processing.calibration_file import read_calibration
from labtool.acquisition.sim_stand import Fault, SimStand
from labtool.cli import main
from labtool.common.errors import FileFormatError, InputError


def cal_recording(path, ka=86.43, freq=79.6, accel=9.81, channel="aE_t", seed=3, duration=2.0, faults=()):
    scene = sc.StandScene(mode="calibration", cal_freq=freq, cal_accel=accel, cal_channel=channel)
    dev = SimStand(scene, sc.ChainParams(ka_m_s2_per_v=(ka, ka)), seed=seed, duration_s=duration,
                   realtime=False, faults=faults)
    session.run(dev, path, 10000, duration)
    return path


@pytest.mark.parametrize("ka,channel", [(86.43, "aE_t"), (72.0, "aE_n"), (101.7, "aE_t")])
def test_cli_recovers_the_ka_that_made_the_recording_within_half_a_percent(tmp_path, ka, channel):
    rec = cal_recording(tmp_path / "ref.h5", ka=ka, channel=channel)
    out = tmp_path / "cal.toml"
    assert main(["calibrate", str(rec), "--channel", channel, "-o", str(out)]) == 0
    doc = tomllib.loads(out.read_text())
    c = doc["channels"][channel]
    assert c["ka_m_s2_per_v"] == pytest.approx(ka, rel=0.005)
    assert 0 < c["uncertainty_m_s2_per_v"] < 0.001 * ka
    assert doc["format"] == "labtool.calibration" and doc["format_version"] == 1
    assert doc["reference"] == {"accel_m_s2": 9.81, "convention": "peak", "freq_hz": 79.6, "rel_uncertainty": 0.0}
    assert read_calibration(out)[channel].ka_m_s2_per_v == c["ka_m_s2_per_v"]


def test_printed_table_keeps_its_units(tmp_path, capsys):
    # "[m/s^2/V]" looks like rich markup and was silently dropped from the header
    rec = cal_recording(tmp_path / "ref.h5", ka=86.43)
    assert main(["calibrate", str(rec), "-o", str(tmp_path / "cal.toml")]) == 0
    out = capsys.readouterr().out
    assert "Ka [m/s^2/V]" in out and "u(Ka) [m/s^2/V]" in out and "fitted f [Hz]" in out


def test_frequency_refinement_and_rms_convention(tmp_path):
    # the exciter runs at 80.4 Hz, not the nominal 79.6; its 9.81 is given as rms
    rec = cal_recording(tmp_path / "ref.h5", ka=90.0, freq=80.4, accel=9.81 * math.sqrt(2))
    out = tmp_path / "cal.toml"
    assert main(["calibrate", str(rec), "--convention", "rms", "--reference-uncertainty", "0.01", "-o", str(out)]) == 0
    c = tomllib.loads(out.read_text())["channels"]["aE_t"]
    assert c["fitted_freq_hz"] == pytest.approx(80.4, abs=0.01)
    assert c["ka_m_s2_per_v"] == pytest.approx(90.0, rel=0.005)
    assert c["uncertainty_m_s2_per_v"] == pytest.approx(0.9, rel=0.05)  # the exciter's 1 % dominates


def test_gaps_in_the_reference_recording_are_left_out_not_joined(tmp_path):
    rec = cal_recording(tmp_path / "ref.h5", ka=80.0, faults=[Fault("overrun", 0.7, 0.13)])
    out = tmp_path / "cal.toml"
    assert main(["calibrate", str(rec), "-o", str(out)]) == 0
    # the rows are joined across the gap; the fit puts them back at their true times
    c = tomllib.loads(out.read_text())["channels"]["aE_t"]
    assert c["ka_m_s2_per_v"] == pytest.approx(80.0, rel=0.005)
    assert c["residual_rms_v"] < 0.01 * c["amplitude_v_peak"]


@settings(max_examples=25, deadline=None)
@given(amp=st.floats(0.01, 10.0), freq=st.floats(20.0, 400.0), phase=st.floats(-3.1, 3.1),
       offset=st.floats(-1.0, 1.0), noise=st.floats(0.0, 0.02))
def test_fit_sine_closed_form(amp, freq, phase, offset, noise):
    rate = 10000.0
    t = np.arange(8000) / rate
    rng = np.random.default_rng(0)
    x = amp * np.sin(2 * np.pi * freq * t + phase) + offset + noise * amp * rng.standard_normal(t.size)
    fit = fit_sine(x, rate, freq * 1.03)
    assert fit.amplitude == pytest.approx(amp, rel=max(1e-6, 5 * noise / math.sqrt(t.size) * 3))
    assert fit.freq_hz == pytest.approx(freq, rel=1e-4)


def test_reported_uncertainty_matches_the_scatter():
    rate, n, amp, sigma = 10000.0, 4000, 1.0, 0.2
    t = np.arange(n) / rate
    est, std = [], []
    for seed in range(40):
        x = amp * np.sin(2 * np.pi * 79.6 * t) + sigma * np.random.default_rng(seed).standard_normal(n)
        f = fit_sine(x, rate, 79.6)
        est.append(f.amplitude)
        std.append(f.amplitude_std)
    # theory for a sine in white noise: sigma * sqrt(2 / n)
    assert np.mean(std) == pytest.approx(sigma * math.sqrt(2 / n), rel=0.1)
    assert np.std(est) == pytest.approx(np.mean(std), rel=0.35)


def test_ka_from_fit_conventions():
    fit = fit_sine(0.1 * np.sin(2 * np.pi * 79.6 * np.arange(5000) / 1e4), 1e4, 79.6)
    assert ka_from_fit(fit, 9.81, "peak")[0] == pytest.approx(98.1, rel=1e-6)
    assert ka_from_fit(fit, 9.81, "rms")[0] == pytest.approx(98.1 * math.sqrt(2), rel=1e-6)
    for bad in [dict(convention="pp"), dict(reference_accel=0.0), dict(reference_rel_uncertainty=-0.1)]:
        kw = dict(reference_accel=9.81, convention="peak")
        kw.update(bad)
        with pytest.raises(InputError):
            ka_from_fit(fit, **kw)


@pytest.mark.slow
def test_bad_input_is_one_line_exit_2(tmp_path, capsys):
    rec = cal_recording(tmp_path / "ref.h5", duration=1.0)
    run = SimStand(sc.StandScene(), seed=1, duration_s=1.0, realtime=False)
    session.run(run, tmp_path / "run.h5", 10000, 1.0)
    (tmp_path / "junk.h5").write_text("not hdf5")
    (tmp_path / "exists.toml").write_text("")
    cases = [
        ["calibrate", str(tmp_path / "missing.h5"), "-o", str(tmp_path / "a.toml")],
        ["calibrate", str(rec), "--channel", "nope", "-o", str(tmp_path / "b.toml")],
        ["calibrate", str(rec), "--channel", "aE_n", "-o", str(tmp_path / "c.toml")],  # noise only
        ["calibrate", str(tmp_path / "run.h5"), "-o", str(tmp_path / "d.toml")],  # a cam run, not a sine
        ["calibrate", str(tmp_path / "junk.h5"), "-o", str(tmp_path / "e.toml")],
        ["calibrate", str(rec), "-o", str(tmp_path / "exists.toml")],
        ["calibrate", str(rec), "--convention", "pp", "-o", str(tmp_path / "f.toml")],
        ["calibrate", str(rec), "--reference-freq", "6000", "-o", str(tmp_path / "g.toml")],
    ]
    for argv in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("labtool: error: "), (argv, err)
    assert not any((tmp_path / f"{c}.toml").exists() for c in "abcdefg")


def test_read_calibration_rejects_bad_files(tmp_path):
    p = tmp_path / "x.toml"
    for text in ["not = [toml", 'format = "other"\nformat_version = 1\n[channels.aE_t]\nka_m_s2_per_v = 3',
                 'format = "labtool.calibration"\nformat_version = 1\n[channels.aE_t]\nka_m_s2_per_v = -3']:
        p.write_text(text)
        with pytest.raises((FileFormatError, InputError)):
            read_calibration(p)
    with pytest.raises(InputError):
        read_calibration(tmp_path / "none.toml")
