"""LVM files of several segments, and channels in units labtool does not read: read where the file
allows it, refused in one line whose advice, followed here, works.

Every file holds the volts of one HDF5 original from the simulated stand (300 rpm, 2 s) and must
give its omega2; the LVM files are written as NI's LVM specification lays out a segment (a channel
header, its End_of_Header line, the column names, the rows), one after the other.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import xarray as xr
from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

from hostile import one_error_line
from labtool.cli import main

FS = 10000.0


def _cli(args, capsys):
    capsys.readouterr()
    code = main([str(a) for a in args])
    return code, capsys.readouterr().err


def _same_omega2(nc, ref):
    om = xr.open_dataset(nc, engine="h5netcdf", decode_times=False)["omega2"].values
    assert np.array_equal(np.isnan(om), np.isnan(ref))
    ok = np.isfinite(ref)
    assert np.abs(om[ok] - ref[ok]).max() <= 1e-6 * np.abs(ref[ok]).max()


FILE_HEADER = ["LabVIEW Measurement\t", "Writer_Version\t2", "Reader_Version\t2", "Separator\tTab",
               "Decimal_Separator\t.", "Multi_Headings\tYes", "X_Columns\tOne", "Time_Pref\tRelative",
               "Operator\tstand", "Date\t2026/11/22", "Time\t04:00:00.0000000000000", "***End_of_Header***\t", ""]


def _segment(volts, a, b, x0, dx):
    """One LVM segment of rows a..b: channel header (X0, Delta_X), column names, rows, a blank line."""
    n = b - a
    lines = ["Channels\t3\t\t\t", f"Samples\t{n}\t{n}\t{n}\t", "Date\t2026/11/22\t2026/11/22\t2026/11/22\t",
             "Time\t04:00:00.0000\t04:00:00.0000\t04:00:00.0000\t", "Y_Unit_Label\tVolts\tVolts\tVolts\t",
             "X_Dimension\tTime\tTime\tTime\t", "X0\t" + "\t".join([f"{x0:.16E}"] * 3) + "\t",
             "Delta_X\t" + "\t".join([f"{dx:.6E}"] * 3) + "\t", "***End_of_Header***\t\t\t\t",
             "X_Value\taE_t\taE_n\ttacho\tComment"]
    lines += [f"{x0 + (i - a) * dx:.6f}\t{volts[i, 0]:.9g}\t{volts[i, 1]:.9g}\t{volts[i, 2]:.9g}" for i in range(a, b)]
    return lines + [""]


def _lvm(path, volts, cuts, x0=None, rates=None):
    """An LVM file of the segments between ``cuts``; X0 of each: where it starts (s), unless given."""
    bounds = [0, *cuts, len(volts)]
    lines = list(FILE_HEADER)
    for k in range(len(bounds) - 1):
        dx = 1.0 / (rates[k] if rates else FS)
        lines += _segment(volts, bounds[k], bounds[k + 1], bounds[k] / FS if x0 is None else x0[k], dx)
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.slow
@pytest.mark.hostile("real_file")
def test_an_lvm_of_contiguous_segments_is_read_as_one_recording(tmp_path, capsys, original):
    """Three segments, the second starting 1.3 s into the file (past the 256 KiB a reader looks at
    first), each X0 continuing the one before: the original's omega2 (main refused any second
    segment: 'save the measurement as one segment', not possible for a past measurement)."""
    volts, ref = original
    p = tmp_path / "three.lvm"
    _lvm(p, volts, [13000, 17000])
    assert p.stat().st_size > 13000 * 30 > 1 << 18
    code, err = _cli(["process", p, "-o", tmp_path / "m.nc", "--rpm", "300"], capsys)
    assert code == 0, err
    assert "3 LVM segments joined: segment 2 continuing segment 1; segment 3 continuing segment 2" in err
    _same_omega2(tmp_path / "m.nc", ref)


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_an_lvm_segment_that_starts_later_is_joined_after_a_gap(tmp_path, capsys, original):
    """Segment 2's X0 says it starts 0.1 s after segment 1 ends: a gap of 1000 samples, processed as
    a recorder's gap is (two contiguous segments, the time axis counting the lost samples)."""
    volts, _ = original
    p = tmp_path / "gap.lvm"
    _lvm(p, volts, [7000], x0=[0.0, 0.8])
    code, err = _cli(["process", p, "-o", tmp_path / "m.nc", "--rpm", "300"], capsys)
    assert code == 0, err
    assert "segment 2 after a gap of 1000 samples (0.1 s)" in err
    ds = xr.open_dataset(tmp_path / "m.nc", engine="h5netcdf", decode_times=False)
    assert ds.attrs["n_segments"] == 2 and ds.attrs["n_samples_lost"] == 1000
    t = ds["time"].values
    assert t[7000] - t[6999] == pytest.approx(1001 / FS)


