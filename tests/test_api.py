"""labtool's Python API: the functions a notebook calls, checked against the library underneath and
against independent facts (the cam-angle grid against a plain interpolation of the time series)."""
from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

import labtool
from labtool.common.operating_point import PAPER_EXPERIMENT
from labtool.units import MM, RPM


def test_the_api_is_listed_and_importing_labtool_loads_nothing_heavy():
    assert {"simulate", "process", "report", "fit", "OperatingPoint", "PAPER_EXPERIMENT"} <= set(dir(labtool))
    code = ("import sys, labtool, labtool.common.units; "
            "print(sorted(m for m in ('numpy', 'xarray', 'numba', 'scipy') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
    with pytest.raises(AttributeError):
        labtool.no_such_function


def test_simulate_equals_the_models_own_run_and_its_cycles_are_on_the_measured_grid():
    from labtool.models.dynamics.scene import Scene
    from labtool.models.dynamics.simulate import simulate as run

    sim = labtool.simulate(PAPER_EXPERIMENT, model="rigid", cam_speed=300 * RPM, backlash=0.128 * MM, revolutions=2,
                           rise_only=False, accuracy="fast")
    ref = run(Scene.at(PAPER_EXPERIMENT, cam_speed=300 * RPM, backlash=0.128 * MM, revolutions=2.0, rise_only=False,
                       accuracy="fast"), "rigid")
    assert sim.model == "rigid" and sim.indicators == ref.indicators
    np.testing.assert_array_equal(sim.dataset["omega2"].values, ref.dataset["omega2"].values)
    assert sim.dataset["omega2"].attrs["units"] == "rad s-1"          # CF, as a measurement says it
    cyc = sim.cycles
    assert cyc.sizes == {"revolution": 2, "phi1": 720} and cyc["omega2"].attrs["units"] == "rad s-1"
    np.testing.assert_allclose(np.diff(cyc["phi1"].values), 2 * math.pi / 720)
    # revolution 1 on the grid against numpy's interpolation of the time series on the unwrapped angle
    phi, om = sim.dataset["phi1"].values, sim.dataset["omega2"].values
    expect = np.interp(cyc["phi1"].values + 2 * math.pi, phi, om)
    np.testing.assert_allclose(cyc["omega2"].sel(revolution=1).values, expect, rtol=1e-10, atol=1e-10)


def test_a_rise_only_run_leaves_the_rest_of_the_revolution_empty():
    sim = labtool.simulate(model="rigid", accuracy="fast")
    row = sim.cycles["omega2"].sel(revolution=0).values
    phi = sim.cycles["phi1"].values
    rise = float(sim.dataset["phi1"].max())
    assert np.isfinite(row[phi <= rise]).all() and np.isnan(row[phi > rise + 1e-9]).all()


def test_simulate_refuses_what_the_owner_refuses():
    from labtool.common.errors import InputError
    with pytest.raises(InputError, match=r"backlash j must be in \[0, 10\] mm"):
        labtool.simulate(backlash=0.05)          # 50 mm: metres were meant as millimetres
    with pytest.raises(TypeError):
        labtool.simulate(rpm=300)                # SI names only: cam_speed in rad/s


@pytest.mark.slow
def test_process_and_report_equal_the_commands(tmp_path):
    from labtool.cli import main

    rec = tmp_path / "r.h5"
    assert main(["acquire", "--device", "sim", "--fast", "--duration", "2", "--status-every", "0", "-o", str(rec)]) == 0
    assert main(["process", str(rec), "-o", str(tmp_path / "cli.nc")]) == 0
    measured = labtool.process(rec, tmp_path / "api.nc")
    in_memory = labtool.process(rec)
    import xarray as xr
    with xr.open_dataset(tmp_path / "cli.nc", engine="h5netcdf") as cli:
        np.testing.assert_array_equal(measured["omega2"].values, cli["omega2"].values)
        np.testing.assert_array_equal(in_memory["omega2"].values, cli["omega2"].values)
    attrs = labtool.process(rec, tmp_path / "attrs.nc", dataset=False)      # the attributes alone
    with xr.open_dataset(tmp_path / "attrs.nc", engine="h5netcdf") as written:
        assert attrs == written.attrs and attrs["n_revolutions_averaged"] == measured.attrs["n_revolutions_averaged"]
    rep = labtool.report(tmp_path / "api.nc", tmp_path / "r.html", models=("kinematic",), omega1=("const",),
                         json=tmp_path / "r.json")
    assert (tmp_path / "r.html").exists() and (tmp_path / "r.json").exists()
    assert rep.scene["cam_speed_rpm_source"].startswith("measured")


@pytest.mark.slow
def test_the_process_command_reads_its_summary_without_opening_the_output_as_a_dataset(tmp_path):
    """Its summary line comes from the written file's attributes: xarray would build the index of
    the whole time axis for them (~300 MB for a 1-hour recording) and load pandas and dask."""
    from labtool.cli import main

    rec = tmp_path / "r.h5"
    assert main(["acquire", "--device", "sim", "--fast", "--duration", "2", "--status-every", "0", "-o", str(rec)]) == 0
    code = ("import sys\nfrom labtool.cli import main\n"
            f"assert main(['process', {str(rec)!r}, '-o', {str(tmp_path / 'm.nc')!r}]) == 0\n"
            "print(sorted(m for m in ('xarray', 'pandas', 'dask') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "[]"
    assert out.stdout.startswith(f"wrote {tmp_path / 'm.nc'}: cam ")


def _recording(path):
    import h5py

    with h5py.File(path, "r") as f:
        attrs = {k: v for k, v in f.attrs.items() if k not in ("start_time_utc", "stop_time_utc", "command")}
        return f["signals"][()], attrs


@pytest.mark.slow
def test_acquire_writes_the_file_the_command_writes(tmp_path):
    from labtool.cli import main

    assert main(["acquire", "--fast", "--duration", "0.5", "--rpm", "240", "--backlash-mm", "0.2", "--seed", "3",
                 "--status-every", "0", "-o", str(tmp_path / "cli.h5")]) == 0
    res = labtool.acquire(tmp_path / "api.h5", stand={"duration_s": 0.5, "cam_speed_rpm": 240, "backlash_mm": 0.2,
                                                      "seed": 3}, realtime=False)
    assert res.complete and res.stop_reason == "done" and res.n_samples == 5000 and res.rate_hz == 10000.0
    assert res.n_channels == 3 and res.overruns == 0 and res.unstated == []
    cli, api = _recording(tmp_path / "cli.h5"), _recording(tmp_path / "api.h5")
    np.testing.assert_array_equal(cli[0], api[0])
    assert {k: str(v) for k, v in cli[1].items()} == {k: str(v) for k, v in api[1].items()}
    assert api[1]["cam_speed_rpm"] == 240.0 and api[1]["backlash_mm"] == 0.2


def test_acquire_refuses_an_unknown_setting_and_a_short_duration_before_writing(tmp_path):
    from labtool.common.errors import InputError

    with pytest.raises(InputError, match="unknown stand setting.*rpm"):
        labtool.acquire(tmp_path / "r.h5", stand={"rpm": 240})
    with pytest.raises(InputError, match="less than one sample"):
        labtool.acquire(tmp_path / "r.h5", stand={"duration_s": 1e-9}, realtime=False)
    assert not (tmp_path / "r.h5").exists()


@pytest.mark.slow
def test_acquire_keeps_what_a_disconnect_left_and_says_so(tmp_path):
    from labtool.common.errors import InputError

    res = labtool.acquire(tmp_path / "r.h5", stand={"duration_s": 1.0}, realtime=False, faults=["disconnect@0.3"],
                          check=False)
    assert res.stop_reason == "disconnected" and 0 < res.n_samples < 10000
    with pytest.raises(InputError, match="kept in"):
        res.check()


FACTORS_2x2 = """
[[factor]]
name = "A"
symbol = "Fu"
unit = "N"
levels = [0, 65]

[[factor]]
name = "B"
symbol = "n1"
unit = "rpm"
levels = [180, 300]
"""


@pytest.mark.slow
def test_run_design_writes_the_table_the_command_writes(tmp_path):
    import pandas as pd

    from labtool.cli import main

    (tmp_path / "f.toml").write_text(FACTORS_2x2)
    assert main(["doe", "run", "--model", "kinematic", "--factors", str(tmp_path / "f.toml"), "--workers", "1",
                 "-o", str(tmp_path / "cli.csv")]) == 0
    res = labtool.run_design(tmp_path / "api.csv", model="kinematic", factors=tmp_path / "f.toml", workers=1)
    assert res.n_runs == 4 and res.n_failed == 0 and res.netcdf == tmp_path / "api.nc"
    assert [f.levels for f in res.factors] == [(0.0, 65.0), (180.0, 300.0)]
    cli, api = pd.read_csv(tmp_path / "cli.csv"), pd.read_csv(tmp_path / "api.csv")
    pd.testing.assert_frame_equal(cli, api)
    # the kinematic MR13D grows with the load: an independent fact the rows must show
    by = api.set_index(["A_Fu_level", "B_n1_level"])["MR13D_max_Nm"]
    assert by[(2, 1)] > by[(1, 1)] and by[(2, 2)] > by[(1, 2)]


def test_run_design_refuses_bad_workers_before_running(tmp_path):
    from labtool.common.errors import InputError

    with pytest.raises(InputError, match="workers must be >= 1"):
        labtool.run_design(tmp_path / "r.csv", model="kinematic", workers=0)
    with pytest.raises(InputError, match="another file than the CSV"):
        labtool.run_design(tmp_path / "r.csv", model="kinematic", netcdf=tmp_path / "r.csv")
    assert not any(tmp_path.iterdir())


@pytest.mark.slow
def test_kinematics_writes_the_file_the_command_writes_and_scales_with_speed(tmp_path):
    import xarray as xr

    from labtool.cli import main

    assert main(["kinematics", "--rpm", "180", "--points", "361", "-o", str(tmp_path / "cli.nc")]) == 0
    k = labtool.kinematics(cam_speed=180 * RPM, points=361, output=tmp_path / "api.nc")
    with xr.open_dataset(tmp_path / "cli.nc", engine="h5netcdf") as cli, \
            xr.open_dataset(tmp_path / "api.nc", engine="h5netcdf") as api:
        xr.testing.assert_identical(cli.drop_attrs(), api.drop_attrs())
        assert {k: v for k, v in cli.attrs.items() if k != "history"} == \
               {k: v for k, v in api.attrs.items() if k != "history"}
    assert k.cam_speed_rpm == 180.0 and k.groove_points is None
    # cam as input: omega2 = psi'(phi1) omega1 and epsilon2 = psi''(phi1) omega1^2 at constant speed
    twice = labtool.kinematics(cam_speed=360 * RPM, points=361)
    assert twice.summary["omega2_max_rad_s"] == pytest.approx(2 * k.summary["omega2_max_rad_s"], rel=1e-12)
    assert twice.summary["epsilon2_max_rad_s2"] == pytest.approx(4 * k.summary["epsilon2_max_rad_s2"], rel=1e-12)


@pytest.mark.slow
def test_simulate_writes_the_file_the_command_writes(tmp_path):
    import xarray as xr

    from labtool.cli import main

    assert main(["simulate", "--model", "rigid", "--rpm", "300", "--accuracy", "fast", "-o", str(tmp_path / "cli.nc")]) == 0
    sim = labtool.simulate(model="rigid", cam_speed=300 * RPM, accuracy="fast", output=tmp_path / "api.nc")
    with xr.open_dataset(tmp_path / "cli.nc", engine="h5netcdf") as cli, \
            xr.open_dataset(tmp_path / "api.nc", engine="h5netcdf") as api:
        xr.testing.assert_equal(cli.drop_attrs(), api.drop_attrs())
        assert cli.attrs["cam_speed_rpm"] == api.attrs["cam_speed_rpm"] == 300.0
        assert cli.attrs["cam_speed_rpm_source"] == "option --rpm" and api.attrs["cam_speed_rpm_source"] == "argument cam_speed"
    from labtool.common.operating_point import default_source
    assert sim.sourced.sources["Fu"] == default_source("Fu") and sim.scene.cam_speed == 300 * RPM


def test_fit_and_suggest_check_their_output_files_before_any_work(tmp_path):
    from labtool.common.errors import InputError

    (tmp_path / "fit.png").write_text("taken")
    with pytest.raises(InputError, match="fit.png"):      # the figure beside the JSON exists
        labtool.fit(tmp_path / "missing.nc", model="rigid", free="backlash", output=tmp_path / "fit.json")
    with pytest.raises(InputError, match="different files"):
        labtool.suggest(tmp_path / "missing.nc", output=tmp_path / "s.png", figure=tmp_path / "s.png")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fit.png"]
