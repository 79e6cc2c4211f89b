"""The curves a report compares, on one cam-angle grid, as files anyone can replot.

One dataset (``curves_dataset``): the measured omega2 and epsilon2 (cycle average, standard
deviation over the revolutions, and every whole revolution), and each model's cycle (its own
standard deviation when its motion is not periodic), all on the report's grid of cam angle phi1.
Written as (``write_curves``):

- CSV: one row per grid point, a column per curve, measured and each model side by side; plain
  column names that end with their unit (``omega2_measured_mean_rad_s``,
  ``epsilon2_rigid_const_rad_s2``, ``omega2_measured_rev3_rad_s``); a metadata header of lines
  starting with ``#`` (test ID, operator, speeds, the operating point with its sources), which
  ``pandas.read_csv(path, comment="#")`` and a spreadsheet's "skip lines starting with #" leave out;
- CF NetCDF (the same variables without the unit suffix, units in ``units``, the per-revolution
  curves over ``revolution`` x ``phi1``);
- MATLAB .mat (scipy.io.savemat, v5): the same variables and a ``metadata`` struct.

Names: ``<signal>_measured_mean``, ``<signal>_measured_std``, ``<signal>_measured`` (revolution x
phi1), ``<signal>_<model>_<omega1>`` and ``<signal>_<model>_<omega1>_std`` (a model that is not
periodic); ``<model>`` is the model asked for (``rigid``, ``elastic``, ``kinematic``,
``rigid_fitted``), with the level that ran in the variable's ``model`` attribute.
"""
from __future__ import annotations

import datetime as dt
import io
import re
from pathlib import Path

import numpy as np
import xarray as xr

from labtool.processing.cycles import cycle_statistics

SIGNALS = ("omega2", "epsilon2")
UNITS = {"omega2": "rad s-1", "epsilon2": "rad s-2", "phi1": "rad"}
SUFFIX = {"rad s-1": "rad_s", "rad s-2": "rad_s2", "rad": "rad", "degree": "deg"}
LONG = {"omega2": "follower angular velocity omega2", "epsilon2": "follower angular acceleration epsilon2"}
FORMATS = ("csv", "netcdf", "mat")
EXTENSION = {"csv": ".csv", "netcdf": ".nc", "mat": ".mat"}


def slug(text: str) -> str:
    """A plain variable-name piece: lower case letters, digits and single underscores."""
    return re.sub(r"[^a-z0-9]+", "_", str(text).lower()).strip("_") or "x"


