"""End to end: simulated-stand recordings with a known truth -> measured.nc; the CLI; bad input.

Inputs come from the one sensor chain (acquisition's simulated stand, tests/stand_data.py); the
truth is that chain's own noise-free truth.
"""
from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
import xarray as xr

from labtool.common.history import History, Lowpass
from labtool.cli import main
from labtool.processing.pipeline import ProcessOptions, process_recording
from labtool.processing.readers import open_recording
from stand_data import impact_bursts, stand_recording, stand_volts, write_v1


def _run(tmp_path, name="r", opts=None, **kw):
    p = tmp_path / f"{name}.h5"
    tr = stand_recording(p, **kw)
    out = tmp_path / f"{name}.nc"
    msgs = []
    with open_recording(p) as rec:
        summary = process_recording(rec, out, opts or ProcessOptions(), warn=msgs.append)
    ds = xr.open_dataset(out, engine="h5netcdf", decode_times=False).load()
    return ds, tr, summary, msgs


def _rise_errors(ds, tr):
    om, ep = ds["omega2"].values, ds["epsilon2"].values
    rise = (np.mod(tr["phi1"], 2 * np.pi) < tr["program"].rise_angle) & np.isfinite(om)
    pk_o = np.abs(tr["omega2"][rise]).max()
    pk_e = np.abs(tr["epsilon2"][rise]).max()
    e_o = np.sqrt(np.mean((om[rise] - tr["omega2"][rise]) ** 2)) / pk_o
    e_e = np.sqrt(np.mean((ep[rise] - tr["epsilon2"][rise]) ** 2)) / pk_e
    return e_o, e_e, int(rise.sum())


@pytest.mark.slow
@pytest.mark.parametrize("rpm, tacho", [(180.0, True), (180.0, False), (500.0, True), (300.0, False)])
def test_recovers_known_omega2_and_epsilon2(tmp_path, rpm, tacho):
    """Noise, gravity, AC coupling, resonance, speed ripple and quantization: omega2 < 2 %, epsilon2 < 5 %."""
    ds, tr, s, _ = _run(tmp_path, rpm=rpm, duration_s=3.0, tacho=tacho, params={"noise_m_s2": 0.5, "highpass_hz": 0.1},
                        scene={"ripple": 0.01})
    e_o, e_e, n = _rise_errors(ds, tr)
    assert n > 1000
    assert e_o < 0.02 and e_e < 0.05
    assert s["phi1_method"] == ("tacho" if tacho else "correlation")
    assert ds.attrs["cam_speed_rpm"] == pytest.approx(rpm, rel=0.01)
    # the |omega2| = sqrt(aE_n/DE) check agrees with the integral
    assert ds.attrs["omega2_normal_check_rel_rms"] < 0.08
    # cycle average close to the kinematics (the speed ripples by 1 %)
    assert ds.attrs["n_revolutions_averaged"] >= int(3.0 * rpm / 60) - 2
    pk = np.abs(ds["omega2_kinematic"]).max()
    assert np.sqrt(np.mean((ds["omega2_mean"] - ds["omega2_kinematic"]) ** 2)) / pk < 0.03


@pytest.mark.slow
def test_undoing_the_ac_coupling_improves_the_result(tmp_path):
    """A 1.06 Hz AC coupling (tau = 0.15 s), undone with the chain's own tau: omega2's error shrinks
    to the floor the rest of the chain (anti-alias delay, resonance, noise) leaves."""
    tau = 0.15
    kw = dict(rpm=180.0, duration_s=2.5, params={"highpass_hz": 1 / (2 * np.pi * tau), "noise_m_s2": 0.05})
    ds0, tr, _, _ = _run(tmp_path, "a", **kw)
    ds1, _, _, _ = _run(tmp_path, "b", ProcessOptions(ac_tau_s=tau), **kw)
    e0, e1 = _rise_errors(ds0, tr), _rise_errors(ds1, tr)
    assert e1[0] < 0.4 * e0[0] and e1[1] < 0.4 * e0[1] and e1[0] < 0.01


