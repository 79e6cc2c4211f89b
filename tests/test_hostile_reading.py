"""Hostile cases of the reading side: a damaged HDF5 file that made h5py loop inside one C call
(100 % CPU, SIGTERM ignored), gap events claiming absurd losses, a recording too short for its
speed, a raw recording given to ``report``. Each ends with one line and exit 2 (or 128 + signal),
and where the line gives advice, the advice is followed and works."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from hostile import REPORT_FAST, cli, one_error_line, run, start
from stand_data import stand_recording

FLIP_AT = 64        # bytes into the global heap collection (GCOL) of vlen string attributes


def _flipped(tmp_path: Path) -> Path:
    """A 3 s recording with 64 bytes flipped in the heap that holds its string attributes (near the
    start of the file): h5py alone loops for ever on it."""
    good = tmp_path / "good.h5"
    stand_recording(good, duration_s=3.0, rpm=300.0, attrs={"operator": "A. Tester", "test_id": "T-1"})
    data = bytearray(good.read_bytes())
    at = data.find(b"GCOL") + FLIP_AT
    assert at > FLIP_AT and at < 8192
    for i in range(at, at + 64):
        data[i] ^= 0xFF
    bad = tmp_path / "flipped.h5"
    bad.write_bytes(bytes(data))
    return bad


def _h5py_hangs(path: Path, seconds: float = 5.0) -> bool:
    """The damage is the one tested: reading the attributes with h5py alone does not end."""
    code = "import sys, h5py\nf = h5py.File(sys.argv[1], 'r')\nfor k in f.attrs: f.attrs[k]\n"
    try:
        subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, timeout=seconds)
    except subprocess.TimeoutExpired:
        return True
    return False


def _holding(path: Path) -> list[int]:
    """Process ids whose command line names ``path`` (a child left behind)."""
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                if os.fsencode(str(path)) in (d / "cmdline").read_bytes():
                    out.append(int(d.name))
            except OSError:
                pass
    return out


@pytest.mark.slow
@pytest.mark.hostile("hang")
def test_a_flipped_attribute_heap_ends_in_one_line(tmp_path):
    """main spun at 100 % CPU for over 10 minutes in h5py's attribute read."""
    from labtool.common.hdf5 import PROBE_TIMEOUT_S
    bad = _flipped(tmp_path)
    assert _h5py_hangs(bad)
    t0 = time.monotonic()
    line = one_error_line(*run(["process", bad, "-o", tmp_path / "m.nc"], timeout=PROBE_TIMEOUT_S + 40))
    assert time.monotonic() - t0 < PROBE_TIMEOUT_S + 30
    assert "flipped.h5" in line and "damaged" in line and f"within {PROBE_TIMEOUT_S:g} s" in line, line
    assert not (tmp_path / "m.nc").exists()
    time.sleep(0.2)
    assert _holding(bad) == []


@pytest.mark.slow
@pytest.mark.hostile("hang")
def test_sigterm_ends_process_of_a_damaged_recording(tmp_path):
    """main ignored SIGTERM (only SIGKILL ended it): now exit 143 at once, no child left behind."""
    bad = _flipped(tmp_path)
    proc = start(["process", bad, "-o", tmp_path / "m.nc"])
    time.sleep(3.0)                      # inside the metadata read
    assert proc.poll() is None
    t0 = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    try:
        _, err = proc.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()                      # what main needed: SIGKILL
        proc.communicate()
        pytest.fail("SIGTERM did not end labtool process within 20 s")
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert time.monotonic() - t0 < 5
    assert "interrupted (SIGTERM)" in err.decode()
    assert not (tmp_path / "m.nc").exists()
    time.sleep(0.2)
    assert _holding(bad) == []


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("lost", [9 * 10**17, 10**12, 2**63 + 5])
def test_gap_events_claiming_absurd_losses_are_refused(tmp_path, capsys, lost):
    """main wrote exit 0 and a measured.nc whose time axis xarray could not decode (9e13 s)."""
    rec = tmp_path / "rec.h5"
    stand_recording(rec, duration_s=2.0, rpm=300.0, events=[(9000, "gap", f"missing_samples={lost}")])
    line = one_error_line(*cli(["process", rec, "-o", tmp_path / "m.nc"], capsys))
    assert "gap events claim" in line and "damaged" in line, line
    assert not (tmp_path / "m.nc").exists()


@pytest.mark.slow
def test_a_gap_a_recorder_writes_is_still_read(tmp_path, capsys):
    """What must keep working: a gap of 1 s lost at 10 kHz, counted in the time axis."""
    rec = tmp_path / "rec.h5"
    stand_recording(rec, duration_s=3.0, rpm=300.0, events=[(15000, "gap", "missing_samples=10000 (1 s)")])
    code, err = cli(["process", rec, "-o", tmp_path / "m.nc"], capsys)
    assert code == 0, err
    t = xr.open_dataset(tmp_path / "m.nc")["time"].values     # decoded: datetime64
    assert (t[-1] - t[0]) / np.timedelta64(1, "s") == pytest.approx(3.0 + 1.0 - 1e-4, abs=1e-6)


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_a_recording_too_short_for_its_speed_gets_the_right_error_first(tmp_path):
    """5 rpm for 3 s: main warned of '1030.8 rpm' (a correlation of a quarter revolution) before
    the error. Now the cause alone; its advice (record 30 s) followed works."""
    rec = tmp_path / "slow.h5"
    code, err = run(["acquire", "--device", "sim", "--rpm", "5", "--duration", "3", "--fast", "-o", rec])
    assert code == 0, err
    code, err = run(["process", rec, "-o", tmp_path / "m.nc"])
    line = one_error_line(code, err)
    assert len([ln for ln in err.splitlines() if ln.strip()]) == 1, err     # no warning before it
    assert "0.25 revolutions at the stated 5 rpm" in line and "record at least 30 s" in line, line
    longer = tmp_path / "slow30.h5"
    code, err = run(["acquire", "--device", "sim", "--rpm", "5", "--duration", "30", "--fast", "-o", longer])
    assert code == 0, err
    code, err = run(["process", longer, "-o", tmp_path / "m.nc"])
    assert code == 0, err
    assert xr.open_dataset(tmp_path / "m.nc").attrs["cam_speed_rpm"] == pytest.approx(5.0, rel=0.01)


@pytest.mark.slow
@pytest.mark.hostile("traceback")
def test_report_of_a_raw_recording_says_to_process_it_first(tmp_path):
    """main leaked Python's "UserWarning: The 'phony_dims' kwarg ..." before a misleading error."""
    rec = tmp_path / "rec.h5"
    stand_recording(rec, duration_s=3.0, rpm=300.0)
    code, err = run(["report", rec, "-o", tmp_path / "r.html", *REPORT_FAST])
    line = one_error_line(code, err)
    assert "Warning" not in err and "phony_dims" not in err, err
    assert "is a labtool recording" in line and "labtool process" in line, line
    code, err = run(["process", rec, "-o", tmp_path / "measured.nc"])     # the advice
    assert code == 0, err
    code, err = run(["report", tmp_path / "measured.nc", "-o", tmp_path / "r.html", *REPORT_FAST])
    assert code in (0, 1), err
    assert (tmp_path / "r.html").exists()
