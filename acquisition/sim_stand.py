"""The simulated stand: accelerometer at E, 480C02 conditioner and DAQ board behind the Device API.

The stand produces fixed-size internal blocks (``block_s``); block k is a pure function of the
scene, the chain, the seed and the filter states carried from block k-1, and its random numbers
come from ``default_rng((seed, k))``. So a run is reproducible for a seed, and the samples after a
gap (overrun, dropped block) are exactly those a fault-free run has at the same indices.

Pacing: ``realtime=True`` delivers each block no earlier than the wall-clock time its last sample
is "measured" and, like a hardware FIFO, keeps only ``buffer_s`` of unread samples: a reader that
falls further behind loses whole blocks, reported as an ``overrun`` event. ``realtime=False``
(``--fast``) generates as fast as the CPU allows.

Fault injection (tests): ``Fault("overrun", at_s, lost_s)`` loses lost_s of samples with an
overrun event, ``Fault("drop", at_s)`` loses the block containing at_s without telling anyone (the
recorder must find the gap), ``Fault("disconnect", at_s)`` raises DeviceDisconnected,
``Fault("clip", at_s)`` adds an impact on aE_t large enough to drive the ADC into its rails.
"""
from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from labtool.acquisition import signal_chain as sc
from labtool.acquisition.device import Block, Device, DeviceDisconnected, Event
from labtool.common.errors import InputError
from labtool.common.recording_attrs import source_name

BOARD_CLOCK_HZ = 12.8e6  # the simulated board divides a 12.8 MHz timebase (as NI DSA boards do)
MIN_RATE_HZ = 1000.0
MAX_RATE_HZ = 51200.0
FAULT_KINDS = ("overrun", "drop", "disconnect", "clip")


@dataclasses.dataclass(frozen=True)
class Fault:
    """An injected fault at time ``at_s`` (s into the run); ``lost_s`` for overruns (s)."""

    kind: str
    at_s: float
    lost_s: float = 0.2

    def __post_init__(self):
        if self.kind not in FAULT_KINDS:
            raise InputError(f"unknown fault '{self.kind}'; known: {', '.join(FAULT_KINDS)}")


def parse_fault(text: str) -> Fault:
    """``kind@seconds`` (e.g. ``overrun@1.5``, ``drop@2``, ``disconnect@3``, ``clip@0.5``)."""
    try:
        kind, at = text.split("@")
        at_s = float(at)
    except ValueError:
        raise InputError(f"fault '{text}' must look like kind@seconds, e.g. overrun@1.5") from None
    if not (math.isfinite(at_s) and 0 <= at_s <= MAX_FAULT_S):
        raise InputError(f"fault '{text}': the time must be a number of seconds from 0 to {MAX_FAULT_S:g}")
    return Fault(kind.strip(), at_s)


MAX_SEED = 2**63 - 1  # stored as an int64 attribute
MAX_FAULT_S = 1e7