@pytest.mark.slow
def test_chunk_size_does_not_change_the_result(tmp_path):
    kw = dict(rpm=300.0, duration_s=3.0, extra_m_s2=impact_bursts([1.234]))
    a, _, _, _ = _run(tmp_path, "big", **kw)
    b, _, _, _ = _run(tmp_path, "small", ProcessOptions(chunk_samples=4096), **kw)
    for v in ("aE_t", "aE_n", "epsilon2", "omega2", "phi1", "revolution", "omega2_mean", "aE_t_psd"):
        np.testing.assert_allclose(a[v].values, b[v].values, rtol=1e-4, atol=1e-4 * float(np.nanmax(np.abs(a[v]))))
    assert a["spike_sample"].values.tolist() == b["spike_sample"].values.tolist()


@pytest.mark.slow
def test_output_names_units_history(tmp_path):
    ds, tr, s, _ = _run(tmp_path, duration_s=2.0, extra_m_s2=impact_bursts([0.777]))
    for v in ("aE_t", "aE_n", "epsilon2", "omega2", "phi1", "revolution", "aE_t_amplitude", "aE_n_psd",
              "omega2_mean", "omega2_std", "epsilon2_mean", "epsilon2_std", "spike_time"):
        assert v in ds
    for name in list(ds.data_vars) + list(ds.coords):
        assert ds[name].attrs.get("long_name"), name
        assert ds[name].attrs.get("units") or ds[name].dtype.kind in "OU", name
    assert set(ds["omega2_mean"].dims) == {"phi1_grid"} and set(ds["aE_t_psd"].dims) == {"frequency"}
    steps = [h["step"] for h in json.loads(ds.attrs["processing_history"])]
    lp = History.parse(ds.attrs["processing_history"]).find(Lowpass)
    assert lp.cutoff_hz == ds.attrs["lowpass_hz"] and lp.order == 4 and lp.zero_phase
    for step in ("read", "apply_ka", "cam_angle", "lowpass", "remove_gravity", "dwell_reference", "epsilon2", "omega2",
                 "check_normal", "cycle_average", "spectra", "spikes"):
        assert step in steps
    assert ds.attrs["ka_source_aE_t"] == "recording attribute ka_m_s2_per_v" and ds.attrs["ka_aE_t_m_s2_per_v"] == 86.43
    assert isinstance(ds.attrs["ka_aE_t_m_s2_per_v"], float)  # numbers stay numbers
    # the impact burst at 0.777 s is found, in the right place
    t = ds["spike_time"].values
    assert np.any(np.abs(t - 0.777) < 0.003)
    # a spectrum peak at the cam frequency harmonics, not at DC: the offset is removed
    f = ds["frequency"].values
    amp = ds["aE_t_amplitude"].values
    assert amp[0] < 0.1 * amp.max() and f[np.argmax(amp)] < 100.0


@pytest.mark.slow
def test_gaps_split_segments_and_clips_are_kept_out(tmp_path):
    gap, clip = 15000, 27000
    ds, tr, s, msgs = _run(tmp_path, rpm=300.0, duration_s=4.0,
                           events=[(gap, "gap", "missing_samples=250 (0.025 s) lost before this row"),
                                   (gap, "overrun", "250 samples lost"), (clip, "clip", "aE_t")])
    t, fs = ds["time"].values, tr["fs"]
    assert np.diff(t)[gap - 1] == pytest.approx(251 / fs) and t[-1] == pytest.approx((40000 - 1 + 250) / fs)
    assert ds.attrs["n_samples_lost"] == 250
    assert s["segments"] == 2 and ds.attrs["n_segments"] == 2
    assert ds["segment_start"].values.tolist() == [0, gap] and ds["segment_stop"].values.tolist() == [gap, 40000]
    # nothing integrated across the gap: the motion interval cut by it is NaN, not interpolated
    om = ds["omega2"].values
    moving = tr["moving"]
    if moving[gap - 1] or moving[gap]:
        assert np.isnan(om[gap - 1]) or np.isnan(om[gap])
    assert ds["clipped"].values[clip] == 1 and np.isnan(ds["epsilon2"].values[clip])
    assert ds.attrs["n_clipped_samples"] >= 1 and any("clipped" in m for m in msgs)
    e_o, e_e, _ = _rise_errors(ds, tr)
    assert e_o < 0.02 and e_e < 0.05


