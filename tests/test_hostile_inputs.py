"""Hostile inputs: TOML files, option values and file names that could raise a
traceback, hang, be ignored or give a silent wrong answer. Each ends with one line and exit 2, or
works. The kind of each test is its ``hostile`` marker."""
from __future__ import annotations

import math
import os
import shutil

import numpy as np
import pytest
import xarray as xr
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hostile import MECHANISM, REFERENCE, REPORT_FAST, SAMPLE, cli, measured_nc, one_error_line  # noqa: F401

TEXT = MECHANISM.read_text()


def _mech(tmp_path, text, name="m.toml"):
    path = tmp_path / name
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    return path


# --- traceback -------------------------------------------------------------------------------
@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("old, new, fragment", [
    ("rr_min_mm = 24.0", "rr_min_mm = [1, 2]", "[cam] rr_min_mm = [1, 2]: expected a number [mm], got a list"),
    ("m2_kg = 0.3681", 'm2_kg = "heavy"', '[follower] m2_kg = "heavy": expected a number [kg], got a string'),
    ("R_mm = 8.0", "R_mm = true", "[roller] R_mm = true: expected a number [mm], got a boolean"),
    ("diameter_mm = 120.0", "diameter_mm = 1979-05-27", "[cam] diameter_mm = 1979-05-27: expected a number [mm], got a date"),
    ("[motor]", "motor = 3\n[motorx]", "unknown table [motorx]"),
])
def test_mechanism_file_with_wrong_types(tmp_path, capsys, old, new, fragment):
    path = _mech(tmp_path, TEXT.replace(old, new))
    assert fragment in one_error_line(*cli(["kinematics", "--mechanism", path], capsys))


@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("raw, fragment", [
    (b"\xff\xfe\x00n\x00a", "is UTF-16 text"),
    (b'name = "caf\xe9"\n', "is not UTF-8 text (byte 0xe9 on line 1)"),
    (b"[frame]\nxD_mm = -34\x00\n", "NUL bytes"),
    (b"[frame\n", "is not valid TOML"),
])
def test_mechanism_file_that_is_not_utf8_toml(tmp_path, capsys, raw, fragment):
    assert fragment in one_error_line(*cli(["kinematics", "--mechanism", _mech(tmp_path, raw)], capsys))


@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("option", ["--mechanism"])
def test_a_folder_given_as_a_toml_file(tmp_path, capsys, option):
    assert "is a folder" in one_error_line(*cli(["kinematics", option, tmp_path], capsys))
    out = tmp_path / "r.h5"
    assert "is a folder" in one_error_line(*cli(["acquire", "--fast", "--scene", tmp_path, "-o", out], capsys))
    assert not out.exists()


@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("stand, fragment", [
    ('cam_speed_rpm = "fast"', '[stand] cam_speed_rpm = "fast": expected a number [rpm], got a string'),
    ("cam_speed_rpm = [1, 2]", "[stand] cam_speed_rpm = [1, 2]: expected a number [rpm], got a list"),
    ("seed = -1", "[stand] seed = -1: must not be negative"),
    ("seed = 99999999999999999999", "seed = 99999999999999999999: must be <= 9223372036854775807"),
    ("fu = 3", "unknown key [stand] fu (did you mean Fu_N?)"),
])
def test_scene_file_with_wrong_types(tmp_path, capsys, stand, fragment):
    scene = tmp_path / "s.toml"
    scene.write_text(f"[stand]\n{stand}\n")
    out = tmp_path / "r.h5"
    assert fragment in one_error_line(*cli(["acquire", "--fast", "--scene", scene, "-o", out], capsys))
    assert not out.exists()


@pytest.mark.hostile("traceback")
def test_process_force_onto_an_existing_folder(tmp_path, capsys):
    folder = tmp_path / "out"
    folder.mkdir()
    (folder / "keep.txt").write_text("mine")
    msg = one_error_line(*cli(["process", SAMPLE / "run_180rpm.h5", "--force", "-o", folder], capsys))
    assert "is a folder" in msg
    assert [p.name for p in folder.iterdir()] == ["keep.txt"] and os.listdir(tmp_path) == ["out"]


@pytest.mark.hostile("traceback")
def test_demo_onto_an_existing_file(tmp_path, capsys):
    target = tmp_path / "results"
    target.write_text("not a folder")
    assert "is a file, not a folder" in one_error_line(*cli(["demo", "-o", target], capsys))
    assert target.read_text() == "not a folder" and os.listdir(tmp_path) == ["results"]