@pytest.mark.slow
@pytest.mark.hostile("real_file")
def test_lvm_segments_at_two_rates_are_refused_and_the_advice_works(tmp_path, capsys, original):
    """Segments that cannot be one recording: one line naming the difference; its advice (the file
    header and one segment in a file of their own) followed, that segment is processed."""
    volts, _ = original
    p = tmp_path / "rates.lvm"
    _lvm(p, volts, [7000], rates=[FS, 2 * FS])
    line = one_error_line(*_cli(["process", p, "-o", tmp_path / "m.nc", "--rpm", "300"], capsys))
    assert "segment 2 differs from segment 1 in its sample rate" in line and "20000 Hz" in line, line
    assert "copy the file header and the segment you want into a file of its own" in line
    text = p.read_text().splitlines()
    second = [i for i, ln in enumerate(text) if ln.startswith("Channels")][1]
    one = tmp_path / "segment1.lvm"
    one.write_text("\n".join(text[:second]) + "\n")
    code, err = _cli(["process", one, "-o", tmp_path / "m.nc", "--rpm", "300"], capsys)
    assert code == 0, err


# --------------------------------------------------------------------------- units, side channels

@pytest.mark.slow
@pytest.mark.hostile("real_file")
def test_a_csv_channel_in_an_unknown_unit_takes_units_and_a_side_channel_is_left_out(tmp_path, capsys, original):
    """'EU' (a DAQ's engineering units): main advised 'convert the channel or fix its unit', which a
    past measurement cannot follow; now --units names the unit. A temperature column beside the
    accelerometer's is left out and said (main refused the whole file for its unit)."""
    volts, ref = original
    t = np.arange(len(volts)) / FS
    df = pd.DataFrame({"time [s]": t, "aE_t [EU]": volts[:, 0], "aE_n [EU]": volts[:, 1], "tacho [V]": volts[:, 2],
                       "Temp [degC]": np.full(len(t), 21.5)})
    p = tmp_path / "run.csv"
    df.to_csv(p, index=False, float_format="%.9g")
    line = one_error_line(*_cli(["process", p, "-o", tmp_path / "m.nc"], capsys))
    assert "unit 'EU'" in line and "--units 'aE_t=V'" in line, line
    code, err = _cli(["process", p, "-o", tmp_path / "m.nc", "--units", "aE_t=V,aE_n=V"], capsys)
    assert code == 0, err
    assert "column 'Temp' is in 'degC', not a voltage or an acceleration: left out" in err
    _same_omega2(tmp_path / "m.nc", ref)


@pytest.mark.slow
@pytest.mark.hostile("real_file")
def test_a_tdms_channel_in_an_unknown_unit_takes_units_and_a_force_channel_is_left_out(tmp_path, capsys, original):
    """DAQmx names a custom scale's unit as the user typed it ('counts'); --units aE_t=V (the chain's
    name) settles it. A load cell in N beside the accelerometer is left out."""
    volts, ref = original
    p = tmp_path / "run.tdms"
    units = {"aE_t": "counts", "aE_n": "V", "tacho": "V"}
    chans = [ChannelObject("data", n, volts[:, j], properties={"wf_increment": 1 / FS, "unit_string": units[n]})
             for j, n in enumerate(("aE_t", "aE_n", "tacho"))]
    chans.append(ChannelObject("data", "Load cell", np.full(len(volts), 3.5),
                               properties={"wf_increment": 1 / FS, "unit_string": "N"}))
    with TdmsWriter(p) as w:
        w.write_segment([RootObject({"cam_speed_rpm": 300.0}), GroupObject("data"), *chans])
    line = one_error_line(*_cli(["process", p, "-o", tmp_path / "m.nc"], capsys))
    assert "unit 'counts'" in line and "--units 'aE_t=V'" in line, line
    code, err = _cli(["process", p, "-o", tmp_path / "m.nc", "--units", "aE_t=V"], capsys)
    assert code == 0, err
    assert "channel 'Load cell' is in 'N', not a voltage or an acceleration: left out" in err
    _same_omega2(tmp_path / "m.nc", ref)


@pytest.mark.hostile("real_file")
def test_a_unit_of_another_quantity_names_the_channels_option(tmp_path, capsys):
    """A channel in MPa is no accelerometer's: --units would be wrong advice; --channels is given."""
    p = tmp_path / "p.csv"
    t = np.arange(20000) / FS
    pd.DataFrame({"time [s]": t, "p [MPa]": np.sin(t), "a [V]": np.cos(t)}).to_csv(p, index=False)
    line = one_error_line(*_cli(["process", p, "-o", tmp_path / "m.nc"], capsys))
    assert "another quantity" in line and "--channels aE_t=<channel>,aE_n=<channel>" in line and "--units" not in line
