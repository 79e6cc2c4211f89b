"""``labtool export``: labtool's results as files for other tools.

``--format csv,netcdf,mat``: the curves on the cam-angle grid (labtool.reports.curves), one file per
format, ``<prefix>_curves.<ext>``: of a measured.nc (the measured mean, standard deviation and every
whole revolution, read as the report reads them), a simulation (``labtool simulate -o``: its cycle),
a report's ``_curves.nc``, or a campaign folder (every finished point: the measured revolutions and
each model, ``<prefix>_<point>_curves.<ext>``).

``--csv`` (a measured.nc): two tables next to ``--output`` (default: the input's name):
``<stem>_cycles.csv``, the cycle statistics ``labtool process`` wrote on its cam-angle grid (phi1 in
rad and deg, means and standard deviations over the revolutions, the ideal kinematics), and
``<stem>_series.csv``, the per-sample time series (time in s from the first sample, then aE_t, aE_n,
epsilon2, omega2, phi1, revolution, clipped). Column names carry the units (``omega2 [rad/s]``).
Written with pandas, in chunks (bounded memory), each file atomically; all or none.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import List, Optional

import typer

SERIES = ("aE_t", "aE_n", "epsilon2", "omega2", "phi1", "revolution", "clipped")
CHUNK = 1 << 18


def register(app: typer.Typer) -> None:
    app.command("export")(export)


def export(
    measured: Path = typer.Argument(..., help="measured.nc ('labtool process'), a simulation .nc ('labtool simulate "
                                    "-o'), a report's _curves.nc, or a campaign folder (--format)"),
    csv: bool = typer.Option(False, "--csv", help="a measured.nc's cycle statistics and time series as CSV tables"),
    formats: Optional[List[str]] = typer.Option(None, "--format", help="the curves on the cam-angle grid, one file "
                                                "per format: csv, netcdf, mat (comma-separated or repeated); omega2 "
                                                "in rad/s, epsilon2 in rad/s², phi1 in deg and rad"),
    output: Optional[Path] = typer.Option(None, "-o", "--output",
                                          help="path prefix of the files (default: the input without .nc)"),
    series: bool = typer.Option(True, help="with --csv, also the per-sample time series (large for long recordings)"),
    grid: int = typer.Option(720, help="--format: cam-angle grid points per revolution [-] (the report's)"),
    harmonics: int = typer.Option(60, help="--format: low-pass, harmonics of the cam frequency kept [-] (the report's)"),
    force: bool = typer.Option(False, help="overwrite existing files"),
) -> None:
    """Curves on the cam-angle grid (CSV, NetCDF, MATLAB) and a measured file's tables as CSV."""
    from labtool.common.errors import InputError
    from labtool.common.files import check_output_path

    if formats:
        _export_curves(measured, formats, output, grid, harmonics, force)
        if not csv:
            return
    if not csv:
        raise InputError("say what to export: --format csv,netcdf,mat (the curves) or --csv (a measured file's tables)")
    prefix = _prefix(output, measured)
    targets = {"cycles": Path(f"{prefix}_cycles.csv"), "series": Path(f"{prefix}_series.csv")}
    if not series:
        del targets["series"]
    for p in targets.values():
        check_output_path(p, force)
    ds = _open(measured)
    try:
        written = _write_all(ds, targets)
    finally:
        ds.close()
    for name, (path, rows) in written.items():
        typer.echo(f"wrote {path}: {rows} rows ({name})")


def _export_curves(source: Path, formats, output, grid: int, harmonics: int, force: bool) -> None:
    """Write the curves of ``source`` in each format, all files as one set (labtool.reports.curves)."""
    from labtool.common.files import OutputSet, check_outputs
    from labtool.reports.align import Conditioning
    from labtool.reports.curves import check_formats, curve_paths, write_curves

    fmts = check_formats(formats)
    cond = Conditioning(n_grid=grid, n_harmonics=harmonics)
    if source.is_dir() and (source / "points").is_dir():
        from labtool.campaign.export import campaign_curves
        sets = campaign_curves(source)
        base = _prefix(output, source) if output is not None else str(source).rstrip("/")
        planned = [(curve_paths(f"{base}_{name}", fmts), ds) for name, ds in sets]
    else:
        from labtool.reports.export import curves_of
        planned = [(curve_paths(_prefix(output, source), fmts), ds) for _, ds in curves_of(source, cond)]
    check_outputs({f"{p}": p for paths, _ in planned for p in paths.values()}, force)
    with OutputSet(kept="the input is untouched") as out:
        for paths, ds in planned:
            write_curves(ds, paths, out)
    for paths, ds in planned:
        n_curves = sum(1 for v in ds.data_vars.values() if v.dims[-1:] == ("phi1",)) - 1
        for p in paths.values():
            typer.echo(f"wrote {p}: {ds.sizes['phi1']} grid points, {n_curves} curves")


