"""The curves of a file on the cam-angle grid, for ``labtool export --format``
(labtool.reports.curves' layout): a measured file (``labtool process``), a simulation (``labtool
simulate -o``), a report's curves, or a campaign point's cycles.nc (a whole campaign folder:
labtool.campaign.export, one set per point).

``curves_of(path, cond)`` returns ``[("", dataset)]``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr

from labtool.common.errors import FileFormatError, InputError
from labtool.common.names import shown
from labtool.reports.curves import SIGNALS, curves_dataset, plain_attr, slug


def curves_of(path: Path, cond=None) -> list[tuple[str, xr.Dataset]]:
    """The curves of ``path`` (module doc); InputError/FileFormatError for anything else."""
    from labtool.reports.align import Conditioning

    cond = cond or Conditioning()
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{shown(path)} is a folder; give a measured.nc, a simulation .nc or a report's _curves.nc "
                         "(a campaign folder: labtool.campaign.export)")
    if not path.is_file():
        raise InputError(f"{shown(path)} does not exist (give a measured.nc, a simulation .nc, a report's _curves.nc "
                         "or a campaign folder)")
    ds = _open(path)
    try:
        return [("", _file_curves(ds, path, cond))]
    finally:
        ds.close()


def _open(path: Path) -> xr.Dataset:
    import warnings

    from labtool.common.hdf5 import check_superblock
    from labtool.processing.readers import recording_kind

    raw = recording_kind(path)
    if raw:
        raise InputError(f"{shown(path)} is a {raw}, not a processed file: run 'labtool process {shown(path)} "
                         "-o measured.nc' first and export measured.nc")
    check_superblock(path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return xr.open_dataset(path, engine="h5netcdf", decode_times=False)
    except Exception as exc:    # h5py/xarray raise many types for a file that is not NetCDF4
        raise FileFormatError(f"{shown(path)} is not a NetCDF4 file from labtool ({type(exc).__name__})") from None


def _file_curves(ds: xr.Dataset, path: Path, cond) -> xr.Dataset:
    if "phi1_deg" in ds.variables and str(ds.attrs.get("title", "")).startswith("labtool curves"):
        return ds.load()            # already curves (a report's _curves.nc)
    if "measured_omega2_mean" in ds.variables and "phi1" in ds.coords:
        return point_curves(ds.load(), {"source_file": shown(str(path))})
    if "phi1" in ds.variables and all(s in ds.variables for s in SIGNALS):
        if "time" in ds.dims and ("phi1_grid" in ds.dims or "revolution_start_time" in ds.variables) and "model" not in ds.attrs:
            return measured_curves(path, cond)
        if "model" in ds.attrs:
            return simulation_curves(ds.load(), path, cond)
    raise FileFormatError(f"{shown(path)} holds no curves labtool can export: expected a measured.nc ('labtool "
                          "process'), a simulation ('labtool simulate -o'), a report's _curves.nc or a campaign point's "
                          "cycles.nc (omega2, epsilon2 and the cam angle phi1)")


def measured_curves(path: Path, cond) -> xr.Dataset:
    """The measured revolutions of a measured.nc, read and conditioned as the report reads them."""
    from labtool.common import recording_attrs
    from labtool.reports import align
    from labtool.reports.pipeline import SIGNALS as REPORT_SIGNALS, load_measured

    ds = load_measured(path)
    try:
        cyc = align.read_measured(ds, REPORT_SIGNALS, cond)
        a = ds.attrs
        meta = {"measured_file": shown(str(path)), "cam_speed_rpm_measured": float(cyc.cam_speed_rpm),
                "whole_revolutions": int(len(cyc.revolutions)), "conditioning": cond.describe()}
        for k in recording_attrs.carried() + ("start_time_utc",):
            if k in a:
                meta[k] = a[k]
        return curves_dataset(cyc.grid, {s: cyc.signals[s] for s in REPORT_SIGNALS}, cyc.revolutions, (), meta)
    finally:
        ds.close()


def simulation_curves(ds: xr.Dataset, path: Path, cond) -> xr.Dataset:
    """A simulation's cycle on the grid (its steady revolution, or its revolutions' statistics);
    a run of part of a revolution (the rise only) is NaN where it did not reach."""
    from labtool.reports import align

    model = str(ds.attrs.get("model", "model"))
    mode = str(ds.attrs.get("omega1_mode", "const"))
    rigid = model == "rigid"
    cyc = align.simulated_cycles(ds, SIGNALS, cond, epsilon2_from_omega2=rigid)
    if cyc is None:
        cyc = align.simulated_cycle(ds, SIGNALS, cond, epsilon2_from_omega2=rigid)
    sig = {s: np.where(cyc.covered, cyc.signals[s], np.nan) for s in SIGNALS}
    std = None if cyc.periodic else {s: np.where(cyc.covered, cyc.std[s], np.nan) for s in SIGNALS}
    label = f"{model}, w1 = {'ct.' if mode == 'const' else 'var.'}"
    meta = {"simulation_file": shown(str(path)), "note": cyc.note, "conditioning": cond.describe()}
    meta.update({k: v for k, v in ds.attrs.items() if k not in ("Conventions", "title", "history")})
    return curves_dataset(cyc.grid, None, None, [{"name": slug(f"{model} {mode}"), "label": label, "model": model,
                                                   "omega1": mode, "signals": sig, "std": std}], meta)


def point_curves(cycles: xr.Dataset, meta: dict | None = None) -> xr.Dataset:
    """A campaign point's cycles.nc (labtool.campaign.steps.cycles_dataset) as curves."""
    grid = np.asarray(cycles["phi1"].values, dtype=float)
    measured, revs = None, None
    if all(f"measured_{s}_revolutions" in cycles for s in SIGNALS):
        measured = {s: np.asarray(cycles[f"measured_{s}_revolutions"].values, dtype=float) for s in SIGNALS}
        revs = cycles["revolution"].values if "revolution" in cycles.coords else None
    models = []
    for k in range(cycles.sizes.get("sim", 0)):
        req, mode = str(cycles["sim_requested"].values[k]), str(cycles["sim_omega1"].values[k])
        models.append({"name": slug(f"{req} {mode}"), "label": str(cycles["sim_label"].values[k]),
                       "model": str(cycles["sim_model"].values[k]) if "sim_model" in cycles else req, "omega1": mode,
                       "signals": {s: np.asarray(cycles[f"sim_{s}"].values[k], dtype=float) for s in SIGNALS}})
    out = curves_dataset(grid, measured, revs, models, {**{k: plain_attr(v) for k, v in cycles.attrs.items()
                                                          if k != "title"}, **(meta or {})})
    if measured is None:     # a point made before the revolutions were kept: its mean and scatter
        for s in SIGNALS:
            out[f"{s}_measured_mean"] = ("phi1", np.asarray(cycles[f"measured_{s}_mean"].values, dtype=float),
                                         dict(cycles[f"measured_{s}_mean"].attrs, units=_cf(s)))
            out[f"{s}_measured_std"] = ("phi1", np.asarray(cycles[f"measured_{s}_std"].values, dtype=float),
                                        dict(cycles[f"measured_{s}_std"].attrs, units=_cf(s)))
    return out


def _cf(signal: str) -> str:
    from labtool.reports.curves import UNITS
    return UNITS[signal]
