"""End to end: synthetic recordings with a known truth -> measured.nc; the CLI; bad input."""
from __future__ import annotations

import json
import math

import h5py
import numpy as np
import pytest
import xarray as xr

from labtool.cli import main
from processing.pipeline import ProcessOptions, process_recording
from processing.readers import open_recording
from processing.synthetic import SynthSpec, write_synthetic, write_v1


def _run(tmp_path, spec, name="r", opts=None, **kw):
    p = tmp_path / f"{name}.h5"
    tr = write_synthetic(p, spec, **kw)
    out = tmp_path / f"{name}.nc"
    msgs = []
    with open_recording(p) as rec:
        summary = process_recording(rec, out, opts or ProcessOptions(), warn=msgs.append)
    ds = xr.open_dataset(out, engine="h5netcdf").load()
    return ds, tr, summary, msgs


def _rise_errors(ds, tr):
    om, ep = ds["omega2"].values, ds["epsilon2"].values
    rise = (np.mod(tr["phi1"], 2 * np.pi) < tr["program"].rise_angle) & np.isfinite(om)
    pk_o = np.abs(tr["omega2"][rise]).max()
    pk_e = np.abs(tr["epsilon2"][rise]).max()
    e_o = np.sqrt(np.mean((om[rise] - tr["omega2"][rise]) ** 2)) / pk_o
    e_e = np.sqrt(np.mean((ep[rise] - tr["epsilon2"][rise]) ** 2)) / pk_e
    return e_o, e_e, int(rise.sum())


@pytest.mark.parametrize("rpm, tacho", [(180.0, True), (180.0, False), (500.0, True), (300.0, False)])
def test_recovers_known_omega2_and_epsilon2(tmp_path, rpm, tacho):
    """Noise, gravity, AC coupling, resonance, offset and quantization: omega2 < 2 %, epsilon2 < 5 %."""
    spec = SynthSpec(rpm=rpm, duration_s=3.0, tacho=tacho, noise_rms_m_s2=2.0, ac_tau_s=1.6, rpm_drift=1.0)
    ds, tr, s, _ = _run(tmp_path, spec)
    e_o, e_e, n = _rise_errors(ds, tr)
    assert n > 1000
    assert e_o < 0.02 and e_e < 0.05
    assert s["phi1_method"] == ("tacho" if tacho else "correlation")
    assert ds.attrs["cam_speed_rpm"] == pytest.approx(rpm + 1.5, rel=0.01)  # mean over the drifting record
    # the |omega2| = sqrt(aE_n/DE) check agrees with the integral
    assert ds.attrs["omega2_normal_check_rel_rms"] < 0.08
    # cycle average close to the kinematics (the speed drifts by 3 rpm)
    assert ds.attrs["n_revolutions_averaged"] >= int(3.0 * rpm / 60) - 2
    pk = np.abs(ds["omega2_kinematic"]).max()
    assert np.sqrt(np.mean((ds["omega2_mean"] - ds["omega2_kinematic"]) ** 2)) / pk < 0.03


def test_undoing_the_ac_coupling_improves_the_result(tmp_path):
    spec = SynthSpec(rpm=180.0, duration_s=2.5, ac_tau_s=0.3, noise_rms_m_s2=0.5)
    ds0, tr, _, _ = _run(tmp_path, spec, "a")
    ds1, _, _, _ = _run(tmp_path, spec, "b", ProcessOptions(ac_tau_s=0.3))
    e0, e1 = _rise_errors(ds0, tr), _rise_errors(ds1, tr)
    assert e1[0] < 0.3 * e0[0] and e1[1] < 0.5 * e0[1] and e1[0] < 0.005


def test_chunk_size_does_not_change_the_result(tmp_path):
    spec = SynthSpec(rpm=300.0, duration_s=3.0, spikes_at_s=(1.234,))
    a, _, _, _ = _run(tmp_path, spec, "big")
    b, _, _, _ = _run(tmp_path, spec, "small", ProcessOptions(chunk_samples=4096))
    for v in ("aE_t", "aE_n", "epsilon2", "omega2", "phi1", "revolution", "omega2_mean", "aE_t_psd"):
        np.testing.assert_allclose(a[v].values, b[v].values, rtol=1e-4, atol=1e-4 * float(np.nanmax(np.abs(a[v]))))
    assert a["spike_sample"].values.tolist() == b["spike_sample"].values.tolist()


