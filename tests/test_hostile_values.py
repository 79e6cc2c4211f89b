"""Hostile values found after issue 20: recording attributes of the wrong type, option values at
the edge of a float, factor files and measured files that were taken at face value. Each ends
with one line and exit 2 (tests/hostile.py ``one_error_line``)."""
from __future__ import annotations

import h5py
import numpy as np
import pytest
import xarray as xr

from hostile import REPORT_FAST, cli, measured_nc, one_error_line, run  # noqa: F401
from stand_data import stand_volts, write_v1


@pytest.fixture(scope="module")
def volts():
    return stand_volts(2.0)[0]


def _recording(tmp_path, volts, **root_attrs):
    path = tmp_path / "rec.h5"
    write_v1(path, volts)
    with h5py.File(path, "a") as f:
        for k, v in root_attrs.items():
            f.attrs[k] = v
    return path


# --- silent wrong: recording attributes --------------------------------------------------------
@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("value", ["no", "false", "0", np.array([1, 0])])
def test_a_complete_flag_that_is_not_a_boolean_is_refused(tmp_path, capsys, volts, value):
    """complete = "no" was read as bool("no") = True: a killed recording passed for a clean one."""
    rec = _recording(tmp_path, volts, complete=value)
    line = one_error_line(*cli(["process", rec, "-o", tmp_path / "m.nc"], capsys))
    assert "complete" in line and "true or false" in line
    assert not (tmp_path / "m.nc").exists()


@pytest.mark.hostile("silent_wrong")
def test_a_sample_rate_with_two_values_is_refused(tmp_path, capsys, volts):
    """sample_rate_hz = [10000, 20000] was read as its first value without a word."""
    rec = _recording(tmp_path, volts, sample_rate_hz=np.array([10000.0, 20000.0]))
    line = one_error_line(*cli(["process", rec, "-o", tmp_path / "m.nc"], capsys))
    assert "sample rate" in line and "one number" in line


# --- traceback / silent wrong: loads and inertias past what a float holds -----------------------
# --- traceback: factor files ------------------------------------------------------------------
# --- silent wrong: measured files -------------------------------------------------------------
def _measured(tmp_path, measured_nc, change):
    ds = xr.open_dataset(measured_nc).load()
    change(ds)
    path = tmp_path / "m.nc"
    ds.to_netcdf(path)
    return path

