"""measured.nc, streamed: the per-sample outputs chunk by chunk, then the small ones, CF-1.10.

Written with h5netcdf's public API only (variables created with their CF attributes, filled by
slices). Layout (docs/processing.md): per-sample variables on ``time``; spectra on ``frequency``;
cycle statistics on ``phi1_grid``; segments, spikes and revolution marks on their own dimensions,
each with a coordinate variable.
"""
from __future__ import annotations

import h5netcdf
import h5py
import numpy as np

from labtool.common import cf

TIME_VARS = {
    # name: (dtype, units, long_name)
    "aE_t": ("f4", "m/s^2", "tangential acceleration of E, + along increasing psi (filtered, gravity and offset removed)"),
    "aE_n": ("f4", "m/s^2", "normal acceleration of E, + towards D (filtered, gravity and offset removed)"),
    "epsilon2": ("f4", "rad/s^2", "follower angular acceleration, aE_t / DE"),
    "omega2": ("f4", "rad/s", "follower angular velocity, integral of epsilon2 with dwell drift control"),
    "phi1": ("f4", "rad", "cam angle from the start of the rise"),
    "revolution": ("i4", "1", "cam revolution index (-1 before the first revolution mark of a segment)"),
    "clipped": ("i1", "1", "1 where a sample is clipped (kept out of the estimates)"),
}
FLOAT_OUT = ("aE_t", "aE_n", "epsilon2", "omega2", "phi1")
STRING = h5py.string_dtype()
# HDF5 chunk of the per-sample variables: as long as a processing chunk, so a block write fills whole
# chunks (measured: 2^16-sample chunks cost 6x more CPU per written sample than 2^17 without a cache)
CHUNK = 1 << 17


class CoreBlock:
    """Reused buffers of one block of per-sample outputs, in the file's dtypes (kernels.core_outputs
    fills them): ``floats`` (5, n) float32 in FLOAT_OUT's order, revolution, clipped, time."""

    def __init__(self, n: int):
        self.floats = np.empty((len(FLOAT_OUT), n), dtype=np.float32)
        self.revolution = np.empty(n, dtype=np.int32)
        self.clipped = np.empty(n, dtype=np.int8)
        self.time = np.empty(n, dtype=np.float64)

    def unusable(self, m: int) -> None:
        """The first m samples as a segment with no cam angle: NaN, revolution -1 (time, clipped kept)."""
        self.floats[:, :m] = np.nan
        self.revolution[:m] = -1

    def arrays(self, m: int) -> dict:
        out = {name: self.floats[j, :m] for j, name in enumerate(FLOAT_OUT)}
        out.update(revolution=self.revolution[:m], clipped=self.clipped[:m], time=self.time[:m])
        return out


class MeasuredWriter:
    """Write ``n`` samples starting at ``start_time_utc`` (ISO 8601, may be '') to ``path``.

    The file's NetCDF structure (dimensions, variables, attributes) is made with h5netcdf; the
    per-sample data are streamed into those variables' HDF5 datasets with h5py (the same file
    reopened, public API of both), because h5netcdf looks every variable up again on each slice
    write (a quarter of the writing time); the small outputs are added with h5netcdf at the end.
    """

    def __init__(self, path, n: int, start_time_utc: str):
        self.path = path
        self.f = h5netcdf.File(path, "w")
        self.f.dimensions["time"] = n
        self.chunk = max(1, min(n, CHUNK))
        self.absolute = cf.time_units(start_time_utc) != "s"
        long_name = "time of the sample (the samples lost at gaps are counted)"
        self._new("time", ("time",), "f8", cf.time_attrs(start_time_utc, long_name))
        for name, (dt, units, long_name) in TIME_VARS.items():
            self._new(name, ("time",), dt, cf.variable_attrs(name, units, long_name))
        self.f.close()
        # no chunk cache: every chunk is written once, whole (a cache of 1 MB per variable only
        # holds memory)
        self.h5 = h5py.File(path, "r+", rdcc_nbytes=0)
        self.v = {name: self.h5[name] for name in ("time", *TIME_VARS)}
        self.f = None

    def _small(self):
        """Switch from streaming (h5py) to the small outputs (h5netcdf, append mode)."""
        if self.f is None:
            self.h5.close()
            self.f = h5netcdf.File(self.path, "a")

    def _new(self, name, dims, dtype, attrs, data=None):
        chunks = (self.chunk,) if dims == ("time",) else None
        v = self.f.create_variable(name, dims, dtype, chunks=chunks, data=data)
        v.attrs.update(attrs)
        return v

    def write_block(self, a: int, b: int, data: dict) -> None:
        """Samples [a, b) of every per-sample variable: ``data[name]`` of the file's dtype
        (CoreBlock.arrays). A block that is exactly one HDF5 chunk (the default chunking) goes in
        as that chunk's bytes (H5Dwrite_chunk: no selection, no conversion, no copy in HDF5; the
        datasets have no filters); any other through h5py's slicing."""
        whole = a % self.chunk == 0 and b - a == self.chunk
        for name, ds in self.v.items():
            x = data[name]
            if whole:
                ds.id.write_direct_chunk((a,), np.ascontiguousarray(x))
            else:
                ds[a:b] = x

    def dimension(self, name: str, coord, units: str, long_name: str) -> None:
        """A dimension with its coordinate variable."""
        self._small()
        coord = np.asarray(coord)
        self.f.dimensions[name] = len(coord)
        self._new(name, (name,), coord.dtype if len(coord) else "i8", cf.variable_attrs(name, units, long_name),
                  data=coord if len(coord) else None)

    def variable(self, name: str, dim: str, data, units: str, long_name: str) -> None:
        self._small()
        data = np.asarray(data)
        if data.dtype.kind in "US":
            attrs = {"long_name": long_name}
            v = self._new(name, (dim,), STRING, attrs)
            if len(data):
                v[:] = data.astype(object)
            return
        self._new(name, (dim,), data.dtype, cf.variable_attrs(name, units, long_name), data=data if len(data) else None)

    def close(self, attrs: dict) -> None:
        self._small()
        self.f.attrs.update(attrs)
        self.f.close()

    def abort(self) -> None:
        (self.h5 if self.f is None else self.f).close()
