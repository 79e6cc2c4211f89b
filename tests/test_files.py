"""labtool.common.files: atomic writes with the user's umask, sets of outputs all-or-nothing, disk errors."""
import errno
import os
import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

from labtool.common.errors import InputError, OutputError
from labtool.common.files import (OutputSet, atomic_write, check_output_dir, check_output_path, disk_error,
                          remove_stale_temporaries, write_netcdf, write_text)


def _leftovers(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


@pytest.mark.parametrize("umask", [0o022, 0o002, 0o077])
def test_outputs_follow_the_umask(tmp_path, umask):
    old = os.umask(umask)
    try:
        write_text(tmp_path / "a.txt", "x")
        atomic_write(tmp_path / "b.bin", lambda tmp: tmp.write_bytes(b"y"))
        write_netcdf(xr.Dataset({"v": ("t", np.arange(3.0))}), tmp_path / "c.nc")
    finally:
        os.umask(old)
    for name in ("a.txt", "b.bin", "c.nc"):
        assert (tmp_path / name).stat().st_mode & 0o777 == 0o666 & ~umask, name


def test_a_set_is_written_whole_or_not_at_all(tmp_path):
    (tmp_path / "old.html").write_text("previous")
    with pytest.raises(ZeroDivisionError):
        with OutputSet() as out:
            out.write_text(tmp_path / "old.html", "new")
            out.write_text(tmp_path / "b.json", "{}")
            1 / 0
    assert (tmp_path / "old.html").read_text() == "previous"
    assert not (tmp_path / "b.json").exists()
    assert _leftovers(tmp_path) == []
    with OutputSet() as out:
        out.write_text(tmp_path / "old.html", "new")
        out.write_text(tmp_path / "b.json", "{}")
        assert not (tmp_path / "b.json").exists()     # nothing final before the end of the set
    assert (tmp_path / "old.html").read_text() == "new" and (tmp_path / "b.json").read_text() == "{}"
    assert _leftovers(tmp_path) == []


def test_a_failed_rename_restores_the_files_already_replaced(tmp_path, monkeypatch):
    (tmp_path / "a").write_text("old a")
    (tmp_path / "b").mkdir()                       # the second rename will fail (a folder)
    with pytest.raises(OutputError):
        with OutputSet() as out:
            out.write_text(tmp_path / "a", "new a")
            out.write_text(tmp_path / "b", "new b")
    assert (tmp_path / "a").read_text() == "old a"
    assert _leftovers(tmp_path) == []


def test_two_outputs_with_one_name_are_refused(tmp_path):
    with pytest.raises(InputError, match="-o and --groove-csv name the same file"):
        with OutputSet() as out:
            out.write_text(tmp_path / "x.nc", "a", "-o")
            out.write_text(tmp_path / "sub" / ".." / "x.nc", "b", "--groove-csv")
    assert not (tmp_path / "x.nc").exists()


def test_the_temporary_keeps_the_extension(tmp_path):
    seen = []
    atomic_write(tmp_path / "t.csv.gz", lambda tmp: seen.append(tmp.name) or tmp.write_bytes(b""))
    assert seen[0].startswith(".t.csv.gz.") and seen[0].endswith(".part.csv.gz")


def test_temporaries_of_a_killed_process_are_removed_by_the_next_write(tmp_path):
    code = ("import os, sys; from pathlib import Path; from labtool.common.files import atomic_write\n"
            "atomic_write(Path(sys.argv[1]), lambda tmp: os.kill(os.getpid(), 9))\n")
    proc = subprocess.run([sys.executable, "-c", code, str(tmp_path / "r.nc")])
    assert proc.returncode == -9
    assert len(_leftovers(tmp_path)) == 1          # SIGKILL: nothing can clean up at that moment
    alive = tmp_path / f".r.nc.{_leftovers(tmp_path)[0].split('.')[3].split('-')[0]}-{os.getpid()}-0.part.nc"
    alive.write_bytes(b"")                         # a live process's temporary is left alone
    write_text(tmp_path / "r.nc", "done")
    assert _leftovers(tmp_path) == [alive.name]
    assert (tmp_path / "r.nc").read_text() == "done"
    assert remove_stale_temporaries(tmp_path / "r.nc") == []


def test_check_output_path_refuses_folders_even_with_force(tmp_path):
    with pytest.raises(InputError, match="is a folder"):
        check_output_path(tmp_path, force=True)
    (tmp_path / "f").write_text("")
    with pytest.raises(InputError, match="already exists"):
        check_output_path(tmp_path / "f")
    check_output_path(tmp_path / "f", force=True)
    with pytest.raises(InputError, match="does not exist"):
        check_output_path(tmp_path / "no" / "f")
    with pytest.raises(InputError, match="is a file, not a folder"):
        check_output_dir(tmp_path / "f")
    check_output_dir(tmp_path / "new" / "deeper")


def test_disk_errors_are_found_in_any_form():
    assert disk_error(OSError(errno.ENOSPC, "No space left on device")) == errno.ENOSPC
    assert disk_error(RuntimeError("Can't write data (file write failed: errno = 28, ...)")) == errno.ENOSPC
    try:
        try:
            raise OSError(errno.EROFS, "Read-only file system")
        except OSError as inner:
            raise ValueError("zlib stream broke") from inner
    except ValueError as outer:
        assert disk_error(outer) == errno.EROFS
    assert disk_error(ValueError("a bug")) is None


def test_full_disk_is_one_line_and_leaves_nothing(small_disk):
    disk = small_disk(256)
    (disk / "kept.txt").write_text("previous")
    big = xr.Dataset({"v": ("t", np.random.default_rng(0).normal(size=200_000))})
    with pytest.raises(OutputError, match=r"no space left on device .* none of kept.txt, big.nc was written \(kept.txt unchanged\)") as info:
        with OutputSet() as out:
            out.write_text(disk / "kept.txt", "new")
            out.write_netcdf(disk / "big.nc", big)
    assert "\n" not in str(info.value)
    assert (disk / "kept.txt").read_text() == "previous"
    assert sorted(p.name for p in disk.iterdir()) == ["kept.txt"]
    # a writer that fills the disk itself (the library raises ENOSPC mid-file)
    with pytest.raises(OutputError, match="no space left on device"):
        atomic_write(disk / "fill.bin", lambda tmp: tmp.write_bytes(b"\0" * (2 << 20)))
    assert sorted(p.name for p in disk.iterdir()) == ["kept.txt"]
