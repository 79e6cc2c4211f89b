"""The calibration file (TOML): its schema, reader, writer and merging (which Ka a channel gets
from it is processing/ka.py).

Written by ``labtool calibrate`` (through ``write_calibration``, with tomli-w: never by string
formatting, so any channel name or file name is quoted as TOML requires) and read by
``labtool process --calibration`` (``read_calibration``). Format version 1::

    format = "labtool.calibration"
    format_version = 1
    created_utc = "2026-11-22T04:30:00+00:00"
    source = "sample_data/calibration_79p6Hz.h5"   # optional: the reference recording(s), "; "-joined
    [reference]                  # optional: the exciter, as given to 'labtool calibrate'
    accel_m_s2 = 9.81            # what the exciter gives, m/s^2 (> 0)
    convention = "peak"          # "peak" or "rms": what accel_m_s2 means
    freq_hz = 79.6               # nominal frequency, Hz
    rel_uncertainty = 0.0        # of the exciter, relative, in [0, 1)
    [channels.aE_t]              # one table per channel; the name is a quoted TOML key if it must be
    ka_m_s2_per_v = 86.43        # the factor: acceleration = Ka * volts, m/s^2/V, 1e-3 < Ka < 1e6
    uncertainty_m_s2_per_v = 0.01  # optional: standard uncertainty (k = 1), fit and reference combined
    ka_std_fit_m_s2_per_v = 0.01   # optional: the fit's part of it
    fitted_freq_hz = 79.6          # optional, Hz
    amplitude_v_peak = 0.1135      # optional, V
    residual_rms_v = 0.0006        # optional, V
    harmonic_distortion = 0.001    # optional: (2f, 3f amplitudes) / fundamental
    n_samples = 20000              # optional
    n_references = 1               # optional: reference recordings merged into this Ka
    birge_ratio = 1.0              # optional: their scatter / their stated uncertainty (> 1: inflated)
    source = "ref.h5"              # optional: where this channel's Ka comes from

Strict (labtool.common.schema): a key this schema does not know, a bool or a string where a number belongs,
a number out of range, NaN or inf is refused with one line naming the file and the key. The header
(``format``, ``format_version``) may be left out of a hand-written file; if present it must match.
"""
from __future__ import annotations

import dataclasses
import datetime as _dt
import math
from pathlib import Path

from labtool.common.errors import InputError
from labtool.common.names import shown
from labtool.common.schema import Integer, MapOf, Number, SchemaError, String, Table, load_toml

CAL_FORMAT = "labtool.calibration"
CAL_VERSION = 1
# The paper's calibration (sec. 2.4): B&K 4291 exciter, 9.81 m/s^2 at 79.6 Hz -> Ka = 86.43 m/s^2/V.
PAPER_KA_M_S2_PER_V = 86.43
# what an accelerometer chain's Ka can be (m/s^2 per V): 1e-3 (a 1 kV/(m/s^2) chain) .. 1e6
KA_MIN, KA_MAX = 1e-3, 1e6
KA = "m/s^2/V"

REFERENCE = Table({
    "accel_m_s2": Number(gt=0, le=1e5, unit="m/s^2"),
    "convention": String(choices=("peak", "rms")),
    "freq_hz": Number(gt=0, le=1e5, unit="Hz"),
    "rel_uncertainty": Number(ge=0, lt=1),
}, required=False)

CHANNEL = Table({
    "ka_m_s2_per_v": Number(gt=KA_MIN, lt=KA_MAX, unit=KA),
    "uncertainty_m_s2_per_v": Number(ge=0, unit=KA, required=False),
    "ka_std_fit_m_s2_per_v": Number(ge=0, unit=KA, required=False),
    "ka_std_m_s2_per_v": Number(ge=0, unit=KA, required=False),    # an alias of uncertainty_m_s2_per_v
    "fitted_freq_hz": Number(gt=0, unit="Hz", required=False),
    "amplitude_v_peak": Number(gt=0, unit="V", required=False),
    "residual_rms_v": Number(ge=0, unit="V", required=False),
    "harmonic_distortion": Number(ge=0, required=False),
    "n_samples": Integer(ge=1, required=False),
    "n_references": Integer(ge=1, required=False),
    "birge_ratio": Number(ge=0, required=False),
    # file names, as given: a newline in one is quoted by the writer, shown escaped by labtool
    "source": String(required=False, single_line=False, max_len=65536),
})

CALIBRATION = Table({
    "format": String(choices=(CAL_FORMAT,), required=False),
    "format_version": Integer(ge=CAL_VERSION, le=CAL_VERSION, required=False),
    "created_utc": String(required=False, max_len=64),
    "source": String(required=False, single_line=False, max_len=65536),
    "reference": REFERENCE,
    "channels": MapOf(CHANNEL, min_len=1, key_max_len=64, noun="channel"),
})


