"""Hostile disks: a real full tmpfs and a read-only mount, labtool in a child process
(HDF5 itself can segfault there). Each command ends with one line saying what was kept, and leaves
no output, no truncated file under a final name and no temporary behind."""
from __future__ import annotations

import contextlib
import os
import subprocess

import pytest

from hostile import REFERENCE, REPORT_FAST, SAMPLE, hidden, measured_nc, one_error_line, run  # noqa: F401

# real child processes, tmpfs mounts and kills: seconds each (make test runs them)
pytestmark = pytest.mark.slow


def _listing(folder):
    return sorted(p.name for p in folder.iterdir() if p.name != "fill")


def _fill_up(disk):
    """Write zeros into ``disk/fill`` until the file system is full."""
    fd = os.open(disk / "fill", os.O_WRONLY | os.O_CREAT)
    try:
        with contextlib.suppress(OSError):
            while True:
                os.write(fd, b"\0" * 4096)
    finally:
        os.close(fd)


@pytest.fixture
def read_only_disk(small_disk):
    """A small tmpfs holding ``old.txt``, remounted read-only."""
    disk = small_disk(512)
    (disk / "old.txt").write_text("kept")
    proc = subprocess.run(["mount", "-o", "remount,ro", str(disk)], capture_output=True, text=True)
    if proc.returncode != 0:
        pytest.skip(f"cannot remount read-only: {proc.stderr.strip()}")
    yield disk
    with contextlib.suppress(Exception):
        subprocess.run(["mount", "-o", "remount,rw", str(disk)], capture_output=True)


CASES = {
    "report": lambda d, m: ["report", m, "-o", d / "r.html", "--pdf", d / "r.pdf", "--json", d / "r.json", *REPORT_FAST],
    "kinematics": lambda d, m: ["kinematics", "-o", d / "k.nc", "--groove-csv", d / "g.csv"],
    "simulate": lambda d, m: ["simulate", "--model", "rigid", "--full-cycle", "--revolutions", "2", "-o", d / "s.nc"],
    "doe analyze --plot": lambda d, m: ["doe", "analyze", REFERENCE / "table2_rigid.csv", "--plot", d / "p.png"],
    "calibrate": lambda d, m: ["calibrate", SAMPLE / "calibration_79p6Hz.h5", "-o", d / "c.toml"],
    "demo": lambda d, m: ["demo", "-o", d / "demo"],
}


@pytest.mark.hostile("full_disk")
@pytest.mark.parametrize("name", list(CASES))
def test_a_full_disk_is_one_line_and_leaves_nothing(small_disk, measured_nc, name):
    disk = small_disk(256)
    (disk / "old.txt").write_text("kept")
    if name == "calibrate":      # a calibration is 600 bytes: leave no room at all
        _fill_up(disk)
    code, err = run(CASES[name](disk, measured_nc))
    msg = one_error_line(code, err)
    assert "no space left on device" in msg and ("nothing was written" in msg or "was written" in msg), msg
    assert _listing(disk) == ["old.txt"] and (disk / "old.txt").read_text() == "kept"


@pytest.mark.hostile("full_disk")
def test_a_disk_that_fills_while_a_library_writes(small_disk):
    """200 kB free: matplotlib's PNG writer (zlib) meets ENOSPC mid-file; the plot must not stay."""
    disk = small_disk(1024)
    (disk / "fill").write_bytes(b"\0" * (1024 - 200) * 1024)
    code, err = run(["doe", "analyze", REFERENCE / "table2_rigid.csv", "--plot", disk / "p.png"])
    assert "no space left on device" in one_error_line(code, err)
    assert _listing(disk) == []


@pytest.mark.hostile("full_disk")
@pytest.mark.parametrize("free_kb", [200, 600])
def test_process_with_little_space_left(small_disk, free_kb):
    """process segfaulted with 200 kB free (HDF5 meeting ENOSPC in its metadata flush)."""
    disk = small_disk(2048)
    (disk / "fill").write_bytes(b"\0" * (2048 - free_kb) * 1024)
    code, err = run(["process", SAMPLE / "run_180rpm.h5", "-o", disk / "m.nc"])
    assert "no space left on device" in one_error_line(code, err)
    assert _listing(disk) == []


@pytest.mark.hostile("full_disk")
def test_a_full_disk_keeps_the_files_a_force_would_replace(small_disk, measured_nc):
    disk = small_disk(384)
    for name in ("r.html", "r.json"):
        (disk / name).write_text(f"previous {name}")
    code, err = run(["report", measured_nc, "-o", disk / "r.html", "--json", disk / "r.json", "--force", *REPORT_FAST])
    assert "no space left on device" in one_error_line(code, err)
    assert (disk / "r.html").read_text() == "previous r.html" and (disk / "r.json").read_text() == "previous r.json"
    assert hidden(disk) == []


@pytest.mark.hostile("full_disk")
@pytest.mark.parametrize("name", ["report", "kinematics", "simulate", "demo", "calibrate"])
def test_a_read_only_mount_is_one_line_before_any_work(read_only_disk, measured_nc, name):
    code, err = run(CASES[name](read_only_disk, measured_nc))
    assert "read-only file system" in one_error_line(code, err)
    assert _listing(read_only_disk) == ["old.txt"]
