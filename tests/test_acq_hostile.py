"""Hostile inputs, the acquisition side: bad options, a real full disk, a second writer, a live reader."""
import os
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from labtool.acquisition.recorder import Recorder
from labtool.common import recording_format
from labtool.cli import main

ROOT = Path(__file__).resolve().parents[1]


def _cli(*args, timeout=120):
    return subprocess.run([sys.executable, "-m", "labtool", *map(str, args)], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout)


def _reference(tmp, n):
    """The first n rows of the same command on a disk with room (runs are deterministic for a seed)."""
    ref = tmp / "ref.h5"
    proc = _cli("acquire", "--fast", "--duration", f"{n / 10000 + 0.2:.1f}", "-o", ref)
    assert proc.returncode == 0, proc.stderr
    return recording_format.load(ref)["signals"][:n]


@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("args,said", [
    (["--seed", "-1"], "--seed must be an integer from 0"),
    (["--seed", "99999999999999999999999999"], "--seed must be an integer from 0"),
    (["--fault", "overrun@nan"], "the time must be a number of seconds"),
    (["--fault", "overrun@-1"], "the time must be a number of seconds"),
    (["--fault", "drop@inf"], "the time must be a number of seconds"),
])
def test_bad_seed_or_fault_one_line_exit_2_nothing_left(tmp_path, capsys, args, said):
    out = tmp_path / "r.h5"
    assert main(["acquire", "--fast", "--duration", "0.5", *args, "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("labtool: error:") and said in err[0], err
    assert not out.exists() and list(tmp_path.iterdir()) == []


@pytest.mark.slow
@pytest.mark.hostile("full_disk")
def test_a_real_full_disk_keeps_every_row_it_claims(small_disk, tmp_path):
    disk = small_disk(1500)
    out = disk / "full.h5"
    proc = _cli("acquire", "--fast", "--duration", "60", "-o", out)
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-2000:])
    lines = _errors(proc.stderr)
    assert len(lines) == 1 and lines[0].startswith("labtool: error: disk full"), proc.stderr[-2000:]
    assert lines[0].endswith("complete=false")
    rec = recording_format.load(out)
    n = rec["signals"].shape[0]
    assert 10000 < n < 600000
    a = rec["attrs"]
    assert bool(a["complete"]) is False and int(a["n_samples"]) == n  # rows claimed = rows written
    assert f"{n} samples (" in lines[0]
    np.testing.assert_array_equal(rec["signals"], _reference(tmp_path, n))  # every sample is the real one
    kinds = [k for _, k, _ in rec["events"]]
    assert kinds[0] == "start" and kinds[-1] == "stop" and "fault" in kinds


def test_recordings_follow_the_umask(tmp_path):
    old = os.umask(0o027)
    try:
        with Recorder(tmp_path / "u.h5", ["a"], 1000.0) as r:
            r.write_block(__import__("labtool.acquisition.device", fromlist=["Block"]).Block(np.zeros((10, 1)), 0))
    finally:
        os.umask(old)
    assert (tmp_path / "u.h5").stat().st_mode & 0o777 == 0o640


def is_being_written(path):
    from labtool.acquisition.writer_lock import is_being_written as held  # new in this change: imported here so the
    return held(path)                                              # other cases still run against older code


def _errors(stderr: str) -> list[str]:
    """stderr without the monitor's status lines (a piped run prints one every few seconds)."""
    return [ln for ln in stderr.strip().splitlines() if not ln.startswith("labtool: acquire ")]