def test_output_names_units_history(tmp_path):
    spec = SynthSpec(duration_s=2.0, spikes_at_s=(0.777,))
    ds, tr, s, _ = _run(tmp_path, spec)
    for v in ("aE_t", "aE_n", "epsilon2", "omega2", "phi1", "revolution", "aE_t_amplitude", "aE_n_psd",
              "omega2_mean", "omega2_std", "epsilon2_mean", "epsilon2_std", "spike_time"):
        assert v in ds
    for name in list(ds.data_vars) + list(ds.coords):
        assert ds[name].attrs.get("units") and ds[name].attrs.get("long_name"), name
    assert set(ds["omega2_mean"].dims) == {"phi1_grid"} and set(ds["aE_t_psd"].dims) == {"frequency"}
    steps = [h["step"] for h in json.loads(ds.attrs["processing_history"])]
    for step in ("read", "apply_ka", "cam_angle", "lowpass", "remove_gravity", "dwell_reference", "epsilon2", "omega2",
                 "check_normal", "cycle_average", "spectra", "spikes"):
        assert step in steps
    assert ds.attrs["ka_source_aE_t"].startswith("paper default") and ds.attrs["ka_aE_t_m_s2_per_v"] == 86.43
    # the impact burst at 0.777 s is found, in the right place
    t = ds["spike_time"].values
    assert np.any(np.abs(t - 0.777) < 0.003)
    # a spectrum peak at the cam frequency harmonics, not at DC: the offset is removed
    f = ds["frequency"].values
    amp = ds["aE_t_amplitude"].values
    assert amp[0] < 0.1 * amp.max() and f[np.argmax(amp)] < 100.0


def test_gaps_split_segments_and_clips_are_kept_out(tmp_path):
    spec = SynthSpec(rpm=300.0, duration_s=4.0)
    gap, clip = 15000, 27000
    ds, tr, s, msgs = _run(tmp_path, spec, events=[(gap, "gap", "missing_samples=250 (0.025 s) lost before this row"),
                                                   (gap, "overrun", "250 samples lost"), (clip, "clip", "aE_t")])
    t = ds["time"].values
    assert np.diff(t)[gap - 1] == pytest.approx(251 / spec.fs) and t[-1] == pytest.approx((40000 - 1 + 250) / spec.fs)
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


def test_saturated_adc_is_flagged(tmp_path):
    spec = SynthSpec(rpm=500.0, duration_s=2.0, adc_range_v=1.0, tacho=True)  # aE_t peaks ~ 3.4 V
    ds, tr, s, _ = _run(tmp_path, spec)
    assert s["clipped"] > 100
    assert np.isnan(ds["omega2"].values[ds["clipped"].values == 1]).all()
    assert ds.attrs["n_revolutions_averaged"] == 0


def test_incomplete_recording_processes_with_warning(tmp_path):
    spec = SynthSpec(duration_s=2.0)
    ds, tr, s, msgs = _run(tmp_path, spec, complete=False)
    assert any("incomplete" in m for m in msgs) and ds.attrs["recording_complete"] == 0
    assert _rise_errors(ds, tr)[0] < 0.02


