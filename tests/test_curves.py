"""Curves out: beside every report and from labtool export, one CSV (a row per grid point, a column
per curve, a commented header) and CF NetCDF holding the same numbers, measured and every model."""
from __future__ import annotations

import csv
import json

import numpy as np
import pandas as pd
import pytest
import xarray as xr

from labtool.cli import main
from labtool.common.files import write_netcdf
from labtool.reports.synthetic import synthetic_measured


@pytest.fixture(scope="module")
def reported(tmp_path_factory):
    d = tmp_path_factory.mktemp("curves")
    ds = synthetic_measured(noise=0.03, gain=1.05, revolutions=4.4)
    ds.attrs.update(test_id="T-43", operator="A. Tester")
    write_netcdf(ds, d / "m.nc")
    assert main(["report", str(d / "m.nc"), "--models", "kinematic", "-o", str(d / "r.html"),
                 "--json", str(d / "r.json")]) == 0
    return d


def _excel_like(path):
    """What a spreadsheet's import with 'skip lines starting with #', ',' separated and '.' decimals gives."""
    return pd.read_csv(path, comment="#", sep=",", decimal=".", header=0, skip_blank_lines=True)


@pytest.mark.slow
def test_the_report_writes_its_curves_beside_it_as_csv_and_netcdf(reported):
    table = _excel_like(reported / "r_curves.csv")
    nc = xr.open_dataset(reported / "r_curves.nc", engine="h5netcdf")
    summary = json.loads((reported / "r.json").read_text())
    # one row per grid point of the report's grid
    assert len(table) == nc.sizes["phi1"] == summary["conditioning"]["grid_points_per_revolution"]
    assert np.allclose(table["phi1_deg"], np.degrees(nc["phi1"].values)) and np.allclose(table["phi1_rad"], nc["phi1"])
    # every compared run has its curves, side by side with the measurement
    runs = {(s["requested_model"], s["omega1"]) for s in summary["simulations"]}
    for model, mode in runs:
        for sig, unit in (("omega2", "rad_s"), ("epsilon2", "rad_s2")):
            col = f"{sig}_{model}_{mode}_{unit}"
            assert col in table, col
            assert np.allclose(table[col], nc[f"{sig}_{model}_{mode}"].values, rtol=1e-8, atol=0, equal_nan=True)
    # the measured mean, standard deviation and each revolution, as in the NetCDF
    revs = [c for c in table if c.startswith("epsilon2_measured_rev")]
    assert len(revs) == nc.sizes["revolution"] == summary["measured"]["whole_revolutions"] >= 3
    matrix = table[revs].to_numpy().T
    assert np.allclose(matrix, nc["epsilon2_measured"].values, rtol=1e-8)
    # an independent fact: the mean and standard deviation columns are those of the revolution columns
    assert np.allclose(table["epsilon2_measured_mean_rad_s2"], matrix.mean(axis=0), rtol=1e-7, atol=1e-6)
    assert np.allclose(table["epsilon2_measured_std_rad_s2"], matrix.std(axis=0), rtol=1e-6, atol=1e-6)
    assert nc["omega2_measured_mean"].attrs["units"] == "rad s-1" and nc["epsilon2_measured"].attrs["units"] == "rad s-2"


@pytest.mark.slow
def test_the_csv_header_says_who_what_and_where_and_a_reader_skips_it(reported):
    text = (reported / "r_curves.csv").read_text()
    head = [line for line in text.splitlines() if line.startswith("#")]
    said = dict(line[2:].split(": ", 1) for line in head if ": " in line)
    assert said["test_id"] == "T-43" and said["operator"] == "A. Tester"
    assert float(said["cam_speed_rpm_measured"]) == pytest.approx(180.0, rel=1e-3)
    assert said["op_load_fu"] == "0 N" and "source" in " ".join(said)
    assert said["verdict"].startswith("verdict")
    # the csv module, skipping the commented lines: a rectangular table, plain names with units
    with open(reported / "r_curves.csv", newline="") as fh:
        rows = list(csv.reader(line for line in fh if not line.startswith("#")))
    assert len({len(r) for r in rows}) == 1
    assert all(" " not in name and "[" not in name for name in rows[0])


@pytest.mark.slow
def test_export_of_the_measured_file_gives_the_reports_measured_curves(reported, tmp_path):
    assert main(["export", str(reported / "m.nc"), "--format", "csv,netcdf,mat", "-o", str(tmp_path / "e")]) == 0
    mine = xr.open_dataset(tmp_path / "e_curves.nc", engine="h5netcdf")
    theirs = xr.open_dataset(reported / "r_curves.nc", engine="h5netcdf")
    for name in ("omega2_measured", "epsilon2_measured_mean", "epsilon2_measured_std"):
        assert np.allclose(mine[name].values, theirs[name].values, rtol=1e-12), name
    assert not any(v.endswith("_kinematic_const") for v in mine.data_vars)     # measured only
    from scipy.io import loadmat
    mat = loadmat(tmp_path / "e_curves.mat")
    assert np.allclose(mat["epsilon2_measured"], mine["epsilon2_measured"].values)
    assert np.allclose(mat["phi1_rad"].ravel(), mine["phi1"].values)
    assert str(mat["metadata"]["test_id"][0, 0][0]) == "T-43"