@pytest.mark.slow
def test_saturated_adc_is_flagged(tmp_path):
    # the accelerometer channels on a +-1 V range (aE_t peaks ~ 3.4 V), the tacho on its own 10 V range
    volts, scene, _, fs = stand_volts(2.0, 500.0)
    lsb = 2.0 / 2**16
    volts[:, :2] = np.clip(volts[:, :2], -1.0, 1.0 - lsb)
    p = tmp_path / "r.h5"
    write_v1(p, volts, fs=fs, cam_speed_rpm=500.0, ka=[86.43, 86.43, np.nan])
    with open_recording(p) as rec:
        s = process_recording(rec, tmp_path / "r.nc", warn=lambda m: None)
    ds = xr.open_dataset(tmp_path / "r.nc", engine="h5netcdf", decode_times=False).load()
    assert s["clipped"] > 100
    assert np.isnan(ds["omega2"].values[ds["clipped"].values == 1]).all()
    assert ds.attrs["n_revolutions_averaged"] == 0


@pytest.mark.slow
def test_incomplete_recording_processes_with_warning(tmp_path):
    ds, tr, s, msgs = _run(tmp_path, duration_s=2.0, complete=False)
    assert any("incomplete" in m for m in msgs) and ds.attrs["recording_complete"] == 0
    assert _rise_errors(ds, tr)[0] < 0.02


@pytest.mark.slow
def test_ka_from_calibration_file_and_recording_attribute(tmp_path, capsys):
    p = tmp_path / "r.h5"
    stand_recording(p, duration_s=1.5, params={"ka_m_s2_per_v": (100.0, 100.0)}, ka=[90.0, 95.0, np.nan])
    assert main(["process", str(p), "-o", str(tmp_path / "a.nc")]) == 0
    a = xr.open_dataset(tmp_path / "a.nc", engine="h5netcdf")
    assert a.attrs["ka_aE_t_m_s2_per_v"] == 90.0 and "recording attribute" in a.attrs["ka_source_aE_t"]
    cal = tmp_path / "cal.toml"
    cal.write_text("[channels.aE_t]\nka_m_s2_per_v = 100.0\nka_std_m_s2_per_v = 0.4\n"
                   "[channels.aE_n]\nka_m_s2_per_v = 100.0\n")
    assert main(["process", str(p), "--calibration", str(cal), "-o", str(tmp_path / "b.nc")]) == 0
    b = xr.open_dataset(tmp_path / "b.nc", engine="h5netcdf")
    assert b.attrs["ka_aE_t_m_s2_per_v"] == 100.0 and b.attrs["ka_aE_t_uncertainty_m_s2_per_v"] == 0.4
    assert "calibration file" in b.attrs["ka_source_aE_t"]
    # the right Ka gives the right amplitude: peak epsilon2 within 5 % of the truth with Ka = 100
    pk = float(np.nanmax(np.abs(b["epsilon2_mean"])))
    assert pk == pytest.approx(float(np.abs(b["epsilon2_kinematic"]).max()), rel=0.05)
    assert "wrote" in capsys.readouterr().out


def _bad_inputs(tmp_path):
    good = tmp_path / "good.h5"
    stand_recording(good, duration_s=1.0)
    trunc = tmp_path / "trunc.h5"
    trunc.write_bytes(good.read_bytes()[:5000])
    other = tmp_path / "other.h5"
    other.write_bytes(b"PK\x03\x04" + bytes(1000))
    norate = tmp_path / "norate.h5"
    stand_recording(norate, duration_s=1.0)
    with h5py.File(norate, "a") as f:
        del f.attrs["sample_rate_hz"]
    wrong = tmp_path / "wrongrate.h5"
    stand_recording(wrong, duration_s=2.0)
    with h5py.File(wrong, "a") as f:
        f.attrs["sample_rate_hz"] = 1000.0  # 10 kHz data labelled 1 kHz
    zero = tmp_path / "zerorate.h5"
    stand_recording(zero, duration_s=1.0)
    with h5py.File(zero, "a") as f:
        f.attrs["sample_rate_hz"] = 0.0
    nan = tmp_path / "nan.h5"
    v = np.random.default_rng(0).normal(size=(5000, 3))
    v[100, 0] = np.nan
    write_v1(nan, v, ["aE_t", "aE_n", "tacho"], 10000.0, ka=[86.43, 86.43, np.nan])
    miss = tmp_path / "missing.h5"
    write_v1(miss, v[:, :2] * 0 + 1, ["aE_t", "tacho"], 10000.0, ka=[86.43, np.nan])
    flat = tmp_path / "flat.h5"
    write_v1(flat, np.zeros((30000, 2)), ["aE_t", "aE_n"], 10000.0, ka=[86.43, 86.43])
    return {
        "truncated": [str(trunc)],
        "other format": [str(other)],
        "missing rate": [str(norate)],
        "zero rate": [str(zero)],
        "wrong rate": [str(wrong)],
        "NaN samples": [str(nan)],
        "missing channel": [str(miss)],
        "no cam motion": [str(flat)],
        "unknown calibration": [str(good), "--calibration", str(tmp_path / "nope.toml")],
        "bad calibration": [str(good), "--calibration", str(other)],
        "missing recording": [str(tmp_path / "nope.h5")],
    }


