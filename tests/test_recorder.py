"""Recorder: format v1 to the letter, gaps as events, SWMR reading while writing, SIGKILL, Ctrl-C, disk full."""
import errno
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from labtool.acquisition import session
from labtool.acquisition import signal_chain as sc
from labtool.acquisition.device import Block, Device, Event
from labtool.acquisition.recorder import Recorder
from labtool.common import recording_format
from labtool.common.recording_format import EVENT_DTYPE
from labtool.acquisition.sim_stand import Fault, SimStand
from labtool.cli import main

ROOT = Path(__file__).resolve().parents[1]


def sim(seed=1, duration=2.0, realtime=False, faults=()):
    # the kinematic truth: these tests pin exact sample indices of the recorder, not the physics
    return SimStand(sc.StandScene(truth_model="kinematic"), seed=seed, duration_s=duration, realtime=realtime, faults=faults)


def reference_data(seed, duration):
    dev = sim(seed, duration)
    dev.configure(10000)
    dev.start()
    out = []
    while (b := dev.read_block()) is not None:
        out.append(b.data)
    return np.concatenate(out)


def test_format_v1_to_the_letter(tmp_path):
    p = tmp_path / "r.h5"
    res = session.run(sim(duration=1.0), p, 10000, 1.0, attrs={"cam_speed_rpm": 180.0},
                      ka_m_s2_per_v=[86.43, 86.43, np.nan])
    assert res.outcome == "done" and res.complete
    with h5py.File(p, "r") as f:
        a = f.attrs
        assert a["format"] == "labtool.recording" and int(a["format_version"]) == 1
        assert float(a["sample_rate_hz"]) == 10000.0 and bool(a["complete"]) is True
        assert float(a["cam_speed_rpm"]) == 180.0
        from datetime import datetime
        datetime.fromisoformat(str(a["start_time_utc"]))
        s = f["signals"]
        assert s.shape == (10000, 3) and s.dtype == np.float32
        assert s.chunks is not None and s.maxshape == (None, 3)
        assert [n.decode() if isinstance(n, bytes) else n for n in s.attrs["channel_names"]] == ["aE_t", "aE_n", "tacho"]
        ka = s.attrs["ka_m_s2_per_v"]
        assert ka[0] == 86.43 and np.isnan(ka[2])
        ev = f["events"]
        assert ev.dtype == EVENT_DTYPE and ev.dtype.names == ("index", "kind", "detail")
        kinds = [k.decode() for k in ev["kind"]]
        assert kinds[0] == "start" and kinds[-1] == "stop"
        # the metadata needed to compare with a known truth
        for key in ("law", "Fu_N", "backlash_mm", "seed", "chain_ka_m_s2_per_v", "truth_omega1_ripple", "resonance_hz"):
            assert key in a, key
    np.testing.assert_array_equal(recording_format.load(p)["signals"], reference_data(1, 1.0))


def test_gaps_and_overruns_are_events_at_the_joint(tmp_path):
    p = tmp_path / "g.h5"
    res = session.run(sim(seed=4, duration=3.0, faults=[Fault("overrun", 1.0, 0.2), Fault("drop", 2.05)]), p, 10000, 3.0)
    assert res.overruns == 1 and res.gaps == 2 and res.samples_lost == 3000
    rec = recording_format.load(p)
    assert rec["signals"].shape[0] == 27000
    ev = [(i, k, d) for i, k, d in rec["events"] if k in ("gap", "overrun")]
    assert [(i, k) for i, k, _ in ev] == [(10000, "overrun"), (10000, "gap"), (18000, "gap")]
    assert ev[1][2].startswith("missing_samples=2000") and ev[2][2].startswith("missing_samples=1000")
    ref = reference_data(4, 3.0)
    # rows around the joints are exactly the device's samples, nothing interpolated
    np.testing.assert_array_equal(rec["signals"][:10000], ref[:10000])
    np.testing.assert_array_equal(rec["signals"][10000:18000], ref[12000:20000])  # overrun lost 10000..11999
    np.testing.assert_array_equal(rec["signals"][18000:], ref[21000:])  # the block 20000..20999 was dropped
    assert rec["attrs"]["samples_lost"] == 3000


