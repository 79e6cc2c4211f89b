import contextlib
import os
import shutil
import subprocess
import uuid
from pathlib import Path

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")
# numba's first compilations are announced on stderr (labtool.models.dynamics.compiling); a test that
# checks a command's stderr line by line would see them after each edit of the models (an empty
# cache). tests/test_compiling.py and tests/test_kernel_cache.py turn them on for themselves.
os.environ.setdefault("LABTOOL_COMPILE_NOTICES", "0")
# pytest-xdist's workers start with COLUMNS=80 and LINES=24 (seen with pytest-xdist 3.8, even with
# no conftest), which labtool honours as the user's width: its tables would be cut as in a narrow
# terminal and a test's "[m/s^2/V]" elided. The tests see a pipe, as without -n; one that wants a
# width sets COLUMNS itself.
if os.environ.get("PYTEST_XDIST_WORKER"):
    for _name in ("COLUMNS", "LINES"):
        os.environ.pop(_name, None)

HOSTILE_KINDS = ("hang", "traceback", "full_disk", "concurrency", "silent_wrong", "injection",
                 "interrupted", "real_file")


def pytest_collection_modifyitems(config, items):
    for item in items:
        for mark in item.iter_markers("hostile"):
            kind = mark.args[0] if mark.args else None
            if kind not in HOSTILE_KINDS:
                raise pytest.UsageError(f"{item.nodeid}: hostile kind must be one of {HOSTILE_KINDS}, got {kind!r}")


@pytest.fixture
def small_disk(tmp_path):
    """A real, small filesystem (tmpfs) for full-disk cases: ``small_disk(size_kb) -> Path``.

    Needs root (CI and the dev machines run as root); skipped with the reason otherwise. The mount
    is removed at the end of the test.
    """
    mounts = []

    def make(size_kb: int) -> Path:
        if os.geteuid() != 0 or shutil.which("mount") is None:
            pytest.skip("a full-disk test needs root to mount a tmpfs")
        where = tmp_path / f"disk-{uuid.uuid4().hex[:8]}"
        where.mkdir()
        proc = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={int(size_kb)}k", "tmpfs", str(where)],
                              capture_output=True, text=True)
        if proc.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs here: {proc.stderr.strip()}")
        mounts.append(where)
        return where

    yield make
    for where in mounts:
        with contextlib.suppress(Exception):
            subprocess.run(["umount", "-l", str(where)], capture_output=True)


@pytest.fixture(scope="session")
def original(tmp_path_factory):
    """The simulated stand's recording at 300 rpm, 2 s (tests/stand_data.py), processed once for the
    readers' tests that write it again in other formats: (its volts (n, 3), the omega2 labtool
    makes of the HDF5 original)."""
    import h5py
    import numpy as np
    import xarray as xr

    from labtool.cli import main
    from stand_data import stand_recording

    d = tmp_path_factory.mktemp("orig")
    p = d / "orig.h5"
    stand_recording(p, duration_s=2.0, rpm=300.0)
    assert main(["process", str(p), "-o", str(d / "orig.nc")]) == 0
    with h5py.File(p) as f:
        volts = f["signals"][()].astype(np.float64)
    with xr.open_dataset(d / "orig.nc", engine="h5netcdf", decode_times=False) as ds:
        return volts, ds["omega2"].values
