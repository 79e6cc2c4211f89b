"""``labtool simulate``: the JSON contract, NetCDF output, dispatch, one-line errors with exit 2."""
import json

import pytest
import xarray as xr
from hypothesis import given, settings
from hypothesis import strategies as st

from labtool.cli import main
from labtool.models.dynamics.simulate import INDICATORS
from labtool.common.units import RPM


def _json(capsys, args):
    assert main(["simulate", *args, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_json_keys_and_rigid_values(capsys):
    out = _json(capsys, ["--model", "rigid", "--rpm", "180", "--fu", "0", "--backlash-mm", "0.128",
                         "--omega1", "var", "--restitution", "1", "--accuracy", "fast"])   # the paper's experiment
    assert list(out) == [*INDICATORS, "model", "accuracy", "wall_s"]
    assert out["model"] == "rigid" and out["accuracy"] == "fast"
    assert out["xel_max_mm"] is None and out["xel_min_mm"] is None
    assert out["MR13D_max_Nm"] == pytest.approx(5.0, rel=0.1)        # Table 2, run 5
    assert isinstance(out["jumps"], int) and out["jumps"] > 0 and out["impacts"] > 0
    assert out["percussion_max_Ns"] > 0 and out["dphi2_max_deg"] > 0


def test_auto_picks_kinematic_without_sign_change(capsys):
    # run 9: MR13D > 0 over the rise; with the cam as input nothing dynamic is needed
    out = _json(capsys, ["--fu", "65", "--omega1", "const", "--accuracy", "fast"])
    assert out["model"] == "kinematic"
    from labtool.models.mechanism.kinematics import analyze, rise_summary

    assert out["MR13D_max_Nm"] == pytest.approx(rise_summary(analyze(rpm=180, Fu=65))["MR13D_max_Nm"], rel=1e-6)
    assert out["jumps"] == 0


def test_auto_runs_the_1dof_rigid_model_when_omega1_varies(capsys):
    # run 9 with the motor characteristic: the speed variation needs the 1-DOF model, no jumps
    out = _json(capsys, ["--fu", "65", "--omega1", "var", "--accuracy", "fast"])
    assert out["model"] == "rigid"
    assert out["MR13D_max_Nm"] == pytest.approx(17.0, rel=0.1)
    assert out["jumps"] == 0 and out["impacts"] == 0


@pytest.mark.slow
def test_netcdf_output_has_units_and_refuses_overwrite(tmp_path, capsys):
    path = tmp_path / "sim.nc"
    args = ["simulate", "--model", "rigid", "--accuracy", "fast", "--omega1", "const", "-o", str(path)]
    assert main(args) == 0
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        for name in ("time", "phi1", "omega1", "phi2", "omega2", "epsilon2", "MR13D", "gap", "contact",
                     "event_time", "event_percussion", "dphi2", "domega2", "domega1"):
            assert "units" in ds[name].attrs and "long_name" in ds[name].attrs, name
        assert ds.attrs["model"] == "rigid" and ds.attrs["omega1_mode"] == "const"
        assert ds.sizes["event"] > 0
    capsys.readouterr()
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "already exists" in err[0]


@pytest.mark.parametrize("args,msg", [
    (["--backlash-mm", "-0.01"], "backlash"),
    (["--restitution", "1.5"], "restitution"),
    (["--restitution", "-0.2"], "restitution"),
    (["--jt-factor", "0"], "Jt"),
    (["--rpm", "0"], "cam speed"),
    (["--omega1", "sometimes"], "omega1"),
    (["--model", "quantum"], "unknown model"),
    (["--accuracy", "perfect"], "accuracy"),
    (["--rpm", "nan"], "--rpm"),
])
def test_bad_input_is_one_line_exit_2(capsys, args, msg):
    assert main(["simulate", "--model", "rigid", *args] if "--model" not in args else ["simulate", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("labtool: error:") and msg in err[0]


@settings(max_examples=25, deadline=None)
@given(k=st.one_of(st.floats(max_value=-1e-9, allow_nan=False, allow_infinity=False),
                   st.floats(min_value=1.0 + 1e-9, allow_nan=False, allow_infinity=False)))
@pytest.mark.slow
def test_any_restitution_outside_unit_interval_is_rejected(k):
    import io
    from contextlib import redirect_stderr
    buf = io.StringIO()
    with redirect_stderr(buf):
        code = main(["simulate", "--model", "rigid", "--restitution", repr(k)])
    assert code == 2
    lines = buf.getvalue().strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("labtool: error:")


import pytest as _pytest


@_pytest.mark.parametrize("args,needle", [
    (["--contact-length-mm", "0"], "contact length lw must be in (0, 100] mm, got 0 mm (--contact-length-mm)"),
    (["--kc-factor", "-1"], "contact stiffness factor must be in (0, 1e+06], got -1 (--kc-factor)"),
    (["--contact-damping", "-2"], "contact damping must be in [0, 10000] s/m, got -2 s/m (--contact-damping)"),
    (["--backlash-mm", "-0.01"], "backlash j must be in [0, 10] mm, got -0.01 mm (--backlash-mm)"),
])
def test_elastic_contact_options_reject_impossible_values(args, needle, capsys):
    from labtool.cli import main

    assert main(["simulate", "--model", "elastic", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0]


@pytest.mark.slow
def test_netcdf_carries_the_whole_scene_the_mechanism_and_the_version(tmp_path):
    """Every Scene field, the mechanism's source and hash, labtool's version: enough to simulate
    the file again from its attributes alone (labtool.models.dynamics.provenance)."""
    import dataclasses
    import hashlib

    from labtool.common.operating_point import FIELDS
    from labtool.models.dynamics.provenance import scene_from_attributes
    from labtool.models.dynamics.scene import Scene
    from labtool.models.mechanism import Mechanism

    mech_file = tmp_path / "mech.toml"
    from importlib import resources
    text = resources.files("labtool.models.data").joinpath("stb216.toml").read_text().replace("R_mm = 8.0", "R_mm = 7.5")
    mech_file.write_text(text)
    path = tmp_path / "sim.nc"
    args = ["simulate", "--model", "elastic", "--accuracy", "fast", "--rpm", "200", "--fu", "10", "--backlash-mm", "0.05",
            "--jt-factor", "2", "--omega1", "const", "--restitution", "0.7", "--revolutions", "1",
            "--contact-length-mm", "7", "--kc-factor", "1.5", "--contact-damping", "2", "--elastic-gap", "closed",
            "--full-cycle", "--mechanism", str(mech_file), "-o", str(path)]
    assert main(args) == 0
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        a = ds.attrs
        assert {f.attr for f in FIELDS} <= set(a)
        assert (a["cam_speed_rpm"], a["Fu_N"], a["backlash_mm"], a["jt_factor"]) == (200.0, 10.0, 0.05, 2.0)
        assert (a["restitution"], a["contact_length_mm"], a["kc_factor"], a["contact_damping_s_per_m"]) == (0.7, 7.0, 1.5, 2.0)
        assert all(a[f.attr + "_source"] == f"option {f.option}" for f in FIELDS if f.name != "law")
        # the file's attributes alone give the scene back (with its mechanism from the file it names)
        again = scene_from_attributes(a, Mechanism.from_toml(mech_file))
        given = Scene(law="sine", cam_speed=200 * RPM, Fu=10.0, backlash=0.05e-3, jt_factor=2.0, omega1_mode="const",
                      restitution=0.7, revolutions=1.0, contact_length=7e-3, kc_factor=1.5, contact_damping=2.0,
                      elastic_gap="closed", accuracy="fast", rise_only=False)
        for f in dataclasses.fields(Scene):
            if f.name != "mechanism":
                v = getattr(given, f.name)
                assert getattr(again, f.name) == (v if isinstance(v, str) else pytest.approx(v, rel=1e-12)), f.name
        assert (a["elastic_gap"], a["omega1_mode"], a["accuracy"], a["revolutions"], a["rise_only"]) == \
            ("closed", "const", "fast", 1.0, 0)
        assert a["mechanism_source"] == str(mech_file)
        assert a["mechanism_sha256"] == hashlib.sha256(text.encode()).hexdigest()
        assert a["labtool_version"] and a["labtool_kernels_sha256"]
        assert a["history"].endswith(" ".join(["labtool", *map(str, args)]))     # the command line as typed
        assert a["validity_warnings"] == "[]"


@pytest.mark.slow
def test_kinematics_netcdf_names_the_mechanism_and_the_version(tmp_path):
    path = tmp_path / "kin.nc"
    assert main(["kinematics", "--rpm", "200", "-o", str(path)]) == 0
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert ds.attrs["mechanism_source"].startswith("built-in STB-216")
        assert len(ds.attrs["mechanism_sha256"]) == 64 and ds.attrs["labtool_version"]
        assert ds.attrs["history"].endswith(f"labtool kinematics --rpm 200 -o {path}")   # the command line as typed