@pytest.mark.slow
@pytest.mark.hostile("traceback")
def test_non_utf8_file_names_in_report(tmp_path, capsys, measured_nc):
    src = tmp_path / os.fsdecode(b"mesur\xe9.nc")
    shutil.copy(measured_nc, src)
    out = tmp_path / os.fsdecode(b"rapport\xe9.html")
    code, err = cli(["report", src, "-o", out, "--json", tmp_path / "s.json", *REPORT_FAST], capsys)
    assert code == 0, err
    assert "mesur\\xe9.nc" in out.read_text(encoding="utf-8")     # the name, escaped, not a crash


@pytest.mark.hostile("traceback")
def test_non_utf8_file_names_in_calibrate(tmp_path, capsys):
    src = tmp_path / os.fsdecode(b"r\xe9f\xe9rence.h5")
    shutil.copy(SAMPLE / "calibration_79p6Hz.h5", src)
    out = tmp_path / os.fsdecode(b"cal\xe9.toml")
    code, err = cli(["calibrate", src, "-o", out], capsys)
    assert code == 0, err
    import tomllib
    assert tomllib.loads(out.read_text(encoding="utf-8"))["source"].endswith("r\\xe9f\\xe9rence.h5")


@pytest.mark.slow
@pytest.mark.hostile("traceback")
def test_non_utf8_file_names_in_doe_analyze_plot(tmp_path, capsys):
    src = tmp_path / os.fsdecode(b"r\xe9sultats.csv")
    shutil.copy(REFERENCE / "table2_rigid.csv", src)
    plot = tmp_path / os.fsdecode(b"effets\xe9.png")
    code, err = cli(["doe", "analyze", src, "--plot", plot], capsys)
    assert code == 0, err
    assert plot.stat().st_size > 10_000


_values = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**6, 10**7),
                    st.text(alphabet="0123456789.-einfa", max_size=8))


@pytest.mark.slow
@pytest.mark.hostile("traceback")
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rpm=_values, points=st.integers(-5, 60_000), jt=_values)
def test_random_kinematics_options_work_or_end_in_one_line(capsys, rpm, points, jt):
    code, err = cli(["kinematics", "--rpm", str(rpm), "--points", str(points), "--jt-factor", str(jt)], capsys)
    if code != 0:
        one_error_line(code, err)


@pytest.mark.slow
@pytest.mark.hostile("traceback")
@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rpm=_values, revolutions=_values, backlash=_values)
def test_random_simulate_options_work_or_end_in_one_line(capsys, rpm, revolutions, backlash):
    code, err = cli(["simulate", "--model", "kinematic", "--rpm", str(rpm), "--revolutions", str(revolutions),
                     "--backlash-mm", str(backlash), "--json"], capsys)
    if code != 0:
        one_error_line(code, err)


_toml_value = st.one_of(st.booleans(), st.integers(-2**63, 2**63 - 1), st.floats(), st.text(max_size=6),
                        st.lists(st.integers(), max_size=2), st.just("1979-05-27"))


def _toml(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, str):
        return v if v == "1979-05-27" else '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return repr(v)


@pytest.mark.slow
@pytest.mark.hostile("traceback")
@settings(max_examples=200, deadline=None)
@given(line=st.integers(0, TEXT.count("\n") - 1), value=_toml_value)
def test_any_value_in_any_line_of_the_mechanism_file(line, value):
    """Every parameter line of stb216.toml, given any TOML value: a Mechanism with finite SI
    values, or one InputError line naming the file."""
    from labtool.common.errors import InputError
    from labtool.models.mechanism import Mechanism

    lines = TEXT.splitlines()
    key, sep, _ = lines[line].partition("=")
    if not sep or lines[line].lstrip().startswith("#"):
        return
    lines[line] = f"{key}= {_toml(value).replace(chr(10), ' ')}"
    try:
        mech = Mechanism.from_toml_text("\n".join(lines), source="m.toml")
    except InputError as exc:
        assert "\n" not in str(exc)
        return
    assert all(math.isfinite(getattr(mech, f)) for f in ("xD", "yD", "l", "DE", "R", "m2", "J2", "Pn"))


@pytest.mark.slow
@pytest.mark.hostile("traceback")
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(raw=st.binary(max_size=200))
def test_random_bytes_as_mechanism_file(tmp_path_factory, raw):
    from labtool.cli import main

    path = tmp_path_factory.mktemp("bytes") / "m.toml"
    path.write_bytes(raw)
    assert main(["kinematics", "--mechanism", str(path)]) == 2


