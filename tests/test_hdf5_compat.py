"""Recordings open in HDF5 1.10+ tools: read back with h5py 3.11 built on HDF5 1.14.2.

The venv with the older h5py is built once per machine (pip from the package index) under the
user's cache folder; without a network or a wheel the test is skipped and says why.
"""
import json
import os
import subprocess
import sys
import venv
from pathlib import Path

import numpy as np
import pytest

from labtool.common import recording_format
from labtool.cli import main

OLD_H5PY = "h5py==3.11.*"
CACHE = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "labtool-tests" / "h5py-3.11"

READER = r"""
import json, sys
import h5py, numpy as np
out = {"hdf5": h5py.version.hdf5_version, "h5py": h5py.version.version}
with h5py.File(sys.argv[1], "r", swmr=True) as f:
    def plain(v):
        if isinstance(v, bytes):
            return v.decode()
        if isinstance(v, np.ndarray):
            return [plain(x) for x in v.tolist()]
        if isinstance(v, (np.generic,)):
            return v.item()
        return v
    out["attrs"] = {k: plain(f.attrs[k]) for k in f.attrs}
    out["signal_attrs"] = {k: plain(f["signals"].attrs[k]) for k in f["signals"].attrs}
    ev = f["events"][...]
    out["events"] = [[int(e["index"]), e["kind"].decode(), e["detail"].decode()] for e in ev]
    out["signals"] = f["signals"][...].astype(float).tolist()
print(json.dumps(out, default=str))
"""


def _old_python() -> Path:
    py = CACHE / "bin" / "python"
    if py.exists():
        return py
    try:
        venv.create(CACHE, with_pip=True, clear=True)
        subprocess.run([str(py), "-m", "pip", "install", "-q", OLD_H5PY, "numpy<2"], check=True,
                       capture_output=True, text=True, timeout=600)
    except (subprocess.SubprocessError, OSError) as exc:
        detail = getattr(exc, "stderr", "") or str(exc)
        pytest.skip(f"cannot install {OLD_H5PY} into {CACHE}: {' '.join(str(detail).split())[-300:]}")
    return py


def _nan_eq(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return a.shape == b.shape and np.allclose(a, b, equal_nan=True)


@pytest.mark.slow
def test_a_recording_reads_with_h5py_3_11_on_hdf5_1_14(tmp_path):
    py = _old_python()
    rec_path = tmp_path / "r.h5"
    assert main(["acquire", "--fast", "--duration", "0.3", "--fault", "drop@0.15", "-o", str(rec_path)]) == 0
    # the superblock is version 3 (HDF5 1.10's, what SWMR needs), not a newer one
    assert rec_path.read_bytes()[8] == 3
    proc = subprocess.run([str(py), "-c", READER, str(rec_path)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    old = json.loads(proc.stdout)
    assert old["hdf5"].startswith("1.14")
    new = recording_format.load(rec_path)
    # every root attribute, with its value
    assert set(old["attrs"]) == set(new["attrs"])
    for k, v in new["attrs"].items():
        if isinstance(v, (str, bytes)):
            assert old["attrs"][k] == (v.decode() if isinstance(v, bytes) else v), k
        else:
            assert _nan_eq(old["attrs"][k], v), k
    assert old["attrs"]["sample_rate_hz"] == 10000.0 and old["attrs"]["format"] == "labtool.recording"
    assert old["signal_attrs"]["channel_names"] == ["aE_t", "aE_n", "tacho"]
    assert _nan_eq(old["signal_attrs"]["ka_m_s2_per_v"], new["ka_m_s2_per_v"])
    assert _nan_eq(old["signal_attrs"]["peak_abs_v"], np.max(np.abs(new["signals"]), axis=0))
    # events (with the gap of the dropped block) and every sample
    assert [tuple(e) for e in old["events"]] == new["events"]
    assert any(k == "gap" for _, k, _ in new["events"])
    np.testing.assert_array_equal(np.asarray(old["signals"]), new["signals"])
