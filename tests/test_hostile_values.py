"""Hostile values: recording attributes of the wrong type, option values at
the edge of a float, factor files and measured files that were taken at face value. Each ends
with one line and exit 2 (tests/hostile.py ``one_error_line``)."""
from __future__ import annotations

import h5py
import numpy as np
import pytest
import xarray as xr

from hostile import REPORT_FAST, cli, measured_nc, one_error_line, run  # noqa: F401
from stand_data import stand_volts, write_v1


@pytest.fixture(scope="module")
def volts():
    return stand_volts(2.0)[0]


def _recording(tmp_path, volts, **root_attrs):
    path = tmp_path / "rec.h5"
    write_v1(path, volts)
    with h5py.File(path, "a") as f:
        for k, v in root_attrs.items():
            f.attrs[k] = v
    return path


# --- silent wrong: recording attributes --------------------------------------------------------
# a recording's root attribute that is not what it must be, and what it was read as before
BAD_ATTRIBUTES = [
    # complete = "no" was read as bool("no") = True: a killed recording passed for a clean one
    *[pytest.param({"complete": v}, ("complete", "true or false"), id=f"complete={v!r}")
      for v in ("no", "false", "0", np.array([1, 0]))],
    # sample_rate_hz = [10000, 20000] was read as its first value without a word
    pytest.param({"sample_rate_hz": np.array([10000.0, 20000.0])}, ("sample rate", "one number"),
                 id="sample_rate_hz=[10000, 20000]"),
    # ac_coupling_tau_s = "0.3 s" was taken for "no AC coupling": it was left in without a word
    *[pytest.param({"ac_coupling_tau_s": v}, ("ac_coupling_tau_s", "--ac-tau"), id=f"ac_coupling_tau_s={v!r}")
      for v in ("0.3 s", np.array([0.3, 0.5]))],
]


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("attrs, words", BAD_ATTRIBUTES)
def test_a_recording_attribute_that_is_not_what_it_must_be_is_refused(tmp_path, capsys, volts, attrs, words):
    rec = _recording(tmp_path, volts, **attrs)
    line = one_error_line(*cli(["process", rec, "-o", tmp_path / "m.nc"], capsys))
    assert all(w in line for w in words), line
    assert not (tmp_path / "m.nc").exists()


@pytest.mark.hostile("silent_wrong")
def test_events_outside_the_samples_are_named_not_dropped_in_silence(tmp_path, capsys, volts):
    """A gap at sample 10**12 or -5 marks no sample: the processing leaves it out, and now says so."""
    rec = tmp_path / "rec.h5"
    write_v1(rec, volts, events=[(10**12, "gap", "missing_samples=3"), (-5, "clip", ""), (100, "clip", "")])
    rc, err = cli(["process", rec, "-o", tmp_path / "m.nc"], capsys)
    assert rc == 0 and (tmp_path / "m.nc").exists()
    assert "ignoring 2 recorder event(s) outside its samples 0..%d" % volts.shape[0] in err
    assert "the first: gap at sample 1000000000000" in err


# --- traceback / silent wrong: loads and inertias past what a float holds -----------------------
@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("option, value", [("--jt-factor", "1e308"), ("--fu", "1e308")])
def test_simulate_with_a_load_or_inertia_past_the_bound(capsys, option, value):
    """simulate --model kinematic --jt-factor 1e308 printed MR13D_max_Nm null (inf) with exit 0."""
    line = one_error_line(*cli(["simulate", "--model", "kinematic", "--law", "sine", "--rpm", "180",
                                option, value, "--json"], capsys))
    assert option.lstrip("-").split("-")[0] in line.lower() or "inertia factor" in line or "load Fu" in line
    assert "1e+06" in line


