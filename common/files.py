"""Writing result files safely: no silent overwrite, nothing left half-written."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

from common.errors import InputError


def check_output_path(path: Path, force: bool = False) -> None:
    """Refuse an existing file without --force, and a folder that cannot be written."""
    path = Path(path)
    if path.exists() and not force:
        raise InputError(f"{path} already exists; use --force to overwrite it")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"cannot write {path}: folder {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise InputError(f"cannot write {path}: folder {parent} is not writable")


def atomic_write(path: Path, writer) -> None:
    """Call ``writer(tmp_path)`` then rename onto ``path``: a crash leaves no partial file behind."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent or ".")
    os.close(fd)
    try:
        writer(Path(tmp))
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_netcdf(ds, path: Path) -> None:
    """Write an xarray Dataset as NetCDF4 (h5netcdf engine), atomically."""
    def _write(tmp: Path):
        try:
            ds.to_netcdf(tmp, engine="h5netcdf")
        except OSError as exc:
            raise InputError(f"cannot write {path}: {exc}") from None
    atomic_write(Path(path), _write)
