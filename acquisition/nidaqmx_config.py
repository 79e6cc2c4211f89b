"""NI-DAQmx device configuration: channels by role, ranges, terminals, coupling, IEPE, sensitivity
or TEDS, sample clock, start trigger. Pure: parsed and checked here, applied by nidaqmx_driver.

One schema, two spellings. A TOML device file::

    [device]
    sample_clock_source = ""         # "" = the board's own clock; e.g. "/cDAQ1/PFI0"
    buffer_s = 10.0                  # DAQmx input buffer (s of samples)
    block_s = 0.1                    # samples per read (s)

    [trigger]
    type = "digital"                 # none | digital (edge on a terminal) | analog (level on a channel)
    source = "/Dev1/PFI0"            # digital: a terminal; analog: a channel name (e.g. "tacho") or physical
    edge = "rising"                  # rising | falling
    level_v = 2.5                    # analog only (V)
    pretrigger_samples = 0           # > 0: keep that many samples before the trigger (software trigger)

    [channels.aE_t]                  # the name is the role: aE_t, aE_n, tacho, or any other
    physical = "Dev1/ai0"
    kind = "accel"                   # accel (IEPE accelerometer channel) | voltage; default by role
    range_v = 5.0                    # +-V at the DAQ input
    terminal = "default"             # default | rse | nrse | diff | pseudodiff
    coupling = "ac"                  # default | ac | dc
    iepe_excitation_a = 0.0          # 0 = off (the 480C02 powers the sensor); e.g. 0.004 = 4 mA from the DAQ
    sensitivity_mv_per_g = 10.0      # sensor sensitivity (nominal: Ka then follows with the gain)
    conditioner_gain = 10.0          # 480C02 gain between sensor and DAQ (1 if none)
    teds = false                     # read the sensitivity from the sensor's TEDS instead
    sensor_model = "PCB 352A76"
    sensor_serial = "LW12345"

    [metadata]                       # run metadata (common/recording_attrs.py RUN_METADATA)
    operator = "A. N. Other"

or the same keys on the command line, ``--ni aE_t.range_v=5 --ni trigger.type=digital`` (values
read as TOML: ``5``, ``true``, ``"text"`` or bare text), which override the file. ``--device
nidaqmx:Dev1/ai0:2`` names the physical channels of aE_t, aE_n, tacho (then ai3, ... for more).

Recorded values stay volts at the DAQ input for every channel (the recording format): Ka per
channel = 9.80665 * 1000 / (sensitivity_mv_per_g * conditioner_gain) m/s^2 per V when a sensitivity
is known (nominal, stated as such), else NaN (calibrate).
"""
from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path

from labtool.common.errors import InputError

G0 = 9.80665  # m/s^2 per g (standard gravity: the unit of accelerometer sensitivities in mV/g)
ROLES = ("aE_t", "aE_n", "tacho")
TERMINALS = ("default", "rse", "nrse", "diff", "pseudodiff")
COUPLINGS = ("default", "ac", "dc")
TRIGGERS = ("none", "digital", "analog")
EDGES = ("rising", "falling")
MAX_CHANNELS = 32

CHANNEL_KEYS = ("physical", "kind", "range_v", "terminal", "coupling", "iepe_excitation_a", "sensitivity_mv_per_g",
                "conditioner_gain", "teds", "sensor_model", "sensor_serial")
DEVICE_KEYS = ("sample_clock_source", "buffer_s", "block_s")
TRIGGER_KEYS = ("type", "source", "edge", "level_v", "pretrigger_samples")


