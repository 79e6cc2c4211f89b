"""NI-DAQmx driver: IEPE accelerometer channels + a tacho channel, continuous buffered reads.

Uses the official ``nidaqmx`` package, imported lazily so labtool works without it (optional extra
``pip install labtool[nidaqmx]``). The contract is tested against a fake Task (tests/test_acq_nidaqmx.py).

Channels. ``--device nidaqmx:Dev1/ai0:2`` (NI range syntax) or a comma list. The first two are the
accelerometer channels ``aE_t``, ``aE_n``, the third (if any) ``tacho``. The accelerometer channels
are IEPE accelerometer channels (``add_ai_accel_chan``) with the current excitation OFF by default,
because the PCB 480C02 conditioner powers the sensor (``iepe_excitation=True`` lets the DAQ
supply ``excitation_current_a`` itself when the sensor is wired straight to the board). They are
configured with a sensitivity of 1000 mV/g and units of g, so the numbers DAQmx returns are the
volts at the input: the recording stays raw volts, and Ka is applied downstream, as with any
device. The tacho is a plain voltage channel.

Reads. A worker thread reads ``block_s`` of samples per channel at a time from a continuous task
(buffer ``buffer_s``) and queues Blocks. The real sample clock is read back from
``task.timing.samp_clk_rate`` (the board divides its timebase; 10 kHz may come out as 10.0xx kHz);
a rate more than 1 % from the request is refused. DAQmx error -200279 (samples no longer
available: the reader fell behind and the buffer was overwritten) is an overrun: the task is
restarted, the lost samples are counted from ``in_stream.total_samp_per_chan_acquired`` plus the
restart time, and the next block starts that many samples later (an ``overrun`` event; the recorder
writes the gap). Any other DAQmx error in the worker ends the run as a disconnect.
"""
from __future__ import annotations

import queue
import re
import threading
import time

import numpy as np

from acquisition.device import Block, Device, DeviceDisconnected, Event
from common.errors import InputError

OVERRUN_ERROR = -200279  # DAQmxErrors.SAMPLES_NO_LONGER_AVAILABLE
DEFAULT_NAMES = ("aE_t", "aE_n", "tacho")


def expand_channels(spec: str) -> list[str]:
    """``Dev1/ai0:2`` -> [Dev1/ai0, Dev1/ai1, Dev1/ai2]; comma lists allowed; InputError if malformed."""
    out = []
    for part in (p.strip() for p in spec.split(",")):
        m = re.fullmatch(r"([^\s:,]+?)(\d+)(?::(\d+))?", part)
        if not m or "/" not in part:
            raise InputError(f"bad NI-DAQmx physical channel '{part}'; expected e.g. Dev1/ai0 or Dev1/ai0:2")
        prefix, a, b = m.group(1), int(m.group(2)), m.group(3)
        b = a if b is None else int(b)
        step = 1 if b >= a else -1
        out += [f"{prefix}{i}" for i in range(a, b + step, step)]
    if not 1 <= len(out) <= 16:
        raise InputError(f"NI-DAQmx: 1 to 16 channels expected, got {len(out)}")
    if len(set(out)) != len(out):
        raise InputError(f"NI-DAQmx: channel listed twice in '{spec}'")
    return out


def _import_nidaqmx():
    try:
        import nidaqmx  # noqa: F401
        import nidaqmx.constants
        import nidaqmx.errors
        return nidaqmx
    except ImportError:
        raise InputError("the nidaqmx package is not installed; install it with: pip install 'labtool[nidaqmx]'") from None


