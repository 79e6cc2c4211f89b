"""Real files made by other software (tests/data/real/README.md names each one's source and licence),
and exports in the layouts LabVIEW and DAQ software write them.

Each real file is taken through ``labtool process`` with the options a user would give: it is read
to omega2, or refused in one line; where the line advises an option, the option is added and the
command run again, until it writes omega2 or is refused for what the data are (not an accelerometer
recording of a turning cam), which is then asserted. The samples are checked against lvm_read (a peer
LVM parser) and npTDMS.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from hostile import cli, one_error_line
from stand_data import stand_volts, write_v1

# a reader that leaves pandas guessing a column's type chunk by chunk (a LabVIEW Comment column
# with text in a few rows) warns the user about labtool's internals: an error here
pytestmark = pytest.mark.filterwarnings("error::pandas.errors.DtypeWarning")

REAL = Path(__file__).parent / "data" / "real"
ALL_DATA = "07/09/2012 06:58:23 PM - Digital Input - All Data"

# file, [(options added, what the refusal says: the option it advises or the cause)]; the last step's
# refusal is caused by the data (no option can make them a cam recording)
CHAINS = {
    "nptdms_raw1.tdms": [
        ([], "--channels"),
        (["--channels", "aE_t=First  Channel,aE_n=Second Chan,tacho=Third Chan"], "not a cam speed")],
    "nptdms_big_endian.tdms": [
        ([], "--channels"),
        (["--channels", "aE_t=Amplitude sweep,aE_n=Phase sweep"], "--rpm"),
        (["--rpm", "300"], "fewer than two cam revolutions")],
    "nptdms_Digital_Input.tdms": [
        ([], "--group"),
        (["--group", ALL_DATA], "--channels")],
    "lvm_read_short.lvm": [
        ([], "--channels"),
        (["--channels", "aE_t=Response (Trigger)"], "--channels aE_n=")],
    "lvm_read_with_comments.lvm": [([], "none of its channels is in a unit of voltage or acceleration")],
    "lvm_read_with_empty_fields.lvm": [
        ([], "--channels"),
        (["--channels", "aE_t=Dev0/Ai0,aE_n=Dev0/Ai2", "--rpm", "300"], "revolutions at the stated 300 rpm")],
    "lvm_read_multi_time_column.lvm": [
        ([], "--channels"),
        (["--channels", "aE_t=Acceleration,aE_n=Voltage", "--rpm", "300"], "revolutions at the stated 300 rpm")],
    "lvm_read_no_decimal_separator.lvm": [
        ([], "--channels"),
        (["--channels", "aE_t=ax,aE_n=az", "--rpm", "300"], "revolutions at the stated 300 rpm")],
    "picoquake_car_vibration_head.csv": [
        ([], "--sample-rate"),
        (["--sample-rate", "2000"], "--channels"),
        (["--channels", "aE_t=a_x,aE_n=a_z"], "--rpm"),
        (["--rpm", "300"], "fewer than two cam revolutions")],
}


@pytest.mark.hostile("real_file")
@pytest.mark.parametrize("name", sorted(CHAINS))
@pytest.mark.slow
def test_a_real_file_goes_as_far_as_its_data_allow(tmp_path, capsys, name):
    opts: list[str] = []
    for added, says in CHAINS[name]:
        opts += added
        line = one_error_line(*cli(["process", REAL / name, "-o", tmp_path / "m.nc", *opts], capsys))
        assert says in line, line
        if says.startswith("--"):                 # the advice is an option: the next step adds it
            continue
        assert not (tmp_path / "m.nc").exists()


def _lvm_read(path):
    lvm_read = pytest.importorskip("lvm_read")
    return lvm_read.read(str(path), read_from_pickle=False, dump_file=False)[0]


@pytest.mark.hostile("real_file")
@pytest.mark.parametrize("name, channels, rate, units, scale", [
    ("lvm_read_short.lvm", ["Response (Trigger)"], 25600.0, ["m/s^2"], [1.0]),
    ("lvm_read_with_empty_fields.lvm", ["Dev0/Ai0", "Dev0/Ai2", "Dev0/Ai0 1"], 1000.0, ["V", "V", "V"], [1.0] * 3),
    ("lvm_read_multi_time_column.lvm", ["Acceleration"], 51200.0, ["m/s^2"], [9.80665]),
    ("lvm_read_no_decimal_separator.lvm", ["ax", "ay", "az"], 4000.0, ["m/s^2"] * 3, [9.80665] * 3),
])
def test_real_lvm_samples_equal_lvm_reads(name, channels, rate, units, scale):
    """Comment columns, side channels, X_Columns No/Multi, decimal commas: the samples as lvm_read
    gives them (its columns by position), in the unit the file states (g x 9.80665)."""
    from labtool.processing.readers import open_recording
    peer = _lvm_read(REAL / name)
    with open_recording(REAL / name) as rec:
        assert rec.channel_names == channels and rec.sample_rate_hz == rate and rec.channel_units == units
        ours = rec.read(0, rec.n_samples)
        notes = " ".join(rec.assumptions)
    cols = [[h.strip() for h in peer["Channel names"]].index(c) for c in channels]   # lvm_read's data columns
    np.testing.assert_allclose(ours, peer["data"][:rec.n_samples][:, cols] * np.array(scale), rtol=1e-12)
    assert "Comment column" in notes            # every one of these files has one


@pytest.mark.hostile("real_file")
def test_real_tdms_read_as_npTDMS_scales_them():
    """DAQmx raw logging (int16 x NI_Scale slope) and a big-endian file: the volts npTDMS gives."""
    from nptdms import TdmsFile

    from labtool.processing.readers import open_recording
    for name, group in (("nptdms_raw1.tdms", "Layer Data"), ("nptdms_big_endian.tdms", "Measured Data")):
        peer = TdmsFile.read(REAL / name)[group]
        with open_recording(REAL / name) as rec:
            ours = rec.read(0, rec.n_samples)
            assert rec.channel_names == [c.name for c in peer.channels()]
            assert rec.sample_rate_hz == pytest.approx(1.0 / peer.channels()[0].properties["wf_increment"])
        np.testing.assert_array_equal(ours, np.column_stack([c[:] for c in peer.channels()]))
    # raw int16 codes times the slope: every value a whole multiple of it
    slope = TdmsFile.read(REAL / "nptdms_raw1.tdms")["Layer Data"].channels()[0].properties[
        "NI_Scale[1]_Linear_Slope"]
    with open_recording(REAL / "nptdms_raw1.tdms") as rec:
        codes = rec.read(0, rec.n_samples) / slope
    assert np.abs(codes - np.round(codes)).max() < 1e-6 and np.abs(codes).max() <= 32768


@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("content", [b"not a tdms file at all\n", b"\x00\x01\x02\x03" * 100, b"TDSm\x00\x01"])
def test_a_file_named_tdms_that_is_not_tdms_is_one_line(tmp_path, capsys, content):
    """npTDMS's struct.error reached the user on main."""
    p = tmp_path / "data.tdms"
    p.write_bytes(content)
    line = one_error_line(*cli(["process", p, "-o", tmp_path / "m.nc"], capsys))
    assert "struct" not in line and ("TDMS" in line or "no table of numbers" in line), line