@dataclasses.dataclass(frozen=True)
class ChannelConfig:
    """One analog input (SI, volts at the DAQ input)."""

    name: str
    physical: str
    kind: str = "accel"
    range_v: float = 10.0
    terminal: str = "default"
    coupling: str = "default"
    iepe_excitation_a: float = 0.0
    sensitivity_mv_per_g: float | None = None
    conditioner_gain: float = 1.0
    teds: bool = False
    sensor_model: str = ""
    sensor_serial: str = ""

    @property
    def nominal_ka(self) -> float:
        """m/s^2 per V at the DAQ input from the stated sensitivity and gain (NaN when unknown)."""
        if self.kind != "accel" or self.sensitivity_mv_per_g is None:
            return math.nan
        return G0 * 1000.0 / (self.sensitivity_mv_per_g * self.conditioner_gain)


@dataclasses.dataclass(frozen=True)
class TriggerConfig:
    type: str = "none"
    source: str = ""
    edge: str = "rising"
    level_v: float | None = None
    pretrigger_samples: int = 0

    @property
    def software(self) -> bool:
        """DAQmx keeps pre-trigger samples only with a reference trigger in a finite acquisition; a
        continuous recording with pre-trigger samples is triggered in software (session.py)."""
        return self.type != "none" and self.pretrigger_samples > 0


@dataclasses.dataclass(frozen=True)
class DeviceConfig:
    channels: tuple[ChannelConfig, ...]
    sample_clock_source: str = ""
    buffer_s: float = 10.0
    block_s: float = 0.1
    trigger: TriggerConfig = TriggerConfig()
    metadata: dict = dataclasses.field(default_factory=dict)
    source: str = "command line"

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.channels)

    def channel(self, name: str) -> ChannelConfig:
        for c in self.channels:
            if c.name == name:
                return c
        raise KeyError(name)


def default_names(n: int) -> tuple[str, ...]:
    """Roles of n physical channels given in order: aE_t, aE_n, tacho, then ai3, ai4, ..."""
    return ROLES[:n] if n <= 3 else ROLES + tuple(f"ai{i}" for i in range(3, n))


def default_kind(name: str) -> str:
    """The accelerometer roles are accel channels; the tacho and any other channel are voltage."""
    return "accel" if name in ("aE_t", "aE_n") else "voltage"


def parse_override(text: str) -> tuple[str, str, object]:
    """``aE_t.range_v=5`` -> ("channels.aE_t", "range_v", 5.0); ``trigger.type=digital`` ->
    ("trigger", "type", "digital"). Values are read as TOML, else kept as text."""
    key, sep, raw = text.partition("=")
    table, dot, field = key.strip().rpartition(".")
    if not sep or not dot or not table or not field:
        raise InputError(f"--ni '{text}' must look like CHANNEL.KEY=VALUE, trigger.KEY=VALUE or device.KEY=VALUE")
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    if table not in ("device", "trigger", "metadata"):
        table = f"channels.{table}"
    return table, field, value


def load_device_file(path) -> dict:
    """The device file as nested dicts; InputError if it cannot be read or is not TOML."""
    p = Path(path)
    try:
        return tomllib.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"device file {p} does not exist") from None
    except IsADirectoryError:
        raise InputError(f"device file {p} is a folder; give a TOML file") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"device file {p} is not valid TOML: {' '.join(str(exc).split())}") from None


