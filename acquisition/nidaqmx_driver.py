"""NI-DAQmx driver: the configured channels (nidaqmx_config), continuous buffered reads through
``nidaqmx.stream_readers.AnalogMultiChannelReader`` into a preallocated array, every setting read
back from the task and stored in the recording.

Uses the official ``nidaqmx`` package, imported when a device is configured so labtool works
without it (optional extra ``pip install labtool[nidaqmx]``). Tested against a fake built with
``unittest.mock.create_autospec`` from the real ``nidaqmx`` classes (tests/test_acq_nidaqmx.py) and,
opt-in, against an NI MAX simulated device (tests/test_nidaqmx_simulated.py, docs/acquisition.md).

Channels. Accelerometer channels are IEPE accelerometer channels (``add_ai_accel_chan``) declared
with 1000 mV/g in units of g, so the numbers DAQmx returns are the volts at the input: the recording
stays raw volts like any device, and Ka is applied downstream. A TEDS channel
(``add_teds_ai_accel_chan``) is scaled by the sensor's own sensitivity S; its readings (g) are
turned back into volts (x S / 1000) here, and S is stored. Excitation is off unless
``iepe_excitation_a`` > 0 (the PCB 480C02 powers the sensor). Tacho and other channels are voltage
channels. Range, terminal configuration and coupling are set per channel.

Reads. A worker thread reads ``block_s`` of samples per channel at a time from a continuous task
(buffer ``buffer_s``) and queues Blocks. Everything set is read back after configuration (channel
ranges as the board coerced them, terminal, coupling, excitation, sensitivity, the real sample
clock rate and source, the start trigger); a setting the board did not take is refused, and a rate
more than 1 % from the request is refused. DAQmx error -200279 (samples no longer available: the
reader fell behind and the buffer was overwritten) is an overrun: the task is restarted, the lost
samples are counted from ``in_stream.total_samp_per_chan_acquired`` plus the restart time, and the
next block starts that many samples later (an ``overrun`` event; the recorder writes the gap). Any
other DAQmx error in the worker ends the run as a disconnect.
"""
from __future__ import annotations

import json
import math
import queue
import re
import threading
import time

import numpy as np

from labtool.acquisition import nidaqmx_config as nc
from labtool.acquisition.device import Block, Device, DeviceDisconnected, Event
from labtool.common.errors import InputError

OVERRUN_ERROR = -200279  # DAQmxErrors.SAMPLES_NO_LONGER_AVAILABLE
DEFAULT_NAMES = nc.ROLES

CHANNEL_READBACK = ("ai_meas_type", "ai_min", "ai_max", "ai_rng_low", "ai_rng_high", "ai_term_cfg", "ai_coupling")
ACCEL_READBACK = ("ai_excit_src", "ai_excit_val", "ai_accel_sensitivity", "ai_accel_sensitivity_units", "ai_accel_units")
TIMING_READBACK = ("samp_clk_rate", "samp_clk_src", "samp_quant_samp_mode", "samp_quant_samp_per_chan")
TRIGGER_READBACK = {"none": ("trig_type",), "digital": ("trig_type", "dig_edge_src", "dig_edge_edge"),
                    "analog": ("trig_type", "anlg_edge_src", "anlg_edge_slope", "anlg_edge_lvl")}


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
    if not 1 <= len(out) <= nc.MAX_CHANNELS:
        raise InputError(f"NI-DAQmx: 1 to {nc.MAX_CHANNELS} channels expected, got {len(out)}")
    if len(set(out)) != len(out):
        raise InputError(f"NI-DAQmx: channel listed twice in '{spec}'")
    return out


def import_nidaqmx():
    """The nidaqmx package, or InputError saying how to install it."""
    try:
        import nidaqmx
        import nidaqmx.constants
        import nidaqmx.errors
        import nidaqmx.stream_readers
        import nidaqmx.system
        return nidaqmx
    except ImportError:
        raise InputError("the nidaqmx package is not installed; install it with: pip install 'labtool[nidaqmx]'") from None


def _reader(task):
    from nidaqmx.stream_readers import AnalogMultiChannelReader
    return AnalogMultiChannelReader(task.in_stream)