# --- silent wrong answers --------------------------------------------------------------------
@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("old, new, fragment", [
    ("xD_mm = -34.073", "xD_mm = 1e300", "[frame] xD_mm = 1e+300: must be <= 10000 [mm]"),
    ("R_mm = 8.0", "R_mm = 8.0\nRr_mm = 9.0", "unknown key [roller] Rr_mm (did you mean R_mm?)"),
    ("[program]", "[extra]\nfoo = 1\n[program]", "unknown table [extra]"),
    ('law = "sine"', 'law = "sine"\nrise = 60.0', "unknown key [program] rise (did you mean rise_deg?)"),
])
def test_mechanism_values_that_were_ignored_or_gave_inf(tmp_path, capsys, old, new, fragment):
    path = _mech(tmp_path, TEXT.replace(old, new))
    code, err = cli(["kinematics", "--mechanism", path], capsys)
    assert fragment in one_error_line(code, err)
    assert "inf" not in capsys.readouterr().out


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_one_cam_speed_range_in_every_command(tmp_path, capsys, measured_nc):
    """simulate --rpm 1e6 gave MR13D = 1.6e8 N m with exit 0 while report refused > 1000 rpm."""
    msgs = [one_error_line(*cli(args, capsys)) for args in (
        ["simulate", "--rpm", "1e6"],
        ["simulate", "--rpm", "1e6", "--model", "kinematic"],
        ["kinematics", "--rpm", "1e6"],
        ["acquire", "--fast", "--rpm", "1e6", "-o", tmp_path / "r.h5"],
        ["report", measured_nc, "--rpm", "1e6", "-o", tmp_path / "r.html", *REPORT_FAST],
    )]
    for msg in msgs:
        assert "1000 rpm" in msg, msg
    assert not list(tmp_path.iterdir())
    code, err = cli(["simulate", "--rpm", "1000", "--model", "kinematic", "--json"], capsys)
    assert code == 0, err


@pytest.mark.hostile("silent_wrong")
def test_one_file_named_by_two_options(tmp_path, capsys):
    x = tmp_path / "x.nc"
    msg = one_error_line(*cli(["kinematics", "-o", x, "--groove-csv", x], capsys))
    assert "-o and --groove-csv name the same file" in msg
    assert not x.exists()
    (tmp_path / "sub").mkdir()
    msg = one_error_line(*cli(["kinematics", "-o", x, "--groove-csv", tmp_path / "sub" / ".." / "x.nc"], capsys))
    assert "same file" in msg


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("stand, fragment", [
    ("seed = 1.5", "seed = 1.5: expected an integer"),
    ("duration_s = true", "duration_s = true: expected a number [s], got a boolean"),
    ("ripple = 1.5", "ripple = 1.5: must be < 1"),
])
def test_scene_values_that_were_rounded_or_taken_as_numbers(tmp_path, capsys, stand, fragment):
    scene = tmp_path / "s.toml"
    scene.write_text(f"[stand]\n{stand}\n")
    code, err = cli(["acquire", "--fast", "--scene", scene, "-o", tmp_path / "r.h5"], capsys)
    assert fragment in one_error_line(code, err)


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("umask", [0o022, 0o002])
def test_outputs_follow_the_users_umask(tmp_path, capsys, umask, measured_nc):
    """mkstemp made every output 0600: colleagues on a shared drive could not open them."""
    old = os.umask(umask)
    try:
        assert cli(["kinematics", "-o", tmp_path / "k.nc", "--groove-csv", tmp_path / "g.csv"], capsys)[0] == 0
        assert cli(["simulate", "--model", "kinematic", "-o", tmp_path / "s.nc"], capsys)[0] == 0
        assert cli(["report", measured_nc, "-o", tmp_path / "r.html", "--json", tmp_path / "r.json",
                    *REPORT_FAST], capsys)[0] in (0, 1)
        assert cli(["calibrate", SAMPLE / "calibration_79p6Hz.h5", "-o", tmp_path / "c.toml"], capsys)[0] == 0
    finally:
        os.umask(old)
    for p in tmp_path.iterdir():
        assert p.stat().st_mode & 0o777 == 0o666 & ~umask, p.name