def curves_dataset(grid, measured: dict | None = None, revolutions=None, models=(), attrs: dict | None = None) -> xr.Dataset:
    """The curves on one cam-angle grid.

    Parameters
    ----------
    grid : array (n,)
        Cam angle phi1 [rad], 0 at the start of the rise.
    measured : dict, optional
        signal -> array (n_rev, n) of the measured whole revolutions on ``grid`` (SI).
    revolutions : array (n_rev,), optional
        Their revolution numbers (default 0..n_rev-1).
    models : sequence of dict
        Each with ``name`` (the variable-name piece, e.g. ``rigid_const``), ``label``,
        ``model`` (the level that ran), ``omega1``, ``signals`` (signal -> (n,), NaN where not
        simulated) and optionally ``std`` (signal -> (n,)) when its motion is not periodic.
    attrs : dict, optional
        Metadata (test ID, operator, operating point, ...): plain values, stored as global attributes.
    """
    grid = np.asarray(grid, dtype=float)
    ds = xr.Dataset(coords={"phi1": ("phi1", grid, {"units": "rad", "long_name": "cam angle from the start of the rise"})})
    ds["phi1_deg"] = ("phi1", np.degrees(grid), {"units": "degree", "long_name": "cam angle from the start of the rise"})
    if measured:
        n_rev = next(iter(measured.values())).shape[0]
        revs = np.arange(n_rev) if revolutions is None else np.asarray(revolutions, dtype=int)
        ds = ds.assign_coords(revolution=("revolution", revs, {"long_name": "measured cam revolution number"}))
        for s in SIGNALS:
            if s not in measured:
                continue
            m = np.asarray(measured[s], dtype=float)
            stats = cycle_statistics(m)
            ds[f"{s}_measured_mean"] = ("phi1", stats.mean, {"units": UNITS[s],
                                                                "long_name": f"measured {LONG[s]}, cycle average"})
            ds[f"{s}_measured_std"] = ("phi1", stats.std, {"units": UNITS[s], "long_name":
                                                              f"measured {LONG[s]}, standard deviation over the revolutions"})
            ds[f"{s}_measured"] = (("revolution", "phi1"), m, {"units": UNITS[s],
                                                                "long_name": f"measured {LONG[s]}, each whole revolution"})
    seen = set()
    for mod in models:
        name = mod["name"]
        if name in seen:
            continue
        seen.add(name)
        for s in SIGNALS:
            meta = {"units": UNITS[s], "long_name": f"{mod['label']}: predicted {LONG[s]}",
                    "model": str(mod["model"]), "omega1_mode": str(mod["omega1"]), "label": str(mod["label"])}
            ds[f"{s}_{name}"] = ("phi1", np.asarray(mod["signals"][s], dtype=float), meta)
            if mod.get("std") is not None:
                ds[f"{s}_{name}_std"] = ("phi1", np.asarray(mod["std"][s], dtype=float),
                                         dict(meta, long_name=f"{mod['label']}: standard deviation of the predicted "
                                                             f"{LONG[s]} over its steady revolutions"))
    ds.attrs.update({"Conventions": "CF-1.10", "title": "labtool curves on the cam-angle grid"})
    ds.attrs.update({k: plain_attr(v) for k, v in (attrs or {}).items() if v is not None})
    return ds


def plain_attr(v):
    """A value a NetCDF attribute, a CSV header and a .mat struct all hold: number or text."""
    if isinstance(v, (bool, np.bool_)):
        return int(v)
    if isinstance(v, (int, float, np.integer, np.floating)):
        return v.item() if hasattr(v, "item") else v
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    return str(v)


def report_curves(report) -> xr.Dataset:
    """The curves of a report (labtool.reports.pipeline.Report): the measured revolutions it read
    and every simulation it compared, with the run's metadata and operating point."""
    models = []
    for run in report.sims:
        cyc = run.cycle
        sig = {s: np.where(cyc.covered, cyc.signals[s], np.nan) for s in SIGNALS}
        std = None if cyc.periodic else {s: np.where(cyc.covered, cyc.std[s], np.nan) for s in SIGNALS}
        models.append({"name": slug(f"{run.requested} {run.omega1}"), "label": run.label, "model": run.model,
                       "omega1": run.omega1, "signals": sig, "std": std})
    cyc = report.cycles
    return curves_dataset(cyc.grid, {s: cyc.signals[s] for s in SIGNALS}, cyc.revolutions, models,
                          report_metadata(report))