@pytest.mark.slow
def test_bad_input_one_line_exit_2_and_no_output(tmp_path, capsys):
    cases = _bad_inputs(tmp_path)
    for label, args in cases.items():
        out = tmp_path / f"out_{label.replace(' ', '_')}.nc"
        code = main(["process", *args, "-o", str(out)])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2, label
        assert len(err) == 1 and err[0].startswith("labtool: error:"), (label, err)
        assert not out.exists(), label
    assert not list(tmp_path.glob("*.part")), "a temporary file was left behind"


def test_existing_output_needs_force(tmp_path, capsys):
    p = tmp_path / "r.h5"
    stand_recording(p, duration_s=1.0)
    out = tmp_path / "m.nc"
    out.write_text("keep me")
    assert main(["process", str(p), "-o", str(out)]) == 2
    assert out.read_text() == "keep me"
    assert main(["process", str(p), "-o", str(out), "--force"]) == 0


from hypothesis import given, settings, strategies as st  # noqa: E402


@settings(max_examples=8, deadline=None)
@given(cuts=st.lists(st.integers(1, 29999), max_size=4), clips=st.lists(st.integers(0, 29999), max_size=3),
       kinds=st.lists(st.sampled_from(["gap", "overrun", "fault", "stop"]), min_size=4, max_size=4))
@pytest.mark.slow
def test_property_events_anywhere(tmp_path_factory, cuts, clips, kinds):
    """Gaps, overruns and clips anywhere: the run ends cleanly (or with a LabtoolError), never
    integrates across a cut, and whatever omega2 it gives over complete motion intervals is right."""
    from labtool.common.errors import LabtoolError

    tmp = tmp_path_factory.mktemp("ev")
    evs = [(c, k, "") for c, k in zip(cuts, kinds)] + [(c, "clip", "") for c in clips]
    try:
        ds, tr, s, _ = _run(tmp, opts=ProcessOptions(chunk_samples=8192), rpm=300.0, duration_s=3.0, events=evs)
    except LabtoolError:
        return
    om = ds["omega2"].values
    splits = sorted({c for c, k in zip(cuts, kinds) if k in ("gap", "overrun")})
    assert ds.attrs["n_segments"] == len(splits) + 1
    ok = np.isfinite(om)
    pk = np.abs(tr["omega2"]).max()
    assert np.all(np.abs(om[ok] - tr["omega2"][ok]) < 0.05 * pk)
    for c in clips:  # flagged, no acceleration, and no omega2 where the follower moves
        assert ds["clipped"].values[c] == 1 and np.isnan(ds["epsilon2"].values[c])
        assert np.isnan(om[c]) or not tr["moving"][c]


@pytest.mark.slow
def test_missed_tacho_pulse_and_dead_tacho(tmp_path):
    from stand_data import truth

    volts, scene, _, fs = stand_volts(3.0, 300.0)
    volts = volts.astype(np.float64)
    names = ["aE_t", "aE_n", "tacho"]
    tr = truth(scene, len(volts), fs)
    # remove the 5th tacho pulse: that revolution looks twice as long
    starts = np.flatnonzero(np.diff((volts[:, 2] > 2.5).astype(int)) == 1) + 1
    s5 = starts[4]
    volts[s5:s5 + 20, 2] = 0.0
    p = tmp_path / "missed.h5"
    write_v1(p, volts, names, fs, cam_speed_rpm=300.0)
    msgs = []
    with open_recording(p) as rec:
        s = process_recording(rec, tmp_path / "m.nc", warn=msgs.append)
    ds = xr.open_dataset(tmp_path / "m.nc", engine="h5netcdf", decode_times=False).load()
    assert any("deviate" in m for m in msgs)
    assert ds.attrs["cam_speed_rpm"] == pytest.approx(300.0, rel=1e-3)
    om = ds["omega2"].values
    assert np.isnan(om[s5 - 100:s5 + 1500]).all()  # the unknown revolution is NaN, not guessed
    e_o, e_e, _ = _rise_errors(ds, tr)
    assert e_o < 0.02 and e_e < 0.05
    # a dead tacho: fall back to the correlation, with a warning
    volts[:, 2] = 0.01
    q = tmp_path / "dead.h5"
    write_v1(q, volts, names, fs, cam_speed_rpm=300.0)
    msgs = []
    with open_recording(q) as rec:
        s = process_recording(rec, tmp_path / "d.nc", warn=msgs.append)
    assert s["phi1_method"] == "correlation" and any("fewer than two pulses" in m for m in msgs)
    ds = xr.open_dataset(tmp_path / "d.nc", engine="h5netcdf", decode_times=False).load()
    e_o, e_e, _ = _rise_errors(ds, tr)
    assert e_o < 0.02 and e_e < 0.05


