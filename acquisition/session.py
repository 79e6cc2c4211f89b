"""One acquisition run: device -> recorder, with clean stops on Ctrl-C, disconnect and a full disk.

``run(device, path, ...)`` configures and starts the device, writes every block, and always
leaves a readable file with a ``stop`` event saying why it ended. ``complete = True`` means the
recording holds what was asked: the duration reached, a device that ended (a disconnect: its
fault event says so), or, without a duration, the user's stop. A recording stopped short of its
duration (Ctrl-C, SIGTERM, SIGHUP) is closed cleanly with every sample kept and ``complete = False``,
so that nothing takes it for the whole recording; a full disk stops the run (before HDF5 meets
ENOSPC: the recorder keeps a reserve), keeps every sample that reached the file and leaves
``complete = False``. A run that fails before its first sample leaves no file.
"""
from __future__ import annotations

import dataclasses
import os
import signal
import threading
import time

import numpy as np

from labtool.acquisition.device import Block, Device, DeviceDisconnected, Event
from labtool.acquisition.recorder import DiskFull, Recorder, _classify
from labtool.common.errors import InputError, Interrupted
from labtool.common.files import inside_another_command


@dataclasses.dataclass
class RunResult:
    """How the run ended. outcome: done | interrupted | disconnected | disk_full | write_error."""

    path: str
    outcome: str
    message: str
    n_samples: int
    rate_hz: float
    wall_s: float
    overruns: int
    gaps: int
    samples_lost: int
    clipped: tuple
    peak_v: tuple
    complete: bool
    signum: int | None = None     # the stop signal received (SIGINT, SIGTERM, SIGHUP), even after the last block