class NIDAQmxDevice(Device):
    """Continuous acquisition on an NI board through nidaqmx (see module docstring).

    config          a DeviceConfig (nidaqmx_config.build), or physical channels ``Dev1/ai0:2``
    task_factory    () -> nidaqmx.Task (tests: an autospec fake)
    reader_factory  (task) -> an object with ``read_many_sample(data, number_of_samples_per_channel,
                    timeout)`` filling ``data`` (channels, samples) (default: AnalogMultiChannelReader)
    physical_channel_factory  (name) -> nidaqmx.system.PhysicalChannel (TEDS)
    """

    def __init__(self, config, task_factory=None, reader_factory=None, physical_channel_factory=None,
                 read_timeout_s: float = 10.0, block_s: float | None = None, iepe_excitation_a: float | None = None):
        if isinstance(config, str):
            config = nc.build(expand_channels(config), iepe_excitation_a=iepe_excitation_a)
        self.config: nc.DeviceConfig = config
        self.channel_names = config.names
        self.physical = [c.physical for c in config.channels]
        self.block_s = config.block_s if block_s is None else block_s
        self.buffer_s = config.buffer_s
        self.read_timeout_s = read_timeout_s
        self._task_factory = task_factory
        self._reader_factory = reader_factory or _reader
        self._phys_factory = physical_channel_factory
        self._task = None
        self._rate = None
        self._thread = None
        self._queue: queue.Queue = queue.Queue()
        self._stop = threading.Event()
        self._fill = None
        self._range = tuple(math.nan for _ in self.channel_names)
        self._to_volts = np.ones(len(self.channel_names))
        self.readback: dict = {}
        self.ka_nominal = tuple(c.nominal_ka for c in config.channels)
        self.metadata = {}

    # -- Device API
    def configure(self, rate_hz: float) -> float:
        nidaqmx = import_nidaqmx()
        try:
            task = self._task_factory() if self._task_factory else nidaqmx.Task()
        except Exception as exc:  # no driver / no runtime
            raise InputError(f"NI-DAQmx is not available: {_one_line(exc)}") from None
        self._task = task
        try:
            teds = _apply(task, self.config, rate_hz, nidaqmx, self._phys_factory)
            self.readback = read_back(task, self.config)
            self.readback["teds"] = teds
            actual = float(self.readback["timing"]["samp_clk_rate"])
            self._reader = self._reader_factory(task)
        except nidaqmx.errors.DaqError as exc:
            self._close_task()
            raise InputError(f"NI-DAQmx refused the configuration ({','.join(self.physical)} at {rate_hz:g} Hz): "
                             f"{_one_line(exc)}") from None
        problems = check_readback(self.config, self.readback, rate_hz)
        if problems:
            self._close_task()
            raise InputError("the NI board did not take the configuration: " + "; ".join(problems))
        self._rate = actual
        self._block = max(1, int(round(self.block_s * actual)))
        self._buf = np.zeros((len(self.channel_names), self._block), dtype=np.float64)  # DAQmx reads into it
        self._range = tuple(min(abs(float(ch["ai_rng_low"])), float(ch["ai_rng_high"]))
                            for ch in self.readback["channels"].values())
        self._to_volts = np.array([teds[c.name]["sensitivity_mv_per_g"] / 1000.0 if c.name in teds else 1.0
                                   for c in self.config.channels])
        self.ka_nominal = tuple(nc.G0 / (teds[c.name]["sensitivity_mv_per_g"] / 1000.0) if c.name in teds else c.nominal_ka
                                for c in self.config.channels)
        self.metadata = self._metadata()
        return actual

    @property
    def actual_rate_hz(self) -> float:
        if self._rate is None:
            raise RuntimeError("configure() the device first")
        return self._rate

    @property
    def input_range_v(self) -> tuple[float, ...]:
        return self._range

    def buffer_fill(self) -> float | None:
        return self._fill

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
        nidaqmx = import_nidaqmx()
        index = 0  # run sample index of the next sample to read
        read_since_start = 0  # samples read since the task (re)started
        bufsize = max(1, int(self.readback.get("in_stream", {}).get("input_buf_size") or self.buffer_s * self._rate))
        try:
            while not self._stop.is_set():
                try:
                    n = self._reader.read_many_sample(self._buf, number_of_samples_per_channel=self._block,
                                                      timeout=self.read_timeout_s)
                except nidaqmx.errors.DaqError as exc:
                    if getattr(exc, "error_code", None) != OVERRUN_ERROR:
                        raise
                    index, lost_event = self._restart_after_overrun(index, read_since_start)
                    read_since_start = 0
                    self._queue.put(Block(np.empty((0, len(self.physical)), np.float32), index, [lost_event]))
                    continue
                n = self._block if n is None else int(n)
                data = (self._buf[:, :n].T * self._to_volts).astype(np.float32)  # (n, channels), volts
                self._queue.put(Block(data, index))
                index += n
                read_since_start += n
                self._fill = min(1.0, float(self._task.in_stream.avail_samp_per_chan) / bufsize)
        except Exception as exc:
            self._queue.put(DeviceDisconnected(f"NI-DAQmx read failed: {_one_line(exc)}"))

    def _restart_after_overrun(self, index: int, read_since_start: int):
        t_stop = time.monotonic()
        acquired = int(self._task.in_stream.total_samp_per_chan_acquired)
        self._task.stop()
        self._task.start()
        restart = int(round((time.monotonic() - t_stop) * self._rate))
        lost = max(0, acquired - read_since_start) + restart
        ev = Event(index, "overrun", f"DAQmx {OVERRUN_ERROR}: buffer overwritten, task restarted; "
                                     f"{lost} samples lost ({restart} of them estimated from the restart time)")
        return index + lost, ev

    def _close_task(self):
        if self._task is not None:
            task, self._task = self._task, None
            for fn in (task.stop, task.close):
                try:
                    fn()
                except Exception:
                    pass

    def _metadata(self) -> dict:
        cfg, rb = self.config, self.readback
        chans = list(rb["channels"].values())
        meta = {"device": "nidaqmx", "physical_channels": ",".join(self.physical),
                "ni_config_source": cfg.source,
                "ni_readback_json": json.dumps(rb, sort_keys=True, default=str),
                "ni_block_samples": int(self._block), "ni_buffer_s": float(cfg.buffer_s)}
        for prop in CHANNEL_READBACK + ACCEL_READBACK:
            vals = [ch.get(prop, "") for ch in chans]
            numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals if v != "")
            meta[f"ni_{prop}"] = np.array([float("nan") if v == "" else v for v in vals], float) if numeric \
                else np.array([str(v) for v in vals], dtype=object)
        for group in ("timing", "trigger", "in_stream"):
            for k, v in rb.get(group, {}).items():
                meta[f"ni_{group}_{k}"] = v
        for key in ("sensor_model", "sensor_serial"):
            meta[f"channel_{key}"] = np.array([getattr(c, key) or rb["teds"].get(c.name, {}).get(key, "")
                                               for c in cfg.channels], dtype=object)
        meta["channel_conditioner_gain"] = np.array([c.conditioner_gain for c in cfg.channels], float)
        meta["channel_sensitivity_mv_per_g"] = np.array(
            [rb["teds"][c.name]["sensitivity_mv_per_g"] if c.name in rb["teds"] else
             (math.nan if c.sensitivity_mv_per_g is None else c.sensitivity_mv_per_g) for c in cfg.channels], float)
        if cfg.trigger.type != "none":
            meta["trigger"] = (f"{cfg.trigger.type} {cfg.trigger.edge} on {cfg.trigger.source}"
                               + (f" at {cfg.trigger.level_v:g} V" if cfg.trigger.level_v is not None else "")
                               + (f", {cfg.trigger.pretrigger_samples} pre-trigger samples (software trigger)"
                                  if cfg.trigger.software else " (hardware start trigger)"))
        accel = [r for c, r in zip(cfg.channels, self._range) if c.kind == "accel"]
        if accel and all(r == accel[0] for r in accel):
            meta["adc_range_v"] = float(accel[0])  # processing's clip detection reads this (one range)
        return meta

    def describe(self) -> str:
        iepe = any(c.iepe_excitation_a > 0 for c in self.config.channels)
        return f"NI-DAQmx {','.join(self.physical)} ({'IEPE from the DAQ' if iepe else 'IEPE from the 480C02'})"