class NIDAQmxDevice(Device):
    """Continuous acquisition on an NI board through nidaqmx (see module docstring)."""

    def __init__(self, physical_channels: str, channel_names=None, iepe_excitation: bool = False,
                 excitation_current_a: float = 0.004, range_v: float = 10.0, block_s: float = 0.1,
                 buffer_s: float = 10.0, task_factory=None, read_timeout_s: float = 10.0):
        self.physical = expand_channels(physical_channels)
        n = len(self.physical)
        names = channel_names or (DEFAULT_NAMES[:n] if n <= 3 else DEFAULT_NAMES[:2] + tuple(f"ai{i}" for i in range(2, n)))
        if len(names) != n:
            raise InputError(f"{n} physical channels but {len(names)} names")
        self.channel_names = tuple(names)
        self.iepe_excitation = iepe_excitation
        self.excitation_current_a = excitation_current_a
        self.range_v = range_v
        self.block_s = block_s
        self.buffer_s = buffer_s
        self.read_timeout_s = read_timeout_s
        self._task_factory = task_factory
        self._task = None
        self._rate = None
        self._thread = None
        self._queue: queue.Queue = queue.Queue()
        self._stop = threading.Event()
        self.metadata = {}

    # -- Device API
    def configure(self, rate_hz: float) -> float:
        nidaqmx = _import_nidaqmx()
        c = nidaqmx.constants
        try:
            task = self._task_factory() if self._task_factory else nidaqmx.Task()
        except Exception as exc:  # no driver / no runtime
            raise InputError(f"NI-DAQmx is not available: {_one_line(exc)}") from None
        self._task = task
        try:
            for phys, name in zip(self.physical, self.channel_names):
                if name in ("aE_t", "aE_n"):
                    task.ai_channels.add_ai_accel_chan(
                        phys, name_to_assign_to_channel=name, min_val=-self.range_v, max_val=self.range_v,
                        units=c.AccelUnits.G, sensitivity=1000.0,
                        sensitivity_units=c.AccelSensitivityUnits.MILLIVOLTS_PER_G,
                        current_excit_source=c.ExcitationSource.INTERNAL if self.iepe_excitation else c.ExcitationSource.NONE,
                        current_excit_val=self.excitation_current_a if self.iepe_excitation else 0.0)
                else:
                    task.ai_channels.add_ai_voltage_chan(phys, name_to_assign_to_channel=name,
                                                         min_val=-self.range_v, max_val=self.range_v)
            task.timing.cfg_samp_clk_timing(rate_hz, sample_mode=c.AcquisitionType.CONTINUOUS,
                                            samps_per_chan=max(1000, int(self.buffer_s * rate_hz)))
            actual = float(task.timing.samp_clk_rate)
        except nidaqmx.errors.DaqError as exc:
            self._close_task()
            raise InputError(f"NI-DAQmx refused the configuration ({','.join(self.physical)} at {rate_hz:g} Hz): "
                             f"{_one_line(exc)}") from None
        if not (actual > 0 and abs(actual - rate_hz) <= 0.01 * rate_hz):
            self._close_task()
            raise InputError(f"the NI board cannot sample at {rate_hz:g} Hz (it would run at {actual:g} Hz)")
        self._rate = actual
        self._block = max(1, int(round(self.block_s * actual)))
        self.metadata = {"device": "nidaqmx", "physical_channels": ",".join(self.physical),
                         "iepe_excitation_a": self.excitation_current_a if self.iepe_excitation else 0.0,
                         "daq_range_v": self.range_v}
        return actual

    @property
    def actual_rate_hz(self) -> float:
        if self._rate is None:
            raise RuntimeError("configure() the device first")
        return self._rate

    def start(self) -> None:
        if self._task is None:
            raise RuntimeError("configure() the device first")
        self._task.start()
        self._stop.clear()
        self._thread = threading.Thread(target=self._worker, name="nidaqmx-reader", daemon=True)
        self._thread.start()

    def read_block(self) -> Block | None:
        try:
            item = self._queue.get(timeout=self.read_timeout_s + 2.0)
        except queue.Empty:
            raise DeviceDisconnected(f"no data from the NI board for {self.read_timeout_s + 2:g} s") from None
        if isinstance(item, BaseException):
            raise item
        return item

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=self.read_timeout_s + 5.0)
            self._thread = None
        self._close_task()

    # -- worker thread
    def _worker(self):
        nidaqmx = _import_nidaqmx()
        index = 0  # run sample index of the next sample to read
        read_since_start = 0  # samples read since the task (re)started
        try:
            while not self._stop.is_set():
                try:
                    raw = self._task.read(number_of_samples_per_channel=self._block, timeout=self.read_timeout_s)
                except nidaqmx.errors.DaqError as exc:
                    if getattr(exc, "error_code", None) != OVERRUN_ERROR:
                        raise
                    t_stop = time.monotonic()
                    acquired = int(self._task.in_stream.total_samp_per_chan_acquired)
                    self._task.stop()
                    self._task.start()
                    restart = int(round((time.monotonic() - t_stop) * self._rate))
                    lost = max(0, acquired - read_since_start) + restart
                    ev = Event(index, "overrun", f"DAQmx {OVERRUN_ERROR}: buffer overwritten, task restarted; "
                                                 f"{lost} samples lost ({restart} of them estimated from the restart time)")
                    index += lost
                    read_since_start = 0
                    self._queue.put(Block(np.empty((0, len(self.physical)), np.float32), index, [ev]))
                    continue
                data = np.asarray(raw, dtype=np.float64)
                if data.ndim == 1:
                    data = data[None, :]
                data = data.T.astype(np.float32)  # (n, channels)
                self._queue.put(Block(data, index))
                index += data.shape[0]
                read_since_start += data.shape[0]
        except Exception as exc:
            self._queue.put(DeviceDisconnected(f"NI-DAQmx read failed: {_one_line(exc)}"))

    def _close_task(self):
        if self._task is not None:
            task, self._task = self._task, None
            for fn in (task.stop, task.close):
                try:
                    fn()
                except Exception:
                    pass

    def describe(self) -> str:
        return f"NI-DAQmx {','.join(self.physical)} ({'IEPE from the DAQ' if self.iepe_excitation else 'IEPE from the 480C02'})"


def _one_line(exc) -> str:
    return " ".join(str(exc).split())[:300]
