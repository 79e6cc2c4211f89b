"""Compare two measured.nc files (or a measured.nc with a stored reference) variable by variable.

Used by tests/test_proc_reference.py (the output against the one of the version before a change)
and benchmarks/bench_process.py (labtool's output against main's on the 1-hour recording). Files are
read with h5py, a variable at a time in slices, so an hour of output is compared in bounded memory.

Equal means: the same variables with the same shapes, integer and text variables identical, NaN at
the same samples, and every float within ``rtol`` of the variable's largest magnitude (float32
resolution is 6e-8: reordered float64 arithmetic passes, a changed sample does not); the same
global attributes (numbers within ``rtol``), the processing history equal but for the source path
(numbers in it within ``rtol``).
"""
from __future__ import annotations

import json
import math

import h5py
import numpy as np

# HDF5/netCDF bookkeeping, not content
INTERNAL = {"DIMENSION_LIST", "REFERENCE_LIST", "CLASS", "NAME", "_Netcdf4Dimid", "_Netcdf4Coordinates",
            "_NCProperties"}
# where the file was read from: differs between a test's temporary copy and the reference
PATH_ATTRS = {"source_file", "history"}
SLICE = 1 << 20


def _datasets(f: h5py.File) -> dict[str, h5py.Dataset]:
    out = {}
    f.visititems(lambda name, obj: out.__setitem__(name, obj) if isinstance(obj, h5py.Dataset) else None)
    return out


def _history(text) -> list:
    steps = json.loads(text if isinstance(text, str) else bytes(text).decode())
    for s in steps:
        s.get("parameters", {}).pop("source", None)
    return steps


def _same_json(a, b, rtol: float) -> bool:
    """Equal structures, numbers within rtol (a history records computed values too)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same_json(a[k], b[k], rtol) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same_json(x, y, rtol) for x, y in zip(a, b))
    if isinstance(a, float) and isinstance(b, (int, float)) and not isinstance(b, bool):
        return math.isclose(a, b, rel_tol=rtol) or (math.isnan(a) and math.isnan(b))
    return a == b


def _same_attr(a, b, rtol: float) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    if a.dtype.kind in "fc" or b.dtype.kind in "fc":
        if a.shape != b.shape:
            return False
        both_nan = np.isnan(a) & np.isnan(b)
        return bool(np.all(both_nan | np.isclose(a, b, rtol=rtol, atol=0.0)))
    return a.tolist() == b.tolist()


def _compare_variable(x: h5py.Dataset, y: h5py.Dataset, rtol: float) -> str | None:
    if x.shape != y.shape:
        return f"shape {y.shape} != {x.shape}"
    if x.dtype.kind != y.dtype.kind:
        return f"dtype {y.dtype} != {x.dtype}"
    n = x.shape[0] if x.ndim else 1
    if x.dtype.kind in "OSU" or x.ndim == 0:
        return None if np.array_equal(x[()], y[()]) else "text/scalar values differ"
    peak, worst, first_bad = 0.0, 0.0, None
    for a in range(0, n, SLICE):
        u, v = x[a:a + SLICE], y[a:a + SLICE]
        if u.dtype.kind in "iub":
            if not np.array_equal(u, v):
                k = int(np.flatnonzero(u != v)[0])
                return f"integer values differ first at index {a + k}: {v[k]} != {u[k]}"
            continue
        u, v = u.astype(np.float64), v.astype(np.float64)
        nu, nv = np.isnan(u), np.isnan(v)
        if not np.array_equal(nu, nv):
            k = int(np.flatnonzero(nu != nv)[0])
            return f"NaN at other samples, first at index {a + k}: {v[k]} vs reference {u[k]}"
        ok = ~nu
        if ok.any():
            peak = max(peak, float(np.abs(u[ok]).max()))
            d = np.abs(u[ok] - v[ok])
            if d.max() > worst:
                worst = float(d.max())
                first_bad = a + int(np.flatnonzero(ok)[np.argmax(d)])
    if worst > rtol * peak:
        return f"largest difference {worst:.3g} (at index {first_bad}) > {rtol:g} x peak {peak:.3g}"
    return None


def compare_measured(reference, candidate, rtol: float = 1e-6) -> tuple[list[str], dict[str, float]]:
    """(problems, largest difference relative to the variable's peak per float variable)."""
    problems, rel = [], {}
    with h5py.File(reference, "r") as fr, h5py.File(candidate, "r") as fc:
        dr, dc = _datasets(fr), _datasets(fc)
        for name in sorted(set(dr) ^ set(dc)):
            problems.append(f"{name}: only in the {'reference' if name in dr else 'candidate'}")
        for name in sorted(set(dr) & set(dc)):
            msg = _compare_variable(dr[name], dc[name], rtol)
            if msg:
                problems.append(f"{name}: {msg}")
            elif dr[name].dtype.kind == "f" and dr[name].size:
                rel[name] = _largest_relative(dr[name], dc[name])
        ar = {k: v for k, v in fr.attrs.items() if k not in INTERNAL | PATH_ATTRS}
        ac = {k: v for k, v in fc.attrs.items() if k not in INTERNAL | PATH_ATTRS}
        for k in sorted(set(ar) ^ set(ac)):
            problems.append(f"attribute {k}: only in the {'reference' if k in ar else 'candidate'}")
        for k in sorted(set(ar) & set(ac)):
            if k == "processing_history":
                if not _same_json(_history(ar[k]), _history(ac[k]), rtol):
                    problems.append("processing_history differs (beyond the source path)")
            elif not _same_attr(ar[k], ac[k], rtol):
                problems.append(f"attribute {k}: {ac[k]!r} != {ar[k]!r}")
    return problems, rel


def _largest_relative(x: h5py.Dataset, y: h5py.Dataset) -> float:
    peak, worst = 0.0, 0.0
    for a in range(0, x.shape[0] if x.ndim else 1, SLICE):
        u, v = x[a:a + SLICE].astype(np.float64), y[a:a + SLICE].astype(np.float64)
        ok = np.isfinite(u) & np.isfinite(v)
        if ok.any():
            peak = max(peak, float(np.abs(u[ok]).max()))
            worst = max(worst, float(np.abs(u[ok] - v[ok]).max()))
    return worst / peak if peak > 0 else (0.0 if worst == 0 else math.inf)


def store_reference(measured, path) -> None:
    """Copy a measured.nc's variables and attributes into a compressed HDF5 file (a test reference)."""
    with h5py.File(measured, "r") as src, h5py.File(path, "w") as dst:
        for name, d in _datasets(src).items():
            data = d[()]
            kw = dict(compression="gzip", compression_opts=9, shuffle=True) if d.size > 64 and d.dtype.kind != "O" else {}
            out = dst.create_dataset(name, data=data, dtype=d.dtype, **kw)
            out.attrs.update({k: v for k, v in d.attrs.items() if k not in INTERNAL})
        dst.attrs.update({k: v for k, v in src.attrs.items() if k not in INTERNAL})