def test_event_index_is_the_row_even_after_a_gap(tmp_path):
    p = tmp_path / "cg.h5"
    session.run(sim(seed=4, duration=3.0, faults=[Fault("overrun", 1.0, 0.2), Fault("clip", 2.5)]), p, 10000, 3.0)
    rec = recording_format.load(p)
    clip = [i for i, k, _ in rec["events"] if k == "clip"]
    assert clip == [25004 - 2000]  # device sample 25004, 2000 samples lost before it
    assert rec["signals"][clip[0], 0] >= 10.0 - 20.0 / 2**16 - 1e-6  # the row sits at the rail
    assert rec["signals"][clip[0] - 1, 0] < 9.9


WRITER = r"""
import sys
from labtool.acquisition import session, signal_chain as sc
from labtool.acquisition.sim_stand import SimStand
dev = SimStand(sc.StandScene(truth_model="kinematic"), seed=11, duration_s=60.0, realtime=True)
def flushed(n):
    print(n, flush=True)
session.run(dev, sys.argv[1], 10000, 60.0, flush_interval_s=0.3, on_flush=flushed)
"""


@pytest.mark.slow
def test_sigkill_leaves_every_flushed_sample_and_complete_false(tmp_path, capsys):
    p = tmp_path / "killed.h5"
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(p)], stdout=subprocess.PIPE, text=True, cwd=ROOT)
    flushed = []
    try:
        while len(flushed) < 6:
            line = proc.stdout.readline()
            assert line, "writer ended early"
            flushed.append(int(line))
            if len(flushed) == 4:
                # read while it is being written (SWMR): every flushed sample is visible
                with h5py.File(p, "r", libver="latest", swmr=True) as f:
                    n_now = f["signals"].shape[0]
                    assert n_now >= flushed[-1]
                    assert bool(f.attrs["complete"]) is False
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert flushed[-1] > 0
    rec = recording_format.load(p)
    n = rec["signals"].shape[0]
    assert n >= flushed[-1]
    assert bool(rec["attrs"]["complete"]) is False
    assert [k for _, k, _ in rec["events"]][0] == "start"
    ref = reference_data(11, n / 10000 + 0.2)
    np.testing.assert_array_equal(rec["signals"], ref[:n])
    # and labtool process (processing's reader) accepts it, with a warning
    capsys.readouterr()
    assert main(["process", str(p), "-o", str(tmp_path / "m.nc")]) == 0
    err = capsys.readouterr().err
    assert "warning" in err and "incomplete" in err


class _StopAfter(Device):
    """Wraps a device and raises KeyboardInterrupt (Ctrl-C) after k blocks."""

    def __init__(self, inner, k, exc=KeyboardInterrupt):
        self.inner, self.k, self.exc = inner, k, exc
        self.channel_names = inner.channel_names
        self.metadata = {}

    def configure(self, rate_hz):
        r = self.inner.configure(rate_hz)
        self.metadata = self.inner.metadata
        return r

    def start(self):
        self.inner.start()

    def stop(self):
        self.stopped = True
        self.inner.stop()

    def read_block(self):
        if self.k == 0:
            raise self.exc()
        self.k -= 1
        return self.inner.read_block()

    @property
    def actual_rate_hz(self):
        return self.inner.actual_rate_hz


@pytest.mark.hostile("concurrency")
def test_a_reader_opening_the_new_file_does_not_fail_the_recording(tmp_path, monkeypatch):
    """A process opening the recording in the instant it is created (a monitor polling for it) holds
    HDF5's shared file lock while its open fails, and the recorder's create failed: 'cannot write
    the recording rec.h5: Resource temporarily unavailable'. The create is tried again."""
    import fcntl
    import threading

    from labtool.acquisition import recorder as rmod

    real = rmod.WriterLock.create
    released = threading.Event()

    def create_then_read(path, replace):
        lock = real(path, replace)
        fd = os.open(path, os.O_RDONLY)          # what h5py's open does first: a shared flock
        fcntl.flock(fd, fcntl.LOCK_SH)
        threading.Timer(0.2, lambda: (os.close(fd), released.set())).start()
        return lock
    monkeypatch.setattr(rmod.WriterLock, "create", staticmethod(create_then_read))
    with Recorder(tmp_path / "r.h5", ["a"], 1000.0) as rec:
        assert released.is_set()               # created once the reader let go
        rec.write_block(Block(np.zeros((10, 1), np.float32), 0))
    assert recording_format.load(tmp_path / "r.h5")["signals"].shape == (10, 1)