# ------------------------------------------------- exports in the layouts other software writes them

FS = 51200.0


@pytest.fixture(scope="module")
def stand51k(tmp_path_factory):
    """A 2 s simulated-stand recording at 51.2 kHz, 300 rpm, and its omega2 processed without tacho."""
    d = tmp_path_factory.mktemp("s51")
    volts, _, pa, fs = stand_volts(2.0, rpm=300.0, fs=FS)
    assert fs == FS
    acc = volts[:, :2].astype(np.float64) * np.asarray(pa.ka_m_s2_per_v)
    orig = d / "orig.h5"
    write_v1(orig, acc, names=("aE_t", "aE_n"), fs=FS, ka=[1.0, 1.0], cam_speed_rpm=None, dtype="float64")
    assert cli_ok(["process", orig, "-o", d / "orig.nc", "--rpm", "300"])
    return acc, xr.open_dataset(d / "orig.nc", engine="h5netcdf", decode_times=False)["omega2"].values


def cli_ok(args) -> bool:
    from labtool.cli import main
    return main([str(a) for a in args]) == 0


def _labview_lvm(path, acc, x_decimals=6, x0=0.0, date="2009/02/03", unit="m/s^2"):
    """'Write To Measurement File' as LabVIEW writes it: comma separated, X values printed with
    ``x_decimals``, two accelerometers and four side channels of 5 samples at Delta_X 1 s, a
    Comment column, a Notes line."""
    n = len(acc)
    names = ["Accel 0", "Accel 1", "Temp", "Speed set", "Humidity", "Supply"]
    head = ["LabVIEW Measurement,", "Writer_Version,2", "Reader_Version,2", "Separator,Comma", "Decimal_Separator,.",
            "Multi_Headings,Yes", "X_Columns,One", "Time_Pref,Relative", "Operator,stand", f"Date,{date}",
            "Time,23:59:59.9999999999999", "***End_of_Header***,", ",",
            "Notes,X values guaranteed valid only for Accel 0",
            "Channels,6,,,,,,", "Samples," + ",".join([str(n)] * 2 + ["5"] * 4),
            "Date," + ",".join([date] * 6), "Time," + ",".join(["23:59:59.9999"] * 6),
            "Y_Unit_Label," + ",".join([unit, unit, "Deg C", "rpm", "%", "V"]),
            "X_Dimension," + ",".join(["Time"] * 6), "X0," + ",".join([f"{x0:.16E}"] * 6),
            "Delta_X," + ",".join([f"{1 / FS:.6E}"] * 2 + ["1.000000"] * 4), "***End_of_Header***,,,,,,",
            "X_Value," + ",".join(names) + ",Comment"]
    scale = 9.80665 if unit == "g" else 1.0
    t = x0 + np.arange(n) / FS
    side = np.array([21.5, 300.0, 40.0, 24.0])
    rows = []
    for i in range(n):
        cells = [f"{t[i]:.{x_decimals}f}", f"{acc[i, 0] / scale:.9g}", f"{acc[i, 1] / scale:.9g}"]
        cells += [f"{v:.6f}" for v in side] if i < 5 else [""] * 4
        cells.append("start of run" if i == 0 else "")
        rows.append(",".join(cells))
    path.write_text("\n".join(head + rows) + "\n")