def check_seed(seed) -> int:
    """The noise seed as an int in [0, 2**63 - 1]; InputError otherwise."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= int(seed) <= MAX_SEED:
        raise InputError(f"--seed must be an integer from 0 to {MAX_SEED} (2**63 - 1), got {seed!r}")
    return int(seed)


def board_rate(rate_hz: float) -> float:
    """Rate the simulated board really runs at: 12.8 MHz / integer divider (Hz); InputError if out of range."""
    if not (math.isfinite(rate_hz) and MIN_RATE_HZ <= rate_hz <= MAX_RATE_HZ):
        raise InputError(f"the simulated stand samples at {MIN_RATE_HZ:g} to {MAX_RATE_HZ:g} Hz, not {rate_hz:g} Hz")
    return BOARD_CLOCK_HZ / round(BOARD_CLOCK_HZ / rate_hz)


class SimStand(Device):
    """Simulated accelerometer chain + DAQ. Channels: aE_t, aE_n (V), tacho (V)."""

    channel_names = sc.CHANNELS

    def __init__(self, scene: sc.StandScene | None = None, params: sc.ChainParams | None = None, seed: int = 0,
                 duration_s: float | None = None, realtime: bool = True, block_s: float = 0.1,
                 faults=(), buffer_s: float = 1.0, clock=time.monotonic, sleep=time.sleep):
        self.scene = scene or sc.StandScene()
        self.params = params or sc.ChainParams()
        self.seed = check_seed(seed)
        self.duration_s = duration_s
        self.realtime = realtime
        self.block_s = block_s
        self.faults = sorted(faults, key=lambda f: f.at_s)
        self.buffer_s = buffer_s
        self._clock, self._sleep = clock, sleep
        self._rate = None
        self._started = False
        self._stopped = False
        self.metadata = {}

    # -- Device API
    @property
    def input_range_v(self) -> tuple[float, ...]:
        return (float(self.params.adc_range_v),) * len(self.channel_names)

    def buffer_fill(self) -> float | None:
        """Unread samples the simulated FIFO holds now, as a fraction of ``buffer_s`` (realtime only)."""
        if not (self.realtime and self._started) or self._rate is None:
            return None
        backlog = (self._clock() - self._t0) * self._rate - self._k * self._block
        return float(min(1.0, max(0.0, backlog / (self.buffer_s * self._rate))))

    def configure(self, rate_hz: float) -> float:
        self._rate = board_rate(rate_hz)
        self._block = max(1, int(round(self.block_s * self._rate)))
        self._state = sc.new_chain_state(self.params, self._rate)
        self._state.hp_level = sc.dc_level(self.scene, self.params)
        self._k = 0  # next internal block to generate
        self._n_total = None if self.duration_s is None else int(round(self.duration_s * self._rate))
        self._fault_at = [(int(f.at_s * self._rate), f) for f in self.faults]
        chain = self.params.attrs()
        self.metadata = {"device": "sim", "seed": self.seed, **self.scene.attrs(), **chain,
                         "block_samples": self._block, "sensor_model": chain.get("sensor", ""),
                         "conditioner_model": chain.get("conditioner", "")}
        if self.scene.mode == "run":  # the operating point is the simulated scene's own (common/recording_attrs)
            for name in ("law", "cam_speed_rpm", "Fu_N", "backlash_mm", "jt_factor"):
                self.metadata[source_name(name)] = "simulated stand scene"
        return self._rate

    @property
    def actual_rate_hz(self) -> float:
        if self._rate is None:
            raise RuntimeError("configure() the device first")
        return self._rate

    def start(self) -> None:
        if self._rate is None:
            self.configure(10000.0)
        self._t0 = self._clock()
        self._started = True

    def stop(self) -> None:
        self._stopped = True

    def read_block(self) -> Block | None:
        if not self._started or self._stopped:
            raise RuntimeError("read_block() outside start()/stop()")
        events: list[Event] = []
        if self._n_total is not None and self._k * self._block >= self._n_total:
            return None
        if self.realtime:
            events += self._pace()
        while True:
            first = self._k * self._block
            if self._n_total is not None and first >= self._n_total:
                return Block(np.empty((0, 3), np.float32), first, events) if events else None
            fault = self._take_fault(first, first + self._block)
            if fault is None:
                break
            if fault.kind == "disconnect":
                raise DeviceDisconnected(f"simulated stand disconnected at sample {first} ({first / self._rate:.3f} s)")
            if fault.kind == "overrun":
                n_lost = max(1, int(math.ceil(fault.lost_s * self._rate / self._block)))
                for _ in range(n_lost):
                    self._generate()  # the board measured them; nobody read them in time
                events.append(Event(first, "overrun", f"injected: {n_lost * self._block} samples lost"))
                continue
            if fault.kind == "drop":
                self._generate()  # produced, then lost in transit: no event, the gap tells
                continue
            if fault.kind == "clip":
                data, clip_events = self._generate(impact_at=int(fault.at_s * self._rate) - first)
                return self._finish(data, first, events + clip_events)
        data, clip_events = self._generate()
        return self._finish(data, first, events + clip_events)

    # -- internals
    def _finish(self, data, first, events):
        if self._n_total is not None:
            data = data[: max(0, self._n_total - first)]
        return Block(data, first, events)

    def _take_fault(self, lo, hi):
        for i, (idx, f) in enumerate(self._fault_at):
            if lo <= idx < hi or (idx < lo and f.kind != "clip"):
                del self._fault_at[i]
                return f
        return None

    def _pace(self) -> list[Event]:
        """Wait for the block's last sample; drop what a full hardware buffer has overwritten."""
        events = []
        now = self._clock() - self._t0
        produced = int(now * self._rate)
        first = self._k * self._block
        backlog = produced - first
        limit = int(self.buffer_s * self._rate)
        if backlog > limit:
            n_lost = int(math.ceil((backlog - limit) / self._block))
            if self._n_total is not None:
                n_lost = min(n_lost, max(0, -(-(self._n_total - first) // self._block)))
            for _ in range(n_lost):
                self._generate()
            events.append(Event(first, "overrun", f"reader {backlog / self._rate:.3f} s behind, buffer {self.buffer_s:g} s: "
                                                  f"{n_lost * self._block} samples lost"))
        ready_at = (self._k + 1) * self._block / self._rate
        wait = ready_at - (self._clock() - self._t0)
        if wait > 0:
            self._sleep(wait)
        return events

    def _generate(self, impact_at: int | None = None):
        """Internal block k: (block, 3) float32 volts after the ADC, and its clip events."""
        os_ = self.params.oversample
        n_os = self._block * os_
        first = self._k * self._block
        t_os = (first * os_ + np.arange(n_os)) / (self._rate * os_)
        rng = np.random.default_rng((self.seed, self._k))
        extra = None
        if impact_at is not None:
            extra = np.zeros((n_os, 2))
            # a 0.5 ms half-sine impact (backlash hit) three times the ADC's reach on aE_t
            width = max(4, int(0.5e-3 * self._rate * os_))
            i0 = min(max(0, impact_at * os_), n_os - width)
            amp = 3.0 * self.params.adc_range_v * self.params.ka_m_s2_per_v[0]
            extra[i0:i0 + width, 0] = amp * np.sin(np.pi * np.arange(width) / width)
        volts_os, self._state = sc.chain_block(self.scene, self.params, self._state, t_os, rng, extra_m_s2=extra)
        data, clipped = sc.adc(sc.decimate(volts_os, os_), self.params)
        events = []
        for c in np.flatnonzero(clipped.any(axis=0)):
            rows = np.flatnonzero(clipped[:, c])
            events.append(Event(first + int(rows[0]), "clip",
                                f"{self.channel_names[c]}: {rows.size} samples beyond +-{self.params.adc_range_v:g} V"))
        self._k += 1
        return data, events

    def describe(self) -> str:
        s = self.scene
        if s.mode == "calibration":
            return f"simulated calibration: {s.cal_accel:g} m/s^2 peak at {s.cal_freq:g} Hz on {s.cal_channel}"
        return f"simulated stand: {s.law} law, {s.cam_speed_rpm:g} rpm, Fu {s.Fu:g} N, j {s.backlash * 1e3:g} mm"
