"""Truncated and damaged HDF5 files end with one line and exit 2, promptly (main hung for
ever in h5py after the SWMR-mode open of a file cut to its first 100..4096 bytes)."""
from __future__ import annotations

import subprocess
import sys

import h5py
import numpy as np
import pytest

from labtool.common.errors import FileFormatError
from stand_data import stand_recording

BOUND_S = 60  # a hang is what is tested; the bound only keeps the suite from hanging with it


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    p = tmp_path_factory.mktemp("h5") / "rec.h5"
    stand_recording(p, duration_s=1.0)
    return p


def _cli(*args):
    return subprocess.run([sys.executable, "-c", "import sys; from labtool.cli import main; sys.exit(main(sys.argv[1:]))",
                           *map(str, args)], capture_output=True, text=True, timeout=BOUND_S)


@pytest.mark.slow
@pytest.mark.hostile("hang")
@pytest.mark.parametrize("size", [100, 512, 2048, 4096])
def test_process_of_a_cut_recording_ends_with_one_line(recording, tmp_path, size):
    cut = tmp_path / f"cut{size}.h5"
    cut.write_bytes(recording.read_bytes()[:size])
    r = _cli("process", cut, "-o", tmp_path / "m.nc")
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1 and err[0].startswith("labtool: error:"), r.stderr
    assert "truncated" in err[0] and not (tmp_path / "m.nc").exists()


@pytest.mark.hostile("hang")
@pytest.mark.parametrize("libver", ["earliest", "v110"])
def test_superblock_check_on_every_cut(tmp_path, libver):
    """Every prefix of a small file shorter than the whole is refused by the superblock check (or is
    not HDF5 at all), for the old and the SWMR-capable file format."""
    from labtool.common.hdf5 import check_superblock, open_file
    p = tmp_path / "f.h5"
    with h5py.File(p, "w", libver=(libver, "latest")) as f:
        f.attrs["format"] = "labtool.recording"
        f.create_dataset("signals", data=np.zeros((500, 3)), chunks=(100, 3), maxshape=(None, 3))
    data = p.read_bytes()
    assert check_superblock(p)["size"] == len(data)
    q = tmp_path / "cut.h5"
    for size in sorted({1, 7, 8, 9, 40, 47, 48, 95, 96, 100, 512, 2048, 4096, len(data) // 2, len(data) - 1}):
        q.write_bytes(data[:size])
        with pytest.raises(FileFormatError):
            check_superblock(q)
    bad = bytearray(data)
    bad[20] ^= 0xFF  # a flipped bit in the superblock's addresses
    q.write_bytes(bytes(bad))
    with pytest.raises(FileFormatError, match="checksum" if libver == "v110" else "truncated|superblock"):
        open_file(q)


WRITER = r"""
import sys, h5py, numpy as np
f = h5py.File(sys.argv[1], "w", libver="v110")
d = f.create_dataset("signals", data=np.ones((100, 3)), chunks=(50, 3), maxshape=(None, 3))
f.swmr_mode = True
d.resize((200, 3)); d[100:] = 2.0; d.flush()
print("ready", flush=True)
sys.stdin.readline()
f.close()
"""


@pytest.mark.slow
def test_a_file_still_open_by_a_swmr_writer_is_read(tmp_path):
    """What must keep working: a live SWMR writer's file (another process) opens with a note."""
    from labtool.common.hdf5 import open_file
    p = tmp_path / "live.h5"
    w = subprocess.Popen([sys.executable, "-c", WRITER, str(p)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert w.stdout.readline().strip() == "ready"
        g, note = open_file(p)
        with g:
            assert g["signals"].shape == (200, 3) and "SWMR" in note
            assert (g["signals"][100:] == 2.0).all()
    finally:
        w.communicate("\n", timeout=BOUND_S)