@pytest.mark.hostile("traceback")
def test_kinematics_and_report_with_an_inertia_factor_of_1e308(tmp_path, capsys, measured_nc):
    """report --jt-factor 1e308 was an internal error (ValueError: Axis limits cannot be NaN or Inf)."""
    one_error_line(*cli(["kinematics", "--law", "sine", "--rpm", "180", "--jt-factor", "1e308",
                         "-o", tmp_path / "k.nc"], capsys))
    one_error_line(*cli(["report", measured_nc, *REPORT_FAST, "--jt-factor", "1e308",
                         "-o", tmp_path / "r.html"], capsys))
    assert not (tmp_path / "k.nc").exists() and not (tmp_path / "r.html").exists()


@pytest.mark.slow
@pytest.mark.hostile("hang")
@pytest.mark.parametrize("option", ["--fu", "--jt-factor"])
def test_acquire_with_a_load_or_inertia_of_1e308_does_not_hang(tmp_path, option):
    """The simulated stand's twin ran for ever on --fu 1e308 (and ignored SIGTERM)."""
    code, err = run(["acquire", "--device", "sim", "--duration", "1", "--fast", option, "1e308",
                     "-o", tmp_path / "r.h5"], timeout=120)
    one_error_line(code, err)
    assert not (tmp_path / "r.h5").exists()


@pytest.mark.hostile("traceback")
def test_acquire_with_a_duration_past_any_sample_count(tmp_path, capsys):
    """--duration 1e308 was an internal error (OverflowError: cannot convert float infinity to integer)."""
    line = one_error_line(*cli(["acquire", "--device", "sim", "--duration", "1e308", "--fast",
                                "-o", tmp_path / "r.h5"], capsys))
    assert "--duration" in line
    assert not (tmp_path / "r.h5").exists()


# --- traceback: factor files ------------------------------------------------------------------
@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("text", ["factor = [1, 2]\n", 'factor = ["A"]\n', "factor = [[1, 2]]\n"])
def test_a_toml_factor_file_whose_factors_are_not_tables(tmp_path, capsys, text):
    """factor = [1, 2] was an internal error (TypeError: argument of type 'int' is not iterable)."""
    path = tmp_path / "f.toml"
    path.write_text(text)
    line = one_error_line(*cli(["doe", "run", "--factors", path, "--yes", "-o", tmp_path / "r.csv"], capsys))
    assert "[[factor]]" in line


# --- silent wrong: measured files -------------------------------------------------------------
def _measured(tmp_path, measured_nc, change):
    ds = xr.open_dataset(measured_nc).load()
    change(ds)
    path = tmp_path / "m.nc"
    ds.to_netcdf(path)
    return path


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("attr, value, option", [("Fu_N", "heavy", "--fu"), ("jt_factor", "x", "--jt-factor"),
                                                 ("backlash_mm", "wide", "--backlash-mm")])
def test_an_operating_point_attribute_that_is_not_a_number_is_refused(tmp_path, capsys, measured_nc, attr, value,
                                                                      option):
    """Fu_N = "heavy" was taken as "the file does not state Fu" and the paper's 0 N used instead."""
    path = _measured(tmp_path, measured_nc, lambda ds: ds.attrs.update({attr: value}))
    line = one_error_line(*cli(["report", path, *REPORT_FAST, "-o", tmp_path / "r.html"], capsys))
    assert attr in line and option in line


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("var, unit", [("omega2", "deg/s"), ("epsilon2", "rpm"), ("phi1", "deg")])
def test_measured_quantities_in_other_units_are_refused(tmp_path, capsys, measured_nc, var, unit):
    """omega2 with units "deg/s" was compared with the models' rad/s as if it were rad/s."""
    path = _measured(tmp_path, measured_nc, lambda ds: ds[var].attrs.update(units=unit))
    line = one_error_line(*cli(["report", path, *REPORT_FAST, "-o", tmp_path / "r.html"], capsys))
    assert var in line and unit in line