def _prefix(output, measured: Path) -> str:
    """The path prefix of the tables: -o as given (the input without .nc by default). An empty
    -o or a folder is refused: Path("") became "." (hidden ._cycles.csv files) and "out/" lost its
    slash (out_cycles.csv beside the folder)."""
    from labtool.common.errors import InputError
    from labtool.common.names import shown

    if output is None:
        return str(measured.with_suffix(""))
    text = os.fspath(output)
    if not text.strip() or text.endswith(os.sep) or Path(text).is_dir():
        raise InputError(f"-o {shown(text)!r} is {'a folder' if text.strip() else 'empty'}: give a path prefix of the "
                         "tables, e.g. -o out/run1 for out/run1_cycles.csv and out/run1_series.csv")
    return text


def _open(path: Path):
    """The measured dataset, its variables checked for what export needs (numbers, not text)."""
    import xarray as xr

    from labtool.common.errors import FileFormatError, InputError
    from labtool.common.hdf5 import check_superblock

    if not path.is_file():
        raise InputError(f"{path} does not exist (give the measured.nc that 'labtool process' wrote)")
    check_superblock(path)  # a cut file must not hang h5py
    try:
        ds = xr.open_dataset(path, engine="h5netcdf", decode_times=False)
    except Exception as exc:  # xarray/h5netcdf raise many kinds on foreign files
        raise FileFormatError(f"{path}: not a NetCDF file from 'labtool process': {type(exc).__name__}: {exc}") from None
    need = ("phi1_grid", "omega2_mean", "time", *SERIES)
    missing = [v for v in need if v not in ds.variables]
    if missing:
        ds.close()
        raise FileFormatError(f"{path}: not a measured file from 'labtool process' (missing {', '.join(missing)})")
    from labtool.common.cf import in_seconds
    from labtool.common.names import shown
    if not in_seconds(ds["time"].attrs.get("units")):
        ds.close()
        raise FileFormatError(f"{path}: its time is in '{shown(str(ds['time'].attrs['units']))}', export writes 'time [s]' "
                              "(s, or 'seconds since <start>', as 'labtool process' writes it); convert time to s")
    for name in SERIES:
        if ds[name].dims != ("time",):
            ds.close()
            raise FileFormatError(f"{path}: variable '{name}' is over dims {ds[name].dims}, not one value per "
                                  "sample ('time',); the file is damaged or not from 'labtool process'")
    for name in ds.variables:
        if name in need or name.endswith(("_mean", "_std", "_kinematic")):
            if ds[name].dtype.kind not in "fiub":
                ds.close()
                raise FileFormatError(f"{path}: variable '{name}' holds {ds[name].dtype} values, not numbers; "
                                      "the file is damaged or not from 'labtool process'")
    return ds


def _label(ds, name: str) -> str:
    units = ds[name].attrs.get("units", "")
    return f"{name} [{units}]" if units and not str(units).startswith("seconds since") else name


def _write_all(ds, targets: dict) -> dict:
    """Write every table as one OutputSet (both or neither, with the user's umask; a full disk is
    one line saying nothing was exported)."""
    from labtool.common.files import OutputSet

    out = {}
    with OutputSet(kept="the measured file is untouched") as outputs:
        for name, path in targets.items():
            write = _cycles if name == "cycles" else _series
            out[name] = (path, outputs.write(path, lambda tmp, write=write: write(ds, tmp), "-o"))
    return out


def _cycles(ds, path: Path) -> int:
    import numpy as np
    import pandas as pd

    grid = ds["phi1_grid"].values
    cols = {"phi1 [rad]": grid, "phi1 [deg]": np.degrees(grid)}
    for name in ds.data_vars:
        if ds[name].dims == ("phi1_grid",):
            cols[_label(ds, name)] = ds[name].values
    pd.DataFrame(cols).to_csv(path, index=False, float_format="%.9g")
    return len(grid)


def _series(ds, path: Path) -> int:
    import pandas as pd

    n = ds.sizes["time"]
    t = ds["time"]
    t0 = float(t[0]) if n else 0.0
    for a in range(0, max(n, 1), CHUNK):
        b = min(a + CHUNK, n)
        cols = {"time [s]": t[a:b].values - t0}
        for name in SERIES:
            cols[_label(ds, name)] = ds[name][a:b].values
        pd.DataFrame(cols).to_csv(path, mode="w" if a == 0 else "a", header=a == 0, index=False, float_format="%.9g")
    return n