def _apply(task, cfg: nc.DeviceConfig, rate_hz: float, nidaqmx, phys_factory) -> dict:
    """Set every channel, the sample clock and the hardware start trigger on ``task``.
    Returns what TEDS sensors said (name -> sensitivity_mv_per_g, sensor_model, sensor_serial)."""
    c = nidaqmx.constants
    term = {"default": c.TerminalConfiguration.DEFAULT, "rse": c.TerminalConfiguration.RSE,
            "nrse": c.TerminalConfiguration.NRSE, "diff": c.TerminalConfiguration.DIFF,
            "pseudodiff": c.TerminalConfiguration.PSEUDO_DIFF}
    teds = {}
    for ch in cfg.channels:
        common = dict(name_to_assign_to_channel=ch.name, terminal_config=term[ch.terminal],
                      min_val=-ch.range_v, max_val=ch.range_v)
        if ch.kind == "accel":
            excit = dict(current_excit_source=c.ExcitationSource.INTERNAL if ch.iepe_excitation_a > 0 else c.ExcitationSource.NONE,
                         current_excit_val=ch.iepe_excitation_a)
            if ch.teds:
                pc = (phys_factory or nidaqmx.system.PhysicalChannel)(ch.physical)
                pc.configure_teds()
                # a TEDS channel's limits are in g: set them once the sensor's sensitivity is known
                task.ai_channels.add_teds_ai_accel_chan(ch.physical, name_to_assign_to_channel=ch.name,
                                                        terminal_config=term[ch.terminal], units=c.AccelUnits.G, **excit)
                aic = task.ai_channels[ch.name]
                s_mv_g = float(aic.ai_accel_sensitivity)
                aic.ai_max, aic.ai_min = ch.range_v / (s_mv_g / 1000.0), -ch.range_v / (s_mv_g / 1000.0)
                teds[ch.name] = {"sensitivity_mv_per_g": s_mv_g, "sensor_model": f"{pc.teds_mfg_id}/{pc.teds_model_num}",
                                 "sensor_serial": str(pc.teds_serial_num)}
            else:
                task.ai_channels.add_ai_accel_chan(ch.physical, units=c.AccelUnits.G, sensitivity=1000.0,
                                                   sensitivity_units=c.AccelSensitivityUnits.MILLIVOLTS_PER_G,
                                                   **common, **excit)
        else:
            task.ai_channels.add_ai_voltage_chan(ch.physical, **common)
        if ch.coupling != "default":
            task.ai_channels[ch.name].ai_coupling = c.Coupling.AC if ch.coupling == "ac" else c.Coupling.DC
    task.timing.cfg_samp_clk_timing(rate_hz, source=cfg.sample_clock_source, sample_mode=c.AcquisitionType.CONTINUOUS,
                                    samps_per_chan=max(1000, int(cfg.buffer_s * rate_hz)))
    tr = cfg.trigger
    if tr.type == "digital" and not tr.software:
        task.triggers.start_trigger.cfg_dig_edge_start_trig(
            trigger_source=tr.source, trigger_edge=c.Edge.RISING if tr.edge == "rising" else c.Edge.FALLING)
    elif tr.type == "analog" and not tr.software:
        task.triggers.start_trigger.cfg_anlg_edge_start_trig(
            trigger_source=nc.trigger_channel(cfg).physical,
            trigger_slope=c.Slope.RISING if tr.edge == "rising" else c.Slope.FALLING, trigger_level=tr.level_v)
    return teds