@pytest.mark.slow
def test_the_curves_follow_cf(reported):
    cf_xarray = pytest.importorskip("cf_xarray")
    nc = xr.open_dataset(reported / "r_curves.nc", engine="h5netcdf")
    assert nc.attrs["Conventions"] == "CF-1.10" and cf_xarray is not None
    for dim in nc.dims:
        assert dim in nc.coords, dim
    for name, v in nc.data_vars.items():
        assert v.attrs.get("units") and v.attrs.get("long_name"), name


@pytest.mark.slow
def test_export_of_a_simulation_gives_its_cycle(tmp_path):
    assert main(["simulate", "--model", "rigid", "--accuracy", "fast", "-o", str(tmp_path / "s.nc")]) == 0
    assert main(["export", str(tmp_path / "s.nc"), "--format", "csv"]) == 0
    table = pd.read_csv(tmp_path / "s_curves.csv", comment="#")
    assert {"omega2_rigid_const_rad_s", "epsilon2_rigid_const_rad_s2"} <= set(table.columns)
    # the default run is the rise only: the cycle is there over the rise, empty beyond
    rise = table["phi1_deg"] < 50
    assert table.loc[rise, "omega2_rigid_const_rad_s"].notna().all()
    assert table.loc[table["phi1_deg"] > 100, "omega2_rigid_const_rad_s"].isna().all()


@pytest.mark.slow
def test_export_refuses_what_it_cannot_write(reported, tmp_path, capsys):
    assert main(["export", str(reported / "m.nc"), "--format", "xls"]) == 2
    assert "unknown export format 'xls'; choose from csv, netcdf, mat" in capsys.readouterr().err
    assert main(["export", str(reported / "m.nc")]) == 2
    assert "--format csv,netcdf,mat" in capsys.readouterr().err
    (tmp_path / "x_curves.csv").write_text("mine")
    assert main(["export", str(reported / "m.nc"), "--format", "csv,netcdf", "-o", str(tmp_path / "x")]) == 2
    assert "already exists" in capsys.readouterr().err
    assert (tmp_path / "x_curves.csv").read_text() == "mine" and not (tmp_path / "x_curves.nc").exists()


def test_csv_and_netcdf_of_made_up_curves_hold_the_same_numbers(tmp_path):
    from labtool.common.files import OutputSet
    from labtool.reports.curves import curve_paths, curves_dataset, write_curves
    grid = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    revs = np.vstack([np.sin(grid) + 0.01 * k for k in range(3)])
    ds = curves_dataset(grid, {"omega2": revs, "epsilon2": 2 * revs}, [4, 5, 7],
                        [{"name": "rigid_const", "label": "rigid, w1 = ct.", "model": "rigid", "omega1": "const",
                          "signals": {"omega2": np.cos(grid), "epsilon2": np.where(grid < 1, np.nan, grid)}}],
                        {"test_id": "T\nwith a line break", "cam_speed_rpm_measured": 180.0})
    paths = curve_paths(str(tmp_path / "c"), ("csv", "netcdf"))
    with OutputSet() as out:
        write_curves(ds, paths, out)
    table = pd.read_csv(paths["csv"], comment="#")
    nc = xr.open_dataset(paths["netcdf"], engine="h5netcdf")
    assert list(table.columns[:4]) == ["phi1_deg", "phi1_rad", "omega2_measured_mean_rad_s", "omega2_measured_std_rad_s"]
    assert [c for c in table if "_rev" in c and c.startswith("omega2")] == [
        "omega2_measured_rev4_rad_s", "omega2_measured_rev5_rad_s", "omega2_measured_rev7_rad_s"]
    assert np.allclose(table["omega2_measured_mean_rad_s"], np.sin(grid) + 0.01)
    assert np.allclose(table["epsilon2_rigid_const_rad_s2"], nc["epsilon2_rigid_const"], equal_nan=True)
    assert table["epsilon2_rigid_const_rad_s2"].isna().sum() == 3         # NaN is an empty cell
    assert list(nc["revolution"].values) == [4, 5, 7]
    assert "# test_id: T with a line break" in paths["csv"].read_text()   # one header line per key


@pytest.mark.slow
def test_export_of_a_campaign_writes_each_points_curves(tmp_path):
    from test_campaign_run import quick_plan
    plan = quick_plan(tmp_path, models='["kinematic"]')
    out = tmp_path / "camp"
    assert main(["campaign", "run", str(plan), "-o", str(out), "--no-report"]) == 0
    assert main(["export", str(out), "--format", "csv,netcdf", "-o", str(tmp_path / "x")]) == 0
    points = sorted(p.name for p in (out / "points").iterdir())
    assert len(points) == 2
    for name in points:
        table = pd.read_csv(tmp_path / f"x_{name}_curves.csv", comment="#")
        nc = xr.open_dataset(tmp_path / f"x_{name}_curves.nc", engine="h5netcdf")
        revs = [c for c in table if c.startswith("omega2_measured_rev")]
        assert len(revs) >= 2 and np.allclose(table[revs].to_numpy().T, nc["omega2_measured"].values, rtol=1e-8)
        assert np.allclose(table["epsilon2_kinematic_const_rad_s2"], nc["epsilon2_kinematic_const"], rtol=1e-8)
        assert nc.attrs["test_id"] == "T-1" and nc.attrs["point"] == name
