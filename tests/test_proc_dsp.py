"""Processing building blocks against closed forms and independent implementations."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import signal

from labtool.common.errors import InputError
from labtool.models.mechanism import Mechanism, sensor_point
from labtool.models.mechanism.motion_laws import CamProgram
from labtool.processing import cam_angle, cycles, events, filters, follower, spectra
from labtool.processing.calibration_file import read_calibration
from labtool.common.history import History


def test_lowpass_rule_and_gain():
    assert filters.lowpass_cutoff_hz(180.0, 10000.0) == pytest.approx(300.0)
    assert filters.lowpass_cutoff_hz(6000.0, 10000.0) == pytest.approx(4000.0)  # capped at 0.4 fs
    sos = filters.lowpass_sos(10000.0, 300.0)
    w, h = signal.sosfreqz(sos, worN=[10.0, 300.0, 3000.0], fs=10000.0)
    g = np.abs(h) ** 2  # zero-phase: squared magnitude
    assert g[0] == pytest.approx(1.0, abs=1e-6) and g[1] == pytest.approx(0.5, rel=1e-3) and g[2] < 1e-7
    with pytest.raises(InputError):
        filters.lowpass_sos(1000.0, 600.0)


def test_chunked_zero_phase_equals_whole():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(20000, 2)).cumsum(axis=0)
    sos = filters.lowpass_sos(10000.0, 300.0)
    whole = filters.zero_phase(sos, x)
    m = filters.settle_samples(sos)
    out = np.empty_like(x)
    for a in range(0, len(x), 3000):
        b = min(a + 3000, len(x))
        wa, wb = max(0, a - m), min(len(x), b + m)
        out[a:b] = filters.zero_phase(sos, x[wa:wb])[a - wa:b - wa]
    assert np.max(np.abs(out - whole)) < 1e-6 * np.max(np.abs(whole))


def test_streaming_sos_equals_one_pass():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(5000, 3)) + 2.0
    sos = filters.lowpass_sos(1000.0, 50.0)
    zi = signal.sosfilt_zi(sos)[:, :, None] * x[0][None, None, :]
    ref, _ = signal.sosfilt(sos, x, axis=0, zi=zi)
    s = filters.StreamingSOS(sos)
    cuts = [0, 1, 17, 999, 1000, 4321, 5000]
    out = np.vstack([s.process(x[a:b]) for a, b in zip(cuts[:-1], cuts[1:])])
    np.testing.assert_allclose(out, ref, rtol=1e-12, atol=1e-12)
    const = filters.StreamingSOS(sos).process(np.full((100, 1), 3.0))
    np.testing.assert_allclose(const, 3.0, rtol=1e-12)  # no start transient


def test_spectra_sine_amplitude_parseval_and_scipy():
    fs, n = 1000.0, 2**15
    t = np.arange(n) / fs
    x = 3.0 * np.sin(2 * np.pi * 62.5 * t) + 0.5 + np.random.default_rng(2).normal(0, 0.1, n)
    f, amp = spectra.amplitude_spectrum(x, fs, nperseg=4096)
    assert amp[np.argmin(np.abs(f - 62.5))] == pytest.approx(3.0, rel=0.01)
    f2, p = spectra.welch_psd(x, fs, nperseg=4096)
    fr, pr = signal.welch(x, fs, window="hann", nperseg=4096, noverlap=2048, detrend="constant")
    np.testing.assert_allclose(p, pr, rtol=1e-4, atol=1e-6 * pr.max())  # float32 transforms
    assert np.sum(p) * (f2[1] - f2[0]) == pytest.approx(np.var(x), rel=0.02)
    acc = spectra.WelchAccumulator(fs, 4096, 1)
    for a in range(0, n, 777):  # block-wise feeding gives the same estimate
        acc.feed(x[a:a + 777, None])
    np.testing.assert_allclose(acc.psd()[:, 0], pr, rtol=1e-4, atol=1e-6 * pr.max())
    bad = np.zeros(n, bool)
    bad[10000] = True
    acc2 = spectra.WelchAccumulator(fs, 4096, 1)
    acc2.feed(x[:, None], bad)
    assert acc2.skipped == 2 and acc2.count == acc.count - 2


def test_tacho_edges_subsample_any_blocking():
    fs, n = 10000.0, 50000
    true = np.arange(123.37, n - 10, 3333.3)
    i = np.arange(n)
    x = np.zeros(n)
    for e in true:  # linear ramp over one sample at the edge, 10 samples high
        x += np.clip(i - e + 0.5, 0, 1) * (i < e + 10)
    x = 0.05 + 5 * x
    for block in (n, 1000, 97):
        det = cam_angle.TachoEdges()
        got = np.concatenate([det.feed(a, x[a:a + block]) for a in range(0, n, block)])
        assert len(got) == len(true)
        assert np.max(np.abs(got - true)) < 0.51


def test_period_estimate_and_phi1_from_marks():
    mech = Mechanism.default()
    prog = CamProgram.for_mechanism(mech)
    fs, period = 10000.0, 60 * 10000.0 / 300.0
    i = np.arange(int(8 * period))
    phi = 2 * np.pi * (i - 500.0) / period
    x = prog(phi)[2] + np.random.default_rng(3).normal(0, 0.1, len(i))
    assert cam_angle.estimate_period(x, fs) == pytest.approx(period, rel=2e-3)
    corr = cam_angle.CorrelationEdges(mech, prog, period)
    marks = corr.feed(0, x, 0, len(x))
    np.testing.assert_allclose(marks, 500.0 + period * np.arange(len(marks)) + (period if marks[0] > 1000 else 0),
                               atol=1.0)
    p1, rev = cam_angle.phi1_from_marks(np.array([0.0, 1500.0, 1500.0 + period / 4]), np.array([1500.0, 1500 + period]), period)
    np.testing.assert_allclose(p1, [2 * np.pi - 2 * np.pi * 1500 / period, 0.0, np.pi / 2])
    assert rev.tolist() == [-1, 0, 0]
    with pytest.raises(InputError):
        cam_angle.estimate_period(np.zeros(5000), fs)


def test_gravity_reading_matches_vector_projection():
    phi2 = np.linspace(0.5, 2.5, 7)
    gt, gn = sensor_point.gravity_reading(phi2, 9.81)
    f = -np.array([0.0, -9.81])  # specific force of a body at rest: a - g
    t = np.stack([-np.sin(phi2), np.cos(phi2)])
    nvec = -np.stack([np.cos(phi2), np.sin(phi2)])
    np.testing.assert_allclose(gt, f @ t)
    np.testing.assert_allclose(gn, f @ nvec)


def test_dwell_baseline_and_integration_closed_form():
    fs, n = 1000.0, 3000
    i = np.arange(n)
    moving = (i >= 1000) & (i < 1500)
    T = 0.5
    tt = (i - 1000) / fs
    eps = np.where(moving, 2 * np.pi / T * np.sin(2 * np.pi * tt / T), 0.0)  # cycloidal: omega = 1 - cos
    omega_true = np.where(moving, 1 - np.cos(2 * np.pi * tt / T), 0.0)
    drift = 0.3 + 0.2 * i / n  # offset and a linear drift
    base = follower.dwell_baseline(eps + drift, ~moving)
    np.testing.assert_allclose(base[1000:1500], drift[1000:1500], atol=1e-9)
    om = follower.integrate_motion(eps + drift - base, moving, fs, margin=50)
    assert np.max(np.abs(om - omega_true)) < 2e-4
    om_bad = follower.integrate_motion(eps + 0.3, moving, fs, margin=50)  # uncorrected offset: drift removed
    assert np.max(np.abs(om_bad - omega_true)) < 0.3 * 0.6 / 4 + 1e-3
    bad = np.zeros(n, bool)
    bad[1200] = True
    assert np.isnan(follower.integrate_motion(eps, moving, fs, 50, bad=bad)[1200])
    assert np.allclose(sensor_point.omega2_abs_from_normal(np.array([-1.0, 0.186 * 4]), 0.186), [0.0, 2.0])


def test_cycle_accumulator_mean_std():
    acc = cycles.CycleAccumulator(["x"], 8)
    pos = np.linspace(0, 2 * np.pi, 100)
    for k in range(5):
        acc.add(pos, {"x": np.sin(pos) + k})
    acc.add(pos, {"x": np.full(100, np.nan)})
    r = acc.result()
    np.testing.assert_allclose(r["x_mean"], np.sin(acc.grid) + 2.0, atol=1e-3)
    np.testing.assert_allclose(r["x_std"], np.std([0, 1, 2, 3, 4], ddof=1), rtol=1e-9)
    assert acc.count == 5 and acc.rejected == 1


def test_spike_detection():
    fs = 10000.0
    rng = np.random.default_rng(4)
    lp = 50 * np.sin(2 * np.pi * 3 * np.arange(20000) / fs)
    r = rng.normal(0, 0.2, 20000)
    r[[5000, 5003, 12000]] += [30.0, -25.0, -40.0]
    idx, amp, thr = events.detect_spikes(r, lp, fs)
    assert idx.tolist() == [5000, 12000] and amp[1] < -39 and thr == pytest.approx(2.5)


def test_calibration_file(tmp_path):
    p = tmp_path / "cal.toml"
    p.write_text("[channels.aE_t]\nka_m_s2_per_v = 85.0\nuncertainty_m_s2_per_v = 0.2\n"
                 "[channels.aE_n]\nka_m_s2_per_v = 87.5\nuncertainty_m_s2_per_v = 0.3\n")
    cal = read_calibration(p)
    assert cal["aE_t"].ka_m_s2_per_v == 85.0 and cal["aE_t"].uncertainty_m_s2_per_v == 0.2
    assert cal["aE_n"].uncertainty_m_s2_per_v == 0.3
    with pytest.raises(InputError):
        read_calibration(tmp_path / "missing.toml")
    p.write_text("not = [toml")
    with pytest.raises(Exception, match="not valid TOML"):
        read_calibration(p)
    p.write_text("[other]\nx = 1\n")
    with pytest.raises(Exception, match=r"unknown table \[other\]; known: .*channels"):
        read_calibration(p)


def test_history_is_json_with_parameters():
    """Steps record typed parameters; numpy scalars become numbers, NaN null; the schema reads back."""
    from labtool.common.history import CheckNormal, Lowpass

    h = History()
    h.add(Lowpass(kind="butterworth", order=np.int64(4), cutoff_hz=np.float64(300.0), zero_phase=True, rule="given",
                  chunk_samples=1024, overlap_samples=np.int64(50)))
    h.add(CheckNormal(value=float("nan")))
    steps = json.loads(h.to_json())
    assert steps[0] == {"step": "lowpass", "parameters": {"kind": "butterworth", "order": 4, "cutoff_hz": 300.0,
                                                          "zero_phase": True, "rule": "given", "chunk_samples": 1024,
                                                          "overlap_samples": 50}}
    assert steps[1]["parameters"]["value"] is None
    back = History.parse(h.to_json())
    assert back.find(Lowpass).cutoff_hz == 300.0 and back.find(Lowpass).order == 4
    # a step of another writer is kept as read; garbage gives an empty history, not an error
    other = History.parse(json.dumps(steps + [{"step": "custom", "parameters": {"x": 1}}]))
    assert other.to_list()[-1] == {"step": "custom", "parameters": {"x": 1}}
    assert History.parse("not json").to_list() == [] and History.parse("[1, 2]").find(Lowpass) is None
    with pytest.raises(TypeError):
        h.add("lowpass")