@pytest.mark.slow
@pytest.mark.hostile("real_file")
@pytest.mark.parametrize("unit, x0, date", [("m/s^2", 0.0, "2009/02/03"), ("g", 12.5, "1904/01/01")])
def test_a_labview_export_of_two_accelerometers_at_51k2_is_read_to_omega2(tmp_path, capsys, stand51k, unit, x0, date):
    """Refused three times on main (the Comment column, the side channels' Delta_X, the X column
    rounded to 1 us against the header's exact 51200 Hz; and --sample-rate 51200 did not help)."""
    acc, ref = stand51k
    p = tmp_path / "run.lvm"
    _labview_lvm(p, acc, x0=x0, date=date, unit=unit)
    code, err = cli(["process", p, "-o", tmp_path / "m.nc", "--channels", "aE_t=Accel 0,aE_n=Accel 1",
                     "--rpm", "300"], capsys)
    assert code == 0, err
    assert "51200 Hz from the LVM header's Delta_X" in err and "within its printed precision (1e-06 s)" in err
    assert "left out 'Temp' (5 samples, at 1 Hz)" in err
    ds = xr.open_dataset(tmp_path / "m.nc", engine="h5netcdf", decode_times=False)
    om = ds["omega2"].values
    ok = np.isfinite(ref)
    assert np.array_equal(np.isfinite(om), ok)
    assert np.abs(om[ok] - ref[ok]).max() <= 1e-6 * np.abs(ref[ok]).max()
    assert ds.attrs["ka_aE_t_m_s2_per_v"] == 1.0        # the unit stated is used: no Ka on top
    assert ds.attrs["start_time_utc"].startswith(date.replace("/", "-") + "T23:59:59.9999")


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_an_lvm_whose_x_column_contradicts_delta_x_takes_the_advised_rate(tmp_path, capsys, stand51k):
    """Delta_X says 51200 Hz, the X column steps at 50000 Hz: refused naming --sample-rate, and
    --sample-rate then decides (main refused it again with the same line)."""
    acc, _ = stand51k
    p = tmp_path / "run.lvm"
    _labview_lvm(p, acc[:60000])
    text = p.read_text().splitlines()
    k = next(i for i, ln in enumerate(text) if ln.startswith("X_Value")) + 1
    text[k:] = [f"{i / 50000:.6f}," + ln.split(",", 1)[1] for i, ln in enumerate(text[k:])]
    p.write_text("\n".join(text) + "\n")
    line = one_error_line(*cli(["process", p, "-o", tmp_path / "m.nc", "--channels", "aE_t=Accel 0,aE_n=Accel 1",
                                "--rpm", "300"], capsys))
    assert "--sample-rate" in line and "51200 Hz" in line and "50000 Hz" in line, line
    code, err = cli(["process", p, "-o", tmp_path / "m.nc", "--channels", "aE_t=Accel 0,aE_n=Accel 1",
                     "--rpm", "300", "--sample-rate", "50000"], capsys)
    assert code == 0, err
    assert xr.open_dataset(tmp_path / "m.nc", engine="h5netcdf").attrs["sample_rate_hz"] == 50000.0


