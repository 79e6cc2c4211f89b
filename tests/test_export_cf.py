"""process output follows CF-1.10 (checked with cf_xarray); labtool export writes it as CSV."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import xarray as xr

from labtool.cli import main
from stand_data import stand_recording

cf_xarray = pytest.importorskip("cf_xarray")


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    d = tmp_path_factory.mktemp("cf")
    rec = d / "rec.h5"
    stand_recording(rec, duration_s=2.0, rpm=300.0, start_time_utc="2026-11-22T04:00:00Z")
    assert main(["process", str(rec), "-o", str(d / "measured.nc")]) == 0
    return d / "measured.nc"


@pytest.mark.slow
def test_cf_conventions_found_by_cf_xarray(measured):
    ds = xr.open_dataset(measured, engine="h5netcdf")
    assert ds.attrs["Conventions"] == "CF-1.10"
    assert ds.cf.axes["T"] == ["time"] and ds.cf.standard_names["time"] == ["time"]
    assert ds.cf["time"].name == "time"
    # absolute time: the recording's start, decoded by xarray from 'seconds since ...'
    assert ds["time"].values[0] == np.datetime64("2026-11-22T04:00:00")
    assert ds["time"].encoding["units"].startswith("seconds since 2026-11-22T04:00:00")
    assert float((ds["time"][1] - ds["time"][0]) / np.timedelta64(1, "ns")) == pytest.approx(1e5)
    for dim in ds.dims:  # a coordinate on every dimension
        assert dim in ds.coords, dim
    for name, v in ds.variables.items():
        if v.dtype.kind in "fiu":
            assert v.attrs.get("units") or v.encoding.get("units"), name
            assert "^" not in v.attrs.get("units", ""), (name, "UDUNITS spelling")
    # numbers are numbers in the attributes (Ka, counts), never formatted text
    for k in ("ka_aE_t_m_s2_per_v", "cam_speed_rpm", "lowpass_hz", "n_revolutions_averaged"):
        assert isinstance(ds.attrs[k], (int, float, np.integer, np.floating)), k


def test_cf_apply_on_a_dataset():
    """labtool.common.cf.apply, offered to the other NetCDF writers (simulate, kinematics)."""
    from labtool.common import cf
    ds = xr.Dataset({"omega2": ("time", np.zeros(3), {"units": "rad/s", "long_name": "omega2"}),
                     "x": ("event", np.arange(2.0), {"units": "m"})},
                    coords={"time": ("time", np.arange(3) * 0.5, {"units": "s"})})
    cf.apply(ds, title="t", source="labtool simulate", start="2026-11-22T04:00:00Z")
    assert ds.attrs["Conventions"] == "CF-1.10" and ds["omega2"].attrs["units"] == "rad s-1"
    assert "event" in ds.coords and ds.cf.axes["T"] == ["time"]


@pytest.mark.parametrize("argv", [
    ["simulate", "--model", "elastic", "--accuracy", "fast", "--rpm", "300"],
    ["simulate", "--model", "rigid", "--accuracy", "fast", "--backlash-mm", "0.128", "--restitution", "0.5"],
    ["kinematics", "--points", "720"],
])
@pytest.mark.slow
def test_simulate_and_kinematics_outputs_are_cf(argv, tmp_path, capsys):
    out = tmp_path / "o.nc"
    assert main([*argv, "-o", str(out)]) == 0
    ds = xr.open_dataset(out, engine="h5netcdf", decode_times=False)
    assert ds.attrs["Conventions"] == "CF-1.10" and ds.attrs["title"].startswith("labtool")
    assert f"labtool {argv[0]} " in ds.attrs["history"]        # the command line, after the date and version
    for dim in ds.dims:
        assert dim in ds.coords, dim
    for name, v in ds.variables.items():
        if v.dtype.kind in "fiu":
            assert v.attrs.get("units"), name
            assert "^" not in v.attrs["units"] and "/" not in v.attrs["units"], (name, v.attrs["units"])
    if "time" in ds.dims:
        assert ds.cf.axes["T"] == ["time"]
    # cf_xarray finds the quantities by their CF attributes
    assert "rad s-1" in {v.attrs.get("units") for v in ds.variables.values()}


@pytest.mark.parametrize("text, expected", [
    ("kg m^2/rad", "kg m2 rad-1"), ("m/s^2", "m s-2"), ("N m/rad", "N m rad-1"), ("1/s", "s-1"),
    ("rad/s^3", "rad s-3"), ("m^2", "m2"), ("(m/s^2)^2/Hz", "m2 s-4 Hz-1"), ("kg*m^2", "kg m2"), ("N", "N"),
])
def test_udunits_spelling(text, expected):
    from labtool.common.cf import udunits
    assert udunits(text) == expected


@pytest.mark.slow
def test_export_csv_cycles_and_series(measured, tmp_path, capsys):
    prefix = tmp_path / "m"
    assert main(["export", str(measured), "--csv", "-o", str(prefix)]) == 0
    ds = xr.open_dataset(measured, engine="h5netcdf", decode_times=False)
    cyc = pd.read_csv(f"{prefix}_cycles.csv")
    np.testing.assert_allclose(cyc["omega2_mean [rad s-1]"], ds["omega2_mean"].values, rtol=1e-8)
    np.testing.assert_allclose(cyc["phi1 [deg]"], np.degrees(ds["phi1_grid"].values))
    ser = pd.read_csv(f"{prefix}_series.csv")
    assert len(ser) == ds.sizes["time"] and ser["time [s]"].iloc[0] == 0.0
    np.testing.assert_allclose(ser["omega2 [rad s-1]"], ds["omega2"].values, rtol=1e-6, equal_nan=True)
    assert main(["export", str(measured), "--csv", "-o", str(prefix)]) == 2  # no silent overwrite
    assert "--force" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.hostile("traceback")
def test_export_of_a_damaged_measured_file_is_one_line(measured, tmp_path, capsys):
    """A NetCDF whose omega2 holds strings, a cut file, a foreign file: one line, exit 2, nothing written."""
    ds = xr.open_dataset(measured, engine="h5netcdf", decode_times=False).load()
    ds["omega2"] = ("time", np.array(["x"] * ds.sizes["time"], dtype=object))
    strings = tmp_path / "strings.nc"
    ds.to_netcdf(strings, engine="h5netcdf")
    cut = tmp_path / "cut.nc"
    cut.write_bytes(measured.read_bytes()[:2048])
    other = tmp_path / "other.nc"
    xr.Dataset({"a": ("x", [1.0])}).to_netcdf(other, engine="h5netcdf")
    for bad, why in ((strings, "'omega2' holds"), (cut, "truncated"), (other, "missing")):
        assert main(["export", str(bad), "--csv", "-o", str(tmp_path / bad.stem)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("labtool: error:") and why in err[0], err
        assert not list(tmp_path.glob(f"{bad.stem}_*.csv")) and not list(tmp_path.glob(".*.part"))
