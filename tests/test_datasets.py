"""labtool.common.datasets.dataset against xarray's own constructor on the same arguments."""
from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from hypothesis import given, settings
from hypothesis import strategies as st

from labtool.common.datasets import dataset

DTYPES = [np.float64, np.float32, np.int64, np.int8, np.bool_, np.complex128]


def _public(data_vars, coords, attrs):
    return xr.Dataset(data_vars=data_vars, coords=coords, attrs=attrs)


def _same(a: xr.Dataset, b: xr.Dataset):
    xr.testing.assert_identical(a, b)
    assert list(a.variables) == list(b.variables)          # the order a file and a report see
    assert list(a.sizes.items()) == list(b.sizes.items())
    assert set(a.xindexes) == set(b.xindexes)
    for name in a.xindexes:
        assert type(a.xindexes[name]) is type(b.xindexes[name])
        assert a.indexes[name].equals(b.indexes[name]) and a.indexes[name].dtype == b.indexes[name].dtype
    for name in a.variables:
        assert a.variables[name].dtype == b.variables[name].dtype
        assert type(a.variables[name]) is type(b.variables[name])
        assert a.variables[name].attrs == b.variables[name].attrs


@settings(max_examples=60, deadline=None)
@given(n_time=st.integers(0, 40), n_event=st.integers(0, 5), n_vars=st.integers(0, 6), seed=st.integers(0, 2**31),
       time_attrs=st.booleans())
def test_the_same_dataset_as_xarrays_constructor(n_time, n_event, n_vars, seed, time_attrs):
    rng = np.random.default_rng(seed)
    t = np.sort(rng.random(n_time))
    coords = {"time": ("time", t, {"units": "s", "long_name": "time"} if time_attrs else {})}
    data_vars = {}
    for k in range(n_vars):
        dtype = DTYPES[rng.integers(len(DTYPES))]
        data_vars[f"v{k}"] = ("time", (rng.random(n_time) * 10).astype(dtype), {"units": "m", "long_name": f"v {k}"})
    data_vars["event_kind"] = ("event", np.array(["contact", "separation", "x"] * 2)[:n_event], {"units": "1"})
    data_vars["event_time"] = ("event", rng.random(n_event), {"units": "s"})
    data_vars["table"] = (("time", "event"), rng.random((n_time, n_event)), {})
    attrs = {"title": "t", "n": 3, "x": 1.5}
    _same(_public(data_vars, coords, attrs), dataset(data_vars, coords, attrs))


def test_a_masked_array_is_filled_as_xarray_fills_it():
    t = np.arange(4.0)
    m = np.ma.masked_array([1.0, 2.0, 3.0, 4.0], mask=[0, 1, 0, 0])
    data_vars = {"x": ("time", m, {"units": "m"})}
    coords = {"time": ("time", t, {})}
    ds = dataset(data_vars, coords)
    _same(_public(data_vars, coords, None), ds)
    assert np.isnan(ds["x"].values[1])


def test_selection_and_arithmetic_work_on_the_index():
    t = np.linspace(0.0, 1.0, 11)
    ds = dataset({"x": ("time", t**2, {"units": "m"})}, {"time": ("time", t, {"units": "s"})})
    assert float(ds["x"].sel(time=0.5)) == 0.25
    assert float(ds["x"].interp(time=0.55)) == pytest.approx(0.5 * (0.25 + 0.36))
    assert ds.differentiate("time")["x"].values[5] == pytest.approx(1.0)


def test_a_netcdf_round_trip_keeps_it(tmp_path):
    t = np.linspace(0.0, 1.0, 11)
    data_vars = {"x": ("time", t**2, {"units": "m", "long_name": "x"}),
                 "event_time": ("event", np.array([0.1, 0.2]), {"units": "s"})}
    ds = dataset(data_vars, {"time": ("time", t, {"units": "s"})}, {"title": "t"})
    ds.to_netcdf(tmp_path / "a.nc", engine="h5netcdf")
    with xr.open_dataset(tmp_path / "a.nc", engine="h5netcdf") as back:
        xr.testing.assert_identical(back.load(), ds)


@pytest.mark.parametrize("data_vars, coords, match", [
    ({"x": ("time", np.zeros(3), {})}, {"time": ("time", np.zeros(4), {})}, "conflicting sizes"),
    ({"x": ("time", np.zeros(3), {}), "y": ("time", np.zeros(2), {})}, {}, "conflicting sizes"),
    ({"x": ("time", np.zeros((3, 2)), {})}, {}, "2-D values"),
    ({}, {"time": ("t", np.zeros(3), {})}, "dimension coordinate"),
    ({"time": ("time", np.zeros(3), {})}, {"time": ("time", np.zeros(3), {})}, "both a coordinate"),
])
def test_what_xarray_refuses_is_refused(data_vars, coords, match):
    with pytest.raises(ValueError, match=match):
        dataset(data_vars, coords)


def test_a_simulation_builds_its_dataset_once_when_first_read_with_every_attribute():
    """labtool.models.dynamics.result: the columns first, the Dataset at the first read of
    ``result.dataset``, with the attributes added before it (scene, model, warnings) and the very
    values the indicators were taken from."""
    from labtool.models.dynamics.result import DatasetParts
    from labtool.models.dynamics.scene import Scene
    from labtool.models.dynamics.simulate import simulate

    for model, key, column, scale in (("elastic", "xel_max_mm", "x_el", 1e3), ("rigid", "MR13D_max_Nm", "MR13D", 1.0)):
        res = simulate(Scene(accuracy="fast"), model)
        assert isinstance(res._dataset, DatasetParts)                    # not built by the simulation
        ds = res.dataset
        assert isinstance(ds, xr.Dataset) and res.dataset is ds          # built once
        assert ds.attrs["model"] == model and ds.attrs["model_reason"] == f"requested --model {model}"
        assert "law" in ds.attrs and ds.attrs["validity_warnings"] == res.attrs["validity_warnings"]
        assert float(ds[column].max()) * scale == res.indicators[key]


@pytest.mark.slow
def test_simulate_without_an_output_file_imports_no_xarray():
    import subprocess
    import sys

    code = ("import sys\nfrom labtool.cli import main\n"
            "assert main(['simulate', '--model', 'elastic', '--accuracy', 'fast', '--json']) == 0\n"
            "print(sorted(m for m in ('xarray', 'dask') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "[]"