def build(physical_spec: list[str] | None, doc: dict | None = None, overrides=(), source: str = "command line",
          iepe_excitation_a: float | None = None) -> DeviceConfig:
    """The checked configuration from physical channels (``--device nidaqmx:...``), a device file's
    document and ``--ni`` overrides (in that order of precedence: overrides win)."""
    doc = {k: (dict(v) if isinstance(v, dict) else v) for k, v in (doc or {}).items()}
    unknown = set(doc) - {"device", "trigger", "channels", "metadata"}
    if unknown:
        raise InputError(f"{source}: unknown tables {', '.join(sorted(unknown))}; known: device, trigger, channels, metadata")
    chans = {name: dict(t) for name, t in _table(doc, "channels", source).items()}
    for name, t in chans.items():
        if not isinstance(t, dict):
            raise InputError(f"{source}: channels.{name} must be a table")
    if physical_spec:
        for name, phys in zip(default_names(len(physical_spec)), physical_spec):
            chans.setdefault(name, {})["physical"] = phys
    device, trigger, meta = _table(doc, "device", source), _table(doc, "trigger", source), _table(doc, "metadata", source)
    for text in overrides:
        table, field, value = parse_override(text)
        target = {"device": device, "trigger": trigger, "metadata": meta}.get(table)
        if target is None:
            target = chans.setdefault(table.split(".", 1)[1], {})
        target[field] = value
    if iepe_excitation_a is not None:
        for name, t in chans.items():
            if t.get("kind", default_kind(name)) == "accel":
                t.setdefault("iepe_excitation_a", iepe_excitation_a)
    channels = tuple(_channel(name, t, source) for name, t in chans.items())
    cfg = DeviceConfig(channels=channels, trigger=_trigger(trigger, source), metadata=dict(meta), source=source,
                       **_device(device, source))
    _check_whole(cfg)
    return cfg


def _table(doc, name, source) -> dict:
    t = doc.get(name, {})
    if not isinstance(t, dict):
        raise InputError(f"{source}: [{name}] must be a table")
    return dict(t)


def _unknown(t: dict, known, where: str):
    bad = set(t) - set(known)
    if bad:
        raise InputError(f"{where}: unknown keys {', '.join(sorted(bad))}; known: {', '.join(known)}")


def _choice(v, options, where):
    if not isinstance(v, str) or v.lower() not in options:
        raise InputError(f"{where} must be one of {', '.join(options)}, got {v!r}")
    return v.lower()


def _num(v, where, lo=None, hi=None, lo_open=False):
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise InputError(f"{where} must be a number, got {v!r}")
    v = float(v)
    ok = math.isfinite(v) and (lo is None or (v > lo if lo_open else v >= lo)) and (hi is None or v <= hi)
    if not ok:
        rng = f"{'(' if lo_open else '['}{lo if lo is not None else '-inf'}, {hi if hi is not None else 'inf'}]"
        raise InputError(f"{where} must lie in {rng}, got {v!r}")
    return v


def _text(v, where):
    if not isinstance(v, str) or "\x00" in v or len(v) > 500:
        raise InputError(f"{where} must be text (at most 500 characters), got {v!r}")
    return v.strip()


def _channel(name: str, t: dict, source: str) -> ChannelConfig:
    where = f"{source}: channels.{name}"
    if not isinstance(name, str) or not name or len(name) > 64 or not name.replace("_", "").isalnum():
        raise InputError(f"{source}: channel name {name!r} must be letters, digits and '_' (at most 64)")
    _unknown(t, CHANNEL_KEYS, where)
    if "physical" not in t:
        raise InputError(f"{where} has no physical channel (e.g. physical = \"Dev1/ai0\")")
    kind = _choice(t.get("kind", default_kind(name)), ("accel", "voltage"), f"{where}.kind")
    sens = t.get("sensitivity_mv_per_g")
    iepe = _num(t.get("iepe_excitation_a", 0.0), f"{where}.iepe_excitation_a", 0.0, 0.025)
    teds = t.get("teds", False)
    if not isinstance(teds, bool):
        raise InputError(f"{where}.teds must be true or false, got {teds!r}")
    if kind == "voltage" and (iepe or sens is not None or teds):
        raise InputError(f"{where}: IEPE excitation, sensitivity and TEDS apply to accel channels only")
    if teds and sens is not None:
        raise InputError(f"{where}: give sensitivity_mv_per_g or teds = true, not both")
    physical = _text(t["physical"], f"{where}.physical")
    if "/" not in physical:
        raise InputError(f"{where}.physical must name a device channel such as Dev1/ai0, got {physical!r}")
    return ChannelConfig(
        name=name, physical=physical, kind=kind,
        range_v=_num(t.get("range_v", 10.0), f"{where}.range_v", 0.0, 100.0, lo_open=True),
        terminal=_choice(t.get("terminal", "default"), TERMINALS, f"{where}.terminal"),
        coupling=_choice(t.get("coupling", "default"), COUPLINGS, f"{where}.coupling"),
        iepe_excitation_a=iepe,
        sensitivity_mv_per_g=None if sens is None else _num(sens, f"{where}.sensitivity_mv_per_g", 0.0, 1e6, lo_open=True),
        conditioner_gain=_num(t.get("conditioner_gain", 1.0), f"{where}.conditioner_gain", 0.0, 1e4, lo_open=True),
        teds=teds, sensor_model=_text(t.get("sensor_model", ""), f"{where}.sensor_model"),
        sensor_serial=_text(t.get("sensor_serial", ""), f"{where}.sensor_serial"))


