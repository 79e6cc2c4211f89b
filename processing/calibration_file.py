"""Reading the calibration TOML written by ``labtool calibrate``.

Format (this module's contract until acquisition/calibration.py fixes its own; unknown keys are
ignored so the writer may add more)::

    [channels.aE_t]
    ka_m_s2_per_v = 86.43            # m/s^2 per V, multiplies the recorded volts
    uncertainty_m_s2_per_v = 0.5     # optional, standard uncertainty of Ka

This is the layout acquisition/calibration.py writes (there the uncertainty is named
``ka_std_m_s2_per_v``; both names are read). A flat form ``[aE_t] ka_m_s2_per_v = ...`` and the key ``ka`` are accepted too.
"""
from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path

from common.errors import FileFormatError, InputError

# The paper's calibration (sec. 3, Figure 6): B&K 4291 exciter, 9.81 m/s^2 at 79.6 Hz.
PAPER_KA_M_S2_PER_V = 86.43


@dataclasses.dataclass(frozen=True)
class ChannelCalibration:
    """Ka (m/s^2/V) of one channel and its standard uncertainty (m/s^2/V, NaN if not stated)."""
    ka_m_s2_per_v: float
    uncertainty_m_s2_per_v: float = math.nan


def read_calibration(path) -> dict[str, ChannelCalibration]:
    """{channel name: ChannelCalibration}; InputError/FileFormatError on a missing or bad file."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"calibration file {p} does not exist")
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise FileFormatError(f"{p}: not a calibration TOML file: {exc}") from None
    table = data.get("channels", None)
    if table is None:
        table = {k: v for k, v in data.items() if isinstance(v, dict) and ("ka_m_s2_per_v" in v or "ka" in v)}
    if not isinstance(table, dict) or not table:
        raise FileFormatError(f"{p}: calibration file has no [channels.<name>] table with ka_m_s2_per_v")
    out = {}
    for name, entry in table.items():
        if not isinstance(entry, dict):
            raise FileFormatError(f"{p}: calibration entry '{name}' is not a table")
        ka = entry.get("ka_m_s2_per_v", entry.get("ka"))
        if ka is None:
            raise FileFormatError(f"{p}: channel '{name}' has no ka_m_s2_per_v")
        try:
            ka = float(ka)
            unc = float(entry.get("uncertainty_m_s2_per_v", entry.get("ka_std_m_s2_per_v", math.nan)))
        except (TypeError, ValueError):
            raise FileFormatError(f"{p}: channel '{name}': Ka and its uncertainty must be numbers") from None
        if not (math.isfinite(ka) and ka != 0.0):
            raise InputError(f"{p}: channel '{name}': Ka = {ka} m/s^2/V is not usable")
        out[str(name)] = ChannelCalibration(ka, unc)
    return out