def check_document(data: dict, where: str) -> dict:
    """The document checked against CALIBRATION (module docstring), plus what a field schema cannot
    say: channel names are printable, an uncertainty is smaller than its Ka."""
    doc = CALIBRATION.check(data, where=where)
    for name, c in doc["channels"].items():
        if not name.isprintable() or name != name.strip() or not name:
            raise SchemaError(f"{where}: channel name {shown(repr(name))} holds control characters or blanks "
                              "at its ends")
        if "ka_std_m_s2_per_v" in c:   # the alias processing documented; one name only
            if "uncertainty_m_s2_per_v" in c:
                raise SchemaError(f"{where}: [channels.{shown(name)}] gives both uncertainty_m_s2_per_v and its alias "
                                  "ka_std_m_s2_per_v; keep one")
            c["uncertainty_m_s2_per_v"] = c.pop("ka_std_m_s2_per_v")
        u = c.get("uncertainty_m_s2_per_v")
        if u is not None and not u < c["ka_m_s2_per_v"]:
            raise SchemaError(f"{where}: [channels.{shown(name)}] uncertainty_m_s2_per_v = {u:g}: must be smaller "
                              f"than Ka ({c['ka_m_s2_per_v']:g} {KA})")
    return doc


@dataclasses.dataclass(frozen=True)
class ChannelCalibration:
    """Ka (m/s^2/V) of one channel, its standard uncertainty (m/s^2/V, NaN if not stated) and
    where it comes from (the calibration file)."""
    ka_m_s2_per_v: float
    uncertainty_m_s2_per_v: float = math.nan
    source: str = ""                # "calibration file <path>"; "" = processing names it


def read_calibration(path) -> dict[str, ChannelCalibration]:
    """{channel name: ChannelCalibration} from one file; InputError (one line) if bad."""
    doc = check_document(load_toml(path, "calibration file"), f"calibration file {shown(path)}")
    return {name: ChannelCalibration(c["ka_m_s2_per_v"], c.get("uncertainty_m_s2_per_v", math.nan),
                                     f"calibration file {shown(path)}")
            for name, c in doc["channels"].items()}


def read_calibrations(paths) -> dict[str, ChannelCalibration]:
    """Several calibration files merged into one table; a channel in two of them is refused.

    Two files that both calibrate a channel may disagree; which one holds is the user's call, not
    labtool's (``labtool calibrate`` on both reference recordings at once merges them with their
    uncertainties instead)."""
    out: dict[str, ChannelCalibration] = {}
    for p in paths:
        for name, cal in read_calibration(p).items():
            if name in out or name.lower() in {k.lower() for k in out}:
                first = next(v for k, v in out.items() if k.lower() == name.lower())
                raise InputError(f"channel {shown(name)} is calibrated in both {first.source.removeprefix('calibration file ')} "
                                 f"and {shown(p)}; give one of them, or calibrate both reference recordings in one "
                                 "'labtool calibrate' call to merge them with their uncertainties")
            out[name] = cal
    return out


def calibration_document(channels: dict[str, dict], reference: dict | None, source: str | None,
                         created_utc: str | None = None) -> dict:
    """A checked document from plain values (the writer's input); InputError if a value is out of range."""
    created = created_utc or _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    data = {"format": CAL_FORMAT, "format_version": CAL_VERSION, "created_utc": created,
            "channels": {k: {kk: vv for kk, vv in v.items() if vv is not None} for k, v in channels.items()}}
    if source is not None:
        data["source"] = source
    if reference is not None:
        data["reference"] = reference
    return check_document(data, "calibration")


def calibration_text(doc: dict) -> str:
    """The file's text: TOML written by tomli-w (every key and string quoted as TOML needs)."""
    import tomli_w

    return "# labtool calibration file: acceleration (m/s^2) = ka_m_s2_per_v * volts\n" + tomli_w.dumps(doc)


def write_calibration(path, doc: dict) -> None:
    """Write the file atomically, with the user's umask (labtool.common.files: a full disk is one line)."""
    from labtool.common.files import write_text

    write_text(Path(path), calibration_text(doc))


__all__ = ["CAL_FORMAT", "CAL_VERSION", "PAPER_KA_M_S2_PER_V", "KA_MIN", "KA_MAX", "CALIBRATION", "check_document",
           "ChannelCalibration", "read_calibration", "read_calibrations", "calibration_document",
           "calibration_text", "write_calibration"]