def test_ctrl_c_stops_cleanly(tmp_path):
    """Stopped short of its duration: every sample kept, the file closed, and marked incomplete
    (it was marked complete, and a campaign took 7000 samples for the whole point)."""
    p = tmp_path / "c.h5"
    dev = _StopAfter(sim(duration=5.0), 7)
    res = session.run(dev, p, 10000, 5.0)
    assert res.outcome == "interrupted" and not res.complete and res.signum == signal.SIGINT and dev.stopped
    rec = recording_format.load(p)
    assert rec["signals"].shape[0] == 7000 and not rec["attrs"]["complete"]
    assert rec["events"][-1][1] == "stop" and "Ctrl-C" in rec["events"][-1][2]
    # a reader says why it is short: the user stopped it, not a recorder that did not close
    from labtool.processing.readers import open_recording
    r = open_recording(p)
    warned = " ".join(r.warnings)
    r.close()
    assert "stopped short: stopped by the user (Ctrl-C)" in warned and "did not close cleanly" not in warned


def test_ctrl_c_ends_a_recording_without_a_duration_complete(tmp_path):
    """Without a duration (until Ctrl-C) the stop is the recording's end: complete."""
    p = tmp_path / "c.h5"
    dev = _StopAfter(sim(duration=5.0), 7)
    res = session.run(dev, p, 10000, None)
    assert res.outcome == "interrupted" and res.complete and res.signum == signal.SIGINT
    assert recording_format.load(p)["attrs"]["complete"]


