"""The narrow driver interface between hardware and everything else: devices deliver Blocks.

A driver is configured (channels, rate), started, read block by block, and stopped. Each
:class:`Block` carries the index of its first sample in the run's sample count, so a gap (samples
the hardware produced but nobody read) is visible as a jump in ``first_index`` and is never joined
silently. Overruns, faults and clipping travel with the block as :class:`Event` objects.

Everything above this module (recorder, CLI, tests) sees only ``Device`` and ``Block``.
"""
from __future__ import annotations

import abc
import dataclasses

import numpy as np

from labtool.common.errors import InputError
from labtool.common.recording_format import EVENT_KINDS


@dataclasses.dataclass(frozen=True)
class Event:
    """Something that happened at sample ``index`` (0-based, run sample count).

    kind: one of EVENT_KINDS (docs/architecture.md recording format v1); detail: free text for a human.
    """

    index: int
    kind: str
    detail: str = ""

    def __post_init__(self):
        if self.kind not in EVENT_KINDS:
            raise ValueError(f"unknown event kind {self.kind!r}")


@dataclasses.dataclass
class Block:
    """A block of samples as the device produced them.

    data         (n_samples, n_channels) raw volts at the DAQ input (float32 or float64)
    first_index  index of data[0] in the run's sample count (samples at the device rate)
    events       overruns, gaps, faults, clipping found in or before this block
    """

    data: np.ndarray
    first_index: int
    events: list[Event] = dataclasses.field(default_factory=list)

    @property
    def n(self) -> int:
        return int(self.data.shape[0])

    @property
    def end_index(self) -> int:
        """Index one past the block's last sample."""
        return self.first_index + self.n


class DeviceDisconnected(Exception):
    """The device stopped delivering (cable pulled, USB gone). The run ends; data so far is kept."""


class Device(abc.ABC):
    """Driver interface. Lifecycle: ``configure`` -> ``start`` -> ``read_block``* -> ``stop``.

    ``read_block`` blocks until the next block is ready (real-time devices) and returns None once
    a finite run has delivered everything. It raises :class:`DeviceDisconnected` when the device
    goes away. ``actual_rate_hz`` is the sample rate the hardware really runs at (Hz), which may
    differ slightly from the requested one (clock dividers); recordings store that one.
    """

    channel_names: tuple[str, ...] = ()
    #: attributes worth storing in the recording (sensor, scene, seed, ...); never required
    metadata: dict

    @abc.abstractmethod
    def configure(self, rate_hz: float) -> float:
        """Set the sample rate (Hz); return the rate really used. InputError if impossible."""

    @abc.abstractmethod
    def start(self) -> None:
        """Start the continuous acquisition."""

    @abc.abstractmethod
    def read_block(self) -> Block | None:
        """Next block of samples, None when a finite run is exhausted."""

    @abc.abstractmethod
    def stop(self) -> None:
        """Stop the acquisition and release the hardware; safe to call twice."""

    @property
    @abc.abstractmethod
    def actual_rate_hz(self) -> float:
        """Sample rate the device really runs at (Hz)."""

    @property
    def input_range_v(self) -> tuple[float, ...]:
        """+-input range of every channel (V) as the hardware really has it; NaN where unknown."""
        return tuple(float("nan") for _ in self.channel_names)

    def buffer_fill(self) -> float | None:
        """Fraction (0..1) of the device's sample buffer holding unread samples; None if unknown.
        Near 1 the next block overruns: the reader is not keeping up."""
        return None

    def describe(self) -> str:
        return type(self).__name__


def parse_device(spec: str) -> tuple[str, str]:
    """Split ``sim`` or ``nidaqmx:<physical channels>`` into (kind, argument); InputError otherwise."""
    spec = (spec or "").strip()
    if spec == "sim":
        return "sim", ""
    if spec.startswith("nidaqmx:"):
        arg = spec.split(":", 1)[1].strip()
        if not arg:
            raise InputError("device 'nidaqmx:' needs physical channels, e.g. nidaqmx:Dev1/ai0:2")
        return "nidaqmx", arg
    if spec == "nidaqmx":
        raise InputError("device 'nidaqmx' needs physical channels, e.g. --device nidaqmx:Dev1/ai0:2")
    raise InputError(f"unknown device '{spec}'; use 'sim' or 'nidaqmx:<physical channels>' (e.g. nidaqmx:Dev1/ai0:2)")