# --- silent wrong: export ---------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("umask", [0o022, 0o002])
def test_export_follows_the_users_umask(tmp_path, capsys, measured_nc, umask):
    """export wrote its tables through mkstemp: 0600 whatever the umask."""
    import os

    old = os.umask(umask)
    try:
        code, err = cli(["export", measured_nc, "--csv", "-o", tmp_path / "m"], capsys)
    finally:
        os.umask(old)
    assert code == 0, err
    for name in ("m_cycles.csv", "m_series.csv"):
        assert (tmp_path / name).stat().st_mode & 0o777 == 0o666 & ~umask, name


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("prefix", ["", "folder/"])
def test_export_to_a_folder_or_an_empty_prefix_is_refused(tmp_path, capsys, measured_nc, monkeypatch, prefix):
    """-o out/ wrote out_cycles.csv beside the folder, -o "" hidden ._cycles.csv files here."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "folder").mkdir()
    line = one_error_line(*cli(["export", measured_nc, "--csv", "-o", prefix], capsys))
    assert "-o" in line and "prefix" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder"]


@pytest.mark.hostile("silent_wrong")
def test_a_factor_csv_with_a_gap_in_its_level_columns_is_refused(tmp_path, capsys):
    """level_1,level_3 (no level_2): the level_3 value became level 2 of the result table."""
    path = tmp_path / "f.csv"
    path.write_text("factor,symbol,unit,level_1,level_3\nA,Fu,N,0,65\n")
    line = one_error_line(*cli(["doe", "run", "--factors", path, "--yes", "-o", tmp_path / "r.csv"], capsys))
    assert "level_2" in line
    assert not (tmp_path / "r.csv").exists()


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("kind, said", [("folder", "is a folder"), ("device", "not a regular file")])
def test_a_factor_file_that_is_a_folder_or_a_device_is_named_so(tmp_path, capsys, kind, said):
    """--factors out/ or /dev/null said "factor file ... does not exist" of a path that exists."""
    path = tmp_path if kind == "folder" else "/dev/null"
    line = one_error_line(*cli(["doe", "run", "--factors", path, "--yes", "-o", tmp_path / "r.csv"], capsys))
    assert said in line and "does not exist" not in line


# --- silent wrong: processing options that were passed over ----------------------------------
@pytest.mark.hostile("silent_wrong")
def test_a_sample_rate_option_the_file_contradicts_is_refused(tmp_path, capsys, volts):
    """process rec.h5 --sample-rate 5000 on a file stating 10000 Hz ran at 10000 Hz without a word."""
    rec = _recording(tmp_path, volts)
    line = one_error_line(*cli(["process", rec, "--sample-rate", "5000", "-o", tmp_path / "m.nc"], capsys))
    assert "--sample-rate 5000" in line and "10000 Hz" in line
    assert not (tmp_path / "m.nc").exists()
    code, err = cli(["process", rec, "--sample-rate", "10000", "-o", tmp_path / "m.nc"], capsys)
    assert code == 0, err


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("tau", ["1e-300", "1e-6"])
def test_an_ac_coupling_constant_shorter_than_the_sampling_is_refused(tmp_path, capsys, volts, tau):
    """--ac-tau 1e-300 wrote omega2 = inf ("inf % rms of peak") with exit 0."""
    rec = _recording(tmp_path, volts)
    line = one_error_line(*cli(["process", rec, "--ac-tau", tau, "-o", tmp_path / "m.nc"], capsys))
    assert "--ac-tau" in line or "AC-coupling" in line
    assert not (tmp_path / "m.nc").exists()


# --- silent wrong: kinematics options that replaced the mechanism file's own values -------------
def _program_mechanism(tmp_path):
    """The STB-216 with a 3-4-5 rise of 70 deg (dwells left to their defaults) and a 20 deg stroke."""
    from hostile import MECHANISM

    text = MECHANISM.read_text().replace('law = "sine"', 'law = "poly345"').replace("rise_deg = 58.0", "rise_deg = 70.0")
    text = text.replace("psi_a_deg = 15.0", "psi_a_deg = 20.0")
    text = "\n".join(line for line in text.splitlines()
                     if not line.startswith(("upper_dwell_deg", "return_deg", "lower_dwell_deg")))
    path = tmp_path / "mech.toml"
    path.write_text(text + "\n")
    return path


@pytest.mark.hostile("silent_wrong")
@pytest.mark.slow
def test_kinematics_takes_the_law_rise_and_stroke_of_its_mechanism_file(tmp_path, capsys):
    """kinematics --mechanism with law = "poly345", rise_deg = 70 wrote a sine rise of 58 deg, exit 0."""
    mech = _program_mechanism(tmp_path)
    code, err = cli(["kinematics", "--mechanism", mech, "-o", tmp_path / "k.nc"], capsys)
    assert code == 0, err
    with xr.open_dataset(tmp_path / "k.nc") as ds:
        rise_end = np.degrees(float(ds.phi1[int(np.argmax(ds.psi.values))]))
        assert rise_end == pytest.approx(70.0, abs=0.5)
        assert np.degrees(float(ds.psi.max())) == pytest.approx(20.0, rel=1e-6)
        # the file's values are recorded as attributes; the history is the command as typed
        assert (ds.attrs["law"], ds.attrs["rise_deg"], ds.attrs["stroke_deg"]) == ("poly345", 70.0, 20.0)
        assert ds.attrs["history"].endswith(f"labtool kinematics --mechanism {mech} -o {tmp_path / 'k.nc'}")
    # given, an option still wins, even when it is the paper's value
    code, err = cli(["kinematics", "--mechanism", mech, "--stroke-deg", "15", "-o", tmp_path / "k.nc", "--force"], capsys)
    assert code == 0, err
    with xr.open_dataset(tmp_path / "k.nc") as ds:
        assert np.degrees(float(ds.psi.max())) == pytest.approx(15.0, rel=1e-6)


@pytest.mark.hostile("silent_wrong")
def test_kinematics_with_an_empty_law_is_refused(tmp_path, capsys):
    """--law "" ran the mechanism's (the paper's) sine law without a word; simulate refuses it."""
    line = one_error_line(*cli(["kinematics", "--law", "", "-o", tmp_path / "k.nc"], capsys))
    assert "motion law ''" in line
    assert not (tmp_path / "k.nc").exists()


@pytest.mark.hostile("silent_wrong")
def test_simulate_takes_the_law_of_its_mechanism_file(tmp_path, capsys):
    """simulate --mechanism with law = "poly345" ran the sine law (MR13D max 5.196 N m), exit 0."""
    import json

    from hostile import MECHANISM
    from labtool.cli import main

    mech = tmp_path / "mech.toml"
    mech.write_text(MECHANISM.read_text().replace('law = "sine"', 'law = "poly345"'))
    got = {}
    for name, args in (("file", ["--mechanism", str(mech)]), ("option", ["--law", "poly345"]),
                       ("sine", ["--law", "sine"])):
        capsys.readouterr()
        assert main(["simulate", "--model", "kinematic", *args, "--json"]) == 0
        got[name] = json.loads(capsys.readouterr().out.strip().splitlines()[-1])["MR13D_max_Nm"]
    assert got["file"] == pytest.approx(got["option"], rel=1e-9)
    assert got["file"] != pytest.approx(got["sine"], rel=1e-3)


# --- doe analyze: results tables that were read wrong -----------------------------------------
def _table2(tmp_path, change):
    """Table 2 (the paper's rigid results) as CSV text lines, changed by ``change(header, rows)``."""
    import csv

    from hostile import ROOT

    rows = list(csv.reader((ROOT / "models" / "data" / "table2_rigid.csv").read_text().splitlines()))
    change(rows[0], rows[1:])
    path = tmp_path / "results.csv"
    with open(path, "w", newline="") as f:
        csv.writer(f).writerows(rows)
    return path


@pytest.mark.hostile("traceback")
def test_doe_analyze_with_two_columns_of_one_name_is_one_line(tmp_path, capsys):
    """A header with "jumps" and " jumps" was an internal error (TypeError: arg must be a list, ...)."""
    def rename(header, rows):
        header[5] = " jumps"
    line = one_error_line(*cli(["doe", "analyze", _table2(tmp_path, rename), "--json"], capsys))
    assert "jumps" in line and "more than once" in line


@pytest.mark.hostile("silent_wrong")
def test_doe_analyze_with_a_response_too_small_to_square_is_refused(tmp_path, capsys):
    """MR13D_max_Nm in units of 1e300 N m was "the response is constant: no effect can be tested", exit 0
    (its squares underflow to 0)."""
    def shrink(header, rows):
        for r in rows:
            r[5] = repr(float(r[5]) * 1e-300)
    line = one_error_line(*cli(["doe", "analyze", _table2(tmp_path, shrink), "--json"], capsys))
    assert "MR13D_max_Nm" in line and "rescale" in line


@pytest.mark.hostile("silent_wrong")
def test_the_stands_twin_refuses_a_groove_no_cam_realises(tmp_path, capsys):
    """acquire --device sim with a backlash that leaves the groove undercut (8 mm: within the bounds
    of a backlash, past what the STB-216's cam realises) wrote a recording, exit 0, where simulate and
    the rigid and elastic truths refuse that groove; 1e6 mm is past the backlash's own bounds."""
    line = one_error_line(*cli(["acquire", "--device", "sim", "--fast", "--duration", "0.1", "--backlash-mm", "8",
                                "--status-every", "0", "-o", tmp_path / "r.h5"], capsys))
    assert "undercut" in line
    line = one_error_line(*cli(["acquire", "--device", "sim", "--fast", "--duration", "0.1", "--backlash-mm", "1e6",
                                "--status-every", "0", "-o", tmp_path / "r.h5"], capsys))
    assert "backlash j must be in [0, 10] mm" in line
    assert not (tmp_path / "r.h5").exists()


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("ka", ["1e308", "1e-300", "0"])
def test_acquire_refuses_a_ka_no_chain_has(tmp_path, capsys, ka):
    """acquire --device sim --ka 1e308 wrote a recording stating Ka = 1e308 (exit 0), which process
    then used: |omega2| vs sqrt(aE_n/DE) 265.6 % rms of peak."""
    line = one_error_line(*cli(["acquire", "--device", "sim", "--fast", "--duration", "0.1", "--ka", ka,
                                "--status-every", "0", "-o", tmp_path / "r.h5"], capsys))
    assert "--ka" in line and "1e+06" in line
    assert not (tmp_path / "r.h5").exists()


# --- traceback: a hand-edited campaign folder ---------------------------------------------------
@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("text", [
    "[]",    # AttributeError: 'list' object has no attribute 'get'
    "{}",    # UndefinedError: 'dict object' has no attribute 'cam_speed_rpm'
    '{"format": "labtool.report.summary", "operating_point": {"cam_speed_rpm": 180}, "measured": {}, "headline": "x"}',
], ids=["list", "empty", "headline-text"])
@pytest.mark.slow
def test_campaign_report_on_a_hand_edited_summary_is_one_line(tmp_path, capsys, text):
    from labtool.common.files import write_netcdf

    point = tmp_path / "camp" / "points" / "01_180rpm"
    point.mkdir(parents=True)
    (point / "summary.json").write_text(text)
    write_netcdf(xr.Dataset({"x": ("t", [1.0])}), point / "cycles.nc")
    line = one_error_line(*cli(["campaign", "report", tmp_path / "camp", "-o", tmp_path / "c.html"], capsys))
    assert "01_180rpm" in line and "summary.json" in line
    assert not (tmp_path / "c.html").exists()


@pytest.mark.hostile("traceback")
@pytest.mark.slow
def test_campaign_report_on_a_foreign_cycles_file_is_one_line(tmp_path, capsys):
    """A point's cycles.nc without the overlays (another NetCDF file copied there) was an internal
    error: KeyError: "No variable named 'phi1'..."."""
    import json

    from labtool.campaign.collect import load_measured_file
    from labtool.campaign.plan import check_compare
    from labtool.common.files import write_netcdf
    from labtool.reports.synthetic import synthetic_measured

    measured = tmp_path / "measured.nc"
    write_netcdf(synthetic_measured(rpm=180.0, revolutions=3.4, seed=1), measured)
    rec = load_measured_file(measured, check_compare({"models": ["kinematic"]}, "options"), {})
    point = tmp_path / "camp" / "points" / "01_180rpm"
    point.mkdir(parents=True)
    (point / "summary.json").write_text(json.dumps(rec.summary, default=str))   # a real summary
    write_netcdf(xr.Dataset({"x": ("t", [1.0])}), point / "cycles.nc")
    line = one_error_line(*cli(["campaign", "report", tmp_path / "camp", "-o", tmp_path / "c.html"], capsys))
    assert "01_180rpm" in line and "cycles.nc" in line and "phi1" in line
    (point / "cycles.nc").unlink()
    write_netcdf(rec.cycles, point / "cycles.nc")   # the real overlays: the point is shown
    code, err = cli(["campaign", "report", tmp_path / "camp", "-o", tmp_path / "c.html"], capsys)
    assert code == 0, err


@pytest.mark.hostile("silent_wrong")
def test_a_scene_ka_past_the_calibration_bounds_is_named_by_its_key(tmp_path, capsys):
    """A scene's ka_m_s2_per_v = 5e6 was taken (the schema allowed 1e7); then refused as "--ka"."""
    scene = tmp_path / "scene.toml"
    scene.write_text("[stand]\nka_m_s2_per_v = 5e6\n")
    line = one_error_line(*cli(["acquire", "--device", "sim", "--fast", "--duration", "0.1", "--scene", scene,
                                "--status-every", "0", "-o", tmp_path / "r.h5"], capsys))
    assert "ka_m_s2_per_v" in line and "1e+06" in line


@pytest.mark.hostile("silent_wrong")
@pytest.mark.slow
def test_a_stated_low_pass_that_is_not_a_number_is_refused(tmp_path, capsys, measured_nc):
    """lowpass_hz = "300 Hz" (and the history unreadable) was read as "no low-pass": the models went
    unfiltered against the filtered measurement (rigid epsilon2 ISO 0.623 -> 0.616), exit 0, no word."""
    def edit(ds):
        ds.attrs["lowpass_hz"] = "300 Hz"
        ds.attrs["processing_history"] = "{"
    path = _measured(tmp_path, measured_nc, edit)
    line = one_error_line(*cli(["report", path, *REPORT_FAST, "-o", tmp_path / "r.html"], capsys))
    assert "low-pass" in line and "300 Hz" in line
    assert not (tmp_path / "r.html").exists()


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("args,said", [
    # 1e-9 s at 10 kHz: a recording of 0 samples marked complete, exit 0 (process refused it later)
    (["--duration", "1e-9"], "less than one sample"),
    (["--duration", "5e-5", "--rate", "10000"], "less than one sample"),
    # the shaker above Nyquist: the recording held its alias, exit 0 (calibrate refused it later)
    (["--mode", "calibration", "--cal-freq", "6000"], "half the sample rate"),
    (["--mode", "calibration", "--cal-freq", "5000"], "half the sample rate"),
])
def test_acquire_refuses_a_recording_that_cannot_hold_what_it_asks(tmp_path, capsys, args, said):
    out = tmp_path / "r.h5"
    line = one_error_line(*cli(["acquire", "--device", "sim", "--fast", *args, "-o", out], capsys))
    assert said in line
    assert not out.exists()


@pytest.mark.hostile("silent_wrong")
def test_process_refuses_a_recording_whose_every_sample_is_flagged(tmp_path, capsys, volts):
    """aE_n on two ADC levels (acquire --ka 1e5: the signal below the ADC's resolution) flagged
    every sample as clipped, and process wrote an all-NaN measured.nc, 0 revolutions, exit 0."""
    two_levels = volts.copy()
    two_levels[:, 1] = np.where(np.sin(np.arange(len(volts)) / 50.0) > 0, 3.05e-4, 0.0).astype(volts.dtype)
    rec = _recording(tmp_path, two_levels)
    line = one_error_line(*cli(["process", rec, "-o", tmp_path / "m.nc"], capsys))
    assert "every one of its" in line and "flagged as clipped" in line
    assert not (tmp_path / "m.nc").exists()
