"""Reader of LabVIEW TDMS files (npTDMS), the format of the paper's stand and of DAQmx logging.

Group: the one named by ``group`` (``--group``); else the only group whose channels have samples
(a metadata group of properties, or of one-value channels, before the data group is skipped); several
candidate groups are refused, naming them. Channels: every channel of the group with the group's
common length (raw int16/int32 data are scaled by npTDMS from their ``NI_Scale`` properties).
Sample rate: the channels' ``wf_increment`` (s), which must be the same for all; else a rate property
(``sample_rate_hz``, ``Sample Rate``, ``SampleRate``, ``wf_samplerate``, Hz) or ``wf_increment`` on the
group or the file; else the caller's ``sample_rate_hz``; none -> InputError. Units: each channel's
``unit_string`` (or ``NI_UnitDescription``) read and converted (V, mV; m/s^2, g) or refused; none
stated -> volts, reported as an assumption. Optional properties: ``ka_m_s2_per_v`` per channel,
``cam_speed_rpm`` on the file or group.
"""
from __future__ import annotations

import contextlib
import logging
import math

import numpy as np

from labtool.common.errors import FileFormatError, InputError
from labtool.processing.readers.base import Recording, as_text, check_finite, check_sample_rate
from labtool.processing.readers.units import signal_unit, usable

RATE_KEYS = ("sample_rate_hz", "sample rate", "samplerate", "sample_rate", "wf_samplerate", "rate")
UNIT_KEYS = ("unit_string", "NI_UnitDescription", "unit")


@contextlib.contextmanager
def _nptdms_quiet():
    """Collect npTDMS's warnings instead of letting its console handler print them (one-line errors)."""
    collect = _Collect()
    parent = logging.getLogger("nptdms")
    parent.addHandler(collect)
    try:
        from nptdms.log import log_manager
        console = log_manager.console_handler
    except (ImportError, AttributeError):  # pragma: no cover - other npTDMS versions
        console = None
    old_level = console.level if console is not None else None
    if console is not None:
        console.setLevel(logging.CRITICAL + 1)
    try:
        yield collect.messages
    finally:
        parent.removeHandler(collect)
        if console is not None:
            console.setLevel(old_level)