def test_ka_from_calibration_file_and_recording_attribute(tmp_path, capsys):
    spec = SynthSpec(duration_s=1.5, ka=100.0)
    p = tmp_path / "r.h5"
    write_synthetic(p, spec, ka=[90.0, 95.0, np.nan])
    assert main(["process", str(p), "-o", str(tmp_path / "a.nc")]) == 0
    a = xr.open_dataset(tmp_path / "a.nc", engine="h5netcdf")
    assert a.attrs["ka_aE_t_m_s2_per_v"] == 90.0 and "recording attribute" in a.attrs["ka_source_aE_t"]
    cal = tmp_path / "cal.toml"
    cal.write_text("[channels.aE_t]\nka_m_s2_per_v = 100.0\nuncertainty_m_s2_per_v = 0.4\n"
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
    write_synthetic(good, SynthSpec(duration_s=1.0))
    trunc = tmp_path / "trunc.h5"
    trunc.write_bytes(good.read_bytes()[:5000])
    other = tmp_path / "other.h5"
    other.write_bytes(b"PK\x03\x04" + bytes(1000))
    norate = tmp_path / "norate.h5"
    write_synthetic(norate, SynthSpec(duration_s=1.0))
    with h5py.File(norate, "a") as f:
        del f.attrs["sample_rate_hz"]
    wrong = tmp_path / "wrongrate.h5"
    write_synthetic(wrong, SynthSpec(duration_s=2.0))
    with h5py.File(wrong, "a") as f:
        f.attrs["sample_rate_hz"] = 1000.0  # 10 kHz data labelled 1 kHz
    zero = tmp_path / "zerorate.h5"
    write_synthetic(zero, SynthSpec(duration_s=1.0))
    with h5py.File(zero, "a") as f:
        f.attrs["sample_rate_hz"] = 0.0
    nan = tmp_path / "nan.h5"
    v = np.random.default_rng(0).normal(size=(5000, 3))
    v[100, 0] = np.nan
    write_v1(nan, v, ["aE_t", "aE_n", "tacho"], 10000.0)
    miss = tmp_path / "missing.h5"
    write_v1(miss, v[:, :2] * 0 + 1, ["aE_t", "tacho"], 10000.0)
    flat = tmp_path / "flat.h5"
    write_v1(flat, np.zeros((30000, 2)), ["aE_t", "aE_n"], 10000.0)
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


def test_bad_input_one_line_exit_2_and_no_output(tmp_path, capsys):
    cases = _bad_inputs(tmp_path)
    for label, args in cases.items():
        out = tmp_path / f"out_{label.replace(' ', '_')}.nc"
        code = main(["process", *args, "-o", str(out)])
        # warnings may come first (the paper's default Ka, say); the error is one line
        err = [x for x in capsys.readouterr().err.strip().splitlines() if not x.startswith("labtool: warning:")]
        assert code == 2, label
        assert len(err) == 1 and err[0].startswith("labtool: error:"), (label, err)
        assert not out.exists(), label
    assert not list(tmp_path.glob("*.part")), "a temporary file was left behind"


def test_existing_output_needs_force(tmp_path, capsys):
    p = tmp_path / "r.h5"
    write_synthetic(p, SynthSpec(duration_s=1.0))
    out = tmp_path / "m.nc"
    out.write_text("keep me")
    assert main(["process", str(p), "-o", str(out)]) == 2
    assert out.read_text() == "keep me"
    assert main(["process", str(p), "-o", str(out), "--force"]) == 0


def test_csv_and_tdms_process_like_hdf5(tmp_path):
    from nptdms import ChannelObject, TdmsWriter

    from processing.synthetic import make_signals

    spec = SynthSpec(duration_s=2.0, rpm=300.0)
    volts, names, tr = make_signals(spec)
    c = tmp_path / "r.csv"
    with open(c, "w") as fh:
        fh.write(",".join(names) + "\n")
        np.savetxt(fh, volts, delimiter=",", fmt="%.7g")
    assert main(["process", str(c), "--sample-rate", "10000", "-o", str(tmp_path / "c.nc")]) == 0
    t = tmp_path / "r.tdms"
    labview = {"aE_t": "aE300t", "aE_n": "aE300n", "tacho": "Dev1/ai2"}  # the paper's style of names
    with TdmsWriter(t) as w:
        w.write_segment([ChannelObject("g", labview[n], volts[:, j], properties={"wf_increment": 1e-4})
                         for j, n in enumerate(names)])
    assert main(["process", str(t), "-o", str(tmp_path / "t.nc")]) == 2  # aE_t missing
    assert main(["process", str(t), "-o", str(tmp_path / "t.nc"), "--channels", "aE_x=aE300t"]) == 2
    assert main(["process", str(t), "-o", str(tmp_path / "t.nc"),
                 "--channels", "aE_t=aE300t,aE_n=aE300n,tacho=Dev1/ai2"]) == 0
    for f in ("c.nc", "t.nc"):
        ds = xr.open_dataset(tmp_path / f, engine="h5netcdf")
        e_o, e_e, _ = _rise_errors(ds, tr)
        assert e_o < 0.02 and e_e < 0.05, f


from hypothesis import given, settings, strategies as st  # noqa: E402


@settings(max_examples=8, deadline=None)
@given(cuts=st.lists(st.integers(1, 29999), max_size=4), clips=st.lists(st.integers(0, 29999), max_size=3),
       kinds=st.lists(st.sampled_from(["gap", "overrun", "fault", "stop"]), min_size=4, max_size=4))
def test_property_events_anywhere(tmp_path_factory, cuts, clips, kinds):
    """Gaps, overruns and clips anywhere: the run ends cleanly (or with a LabtoolError), never
    integrates across a cut, and whatever omega2 it gives over complete motion intervals is right."""
    from common.errors import LabtoolError

    tmp = tmp_path_factory.mktemp("ev")
    spec = SynthSpec(rpm=300.0, duration_s=3.0)
    evs = [(c, k, "") for c, k in zip(cuts, kinds)] + [(c, "clip", "") for c in clips]
    try:
        ds, tr, s, _ = _run(tmp, spec, events=evs, opts=ProcessOptions(chunk_samples=8192))
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


def test_missed_tacho_pulse_and_dead_tacho(tmp_path):
    from processing.synthetic import make_signals

    spec = SynthSpec(rpm=300.0, duration_s=3.0)
    volts, names, tr = make_signals(spec)
    # remove the 5th tacho pulse: that revolution looks twice as long
    starts = np.flatnonzero(np.diff((volts[:, 2] > 2.5).astype(int)) == 1) + 1
    s5 = starts[4]
    volts[s5:s5 + 20, 2] = 0.0
    p = tmp_path / "missed.h5"
    write_v1(p, volts, names, spec.fs)
    msgs = []
    with open_recording(p) as rec:
        s = process_recording(rec, tmp_path / "m.nc", warn=msgs.append)
    ds = xr.open_dataset(tmp_path / "m.nc", engine="h5netcdf").load()
    assert any("deviate" in m for m in msgs)
    assert ds.attrs["cam_speed_rpm"] == pytest.approx(300.0, rel=1e-3)
    om = ds["omega2"].values
    assert np.isnan(om[s5 - 100:s5 + 1500]).all()  # the unknown revolution is NaN, not guessed
    e_o, e_e, _ = _rise_errors(ds, tr)
    assert e_o < 0.02 and e_e < 0.05
    # a dead tacho: fall back to the correlation, with a warning
    volts[:, 2] = 0.01
    q = tmp_path / "dead.h5"
    write_v1(q, volts, names, spec.fs)
    msgs = []
    with open_recording(q) as rec:
        s = process_recording(rec, tmp_path / "d.nc", warn=msgs.append)
    assert s["phi1_method"] == "correlation" and any("fewer than two pulses" in m for m in msgs)
    ds = xr.open_dataset(tmp_path / "d.nc", engine="h5netcdf").load()
    e_o, e_e, _ = _rise_errors(ds, tr)
    assert e_o < 0.02 and e_e < 0.05


def test_spike_records_are_bounded(tmp_path, monkeypatch):
    import processing.pipeline as pl

    monkeypatch.setattr(pl, "MAX_SPIKES", 2)
    spec = SynthSpec(duration_s=2.0, spikes_at_s=(0.3, 0.8, 1.3, 1.7))
    ds, tr, s, msgs = _run(tmp_path, spec)
    assert s["spikes"] >= 4 and ds.sizes["spike"] == 2 and any("only the first 2" in m for m in msgs)
    assert ds.attrs["n_spikes"] == s["spikes"]


def test_a_channel_missing_from_the_calibration_names_its_fallback(tmp_path):
    from processing.calibration_file import ChannelCalibration

    cal = {"aE_t": ChannelCalibration(90.0, 0.01, "calibration file cal.toml")}
    opts = ProcessOptions(calibration=cal)
    ds, _, _, msgs = _run(tmp_path, SynthSpec(rpm=180.0, duration_s=1.5), opts=opts)
    missing = [m for m in msgs if "no entry for channel aE_n" in m]
    assert len(missing) == 1
    assert "using the" in missing[0] and f"Ka = {ds.attrs['ka_aE_n_m_s2_per_v']:.4g}" in missing[0]
    assert not any("aE_t" in m for m in msgs if "no entry" in m)
