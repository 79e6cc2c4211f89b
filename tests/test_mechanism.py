"""The mechanism file: loading, SI conversion, and bad input (one line, exit 2 through the CLI)."""
import math
from importlib import resources

import pytest
import xarray as xr
from hypothesis import given, settings
from hypothesis import strategies as st

from labtool.cli import main
from labtool.common.errors import InputError
from labtool.models.mechanism import Mechanism

TEXT = resources.files("labtool.models.data").joinpath("stb216.toml").read_text()


def test_default_is_in_si():
    m = Mechanism.default()
    assert m.l == pytest.approx(0.061)
    assert m.psi_a == pytest.approx(math.radians(15))
    assert m.J4 == pytest.approx(905.444e-6)
    assert m.M_nominal_motor == pytest.approx(1100 / (920 * math.pi / 30))


def test_user_file_round_trip(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(TEXT.replace("m4_kg = 0.1266", "m4_kg = 0.2"))
    assert Mechanism.from_toml(path).m4 == pytest.approx(0.2)


def _cli_error(capsys, args):
    code = main(args)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and err[0].startswith("labtool: error:")
    return err[0]


def test_missing_parameter(tmp_path, capsys):
    path = tmp_path / "m.toml"
    path.write_text(TEXT.replace("DE_mm = 186.0", ""))
    msg = _cli_error(capsys, ["kinematics", "--mechanism", str(path)])
    assert "missing parameter [follower] DE_mm" in msg


def test_negative_parameter(tmp_path, capsys):
    path = tmp_path / "m.toml"
    path.write_text(TEXT.replace("m2_kg = 0.3681", "m2_kg = -0.3681"))
    assert "must not be negative" in _cli_error(capsys, ["kinematics", "--mechanism", str(path)])


def test_linkage_that_cannot_close(tmp_path, capsys):
    path = tmp_path / "m.toml"
    path.write_text(TEXT.replace("FG_mm = -13.75", "FG_mm = -250.0"))
    assert "rod cannot close" in _cli_error(capsys, ["kinematics", "--mechanism", str(path)])


def test_not_toml_and_missing_file(tmp_path, capsys):
    path = tmp_path / "m.toml"
    path.write_text("this is [not toml")
    assert "not valid TOML" in _cli_error(capsys, ["kinematics", "--mechanism", str(path)])
    assert "cannot read mechanism file" in _cli_error(capsys, ["kinematics", "--mechanism", str(tmp_path / "nope.toml")])


def test_unknown_law_and_impossible_operating_point(capsys):
    assert "unknown motion law" in _cli_error(capsys, ["kinematics", "--law", "spline"])
    assert "cam speed" in _cli_error(capsys, ["kinematics", "--rpm", "-5"])
    assert "inertia factor" in _cli_error(capsys, ["kinematics", "--jt-factor", "0"])


def test_a_length_that_underflows_in_si_is_refused():
    # found by the hypothesis test below: 5e-324 mm passed the schema's > 0 and became 0.0 m
    with pytest.raises(InputError, match="too small to be represented in SI"):
        Mechanism.from_toml_text(TEXT.replace("l_DC_mm = 61.0", "l_DC_mm = 5e-324"))


@settings(max_examples=40, deadline=None)
@given(value=st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=5), st.booleans()))
def test_any_bad_value_for_a_length_is_an_input_error_or_accepted(value):
    text = TEXT.replace("l_DC_mm = 61.0", f"l_DC_mm = {value!r}" if not isinstance(value, str) else f"l_DC_mm = {value!r}".replace("'", '"'))
    try:
        m = Mechanism.from_toml_text(text)
    except InputError:
        return
    assert m.l > 0 and math.isfinite(m.l)


@pytest.mark.slow
def test_kinematics_cli_writes_netcdf_with_units_and_groove_csv(tmp_path, capsys):
    out, csv = tmp_path / "kin.nc", tmp_path / "groove.csv"
    assert main(["kinematics", "--law", "sine", "--rpm", "180", "-o", str(out), "--groove-csv", str(csv)]) == 0
    ds = xr.open_dataset(out, engine="h5netcdf")
    for name, var in ds.variables.items():
        assert "units" in var.attrs, name
    assert ds.attrs["cam_speed_rpm"] == 180
    lines = csv.read_text().splitlines()
    assert lines[0].startswith("phi1_deg,pitch_x_mm") and len(lines) - 1 >= 720
    # existing output is not overwritten without --force
    assert main(["kinematics", "-o", str(out)]) == 2
    assert "already exists" in capsys.readouterr().err
