"""Hostile file contents (hunt 3): hand-edited measured files and text exports, where earlier hunts
tried options. Each ends with one line and exit 2 (tests/hostile.py ``one_error_line``), or, where
the file is usable, with exit 0 and the right answer."""
from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from hostile import REPORT_FAST, cli, measured_nc, one_error_line  # noqa: F401
from stand_data import stand_volts


@pytest.fixture(scope="module")
def volts():
    return stand_volts(2.0)[0]


def _csv(tmp_path, volts, header: dict, time_column: bool = True):
    """A CSV export of the stand recording (aE_t, aE_n, tacho in V) with a ``# key = value`` header."""
    path = tmp_path / "rec.csv"
    t = np.arange(volts.shape[0]) / 1e4
    lines = [f"# {k} = {v}" for k, v in header.items()]
    lines.append(("time [s]," if time_column else "") + "aE_t [V],aE_n [V],tacho [V]")
    rows = np.column_stack([t, volts]) if time_column else volts
    lines += [",".join("%.9g" % v for v in r) for r in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def _measured(tmp_path, measured_nc, change):
    ds = xr.open_dataset(measured_nc, decode_times=False).load()
    ds = change(ds) or ds
    path = tmp_path / "m.nc"
    ds.to_netcdf(path)
    return path


# --- traceback: measured files for report ------------------------------------------------------
@pytest.mark.slow
@pytest.mark.hostile("traceback")
def test_report_on_a_measured_file_with_a_short_run_of_finite_samples(tmp_path, capsys, measured_nc):
    """epsilon2 NaN from sample 100 to 200 left a piece of 100 finite samples, shorter than the
    impact detector's speed average (166 samples at 180 rpm): an internal error (ValueError:
    operands could not be broadcast together with shapes (100,) (166,))."""
    def edit(ds):
        ds["epsilon2"][100:200] = np.nan
    path = _measured(tmp_path, measured_nc, edit)
    code, err = cli(["report", path, *REPORT_FAST, "-o", tmp_path / "r.html"], capsys)
    assert code == 0, err
    assert (tmp_path / "r.html").exists()


def _two_columns(ds):
    """omega2 over (time, x): two columns of one signal, as another tool may store channels."""
    ds["omega2"] = (("time", "x"), np.stack([ds["omega2"].values] * 2, axis=1))


@pytest.mark.slow
@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("command", [[*["report"], "{m}", *REPORT_FAST, "-o", "{o}/r.html"],
                                     ["export", "{m}", "--csv", "-o", "{o}/x"]], ids=["report", "export"])
def test_a_measured_signal_over_two_dimensions_is_refused(tmp_path, capsys, measured_nc, command):
    """omega2 over (time, x) was an internal error: report 'ValueError: operands could not be
    broadcast together with shapes (40000,) (40000,2) (40000,)', export 'ValueError: Per-column
    arrays must each be 1-dimensional'."""
    path = _measured(tmp_path, measured_nc, _two_columns)
    args = [str(a).format(m=path, o=tmp_path) for a in command]
    line = one_error_line(*cli(args, capsys))
    assert "omega2" in line and "('time', 'x')" in line and "time" in line
    assert not list(tmp_path.glob("r.html")) and not list(tmp_path.glob("x_*.csv"))


def _time_in(unit, scale):
    def edit(ds):
        ds["time"] = ("time", (ds["time"].values - ds["time"].values[0]) * scale, {"units": unit})
    return edit


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("unit, scale", [("ms", 1e3), ("minutes since 2026-01-01", 1 / 60)])
def test_export_refuses_a_time_that_is_not_in_seconds(tmp_path, capsys, measured_nc, unit, scale):
    """time with units "ms" was written as the column 'time [s]' in ms (3999.9 for 4 s), exit 0."""
    path = _measured(tmp_path, measured_nc, _time_in(unit, scale))
    line = one_error_line(*cli(["export", path, "--csv", "-o", tmp_path / "x"], capsys))
    assert unit in line and "seconds" in line
    assert not list(tmp_path.glob("x_*.csv"))


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_report_refuses_a_time_that_is_not_in_seconds(tmp_path, capsys, measured_nc):
    """time in ms was read as seconds: the cam turned 1000x slower (at 180 rpm refused as 'cam speed
    0.18 rpm is outside the range'; at 1000 rpm simulated at 1 rpm)."""
    path = _measured(tmp_path, measured_nc, _time_in("ms", 1e3))
    line = one_error_line(*cli(["report", path, *REPORT_FAST, "-o", tmp_path / "r.html"], capsys))
    assert "'ms'" in line and "seconds" in line


@pytest.mark.slow
@pytest.mark.parametrize("unit", [None, "s", "seconds", "seconds since 2026-12-07T01:08:47+00:00"])
def test_a_time_in_seconds_is_exported(tmp_path, capsys, measured_nc, unit):
    def edit(ds):
        ds["time"] = ("time", ds["time"].values, {} if unit is None else {"units": unit})
    path = _measured(tmp_path, measured_nc, edit)
    code, err = cli(["export", path, "--csv", "-o", tmp_path / "x"], capsys)
    assert code == 0, err


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_report_says_when_the_measured_file_states_no_law(tmp_path, capsys, measured_nc):
    """A measured file without its law attribute (another tool's) was compared with the sine law with
    exit 0 and no note, where a missing Fu, j or Jt is noted."""
    from labtool.cli import main
    path = _measured(tmp_path, measured_nc, lambda ds: ds.attrs.pop("law") and None)
    capsys.readouterr()
    code = main(["report", str(path), *REPORT_FAST, "-o", str(tmp_path / "r.html")])
    out = capsys.readouterr()
    assert code == 0, out.err
    note = [line for line in out.out.splitlines() if "does not state" in line]
    assert note and "motion law = sine" in note[0] and "--law" in note[0], out.out


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("key, value, unit", [("ka_aE_t", "86.43 m/s^2/V", "m/s^2/V"), ("cam_speed_rpm", "fast", "rpm")])
def test_a_csv_header_value_that_is_not_one_number_is_refused(tmp_path, capsys, volts, key, value, unit):
    """ka_aE_t = "86.43 m/s^2/V" was read as "not stated": the paper's Ka was used with a warning that
    the recording gives none (right here by chance; 864.3 gave omega2 10x too small), exit 0."""
    header = {"sample_rate_hz": 10000, "cam_speed_rpm": 180, "ka_aE_t": 86.43, "ka_aE_n": 86.43, key: value}
    rec = _csv(tmp_path, volts, header)
    line = one_error_line(*cli(["process", rec, "-o", tmp_path / "m.nc"], capsys))
    assert key.lower() in line and value in line and unit in line
    assert not (tmp_path / "m.nc").exists()


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("key, value, unit", [("sample_rate_hz", "10 kHz", "Hz"), ("dt", "0.1 ms", "in s")])
def test_a_csv_header_rate_in_another_unit_is_refused(tmp_path, capsys, volts, key, value, unit):
    """sample_rate_hz = "10 kHz" was read as 10 Hz (the number before the unit): without a time column
    or a stated cam speed, process wrote "cam 0.18 rpm ... low-pass 0 Hz" with exit 0."""
    rec = _csv(tmp_path, volts, {key: value, "ka_aE_t": 86.43, "ka_aE_n": 86.43}, time_column=False)
    line = one_error_line(*cli(["process", rec, "-o", tmp_path / "m.nc"], capsys))
    assert key in line and value in line and unit in line
    assert not (tmp_path / "m.nc").exists()


@pytest.mark.slow
@pytest.mark.parametrize("value", ["10000", "10000 Hz", "10000 S/s"])
def test_a_csv_header_rate_in_hz_is_read(tmp_path, capsys, volts, value):
    rec = _csv(tmp_path, volts, {"sample_rate_hz": value, "ka_aE_t": 86.43, "ka_aE_n": 86.43}, time_column=False)
    code, err = cli(["process", rec, "-o", tmp_path / "m.nc"], capsys)
    assert code == 0, err


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("value", ["1e300", "1e30"])
def test_a_sample_past_any_adc_is_refused(tmp_path, capsys, volts, value):
    """One CSV cell of 1e300 V was processed with exit 0: omega2 inf at 5768 samples, omega2_mean up
    to 4e298 rad/s, "|omega2| vs sqrt(aE_n/DE): inf % rms" and numpy RuntimeWarnings on stderr."""
    rec = _csv(tmp_path, volts, {"sample_rate_hz": 10000, "ka_aE_t": 86.43, "ka_aE_n": 86.43})
    text = rec.read_text().splitlines()
    row = text[4 + 5000].split(",")      # 3 header lines, the column names, then sample 5000
    text[4 + 5000] = ",".join([row[0], value, *row[2:]])
    rec.write_text("\n".join(text) + "\n")
    line = one_error_line(*cli(["process", rec, "-o", tmp_path / "m.nc"], capsys))
    assert "sample 5000 of channel 'aE_t'" in line and f"{float(value):g}" in line and "1e+12" in line
    assert not (tmp_path / "m.nc").exists()


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_a_recorded_sample_past_any_adc_is_refused(tmp_path, capsys, volts):
    """A v1 recording (no adc_range_v) with one sample of 3e38 V was processed with exit 0: aE_t inf at
    83 samples, epsilon2_mean up to 8e39 rad/s^2, "10 revolutions averaged, 0 clipped samples"."""
    from stand_data import write_v1
    bad = np.array(volts, dtype=np.float32)
    bad[5000, 0] = 3e38
    rec = tmp_path / "rec.h5"
    write_v1(rec, bad)
    line = one_error_line(*cli(["process", rec, "-o", tmp_path / "m.nc"], capsys))
    assert "sample 5000 of channel 'aE_t'" in line and "1e+12" in line
    assert not (tmp_path / "m.nc").exists()


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_fit_says_when_the_measured_file_states_no_law_or_load(tmp_path, capsys, measured_nc):
    """fit on a measured file without law and Fu_N identified the backlash under the paper's sine law
    and Fu = 0 with exit 0 and no note (report notes them)."""
    from labtool.cli import main

    def edit(ds):
        ds.attrs.pop("law")
        ds.attrs.pop("Fu_N", None)
    path = _measured(tmp_path, measured_nc, edit)
    capsys.readouterr()
    code = main(["fit", str(path), "--model", "rigid", "--free", "backlash", "--accuracy", "fast", "--no-scan",
                 "--max-runs", "4", "-o", str(tmp_path / "f.json")])
    out = capsys.readouterr()
    assert code == 0, out.err
    note = [line for line in out.out.splitlines() if "does not state" in line]
    assert note and "load Fu" in note[0] and "motion law = sine" in note[0] and "--law" in note[0], out.out


@pytest.mark.slow
@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("var", ["omega2", "epsilon2"])
def test_a_measured_signal_past_any_motion_is_refused(tmp_path, capsys, measured_nc, var):
    """omega2 = 1e300 rad/s (a damaged or foreign file) was an internal error in report and fit
    (OverflowError: (34, 'Numerical result out of range') in the impact check)."""
    def edit(ds):
        y = ds[var].values.astype(float)
        y[np.isfinite(y)] = 1e300
        ds[var] = ("time", y, ds[var].attrs)
    path = _measured(tmp_path, measured_nc, edit)
    line = one_error_line(*cli(["report", path, *REPORT_FAST, "-o", tmp_path / "r.html"], capsys))
    assert var in line and "1e+300" in line and "1e+12" in line


@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("delta", ["0", "abc", "0.0001 s"])
def test_an_lvm_delta_x_that_is_no_interval_is_refused(tmp_path, capsys, volts, delta):
    """An LVM channel header's Delta_X of 0 was an internal error (ZeroDivisionError: float division by
    zero), "abc" another (ValueError: could not convert string to float: 'abc')."""
    from test_readers_formats import _lvm
    path = tmp_path / "rec.lvm"
    _lvm(path, volts, "\t", ".")
    text = path.read_text()
    assert "Delta_X\t0.0001\t0.0001\t0.0001" in text
    path.write_text(text.replace("Delta_X\t0.0001\t0.0001\t0.0001", f"Delta_X\t{delta}\t{delta}\t{delta}"))
    line = one_error_line(*cli(["process", path, "-o", tmp_path / "m.nc"], capsys))
    assert "Delta_X" in line and delta in line and "seconds > 0" in line
    assert not (tmp_path / "m.nc").exists()