def _plain(v):
    """A read-back property as JSON-friendly data (enums by name)."""
    if hasattr(v, "name") and hasattr(v, "value") and not isinstance(v, (int, float, str)):
        return v.name
    if isinstance(v, bool) or isinstance(v, (int, str)):
        return v
    if isinstance(v, float):
        return v
    try:
        return float(v)
    except (TypeError, ValueError):
        return str(v)


def read_back(task, cfg: nc.DeviceConfig) -> dict:
    """What the task really holds, property by property (nidaqmx names), for the recording."""
    chans = {}
    for ch in cfg.channels:
        aic = task.ai_channels[ch.name]
        props = CHANNEL_READBACK + (ACCEL_READBACK if ch.kind == "accel" else ())
        chans[ch.name] = {"physical_channel": str(aic.physical_channel.name),
                          **{p: _plain(getattr(aic, p)) for p in props}}
    timing = {p: _plain(getattr(task.timing, p)) for p in TIMING_READBACK}
    hw = cfg.trigger.type if not cfg.trigger.software else "none"
    trigger = {p: _plain(getattr(task.triggers.start_trigger, p)) for p in TRIGGER_READBACK[hw]}
    return {"channels": chans, "timing": timing, "trigger": trigger,
            "in_stream": {"input_buf_size": _plain(task.in_stream.input_buf_size)}}


