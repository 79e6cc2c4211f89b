"""Real-world files: TDMS as DAQmx and LabVIEW write it, LVM, CSV dialects.

Each file holds the same volts as one HDF5 original from the simulated stand, written with the real
writer where one exists (npTDMS's TdmsWriter; pandas for CSV); each must give the original's omega2
to 1e-6 of its peak, or be refused with one line saying what to give.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
import xarray as xr
from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

from labtool.cli import main
from stand_data import stand_recording

FS = 10000.0
KA = 86.43


def _same_omega2(nc, ref):
    om = xr.open_dataset(nc, engine="h5netcdf", decode_times=False)["omega2"].values
    assert np.array_equal(np.isnan(om), np.isnan(ref))
    ok = np.isfinite(ref)
    assert np.abs(om[ok] - ref[ok]).max() <= 1e-6 * np.abs(ref[ok]).max()


def _process(path, tmp_path, *opts, code=0, capsys=None):
    out = tmp_path / f"{path.stem}.nc"
    assert main(["process", str(path), "-o", str(out), "--force", *opts]) == code
    return out


def _one_line_error(capsys, *words):
    err = [ln for ln in capsys.readouterr().err.strip().splitlines() if not ln.startswith("labtool: warning:")]
    assert len(err) == 1 and err[0].startswith("labtool: error:"), err
    for w in words:
        assert w in err[0], err[0]


# ----------------------------------------------------------------------------------------- TDMS

def _tdms(path, groups, root=None):
    with TdmsWriter(path) as w:
        objs = [RootObject(root or {})]
        for gname, gprops, chans in groups:
            objs.append(GroupObject(gname, gprops))
            objs += [ChannelObject(gname, cname, data, properties=props) for cname, data, props in chans]
        w.write_segment(objs)


def _chans(volts, names=("aE_t", "aE_n", "tacho"), props=None):
    return [(n, volts[:, j], dict(props or {"wf_increment": 1 / FS, "unit_string": "V",
                                           **({"ka_m_s2_per_v": KA} if j < 2 else {})}))
            for j, n in enumerate(names)]


@pytest.mark.slow
def test_tdms_raw_int16_with_ni_scale(tmp_path, original):
    """Raw ADC codes with a linear NI_Scale (npTDMS scales them; main read this case too)."""
    volts, ref = original
    slope = 20.0 / 65536
    raw = np.round(volts / slope).astype(np.int16)  # the ADC codes: the float32 volts are exact multiples
    assert np.array_equal(raw * slope, volts.astype(np.float32).astype(np.float64))
    props = [{"wf_increment": 1 / FS, "unit_string": "V", "NI_Number_Of_Scales": 1,
              "NI_Scale[0]_Scale_Type": "Linear", "NI_Scale[0]_Linear_Slope": slope,
              "NI_Scale[0]_Linear_Y_Intercept": 0.0, "NI_Scaling_Status": "unscaled",
              **({"ka_m_s2_per_v": KA} if j < 2 else {})} for j in range(3)]
    p = tmp_path / "raw.tdms"
    _tdms(p, [("data", {}, [(n, raw[:, j], props[j]) for j, n in enumerate(("aE_t", "aE_n", "tacho"))])])
    _same_omega2(_process(p, tmp_path), ref)


@pytest.mark.slow
@pytest.mark.hostile("real_file")
def test_tdms_daqmx_names_metadata_group_rate_on_group(tmp_path, original, capsys):
    """Dev1/ai0.. names, a metadata group first, the rate only as a group property: read with
    --channels; without it, one line listing the channels."""
    volts, ref = original
    p = tmp_path / "daqmx.tdms"
    meta = ("Settings", {"operator": "me"}, [("serial", np.array([12345.0]), {})])
    data = ("Measured Data", {"Sample Rate": FS},
            [(f"Dev1/ai{j}", volts[:, j], {"unit_string": "Volts", **({"ka_m_s2_per_v": KA} if j < 2 else {})})
             for j in range(3)])
    _tdms(p, [meta, data], root={"cam_speed_rpm": 300.0})
    _process(p, tmp_path, code=2)
    _one_line_error(capsys, "aE_t", "Dev1/ai0", "--channels")
    _same_omega2(_process(p, tmp_path, "--channels", "aE_t=Dev1/ai0,aE_n=Dev1/ai1,tacho=Dev1/ai2"), ref)


@pytest.mark.slow
@pytest.mark.hostile("real_file")
def test_tdms_two_data_groups_need_group(tmp_path, original, capsys):
    volts, ref = original
    p = tmp_path / "two.tdms"
    _tdms(p, [("run1", {}, _chans(volts)), ("run2", {}, _chans(volts[:5000]))])
    _process(p, tmp_path, code=2)
    _one_line_error(capsys, "--group", "run1", "run2")
    _same_omega2(_process(p, tmp_path, "--group", "run1"), ref)


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_tdms_channel_in_m_s2_is_not_multiplied_by_ka(tmp_path, original):
    """DAQmx logs an accelerometer channel in m/s^2 (unit_string): Ka must not be applied again
    (main multiplied by Ka a second time: omega2 86x too large)."""
    volts, ref = original
    acc = volts.copy()
    acc[:, :2] *= KA
    p = tmp_path / "accel.tdms"
    chans = [(n, acc[:, j], {"wf_increment": 1 / FS, "unit_string": u})
             for j, (n, u) in enumerate(zip(("aE_t", "aE_n", "tacho"), ("m/s^2", "m/s^2", "V")))]
    _tdms(p, [("data", {}, chans)])
    out = _process(p, tmp_path)
    _same_omega2(out, ref)
    ds = xr.open_dataset(out, engine="h5netcdf", decode_times=False)
    assert ds.attrs["ka_aE_t_m_s2_per_v"] == 1.0 and "m/s^2" in ds.attrs["ka_source_aE_t"]
    g = tmp_path / "g.tdms"  # in g: converted with g0
    chans = [(n, acc[:, j] / (9.80665 if j < 2 else 1.0), {"wf_increment": 1 / FS, "unit_string": u})
             for j, (n, u) in enumerate(zip(("aE_t", "aE_n", "tacho"), ("g", "g", "V")))]
    _tdms(g, [("data", {}, chans)])
    _same_omega2(_process(g, tmp_path), ref)


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("case", ["increments", "unit"])
def test_tdms_ambiguous_rate_or_unit_is_refused(tmp_path, original, capsys, case):
    volts, _ = original
    p = tmp_path / f"{case}.tdms"
    chans = _chans(volts)
    if case == "increments":
        chans[1][2]["wf_increment"] = 2 / FS
        words = ("wf_increment",)
    else:
        chans[0][2]["unit_string"] = "psi"
        words = ("psi", "unit")
    _tdms(p, [("data", {}, chans)])
    _process(p, tmp_path, code=2)
    _one_line_error(capsys, *words)


# ------------------------------------------------------------------------------------------ LVM

def _lvm(path, volts, sep, dec, x_column=True):
    sepname = {"\t": "Tab", ",": "Comma", ";": "Semicolon"}[sep]

    def num(v):
        return (f"{v:.9g}").replace(".", dec)

    names = ["aE_t", "aE_n", "tacho"]
    lines = ["LabVIEW Measurement", f"Writer_Version{sep}2", f"Reader_Version{sep}2", f"Separator{sep}{sepname}",
             f"Decimal_Separator{sep}{dec}", f"Multi_Headings{sep}No", f"X_Columns{sep}{'One' if x_column else 'No'}",
             f"Time_Pref{sep}Relative", f"Operator{sep}test", f"Date{sep}2026/11/22", f"Time{sep}04:00:00.0",
             "***End_of_Header***", "", f"Channels{sep}3", "Samples" + (sep + str(len(volts))) * 3,
             "Date" + (sep + "2026/11/22") * 3, "Time" + (sep + "04:00:00") * 3, "X_Dimension" + (sep + "Time") * 3,
             "X0" + (sep + num(0.0)) * 3, "Delta_X" + (sep + num(1 / FS)) * 3, "***End_of_Header***",
             sep.join((["X_Value"] if x_column else []) + names)]
    rows = []
    for i, r in enumerate(volts):
        cells = ([num(i / FS)] if x_column else []) + [num(v) for v in r]
        rows.append(sep.join(cells))
    path.write_text("\n".join(lines + rows) + "\n")


@pytest.mark.slow
@pytest.mark.hostile("real_file")
@pytest.mark.parametrize("sep, dec, x_column", [("\t", ".", True), (",", ".", False), (";", ",", True)])
def test_lvm_dialects(tmp_path, original, sep, dec, x_column):
    volts, ref = original
    p = tmp_path / "m.lvm"
    _lvm(p, volts.astype(np.float32), sep, dec, x_column)
    _same_omega2(_process(p, tmp_path, "--rpm", "300"), ref)


def test_lvm_cross_checked_with_lvm_read(tmp_path, original):
    """The samples as lvm_read (the nearest library) reads them."""
    lvm_read = pytest.importorskip("lvm_read")
    from labtool.processing.readers import open_recording
    volts, _ = original
    p = tmp_path / "x.lvm"
    _lvm(p, volts[:3000].astype(np.float32), "\t", ".", True)
    peer = lvm_read.read(str(p), read_from_pickle=False, dump_file=False)[0]["data"]
    with open_recording(p) as rec:
        ours = rec.read(0, rec.n_samples)
    np.testing.assert_array_equal(ours, peer[:, 1:4])


# ------------------------------------------------------------------------------------------ CSV

def _csv(path, volts, sep=",", dec=".", header_block=(), time=None, names=("aE_t [V]", "aE_n [V]", "tacho [V]")):
    df = pd.DataFrame(volts.astype(np.float32), columns=list(names))
    if time is not None:
        df.insert(0, time[0], time[1])
    with open(path, "w", newline="") as fh:
        for line in header_block:
            fh.write(line + "\n")
        df.to_csv(fh, sep=sep, decimal=dec, index=False, float_format="%.9g")


@pytest.mark.slow
@pytest.mark.hostile("real_file")
@pytest.mark.parametrize("kind", ["header_block", "tab", "semicolon_decimal_comma", "time_ms", "iso_timestamps"])
def test_csv_exports(tmp_path, original, kind):
    volts, ref = original
    n = len(volts)
    p = tmp_path / f"{kind}.csv"
    if kind == "header_block":  # NI 'Write To Measurement File' style: key/value lines, then the table
        _csv(p, volts, header_block=["Operator,test", "Sample Rate,10000", "cam_speed_rpm,300",
                                     "Start,2026-11-22T04:00:00Z", ""])
    elif kind == "tab":
        _csv(p, volts, sep="\t", time=("Time [s]", np.arange(n) / FS))
    elif kind == "semicolon_decimal_comma":
        _csv(p, volts, sep=";", dec=",", time=("Zeit (s)", np.arange(n) / FS))
    elif kind == "time_ms":
        _csv(p, volts, time=("time_ms", np.arange(n) * (1000 / FS)))
    else:
        stamps = pd.Timestamp("2026-11-22T04:00:00Z") + pd.to_timedelta(np.arange(n) * 100, unit="us")
        _csv(p, volts, time=("Timestamp", stamps.strftime("%Y-%m-%dT%H:%M:%S.%fZ")))
    opts = [] if kind == "header_block" else ["--rpm", "300"]
    _same_omega2(_process(p, tmp_path, *opts), ref)


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_csv_time_in_ms_without_unit_is_refused_or_overridden(tmp_path, original, capsys):
    """'time' in ms with no unit gave fs = 10 Hz on main; now: one line asking for --time-unit."""
    volts, ref = original
    p = tmp_path / "ms.csv"
    _csv(p, volts, time=("time", np.arange(len(volts)) * (1000 / FS)))
    _process(p, tmp_path, code=2)
    _one_line_error(capsys, "--time-unit")
    _same_omega2(_process(p, tmp_path, "--time-unit", "ms", "--rpm", "300"), ref)


@pytest.mark.hostile("silent_wrong")
def test_csv_time_column_is_checked_beyond_its_first_rows(tmp_path, original, capsys):
    """A gap of 100 rows in the time column after row 5000: main read only rows 1-2."""
    volts, _ = original
    t = np.arange(len(volts)) / FS
    t[5000:] += 0.01
    p = tmp_path / "gap.csv"
    _csv(p, volts, time=("time [s]", t))
    _process(p, tmp_path, "--rpm", "300", code=2)
    _one_line_error(capsys, "row 5001", "not uniform")


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("bad", [0.0, math.inf, -86.43])
def test_ka_zero_or_inf_in_a_recording_is_refused(tmp_path, bad, capsys):
    """main silently used the paper's Ka instead."""
    p = tmp_path / "ka.h5"
    stand_recording(p, duration_s=1.0, ka=[bad, KA, np.nan])
    _process(p, tmp_path, code=2)
    _one_line_error(capsys, "Ka", "--calibration")