@pytest.mark.slow
def test_spike_records_are_bounded(tmp_path, monkeypatch):
    import labtool.processing.accumulators as acc

    monkeypatch.setattr(acc, "MAX_SPIKES", 2)
    ds, tr, s, msgs = _run(tmp_path, duration_s=2.0, extra_m_s2=impact_bursts([0.3, 0.8, 1.3, 1.7]))
    assert s["spikes"] >= 4 and ds.sizes["spike"] == 2 and any("only the first 2" in m for m in msgs)
    assert ds.attrs["n_spikes"] == s["spikes"]


@pytest.mark.slow
def test_a_channel_missing_from_the_calibration_names_its_fallback(tmp_path):
    from labtool.processing.calibration_file import ChannelCalibration

    cal = {"aE_t": ChannelCalibration(90.0, 0.01)}
    opts = ProcessOptions(calibration=cal, calibration_source="cal.toml")
    ds, _, _, msgs = _run(tmp_path, opts=opts, rpm=180.0, duration_s=1.5)
    missing = [m for m in msgs if "no entry for channel aE_n" in m]
    assert len(missing) == 1
    assert "using the" in missing[0] and f"Ka = {ds.attrs['ka_aE_n_m_s2_per_v']:.4g}" in missing[0]
    assert not any("aE_t" in m for m in msgs if "no entry" in m)


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_a_quantised_quiet_channel_is_not_taken_for_clipping(tmp_path):
    """At Ka = 8643 m/s^2/V (gain x0.1) aE_n spans a few dozen ADC levels and holds its top code
    for several samples at every omega2 peak: that is quantisation, not a saturated conditioner,
    so no sample is flagged and the revolutions are averaged. The same recording clipped at
    +-1 V on a stated 10 V range is still flagged."""
    volts, scene, _, fs = stand_volts(2.0, 500.0, params={"ka_m_s2_per_v": (8643.0, 8643.0)})
    lsb = 20.0 / 2**16
    levels = (volts[:, 1].max() - volts[:, 1].min()) / lsb
    top_run = np.diff(np.flatnonzero(np.diff(np.concatenate([[0], volts[:, 1] == volts[:, 1].max(), [0]]).astype(int))))
    assert levels < 256 and top_run.max() >= 3          # the case: few levels, runs at the extreme
    adc = {"adc_range_v": 10.0, "adc_bits": 16}
    p = tmp_path / "quiet.h5"
    write_v1(p, volts, fs=fs, cam_speed_rpm=500.0, ka=[8643.0, 8643.0, np.nan], attrs=adc)
    with open_recording(p) as rec:
        s = process_recording(rec, tmp_path / "quiet.nc", warn=lambda m: None)
    assert s["clipped"] == 0
    ds = xr.open_dataset(tmp_path / "quiet.nc", engine="h5netcdf", decode_times=False).load()
    assert ds.attrs["n_revolutions_averaged"] > 10
    sat = volts.copy()
    sat[:, :2] = np.clip(sat[:, :2] * 100.0, -1.0, 1.0 - lsb)     # Ka 86.43 on a conditioner saturating at 1 V
    p2 = tmp_path / "sat.h5"
    write_v1(p2, sat, fs=fs, cam_speed_rpm=500.0, ka=[86.43, 86.43, np.nan], attrs=adc)
    with open_recording(p2) as rec:
        assert process_recording(rec, tmp_path / "sat.nc", warn=lambda m: None)["clipped"] > 100