def report_metadata(report) -> dict:
    """The header of a report's curves: the measured file, the run's metadata, the speeds and the
    operating point the models ran at, with where each value came from."""
    from labtool.common import recording_attrs
    from labtool.reports.pipeline import point_rows

    a = report.measured.attrs
    out = {"measured_file": report.measured_path,
           "created_utc": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")}
    for k in recording_attrs.RUN_METADATA + ("start_time_utc",):
        if k in a:
            out[k] = a[k]
    out["cam_speed_rpm_measured"] = float(report.cycles.cam_speed_rpm)
    out["whole_revolutions"] = int(len(report.cycles.revolutions))
    out["conditioning"] = report.conditioning.describe()
    for what, value, source in point_rows(report.scene):
        key = "op_" + slug(what)
        out[key] = value
        if source:
            out[key + "_source"] = source
    if report.verdict is not None and report.verdict.get("sentence"):
        out["verdict"] = report.verdict["sentence"]
    from labtool.models.dynamics.provenance import labtool_version
    out["labtool_version"] = labtool_version()
    return out


# --------------------------------------------------------------------------- writers

def unit_suffix(units: str) -> str:
    return SUFFIX.get(units, slug(units))


def csv_table(ds: xr.Dataset):
    """The CSV's table (pandas DataFrame): phi1 in deg and rad, then every curve; the
    per-revolution matrix as one column per revolution."""
    import pandas as pd

    cols = {"phi1_deg": ds["phi1_deg"].values, "phi1_rad": ds["phi1"].values}
    for name, var in ds.data_vars.items():
        if name == "phi1_deg":
            continue
        unit = unit_suffix(var.attrs.get("units", ""))
        if var.dims == ("phi1",):
            cols[f"{name}_{unit}"] = var.values
        elif var.dims == ("revolution", "phi1"):
            for rev, row in zip(ds["revolution"].values, var.values):
                cols[f"{name}_rev{int(rev)}_{unit}"] = row
    return pd.DataFrame(cols)


def csv_text(ds: xr.Dataset) -> str:
    """The CSV: the metadata header (``# key: value``, one line each, line breaks in values
    replaced) and the table (``.`` decimals, 9 significant digits, empty cells where NaN)."""
    head = ["# labtool curves on the cam-angle grid: one row per grid point, a column per curve",
            "# units are in the column names (rad_s = rad/s, rad_s2 = rad/s^2); read with pandas.read_csv(path, comment='#')"]
    for k, v in ds.attrs.items():
        text = re.sub(r"\s+", " ", str(v)).strip()
        head.append(f"# {k}: {text}")
    buf = io.StringIO()
    csv_table(ds).to_csv(buf, index=False, float_format="%.9g", lineterminator="\n")
    return "\n".join(head) + "\n" + buf.getvalue()


def write_mat(ds: xr.Dataset, path: Path) -> None:
    """MATLAB v5 .mat: every variable (column vectors over phi1; revolution x phi1 matrices),
    ``phi1_rad``, ``revolution`` and a ``metadata`` struct of the attributes."""
    from scipy.io import savemat

    data = {"phi1_rad": ds["phi1"].values.reshape(-1, 1)}
    if "revolution" in ds.coords:
        data["revolution"] = ds["revolution"].values.astype(float).reshape(-1, 1)
    for name, var in ds.data_vars.items():
        v = np.asarray(var.values, dtype=float)
        data[name[:63]] = v.reshape(-1, 1) if v.ndim == 1 else v
    meta = {}
    for k, v in ds.attrs.items():      # a struct's field names: a letter first, at most 31 characters
        key = slug(k)
        key = (key if key[0].isalpha() else "m_" + key)[:31]
        while key in meta:
            key = key[:28] + f"_{len(meta) % 100:02d}"
        meta[key] = str(v)
    data["metadata"] = meta
    savemat(path, data, do_compression=True, oned_as="column")


def curve_paths(prefix: str, formats) -> dict:
    """format -> the file ``<prefix>_curves.<ext>`` for each format asked for."""
    return {f: Path(f"{prefix}_curves{EXTENSION[f]}") for f in formats}


def write_curves(ds: xr.Dataset, paths: dict, out) -> None:
    """Write the curves in each format of ``paths`` (format -> path) into ``out``, an open
    labtool.common.files.OutputSet (all files of the set, or none)."""
    for fmt, path in paths.items():
        if fmt == "csv":
            out.write_text(path, csv_text(ds), "curves")
        elif fmt == "netcdf":
            out.write_netcdf(path, ds, "curves")
        elif fmt == "mat":
            out.write(path, lambda tmp: write_mat(ds, tmp), "curves")


def check_formats(formats) -> tuple:
    """The formats asked for (comma-separated or repeated), checked."""
    from labtool.common.errors import InputError

    got = [f.strip().lower() for item in formats for f in str(item).split(",") if f.strip()]
    bad = [f for f in got if f not in FORMATS]
    if bad:
        raise InputError(f"unknown export format {', '.join(map(repr, bad))}; choose from {', '.join(FORMATS)}")
    return tuple(dict.fromkeys(got))