def _popen(*args):
    return subprocess.Popen([sys.executable, "-m", "labtool", *map(str, args)], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _wait_rows(path, n, timeout=60):
    deadline = time.time() + timeout
    while time.time() < deadline:
        try:
            with h5py.File(path, "r", swmr=True) as f:
                if f["signals"].shape[0] >= n:
                    return
        except (OSError, KeyError):
            pass
        time.sleep(0.2)
    raise AssertionError(f"{path} never reached {n} rows")


def _finish(proc, timeout=60):
    try:
        out, err = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
    return proc.returncode, out, err


@pytest.mark.slow
@pytest.mark.hostile("concurrency")
def test_a_second_writer_is_refused_even_with_force(tmp_path):
    f = tmp_path / "f.h5"
    first = _popen("acquire", "--duration", "30", "-o", f)
    try:
        _wait_rows(f, 5000)
        assert is_being_written(f)
        second = _cli("acquire", "--force", "--fast", "--duration", "1", "-o", f)
        assert second.returncode == 2
        lines = _errors(second.stderr)
        assert len(lines) == 1 and lines[0].startswith("labtool: error:") and "being recorded" in lines[0], second.stderr
        assert "--force does not replace" in lines[0]
        first.send_signal(__import__("signal").SIGINT)
        rc, out, err = _finish(first)
    finally:
        if first.poll() is None:
            first.kill()
    assert rc == 130, err
    rec = recording_format.load(f)
    n = rec["signals"].shape[0]
    assert not bool(rec["attrs"]["complete"]) and int(rec["attrs"]["n_samples"]) == n >= 5000
    assert f"wrote {f}: {n} samples" in out  # the first run's summary describes the file
    assert not is_being_written(f)


@pytest.mark.slow
@pytest.mark.hostile("concurrency")
def test_a_live_swmr_reader_does_not_stop_the_close(tmp_path):
    f = tmp_path / "live.h5"
    writer = _popen("acquire", "--duration", "3", "-o", f)
    reader = None
    try:
        _wait_rows(f, 2000)
        hold = ("import h5py, sys, time\n"
                "f = h5py.File(sys.argv[1], 'r', swmr=True)\n"
                "print('open', flush=True)\n"
                "time.sleep(20)\n")
        reader = subprocess.Popen([sys.executable, "-c", hold, str(f)], stdout=subprocess.PIPE, text=True)
        assert reader.stdout.readline().strip() == "open"
        rc, out, err = _finish(writer)
        assert rc == 0 and _errors(err) == [], err
        assert reader.poll() is None  # the reader still holds the file
    finally:
        for p in (writer, reader):
            if p is not None and p.poll() is None:
                p.kill()
    rec = recording_format.load(f)
    assert bool(rec["attrs"]["complete"]) and rec["signals"].shape[0] == 30000
    assert rec["events"][-1][1] == "stop"


@pytest.mark.slow
@pytest.mark.hostile("concurrency")
@pytest.mark.parametrize("force", [True, False])
def test_two_acquires_started_together(tmp_path, force):
    f = tmp_path / "both.h5"
    args = ["acquire", "--duration", "2", "-o", f] + (["--force"] if force else [])
    procs = [_popen(*args), _popen(*args)]
    results = [_finish(p) for p in procs]
    codes = sorted(rc for rc, _, _ in results)
    assert codes == [0, 2], results
    for rc, out, err in results:
        assert "Traceback" not in err
        if rc == 2:
            lines = _errors(err)
            assert len(lines) == 1 and lines[0].startswith("labtool: error:"), err
            assert ("being recorded" in lines[0]) or ("already exists" in lines[0])
        else:
            winner = out
    rec = recording_format.load(f)
    n = rec["signals"].shape[0]
    assert bool(rec["attrs"]["complete"]) and n == 20000 and f"{n} samples" in winner


@pytest.mark.slow
@pytest.mark.hostile("hang")
@pytest.mark.parametrize("keep", [100, 512, 4096])
def test_loading_a_truncated_file_is_one_error_not_a_hang(tmp_path, keep):
    full = tmp_path / "full.h5"
    assert main(["acquire", "--fast", "--duration", "0.3", "-o", str(full)]) == 0
    cut = tmp_path / "cut.h5"
    cut.write_bytes(full.read_bytes()[:keep])
    code = ("import sys\nfrom labtool.common import recording_format\nfrom labtool.common.errors import FileFormatError\n"
            "try:\n    recording_format.load(sys.argv[1])\nexcept FileFormatError as e:\n    print('refused:', e)\n")
    try:  # in a child with a bound: before the safe opener, h5py looped for ever on such a file
        proc = subprocess.run([sys.executable, "-c", code, str(cut)], cwd=ROOT, capture_output=True, text=True,
                              timeout=90)
    except subprocess.TimeoutExpired:
        pytest.fail(f"recording_format.load hung on a file cut to {keep} bytes")
    assert proc.returncode == 0 and proc.stdout.startswith("refused:"), (proc.stdout, proc.stderr[-500:])