def _device(t: dict, source: str) -> dict:
    where = f"{source}: device"
    _unknown(t, DEVICE_KEYS, where)
    return {"sample_clock_source": _text(t.get("sample_clock_source", ""), f"{where}.sample_clock_source"),
            "buffer_s": _num(t.get("buffer_s", 10.0), f"{where}.buffer_s", 0.5, 600.0),
            "block_s": _num(t.get("block_s", 0.1), f"{where}.block_s", 0.001, 5.0)}


def _trigger(t: dict, source: str) -> TriggerConfig:
    where = f"{source}: trigger"
    _unknown(t, TRIGGER_KEYS, where)
    kind = _choice(t.get("type", "none"), TRIGGERS, f"{where}.type")
    pre = t.get("pretrigger_samples", 0)
    if isinstance(pre, bool) or not isinstance(pre, int) or not 0 <= pre <= 10_000_000:
        raise InputError(f"{where}.pretrigger_samples must be an integer from 0 to 10000000, got {pre!r}")
    src = _text(t.get("source", ""), f"{where}.source")
    if kind != "none" and not src:
        raise InputError(f"{where}: a {kind} trigger needs a source (a terminal such as /Dev1/PFI0, or a channel)")
    return TriggerConfig(type=kind, source=src, edge=_choice(t.get("edge", "rising"), EDGES, f"{where}.edge"),
                         level_v=None if t.get("level_v") is None else _num(t["level_v"], f"{where}.level_v"),
                         pretrigger_samples=pre)


def _check_whole(cfg: DeviceConfig) -> None:
    if not cfg.channels:
        raise InputError(f"{cfg.source}: no channels; give --device nidaqmx:Dev1/ai0:2 or [channels.*] tables")
    if len(cfg.channels) > MAX_CHANNELS:
        raise InputError(f"{cfg.source}: at most {MAX_CHANNELS} channels, got {len(cfg.channels)}")
    phys = [c.physical for c in cfg.channels]
    dup = sorted({p for p in phys if phys.count(p) > 1})
    if dup:
        raise InputError(f"{cfg.source}: physical channel {', '.join(dup)} given to two channels")
    tr = cfg.trigger
    if tr.type == "analog" or tr.software:
        ch = trigger_channel(cfg)
        if ch is None:
            what = "an analog" if tr.type == "analog" else "a software (pre-trigger)"
            raise InputError(f"{cfg.source}: {what} trigger needs its source among the channels "
                             f"({', '.join(cfg.names)}), got '{tr.source}'")
        if tr.level_v is None:
            raise InputError(f"{cfg.source}: the trigger on {ch.name} needs its level (trigger.level_v, V)")
        if abs(tr.level_v) >= ch.range_v:
            raise InputError(f"{cfg.source}: trigger level {tr.level_v:g} V is outside {ch.name}'s range +-{ch.range_v:g} V")


def trigger_channel(cfg: DeviceConfig) -> ChannelConfig | None:
    """The channel an analog or software trigger watches (by name or physical channel)."""
    for c in cfg.channels:
        if cfg.trigger.source in (c.name, c.physical):
            return c
    return None