@pytest.mark.slow
@pytest.mark.hostile("real_file")
@pytest.mark.parametrize("dialect", ["comment_and_blank_lines", "dewesoft_units_row", "excel_sep_line"])
def test_csv_exports_with_lines_between_rows_are_read(tmp_path, capsys, stand51k, dialect):
    """Blank lines and '#' comment lines between data rows were refused on main ('blank line inside
    the data')."""
    acc, ref = stand51k
    t = np.arange(len(acc)) / FS
    lines = []
    if dialect == "excel_sep_line":
        lines += ["sep=;", "Time [s];aE_t [m/s^2];aE_n [m/s^2]"]
        body = [f"{t[i]:.9f};{acc[i, 0]:.9g};{acc[i, 1]:.9g}".replace(".", ",") for i in range(len(acc))]
    elif dialect == "dewesoft_units_row":
        lines += ['"Time";"aE_t";"aE_n"', '"s";"m/s2";"m/s2"']
        body = [f"{t[i]:.9f};{acc[i, 0]:.9g};{acc[i, 1]:.9g}".replace(".", ",") for i in range(len(acc))]
    else:
        lines += ["# exported by a DAQ", "time [s],aE_t [m/s^2],aE_n [m/s^2]"]
        body = [f"{t[i]:.9f},{acc[i, 0]:.9g},{acc[i, 1]:.9g}" for i in range(len(acc))]
        for k in range(len(body) - 1000, 0, -25000):
            body[k:k] = ["", f"# block {k} written", ""]
    (tmp_path / "run.csv").write_text("\n".join(lines + body) + "\n")
    code, err = cli(["process", tmp_path / "run.csv", "-o", tmp_path / "m.nc", "--rpm", "300"], capsys)
    assert code == 0, err
    om = xr.open_dataset(tmp_path / "m.nc", engine="h5netcdf", decode_times=False)["omega2"].values
    ok = np.isfinite(ref)
    assert np.array_equal(np.isfinite(om), ok)
    assert np.abs(om[ok] - ref[ok]).max() <= 1e-6 * np.abs(ref[ok]).max()
    assert not re.search(r"assumed: column .* states no unit", err), err