@pytest.mark.slow
@pytest.mark.parametrize("sig,said", [(signal.SIGINT, "Ctrl-C"), (signal.SIGTERM, "SIGTERM")])
def test_ctrl_c_or_sigterm_to_a_realtime_cli_run_closes_the_file(tmp_path, sig, said):
    p = tmp_path / "int.h5"
    proc = subprocess.Popen([sys.executable, "-m", "labtool", "acquire", "--duration", "60", "-o", str(p)],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.time() + 60
        while time.time() < deadline:
            time.sleep(0.3)
            try:
                with h5py.File(p, "r", libver="latest", swmr=True) as f:
                    if f["signals"].shape[0] >= 5000:
                        break
            except (OSError, KeyError):
                pass
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 128 + sig, err
    rec = recording_format.load(p)
    assert not rec["attrs"]["complete"] and 5000 <= rec["signals"].shape[0] < 600000
    assert said in rec["events"][-1][2]
    assert f"interrupted ({signal.Signals(sig).name}); {p} keeps its {rec['signals'].shape[0]} samples" in err


def _full_disk_after(monkeypatch, n_ok):
    calls = {"n": 0}
    real = Recorder._append_rows

    def append(self, rows):
        calls["n"] += 1
        if calls["n"] > n_ok:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        real(self, rows)
    monkeypatch.setattr(Recorder, "_append_rows", append)


def test_disk_full_stops_cleanly_and_keeps_the_data(tmp_path, monkeypatch):
    _full_disk_after(monkeypatch, 12)
    p = tmp_path / "full.h5"
    res = session.run(sim(duration=3.0), p, 10000, 3.0)
    assert res.outcome == "disk_full" and not res.complete
    rec = recording_format.load(p)
    assert rec["signals"].shape[0] == 12000
    assert rec["attrs"]["complete"] == False  # noqa: E712 (numpy bool)
    assert any(k == "fault" and "disk full" in d for _, k, d in rec["events"])
    np.testing.assert_array_equal(rec["signals"], reference_data(1, 1.2))


@pytest.mark.slow
def test_disk_full_cli_one_line_exit_2(tmp_path, monkeypatch, capsys):
    _full_disk_after(monkeypatch, 5)
    p = tmp_path / "full.h5"
    assert main(["acquire", "--fast", "--duration", "2", "-o", str(p)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("labtool: error: disk full") and "5000 samples (0.500 s) kept" in err[-1]
    assert recording_format.load(p)["signals"].shape[0] == 5000


def test_disconnect_keeps_the_data_and_says_so(tmp_path, capsys):
    p = tmp_path / "d.h5"
    assert main(["acquire", "--fast", "--duration", "2", "--fault", "disconnect@0.55", "-o", str(p)]) == 2
    err = capsys.readouterr().err
    assert "labtool: error: device disconnected" in err
    rec = recording_format.load(p)
    assert rec["signals"].shape[0] == 5000 and rec["attrs"]["complete"]
    assert any(k == "fault" for _, k, _ in rec["events"])


def test_block_before_what_was_written_is_a_bug(tmp_path):
    r = Recorder(tmp_path / "x.h5", ["a"], 1000.0)
    r.write_block(Block(np.zeros((10, 1)), 0))
    with pytest.raises(ValueError):
        r.write_block(Block(np.zeros((10, 1)), 5))
    r.close()
    with pytest.raises(ValueError):
        Event(0, "nonsense")


class _ModelFailure(Exception):
    pass


def test_an_unexpected_error_mid_run_keeps_the_data_marks_it_incomplete_and_propagates(tmp_path):
    p = tmp_path / "e.h5"
    with pytest.raises(_ModelFailure):
        session.run(_StopAfter(sim(duration=5.0), 4, exc=_ModelFailure), p, 10000, 5.0)
    rec = recording_format.load(p)
    assert rec["signals"].shape[0] == 4000 and not rec["attrs"]["complete"]
    assert any(k == "fault" and "_ModelFailure" in d for _, k, d in rec["events"])


def _sigterm_after_blocks(n):
    """on_block that sends this process SIGTERM after the n-th block."""
    seen = {"k": 0}

    def on_block(block):
        seen["k"] += 1
        if seen["k"] == n:
            os.kill(os.getpid(), signal.SIGTERM)
    return on_block


@pytest.mark.hostile("interrupted")
def test_sigterm_to_a_recording_stops_it_and_the_command_goes_on(tmp_path):
    """labtool acquire on its own: SIGTERM is the user's stop, the file is closed (incomplete: short
    of its duration) and the run returns (the CLI then exits 128 + 15:
    test_ctrl_c_or_sigterm_to_a_realtime_cli_run_closes_the_file)."""
    from labtool.common.files import command_scope, signals_interrupt
    p = tmp_path / "t.h5"
    with command_scope(), signals_interrupt():
        res = session.run(sim(duration=5.0), p, 10000, 5.0, on_block=_sigterm_after_blocks(5))
    assert res.outcome == "interrupted" and not res.complete and "SIGTERM" in res.message
    assert res.signum == signal.SIGTERM
    assert not recording_format.load(p)["attrs"]["complete"]


@pytest.mark.hostile("interrupted")
def test_sigterm_to_a_recording_another_command_runs_ends_that_command(tmp_path):
    """labtool demo runs acquire: a SIGTERM there must end the demo (found by CI: the demo went on
    and exited 0), once the recording is closed."""
    from labtool.common.errors import Interrupted
    from labtool.common.files import command_scope, signals_interrupt
    p = tmp_path / "t.h5"
    with pytest.raises(Interrupted) as caught:
        with command_scope(), signals_interrupt():          # the outer command (demo)
            with command_scope(), signals_interrupt():      # the acquire step it runs
                session.run(sim(duration=5.0), p, 10000, 5.0, on_block=_sigterm_after_blocks(5))
    assert caught.value.signum == signal.SIGTERM
    rec = recording_format.load(p)
    assert not rec["attrs"]["complete"] and "SIGTERM" in rec["events"][-1][2]     # closed, short of 5 s


@pytest.mark.hostile("interrupted")
@pytest.mark.slow
def test_a_command_that_another_runs_passes_the_interrupt_on(tmp_path):
    """The CLI of a command that another runs re-raises the interrupt instead of returning 143,
    so that the outer command ends with it (and cleans up) instead of reporting a failed step."""
    import threading

    from labtool.common.errors import Interrupted
    from labtool.common.files import command_scope, signals_interrupt
    p = tmp_path / "r.h5"
    done = threading.Event()

    def stop_once_recording():
        deadline = time.time() + 60
        while not p.exists() and time.time() < deadline and not done.is_set():
            time.sleep(0.02)
        time.sleep(0.3)
        if not done.is_set():
            os.kill(os.getpid(), signal.SIGTERM)

    killer = threading.Thread(target=stop_once_recording, daemon=True)
    with pytest.raises(Interrupted):
        with command_scope(), signals_interrupt():           # the outer command
            killer.start()
            try:
                main(["acquire", "--duration", "20", "-o", str(p)])
            finally:
                done.set()
    rec = recording_format.load(p)
    assert not rec["attrs"]["complete"] and 0 < rec["signals"].shape[0] < 200000     # closed, short of 20 s
