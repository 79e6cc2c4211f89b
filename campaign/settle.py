"""Waiting for a steady cam speed before a point is recorded (real hardware).

The operator sets the drive; the stand needs a few seconds (the motor's slip, the flywheel) to
reach its speed. Two ways to wait, chosen by the plan's ``device.settle``:

- ``prompt``: ask the operator to set the speed and confirm (a terminal is needed);
- ``tacho``: read the device, find the tacho's rising edges (labtool.processing.cam_angle.TachoEdges) and
  wait until the last ``revolutions`` periods all give a speed within ``tolerance`` (relative) of
  the planned rpm; give up after ``timeout_s`` with one line saying the speed seen.

``steady(edges_samples, rate_hz, target_rpm, tolerance, revolutions)`` is the criterion, pure.
"""
from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from labtool.common.errors import InputError


@dataclasses.dataclass(frozen=True)
class SettleResult:
    """How the wait ended: steady or not, the speed of the last revolutions (rpm), the spread
    (max relative deviation of one revolution from the target), the wall time waited (s)."""
    steady: bool
    rpm: float
    spread: float
    waited_s: float
    how: str

    def attrs(self) -> dict:
        return {"settle_method": self.how, "settle_rpm_measured": self.rpm, "settle_spread_rel": self.spread,
                "settle_waited_s": self.waited_s}


def steady(edges, rate_hz: float, target_rpm: float, tolerance: float, revolutions: int) -> tuple[bool, float, float]:
    """(steady, mean rpm, worst relative deviation) over the last ``revolutions`` periods between
    tacho edges (sample positions); not steady while fewer periods are known."""
    e = np.asarray(edges, dtype=float)
    if e.size < revolutions + 1:
        return False, math.nan, math.nan
    periods = np.diff(e[-(revolutions + 1):]) / rate_hz
    rpm = 60.0 / periods
    dev = float(np.max(np.abs(rpm / target_rpm - 1.0)))
    return dev <= tolerance, float(60.0 / periods.mean()), dev


def wait_for_tacho(device, rate_hz: float, target_rpm: float, tolerance: float, revolutions: int,
                   timeout_s: float, tacho: str = "tacho", clock=time.monotonic, say=None) -> SettleResult:
    """Read ``device`` (configured, started and stopped here) until the speed is steady."""
    from labtool.processing.cam_angle import TachoEdges

    if tacho not in device.channel_names:
        raise InputError(f"settle = \"tacho\" needs a '{tacho}' channel; the device has "
                         f"{', '.join(device.channel_names)} (use settle = \"prompt\")")
    j = list(device.channel_names).index(tacho)
    actual = device.configure(rate_hz)
    finder = TachoEdges()
    edges: list[float] = []
    t0 = clock()
    ok, rpm, dev = False, math.nan, math.nan
    device.start()
    try:
        while clock() - t0 < timeout_s:
            block = device.read_block()
            if block is None:
                break
            edges.extend(finder.feed(block.first_index, block.data[:, j]).tolist())
            ok, rpm, dev = steady(edges, actual, target_rpm, tolerance, revolutions)
            if ok:
                break
            if say is not None and math.isfinite(rpm):
                say(f"waiting for a steady {target_rpm:g} rpm: {rpm:.1f} rpm, {100 * dev:.1f} % off")
    finally:
        device.stop()
    waited = clock() - t0
    if not ok:
        seen = "no tacho pulses" if not edges else (f"{rpm:.1f} rpm, {100 * dev:.1f} % off" if math.isfinite(rpm)
                                                    else f"{len(edges)} tacho pulses")
        raise InputError(f"the cam speed did not settle at {target_rpm:g} rpm within +-{100 * tolerance:g} % over "
                         f"{revolutions} revolutions in {timeout_s:g} s ({seen}); set the drive, or raise "
                         "settle_timeout_s / settle_tolerance in the plan")
    return SettleResult(True, rpm, dev, waited, f"tacho: {revolutions} revolutions within +-{100 * tolerance:g} %")


def wait_for_operator(ask, message: str) -> SettleResult:
    """``ask(message)`` returns when the operator confirms; no measurement of the speed."""
    t0 = time.monotonic()
    ask(message)
    return SettleResult(True, math.nan, math.nan, time.monotonic() - t0, "prompt: confirmed by the operator")
