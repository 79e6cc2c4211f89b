"""The cam speed from the revolution marks, checked against the stated speed and sample rate.

A revolution is irregular when its period leaves (1 - IRREGULAR, 1 / (1 - IRREGULAR)) x the median period (0.8, 1.25) (a
missed or extra tacho pulse, a stall): its cam angle is not known, so its samples become NaN and it
stays out of the statistics. A measured speed more than 1.5x off the stated one means the sample
rate (or the stated speed) is wrong: refused, never processed at the wrong scale.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from labtool.common.errors import InputError

IRREGULAR = 0.2          # relative deviation from the median period that makes a revolution irregular
DRIFT_SAID = 0.02        # per-revolution speeds spread wider than this (relative to the mean): said
REFUSE_RATIO = 1.5       # measured / stated speed beyond this (either way): the rate is wrong
PLAUSIBLE_RPM = (1.0, 3000.0)   # rpm: a measured cam speed outside is a wrong channel or rate, not a cam


@dataclasses.dataclass(frozen=True)
class CamSpeed:
    period_samples: float            # median revolution period (samples)
    rpm: float                       # mean over the regular revolutions (rpm)
    periods: np.ndarray              # every mark-to-mark period (samples)
    irregular_by_segment: list       # per segment: bool per revolution
    n_irregular: int
    rpm_min: float = math.nan        # slowest and fastest regular revolution (rpm)
    rpm_max: float = math.nan
    drift: float = math.nan          # relative change of the speed over the recording, by a line through the revolutions'


def estimate(marks_by_seg, fs: float, rpm_hint, source: str, warn) -> CamSpeed:
    """CamSpeed from the marks of every segment (samples); ``rpm_hint`` the stated speed or None."""
    periods = np.concatenate([np.diff(m) for m in marks_by_seg if len(m) >= 2] or [np.empty(0)])
    if len(periods) == 0:
        raise InputError(f"{source}: fewer than two cam revolutions found; cannot process "
                         "(is the cam turning, are aE_t and the tacho connected?)")
    period = float(np.median(periods))
    lo, hi = (1 - IRREGULAR) * period, period / (1 - IRREGULAR)
    regular = (periods > lo) & (periods < hi)
    rpm = 60.0 * fs / float(np.mean(periods[regular]))
    if not PLAUSIBLE_RPM[0] <= rpm <= PLAUSIBLE_RPM[1]:
        # noise on a channel taken for the tacho gave 632684 rpm, with exit 0
        raise InputError(f"{source}: the revolution marks give {rpm:.6g} rpm at {fs:g} Hz, not a cam speed "
                         f"({PLAUSIBLE_RPM[0]:g} to {PLAUSIBLE_RPM[1]:g} rpm): is the tacho channel a tacho (name it "
                         "with --channels tacho=<channel>), is the sample rate right?")
    if rpm_hint and math.isfinite(rpm_hint):
        ratio = rpm / rpm_hint
        if not (1 / REFUSE_RATIO < ratio < REFUSE_RATIO):
            raise InputError(
                f"{source}: the data give {rpm:.1f} rpm at the stated {fs:g} Hz, but the cam turned at "
                f"{rpm_hint:g} rpm: the sample rate (or the stated cam speed) is wrong; fix the file or give --rpm")
        if abs(ratio - 1) > IRREGULAR:
            warn(f"measured cam speed {rpm:.1f} rpm differs from the stated {rpm_hint:g} rpm by "
                 f"{100 * abs(ratio - 1):.0f} %")
    irregular = [~((np.diff(m) > lo) & (np.diff(m) < hi)) for m in marks_by_seg]
    n_irr = int(sum(x.sum() for x in irregular))
    if n_irr:
        warn(f"{n_irr} revolutions deviate by more than {100 * IRREGULAR:.0f} % from the median period "
             f"{period / fs * 1e3:.1f} ms (missed tacho pulses?); their samples are NaN")
    rpm_min, rpm_max, drift = _spread(marks_by_seg, fs, lo, hi)
    if (rpm_max - rpm_min) > DRIFT_SAID * rpm:
        warn(f"the cam speed varies over the recording: {rpm_min:.2f} to {rpm_max:.2f} rpm per revolution "
             f"({100 * (rpm_max - rpm_min) / rpm:.1f} % of the mean {rpm:.2f} rpm; a line through them changes by "
             f"{100 * drift:+.1f} %): the cycle statistics (omega2_mean, ...) average revolutions of these speeds, and "
             "their _std holds the spread (attributes cam_speed_rpm_min, cam_speed_rpm_max, cam_speed_drift)")
    return CamSpeed(period, rpm, periods, irregular, n_irr, rpm_min, rpm_max, drift)


def _spread(marks_by_seg, fs: float, lo: float, hi: float):
    """(slowest, fastest regular revolution in rpm, relative change over the recording of a line
    fitted to the regular revolutions' speeds against their mid-times)."""
    mid, rpm = [], []
    for m in marks_by_seg:
        d = np.diff(m)
        ok = (d > lo) & (d < hi)
        mid.append((0.5 * (m[:-1] + m[1:]))[ok] if len(m) >= 2 else np.empty(0))
        rpm.append(60.0 * fs / d[ok] if len(m) >= 2 else np.empty(0))
    mid, rpm = np.concatenate(mid), np.concatenate(rpm)
    if len(rpm) == 0:
        return math.nan, math.nan, math.nan
    drift = 0.0
    if len(rpm) >= 3 and np.ptp(mid) > 0:
        slope = np.polyfit(mid, rpm, 1)[0]
        drift = float(slope * np.ptp(mid) / np.mean(rpm))
    return float(rpm.min()), float(rpm.max()), drift
