"""Which Ka (m/s^2 per V) multiplies each acceleration channel, and why: stated or refused.

In order: a calibration file's entry (with a warning when it is more than 20 % off the Ka the
recording states: a conditioner gain changed since the calibration); the recording's own
``ka_m_s2_per_v``; the paper's Ka (86.43 m/s^2/V) with a warning. A recording that states Ka = 0, a negative or an infinite Ka is
damaged, as is one outside a calibration file's bounds (1e-3 .. 1e6 m/s^2/V): refused, never
replaced by the paper's. A channel the file already gives in m/s^2 (a
TDMS ``unit_string`` as DAQmx writes for an accelerometer; the readers convert g and mm/s^2 to
m/s^2) takes no Ka: factor 1, and a calibration entry for it is refused as contradictory.
"""
from __future__ import annotations

import math

from labtool.common import history as H
from labtool.common.errors import InputError
from labtool.processing.calibration_file import KA_MAX, KA_MIN, PAPER_KA_M_S2_PER_V

CHANNELS = ("aE_t", "aE_n")


def ka_for_channels(rec, calibration: dict | None, calibration_source: str, warn) -> H.ApplyKa:
    """The ApplyKa step for aE_t and aE_n of ``rec`` (a labtool.processing.readers.Recording)."""
    out = {}
    for name in CHANNELS:
        j = rec.channel_index(name)
        unit = rec.channel_units[j]
        cal = _entry(calibration, name)
        if unit == "m/s^2":
            if cal is not None:
                raise InputError(f"{rec.source}: channel '{name}' is already in m/s^2 ({rec.unit_sources[j]}), "
                                 f"but {calibration_source} gives it a Ka; remove that entry or give the volts")
            out[name] = _ka(1.0, math.nan, f"none: the file gives m/s^2 ({rec.unit_sources[j]})")
            continue
        stated = float(rec.ka_m_s2_per_v[j])
        if cal is not None:
            source = getattr(cal, "source", "") or f"calibration file {calibration_source}"
            out[name] = _ka(cal.ka_m_s2_per_v, cal.uncertainty_m_s2_per_v, source)
            if math.isfinite(stated) and stated > 0 and not 1 / 1.2 < cal.ka_m_s2_per_v / stated < 1.2:
                # a factor 10 is the conditioner at another gain than at calibration (x1 vs x10)
                warn(f"{source} gives Ka = {cal.ka_m_s2_per_v:.4g} m/s^2/V for channel {name}, "
                     f"{cal.ka_m_s2_per_v / stated:.3g} x the {stated:.4g} m/s^2/V that {rec.source} states: "
                     "was the calibration made with the same conditioner gain?")
            continue
        if not math.isnan(stated):
            if not (math.isfinite(stated) and KA_MIN < stated < KA_MAX):
                raise InputError(f"{rec.source}: the recording states Ka = {stated!r} m/s^2/V for channel '{name}', "
                                 f"which is not usable (a chain's Ka lies between {KA_MIN:g} and {KA_MAX:g} m/s^2/V, "
                                 "as in a calibration file); give a calibration with --calibration")
            out[name] = _ka(stated, math.nan, "recording attribute ka_m_s2_per_v")
        else:
            out[name] = _ka(PAPER_KA_M_S2_PER_V, math.nan, f"paper default (Ka = {PAPER_KA_M_S2_PER_V} m/s^2/V)")
        if calibration is not None:
            # say what is used instead, so the user can tell whether to calibrate that channel too
            warn(f"calibration file {calibration_source} has no entry for channel {name}; using the "
                 f"{out[name]['source']} (Ka = {out[name]['ka_m_s2_per_v']:.4g} m/s^2/V)")
        elif math.isnan(stated):
            warn(f"neither the recording nor a calibration gives Ka for channel {name}; using the paper's "
                 f"Ka = {PAPER_KA_M_S2_PER_V} m/s^2/V (give --calibration to use yours)")
    return H.ApplyKa(channels=out)


def _ka(ka: float, unc: float, source: str) -> dict:
    return {"ka_m_s2_per_v": float(ka), "uncertainty_m_s2_per_v": float(unc), "source": source}


def _entry(calibration, name):
    if calibration is None:
        return None
    return calibration.get(name) or next((v for k, v in calibration.items() if k.lower() == name.lower()), None)