def run(device: Device, path, rate_hz: float, duration_s: float | None, attrs: dict | None = None,
        ka_m_s2_per_v=None, progress=None, recorder_factory=Recorder, flush_interval_s: float = 0.5,
        on_flush=None, replace: bool = True, on_block=None) -> RunResult:
    """Acquire ``duration_s`` seconds (None: until Ctrl-C or the device ends) into ``path``.

    progress(recorder, elapsed_wall_s) is called after every block (the CLI's live display);
    on_block(block) sees every block as written (the monitor's statistics). ``replace`` lets an
    existing file be replaced, never one that another process is recording into.
    """
    actual = device.configure(rate_hz)
    meta = dict(getattr(device, "metadata", {}) or {})
    meta.update(attrs or {})
    meta["requested_rate_hz"] = float(rate_hz)
    if duration_s is not None:
        meta["requested_duration_s"] = float(duration_s)
    try:
        rec = recorder_factory(path, device.channel_names, actual, attrs=meta, ka_m_s2_per_v=ka_m_s2_per_v,
                               input_range_v=device.input_range_v, flush_interval_s=flush_interval_s,
                               on_flush=on_flush, replace=replace)
    except OSError as exc:
        _try(device.stop)
        reason = os.strerror(exc.errno) if exc.errno else " ".join(str(exc).split())
        raise InputError(f"cannot write the recording {path}: {reason}") from None
    except BaseException:
        _try(device.stop)
        raise
    target = None if duration_s is None else int(round(duration_s * actual))
    outcome, message, complete = "done", "duration reached", True
    t0 = time.perf_counter()
    stop = _StopRequest()
    insist = None
    try:
        stop.install()
        device.start()
        while target is None or rec.device_index < target:
            if stop.signum is not None:
                outcome, message = "interrupted", f"stopped by the user ({stop.name})"
                complete = target is None       # short of its duration: never taken for the whole recording
                break
            block = device.read_block()
            if block is None:
                outcome, message = "done", "device finished"
                if target is not None and rec.device_index < target:   # its last samples never came
                    missing = target - rec.device_index
                    rec.write_block(Block(np.empty((0, len(device.channel_names)), np.float32), target))
                    message = f"device finished {missing} samples short of the requested duration (a gap)"
                break
            if target is not None and block.end_index > target:
                block.data = block.data[: max(0, target - block.first_index)]
                block.events = [e for e in block.events if e.index < target]
            rec.write_block(block)
            if on_block is not None:
                on_block(block)
            if progress is not None:
                progress(rec, time.perf_counter() - t0)
    except KeyboardInterrupt as exc:
        name = signal.Signals(exc.signum).name if isinstance(exc, Interrupted) else "Ctrl-C"
        outcome, message = "interrupted", f"stopped by the user ({name})"
        complete = target is None or rec.device_index >= target
        insist = exc
    except DeviceDisconnected as exc:
        outcome, message = "disconnected", f"device disconnected: {exc}"
        _try(lambda: rec.add_event(Event(rec.n_samples, "fault", message)))
    except OSError as exc:  # DiskFull included; a plain ENOSPC from below is the same thing
        if isinstance(_classify(exc), DiskFull):
            outcome, message = "disk_full", f"disk full ({_classify(exc).strerror}): recording stopped"
        else:
            outcome, message = "write_error", f"cannot write {path}: {exc.strerror or exc}; recording stopped"
        complete = False
        if rec.healthy:
            _try(lambda: rec.add_event(Event(rec.n_samples, "fault", message[:250])))
    except BaseException as exc:  # a bug or a model failure mid-run: keep the data, say so, re-raise
        outcome, message, complete = "error", f"stopped by {type(exc).__name__}: {' '.join(str(exc).split())}", False
        _try(lambda: rec.add_event(Event(rec.n_samples, "fault", message[:250])))
        raise
    finally:
        try:       # a signal while the file is closed is seen (stop.signum), never lost nor raised mid-close
            _try(device.stop)
            outcome, message, complete = _close(rec, outcome, message, complete)
        finally:
            stop.restore()
    # a recording that another command runs (labtool demo's acquire step): a stop signal ends that
    # command too, once this file is closed, not only this recording (a second signal always does)
    if stop.signum is not None and inside_another_command():
        raise Interrupted(stop.signum) if stop.signum != signal.SIGINT else KeyboardInterrupt()
    if insist is not None and inside_another_command():
        raise insist
    wall = time.perf_counter() - t0
    signum = stop.signum if stop.signum is not None else \
        (getattr(insist, "signum", signal.SIGINT) if insist is not None else None)
    return RunResult(str(path), outcome, message, rec.n_samples, actual, wall, rec.overruns, rec.gaps,
                     rec.samples_lost, tuple(sorted(rec.clipped)), tuple(float(p) for p in rec.peak_v), complete,
                     signum)


def _close(rec: Recorder, outcome: str, message: str, complete: bool):
    """Close the recording as the run ended; returns (outcome, message, complete) as they stand after."""
    if outcome == "error" and rec.n_samples == 0:
        rec.discard()  # nothing was recorded: leave no empty file behind
    elif not rec.healthy:
        rec.abandon(message)
    else:
        try:
            rec.close(complete=complete, reason=message)
        except OSError:
            rec.abandon("disk full while closing")
            return "disk_full", "disk full (ENOSPC) while closing", False
    return outcome, message, complete


class _StopRequest:
    """Ctrl-C / SIGTERM set a flag the loop checks between blocks, so a stop never lands in the
    middle of an HDF5 write; a second signal raises KeyboardInterrupt (the user insists)."""

    def __init__(self):
        self.signum = None
        self._old = {}

    @property
    def name(self) -> str:
        return "Ctrl-C" if self.signum == signal.SIGINT else "SIGTERM"

    def install(self):
        if threading.current_thread() is not threading.main_thread():
            return  # signals reach the main thread only; KeyboardInterrupt is still caught
        for s in (signal.SIGINT, signal.SIGTERM):
            self._old[s] = signal.signal(s, self._handler)

    def _handler(self, signum, frame):
        if self.signum is not None:
            raise KeyboardInterrupt
        self.signum = signum

    def restore(self):
        for s, h in self._old.items():
            signal.signal(s, h)
        self._old = {}


def _try(fn):
    try:
        fn()
    except Exception:
        pass