def check_readback(cfg: nc.DeviceConfig, rb: dict, rate_hz: float) -> list[str]:
    """Differences between what was asked and what the board holds (empty when it took it all)."""
    out = []
    for ch in cfg.channels:
        got = rb["channels"][ch.name]
        where = f"{ch.name} ({ch.physical})"
        if not (float(got["ai_rng_high"]) >= ch.range_v * (1 - 1e-6) and -float(got["ai_rng_low"]) >= ch.range_v * (1 - 1e-6)):
            out.append(f"{where} range {got['ai_rng_low']:g}..{got['ai_rng_high']:g} V does not cover +-{ch.range_v:g} V")
        want_term = {"rse": "RSE", "nrse": "NRSE", "diff": "DIFF", "pseudodiff": "PSEUDO_DIFF"}.get(ch.terminal)
        if want_term and got["ai_term_cfg"] != want_term:
            out.append(f"{where} terminal configuration is {got['ai_term_cfg']}, not {want_term}")
        if ch.coupling != "default" and got["ai_coupling"] != ch.coupling.upper():
            out.append(f"{where} coupling is {got['ai_coupling']}, not {ch.coupling.upper()}")
        if ch.kind == "accel":
            want_src = "INTERNAL" if ch.iepe_excitation_a > 0 else "NONE"
            if got["ai_excit_src"] != want_src or (ch.iepe_excitation_a > 0 and
                                                    not math.isclose(float(got["ai_excit_val"]), ch.iepe_excitation_a, rel_tol=1e-6)):
                out.append(f"{where} excitation is {got['ai_excit_src']} {got['ai_excit_val']} A, "
                           f"not {want_src} {ch.iepe_excitation_a:g} A")
            if not ch.teds and not math.isclose(float(got["ai_accel_sensitivity"]), 1000.0, rel_tol=1e-9):
                out.append(f"{where} sensitivity is {got['ai_accel_sensitivity']}, not 1000 mV/g (volts out)")
    actual = float(rb["timing"]["samp_clk_rate"])
    if not (actual > 0 and abs(actual - rate_hz) <= 0.01 * rate_hz):
        out.append(f"the board cannot sample at {rate_hz:g} Hz (it would run at {actual:g} Hz)")
    if cfg.sample_clock_source and str(rb["timing"]["samp_clk_src"]).lstrip("/") != cfg.sample_clock_source.lstrip("/"):
        out.append(f"sample clock source is {rb['timing']['samp_clk_src']}, not {cfg.sample_clock_source}")
    hw = cfg.trigger.type if not cfg.trigger.software else "none"
    want_trig = {"none": "NONE", "digital": "DIGITAL_EDGE", "analog": "ANALOG_EDGE"}[hw]
    if rb["trigger"]["trig_type"] != want_trig:
        out.append(f"start trigger is {rb['trigger']['trig_type']}, not {want_trig}")
    return out


def list_devices(system=None) -> list[dict]:
    """What NI-DAQmx sees: one dict per device (name, product type, serial, simulated, AI channels,
    max single-channel rate, AI voltage ranges). InputError when the package or the driver is absent."""
    nidaqmx = import_nidaqmx()
    try:
        system = system or nidaqmx.system.System.local()
        driver = system.driver_version
        devices = list(system.devices)
    except Exception as exc:
        raise InputError(f"NI-DAQmx driver not found: {_one_line(exc)}; install NI-DAQmx "
                         "(Linux: the ni-daqmx packages; see docs/acquisition.md)") from None
    out = []
    for d in devices:
        info = {"driver": f"{driver.major_version}.{driver.minor_version}.{driver.update_version}", "name": d.name}
        for key, prop in (("product_type", "product_type"), ("serial_num", "serial_num"),
                          ("simulated", "is_simulated"), ("ai_max_single_chan_rate_hz", "ai_max_single_chan_rate")):
            try:
                info[key] = _plain(getattr(d, prop))
            except Exception as exc:  # a property some devices do not have
                info[key] = f"n/a ({_one_line(exc)[:60]})"
        try:
            info["ai_channels"] = [pc.name for pc in d.ai_physical_chans]
        except Exception:
            info["ai_channels"] = []
        try:
            r = list(d.ai_voltage_rngs)
            info["ai_ranges_v"] = [f"{r[i]:g}..{r[i + 1]:g}" for i in range(0, len(r) - 1, 2)]
        except Exception:
            info["ai_ranges_v"] = []
        out.append(info)
    return out


def _one_line(exc) -> str:
    return " ".join(str(exc).split())[:300]
