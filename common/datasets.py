"""One xarray Dataset from numpy columns, assembled once.

``xr.Dataset(data_vars=..., coords=...)`` merges and aligns its arguments variable by variable:
for a model's 20-30 columns on one time axis that is ~1 ms a run (more than the elastic
model's whole integration loop). The models' columns need none of it: each is a numpy array on
dimensions whose sizes are known, and the only index is the dimension coordinate. ``dataset``
checks exactly that (one size per dimension, numpy data, 1-D dimension coordinates) and then
assembles the Dataset directly, with the same variables, index, attributes and dtypes as the
public constructor gives (``tests/test_datasets.py`` compares them with ``xr.testing.
assert_identical`` and the index itself). Where xarray lacks the direct constructor (a release
that renamed it), the public constructor is used: slower, the same Dataset.
"""
from __future__ import annotations

import numpy as np


def dataset(data_vars: dict, coords: dict, attrs: dict | None = None):
    """``xr.Dataset(data_vars=data_vars, coords=coords, attrs=attrs)`` for numpy columns.

    ``data_vars``: name -> (dims, values, attrs), dims a name or a tuple of names; ``coords``:
    name -> (name, values, attrs), 1-D dimension coordinates only (each becomes the dimension's
    index). Values are taken as numpy arrays (``np.asarray``, not copied; a masked array as the
    public constructor takes it). A dimension with two sizes, or a coordinate that is not a
    dimension coordinate, raises ValueError, as the public constructor does."""
    import xarray as xr

    direct = getattr(xr.Dataset, "_construct_direct", None)
    if direct is None:                                       # pragma: no cover (older/newer xarray)
        return xr.Dataset(data_vars=data_vars, coords=coords, attrs=attrs)
    from xarray.core.indexes import PandasIndex
    import pandas as pd

    sizes: dict = {}
    variables: dict = {}
    indexes: dict = {}

    def add(name, dims, values, var_attrs):
        dims = (dims,) if isinstance(dims, str) else tuple(dims)
        if not isinstance(values, np.ma.MaskedArray):     # its mask is the public path's to fill
            values = np.asarray(values)
        if values.ndim != len(dims):
            raise ValueError(f"variable {name!r}: {values.ndim}-D values on dimensions {dims}")
        for dim, n in zip(dims, values.shape):
            if sizes.setdefault(dim, n) != n:
                raise ValueError(f"conflicting sizes for dimension {dim!r}: {sizes[dim]} and {n} ({name!r})")
        return dims, values, dict(var_attrs or {})

    coord_variables: dict = {}
    for name, spec in coords.items():
        dims, values, var_attrs = add(name, *spec)
        if dims != (name,):
            raise ValueError(f"coordinate {name!r} must be a 1-D dimension coordinate, got dimensions {dims}")
        index = PandasIndex(pd.Index(values, name=name), name)
        coord_variables.update(index.create_variables({name: xr.Variable(dims, values, var_attrs)}))
        indexes[name] = index
    for name, spec in data_vars.items():
        if name in coord_variables:
            raise ValueError(f"{name!r} is both a coordinate and a data variable")
        dims, values, var_attrs = add(name, *spec)
        # numbers and booleans need none of the public path's conversions (masked arrays, dates,
        # objects); anything else takes it
        variables[name] = xr.Variable(dims, values, var_attrs, fastpath=type(values) is np.ndarray and values.dtype.kind in "biufc")
    variables.update(coord_variables)                # the public constructor's order: data, then coordinates
    dims = {}
    for var in variables.values():                   # and its order of the dimensions: as first met
        for dim in var.dims:
            dims.setdefault(dim, sizes[dim])
    return direct(variables, set(coords), dims, dict(attrs or {}), indexes)