# --- injection -------------------------------------------------------------------------------
@pytest.mark.hostile("injection")
def test_a_newline_in_a_file_name_keeps_the_error_on_one_line(tmp_path, capsys):
    msg = one_error_line(*cli(["kinematics", "--mechanism", tmp_path / "a\nlabtool: ok.toml"], capsys))
    assert "a\\nlabtool: ok.toml" in msg
    bad = tmp_path / "b\nc.toml"
    bad.write_text("[frame\n")
    assert "b\\nc.toml is not valid TOML" in one_error_line(*cli(["kinematics", "--mechanism", bad], capsys))


@pytest.mark.hostile("injection")
def test_a_newline_and_a_table_in_a_mechanism_name(tmp_path, capsys):
    path = _mech(tmp_path, TEXT.replace('name = "STB-216', 'name = "x\\n[frame]\\nxD_mm = 0\\n STB-216'))
    assert "name = " in one_error_line(*cli(["kinematics", "--mechanism", path], capsys))


@pytest.mark.slow
@pytest.mark.hostile("injection")
def test_mathtext_and_markup_in_file_names_are_text(tmp_path, capsys, measured_nc):
    src = tmp_path / "a$x^$[red].csv"
    shutil.copy(REFERENCE / "table2_rigid.csv", src)
    code, err = cli(["doe", "analyze", src, "--plot", tmp_path / "p$^$.png"], capsys)
    assert code == 0, err
    m = tmp_path / "[bold]m$^$.nc"
    shutil.copy(measured_nc, m)
    code, err = cli(["report", m, "-o", tmp_path / "[red]r.html", "--pdf", tmp_path / "r$^$.pdf", *REPORT_FAST], capsys)
    assert code in (0, 1), err
    assert (tmp_path / "[red]r.html").exists() and (tmp_path / "r$^$.pdf").exists()


# --- real files ------------------------------------------------------------------------------
@pytest.mark.hostile("real_file")
def test_a_mechanism_file_saved_by_notepad(tmp_path):
    """Notepad (Windows 10 before 1903, and 'UTF-8 with BOM' today) writes a BOM and CRLF."""
    from labtool.models.mechanism import Mechanism

    path = _mech(tmp_path, b"\xef\xbb\xbf" + TEXT.replace("\n", "\r\n").encode())
    mine, ref = Mechanism.from_toml(path), Mechanism.default()
    # the same parameters; the provenance (path, SHA-256 of the text as saved) is the file's own
    own = ("source", "name", "source_sha256")
    assert {k: v for k, v in vars(mine).items() if k not in own} == \
        {k: v for k, v in vars(ref).items() if k not in own}


@pytest.mark.hostile("real_file")
def test_a_mechanism_file_saved_as_utf16(tmp_path, capsys):
    path = _mech(tmp_path, TEXT.encode("utf-16"))
    assert "is UTF-16 text" in one_error_line(*cli(["kinematics", "--mechanism", path], capsys))


@pytest.mark.hostile("real_file")
def test_threshold_and_scene_files_with_bom_and_crlf(tmp_path):
    from labtool.api.acquisition import load_scene
    from labtool.reports.thresholds import load_thresholds

    th = tmp_path / "th.toml"
    th.write_bytes(b"\xef\xbb\xbf[omega2]\r\niso_rating = 0.6\r\n[apply]\r\nmodels = [\"rigid\"]\r\n")
    got = load_thresholds(th)
    assert got.models == ("rigid",) and got.limits[0].min == 0.6
    scene = tmp_path / "s.toml"
    scene.write_bytes(b"\xef\xbb\xbf" + (SAMPLE / "scenes" / "run_180rpm.toml").read_bytes().replace(b"\n", b"\r\n"))
    assert load_scene(scene)["rpm"] == 180 and load_scene(scene)["seed"] == 1


@pytest.mark.slow
@pytest.mark.hostile("real_file")
def test_outputs_open_in_a_second_tool(tmp_path, capsys):
    """What labtool writes opens elsewhere: the NetCDF with plain h5py, the CSV with numpy."""
    import h5py

    assert cli(["kinematics", "-o", tmp_path / "k.nc", "--groove-csv", tmp_path / "g.csv"], capsys)[0] == 0
    with h5py.File(tmp_path / "k.nc", "r") as f:
        assert f["omega2"].shape[0] == xr.open_dataset(tmp_path / "k.nc", engine="h5netcdf").sizes["phi1"]
    table = np.loadtxt(tmp_path / "g.csv", delimiter=",", skiprows=1)
    assert table.shape[1] == 8 and np.isfinite(table).all()
