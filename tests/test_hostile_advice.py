"""Mistakes that got a traceback or advice that did not work: a measured variable that holds text,
a second acquire onto a recording in progress, a campaign's ``revolutions``, a factor level no
model takes, and requests far larger than meant (``--duration 2000`` meant as ms). Each ends in
one line (tests/hostile.py ``one_error_line``) whose advice, followed, works."""
from __future__ import annotations

import os
import pty
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest
import xarray as xr

from hostile import (REPORT_FAST, SAMPLE, _prepare_child, cli, command, env, measured_nc,  # noqa: F401
                     one_error_line, run, start, wait_for)
from test_campaign_run import CAL

REPORT_QUICK = [*REPORT_FAST, "--no-robustness"]


# --- advice: a second acquire onto a recording in progress -----------------------------------
def _rows(path) -> int:
    try:
        with h5py.File(path, "r", swmr=True) as f:
            return int(f["signals"].shape[0])
    except (OSError, KeyError):
        return 0


@pytest.mark.slow
@pytest.mark.hostile("concurrency")
def test_a_second_acquire_onto_a_recording_in_progress_is_not_advised_to_force(tmp_path):
    """It said 'already exists; use --force to overwrite it', and --force was then refused."""
    f = tmp_path / "f.h5"
    first = start(["acquire", "--duration", "30", "--status-every", "0", "-o", f])
    try:
        assert wait_for(lambda: _rows(f) >= 5000, timeout=60)
        line = one_error_line(*run(["acquire", "--fast", "--duration", "1", "-o", f]))
        assert "being recorded by another process" in line and "use --force" not in line
        line_forced = one_error_line(*run(["acquire", "--fast", "--duration", "1", "--force", "-o", f]))
        assert line_forced == line
        first.send_signal(signal.SIGINT)
        first.communicate(timeout=60)
    finally:
        if first.poll() is None:
            first.kill()
    assert first.returncode == 128 + signal.SIGINT
    # the first run's recording, stopped short: the same command records it again without --force
    code, err = run(["acquire", "--fast", "--duration", "1", "-o", f])
    assert code == 0 and "recording over" in err, err


