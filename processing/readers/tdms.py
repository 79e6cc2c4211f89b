"""Reader of LabVIEW TDMS files (npTDMS), the format of the paper's stand.

Channels are taken from the first group that has any (or the group named ``group``); all must have
the same length. Sample rate: the channels' ``wf_increment`` (s), else a ``sample_rate_hz``
property on the file, group or channel, else the caller's ``sample_rate_hz``; none -> InputError.
Optional properties: ``ka_m_s2_per_v`` per channel, ``cam_speed_rpm`` on the file or group.
"""
from __future__ import annotations

import contextlib
import logging
import math

import numpy as np

from common.errors import FileFormatError, InputError
from processing.readers.base import Recording, as_text, check_finite, check_sample_rate


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


def open_tdms(path, sample_rate_hz: float | None = None, group: str | None = None) -> Recording:
    from nptdms import TdmsFile

    src = str(path)
    with _nptdms_quiet() as messages:
        try:
            tf = TdmsFile.open(path)
        except Exception as exc:  # npTDMS raises ValueError/KeyError/struct.error on damaged files
            raise FileFormatError(f"{src}: not a readable TDMS file (truncated or corrupt?): "
                                  f"{type(exc).__name__}: {exc}") from None
        try:
            rec = _build(tf, src, sample_rate_hz, group)
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


def _build(tf, src, sample_rate_hz, group_name) -> Recording:
    groups = [g for g in tf.groups() if len(g.channels())]
    if group_name is not None:
        groups = [g for g in groups if g.name == group_name]
    if not groups:
        raise FileFormatError(f"{src}: TDMS file has no channels" + (f" in group '{group_name}'" if group_name else ""))
    g = groups[0]
    chans = list(g.channels())
    names = [c.name for c in chans]
    lengths = {len(c) for c in chans}
    if len(lengths) != 1:
        raise FileFormatError(f"{src}: TDMS channels of group '{g.name}' have different lengths {sorted(lengths)}")
    n = lengths.pop()
    if n == 0:
        raise FileFormatError(f"{src}: TDMS channels hold no samples")
    for c in chans:
        if np.dtype(c.dtype).kind not in "fiu":
            raise FileFormatError(f"{src}: TDMS channel '{c.name}' holds {c.dtype}, not numbers")
    fs = None
    incs = {c.properties.get("wf_increment") for c in chans} - {None}
    if incs:
        inc = float(incs.pop())
        if not (math.isfinite(inc) and inc > 0):
            raise InputError(f"{src}: TDMS wf_increment {inc!r} s is not a usable sample interval")
        fs = 1.0 / inc
    for props in [tf.properties, g.properties] + [c.properties for c in chans]:
        if fs is None and "sample_rate_hz" in props:
            fs = props["sample_rate_hz"]
    if fs is None:
        fs = sample_rate_hz
    if fs is None:
        raise InputError(f"{src}: TDMS file states no sample rate (wf_increment or sample_rate_hz); "
                         "give it with --sample-rate")
    fs = check_sample_rate(fs, src)
    ka = np.array([float(c.properties.get("ka_m_s2_per_v", math.nan)) for c in chans])
    rpm = float(tf.properties.get("cam_speed_rpm", g.properties.get("cam_speed_rpm", math.nan)))

    def read(start: int, stop: int) -> np.ndarray:
        with _nptdms_quiet() as messages:
            try:
                cols = [np.asarray(c[start:stop], dtype=np.float64) for c in chans]
            except Exception as exc:
                raise FileFormatError(f"{src}: cannot read TDMS samples {start}..{stop}: {exc}") from None
        if any(len(col) != stop - start for col in cols):
            raise FileFormatError(f"{src}: TDMS samples {start}..{stop} are missing (truncated file"
                                  + (f": {messages[0]}" if messages else "") + ")")
        block = np.column_stack(cols)
        check_finite(block, start, names, src)
        return block

    attrs = {k: as_text(v) for k, v in tf.properties.items()}
    return Recording(source=src, format="tdms", sample_rate_hz=fs, channel_names=names, n_samples=int(n), read=read,
                     ka_m_s2_per_v=ka, start_time_utc=as_text(tf.properties.get("start_time_utc", "")),
                     cam_speed_rpm=rpm if rpm > 0 else math.nan, attrs=attrs, close=tf.close)