class _Collect(logging.Handler):
    """npTDMS logs damage (a truncated last segment) as warnings: collect them for one summary line."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record):
        self.messages.append(record.getMessage())


def open_tdms(path, sample_rate_hz: float | None = None, group: str | None = None, units: dict | None = None,
              wanted: list | None = None) -> Recording:
    """A Recording of the TDMS file ``path``; ``units``: the user's unit per channel (--units),
    replacing the file's; ``wanted``: the channels named with --channels (the others may be side
    channels in any unit, left out)."""
    from nptdms import TdmsFile

    src = str(path)
    with _nptdms_quiet() as messages:
        try:
            tf = TdmsFile.open(path)
        except Exception:  # npTDMS raises ValueError/KeyError/struct.error on damaged files
            raise FileFormatError(f"{src}: not a readable TDMS file: its lead-in or metadata is cut or corrupt "
                                  "(give an undamaged copy)") from None
        try:
            rec = _build(tf, src, sample_rate_hz, group, units or {}, wanted)
        except (FileFormatError, InputError):
            tf.close()
            raise
        except Exception as exc:
            tf.close()
            raise FileFormatError(f"{src}: damaged TDMS file: {type(exc).__name__}: {exc}") from None
    if messages:
        rec.warnings.append(f"{src}: TDMS file looks damaged or truncated ({messages[0]}); "
                            f"reading what is there")
    return rec


def _group(tf, src, group_name):
    """The data group: named, or the only one whose channels hold more than one sample."""
    groups = list(tf.groups())
    if group_name is not None:
        named = [g for g in groups if g.name == group_name]
        if not named:
            raise InputError(f"{src}: TDMS file has no group '{group_name}' (groups: "
                             f"{', '.join(g.name for g in groups) or 'none'})")
        return named[0]
    data = [g for g in groups if any(len(c) > 1 for c in g.channels())]
    if not data:
        raise FileFormatError(f"{src}: TDMS file has no channels with samples")
    if len(data) > 1:
        raise InputError(f"{src}: TDMS file has several groups with samples ({', '.join(g.name for g in data)}); "
                         "choose one with --group")
    return data[0]


def _rate(tf, g, chans, src, sample_rate_hz):
    incs = {float(c.properties["wf_increment"]) for c in chans if "wf_increment" in c.properties}
    if len(incs) > 1:
        raise InputError(f"{src}: TDMS channels of group '{g.name}' have different wf_increment {sorted(incs)} s; "
                         "labtool needs one sample rate (split the file by rate)")
    if incs:
        inc = incs.pop()
        if not (math.isfinite(inc) and inc > 0):
            raise InputError(f"{src}: TDMS wf_increment {inc!r} s is not a usable sample interval")
        return 1.0 / inc
    for props in [g.properties, tf.properties] + [c.properties for c in chans]:
        low = {str(k).lower(): v for k, v in props.items()}
        for k in RATE_KEYS:
            if k in low:
                return low[k]
        if "wf_increment" in low:
            inc = float(low["wf_increment"])
            return 1.0 / inc if inc > 0 else inc
    if sample_rate_hz is None:
        raise InputError(f"{src}: TDMS file states no sample rate (wf_increment or sample_rate_hz); "
                         "give it with --sample-rate")
    return sample_rate_hz


def _stated_unit(c, given: dict):
    """(unit text, where it was read) of channel c: --units, else its unit property, else (None, None)."""
    mine = {str(k).lower(): v for k, v in given.items()}.get(c.name.lower())
    if mine is not None:
        return str(mine), f"--units {c.name}={mine}"
    key = next((k for k in UNIT_KEYS if str(c.properties.get(k, "")).strip()), None)
    return (c.properties[key], f"TDMS {key} = {c.properties[key]!r}") if key else (None, None)


def _side_channels(chans, given: dict, wanted):
    """The channels in a unit neither of voltage nor of acceleration that are not the accelerometer's
    (named with --channels, or called aE_t/aE_n): left out, as LVM side channels are."""
    names = {c.name.lower() for c in chans}
    known = {w.lower() for w in wanted} if wanted else ({"ae_t", "ae_n", "tacho"} if {"ae_t", "ae_n"} <= names else None)
    if known is None:
        return []
    return [c for c in chans if c.name.lower() not in known and _stated_unit(c, given)[0] is not None
            and not usable(_stated_unit(c, given)[0])]


def _units(chans, src, given: dict):
    kinds, factors, sources, assumed = [], [], [], []
    for c in chans:
        unit, where = _stated_unit(c, given)
        if unit is None:
            kinds.append("V")
            factors.append(1.0)
            sources.append("none stated: volts assumed")
            assumed.append(f"channel '{c.name}' states no unit_string: read as volts")
            continue
        kind, f = signal_unit(unit, f"{src}: TDMS channel '{c.name}'", c.name)
        kinds.append(kind)
        factors.append(f)
        sources.append(where)
    return kinds, np.asarray(factors), sources, assumed


def _build(tf, src, sample_rate_hz, group_name, given: dict, wanted) -> Recording:
    g = _group(tf, src, group_name)
    chans = list(g.channels())
    aside = _side_channels(chans, given, wanted)
    chans = [c for c in chans if c not in aside]
    if not chans:
        raise FileFormatError(f"{src}: TDMS group '{g.name}' holds no channel in volts or an acceleration")
    n = max(len(c) for c in chans)
    short = [c.name for c in chans if len(c) != n]
    if short:
        raise FileFormatError(f"{src}: TDMS channels {short} of group '{g.name}' are shorter than the others "
                              f"({n} samples)")
    names = [c.name for c in chans]
    for c in chans:
        if np.dtype(c.dtype).kind not in "fiu":
            raise FileFormatError(f"{src}: TDMS channel '{c.name}' holds {c.dtype}, not numbers")
    fs = check_sample_rate(_rate(tf, g, chans, src, sample_rate_hz), src)
    kinds, factors, sources, assumed = _units(chans, src, given)
    assumed += [f"channel '{c.name}' is in {_stated_unit(c, given)[0]!r}, not a voltage or an acceleration: left out"
                for c in aside]
    ka = np.array([float(c.properties.get("ka_m_s2_per_v", math.nan)) for c in chans])
    rpm = float(tf.properties.get("cam_speed_rpm", g.properties.get("cam_speed_rpm", math.nan)))

    def read(start: int, stop: int) -> np.ndarray:
        with _nptdms_quiet() as messages:
            try:  # npTDMS applies the channels' NI_Scale scaling to raw integer data
                cols = [np.asarray(c[start:stop], dtype=np.float64) for c in chans]
            except Exception as exc:
                raise FileFormatError(f"{src}: cannot read TDMS samples {start}..{stop}: {exc}") from None
        if any(len(col) != stop - start for col in cols):
            raise FileFormatError(f"{src}: TDMS samples {start}..{stop} are missing (truncated file"
                                  + (f": {messages[0]}" if messages else "") + ")")
        block = np.column_stack(cols) * factors[None, :]
        check_finite(block, start, names, src)
        return block

    attrs = {k: as_text(v) for k, v in tf.properties.items()}
    start = tf.properties.get("start_time_utc", "") or chans[0].properties.get("wf_start_time", "")
    rec = Recording(source=src, format=f"tdms (group '{g.name}')", sample_rate_hz=fs, channel_names=names,
                    n_samples=int(n), read=read, ka_m_s2_per_v=ka, start_time_utc=_iso(start),
                    cam_speed_rpm=rpm if rpm > 0 else math.nan, attrs=attrs, close=tf.close,
                    channel_units=kinds, unit_sources=sources, assumptions=assumed)
    rec.left_out = [c.name for c in aside]
    rec.warnings.extend(f"{src}: assumed: {a}" for a in assumed)
    return rec


def _iso(v) -> str:
    """A TDMS time (numpy datetime64, as npTDMS gives wf_start_time) or text, as ISO 8601 UTC."""
    if isinstance(v, np.datetime64):
        return np.datetime_as_string(v.astype("datetime64[us]"), unit="us") + "+00:00"
    return as_text(v)
