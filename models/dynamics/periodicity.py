"""Whether a simulated motion has settled: its last two cam revolutions compared.

One measure, ``revolution_change``: the difference between the last revolution of a signal and the
one before it, relative to the signal's size. Two tolerances, because the two uses differ in what a
wrong "periodic" costs:

- ``STEADY_CYCLE_TOL`` (rms measure, 5 %): a report compares a model's cycle with a measured cycle
  average whose own scatter over revolutions is a few per cent; a model whose last two revolutions
  differ by less than that is represented by its last revolution, otherwise by its mean over
  revolutions with their scatter (``labtool.reports.align.steady_cycles``). Measured on the
  conditioned revolutions (low-passed, on the report's grid), so impacts count with the bandwidth
  the measurement has.
- ``REPEAT_TOL`` (max measure, 0.5 % of the peak |omega2|, away from contact events) with
  ``EVENT_ANGLE_TOL`` (rad): the simulated stand repeats a model's last revolution for as long as a
  recording lasts (``labtool.acquisition.signal_chain``); a motion that still drifts would then be
  recorded as if steady, so every sample must repeat, events included (the elastic model's dwell
  micro-bounces drift 0.2 deg a turn at 300 rpm, inside the event tolerance).
"""
from __future__ import annotations

import numpy as np

STEADY_CYCLE_TOL = 0.05   # rms(last - previous) / rms(last), per signal: the report's steady cycle
REPEAT_TOL = 5e-3         # max|last - previous| / max|omega2| away from events: repeatable truth
EVENT_ANGLE_TOL = 1e-2    # rad: the last two revolutions' events at the same cam angles


def revolution_change(last, previous, measure: str = "rms", keep=None, scale: float | None = None) -> float:
    """Relative difference of a signal's last revolution from the one before (1).

    Parameters
    ----------
    last, previous : array_like
        The signal over its last and its previous revolution, at the same cam angles (any unit).
    measure : {"rms", "max"}
        Root mean square or largest absolute difference.
    keep : array_like of bool, optional
        The samples compared (e.g. away from impacts); default all.
    scale : float, optional
        The size the difference is relative to (unit of the signal); default the same measure of
        ``last`` over the kept samples.

    Returns
    -------
    float
        The difference over the scale; 0 when the scale is 0 (a signal that is zero throughout)
        or no sample is kept.
    """
    last, previous = np.asarray(last, dtype=float), np.asarray(previous, dtype=float)
    if keep is not None:
        last, previous = last[keep], previous[keep]
    if last.size == 0:
        return 0.0
    size = (lambda y: float(np.sqrt(np.mean(y**2)))) if measure == "rms" else (lambda y: float(np.max(np.abs(y))))
    ref = size(last) if scale is None else float(scale)
    return size(last - previous) / ref if ref > 0 else 0.0


def events_repeat(angles_last, angles_previous, tol: float = EVENT_ANGLE_TOL) -> bool:
    """True when both revolutions hold as many events, each at the same cam angle within ``tol``.

    Parameters
    ----------
    angles_last, angles_previous : array_like
        Cam angles (rad) of the events in each revolution, in order, on one origin (the last
        revolution's shifted back by 2 pi).
    tol : float
        Largest allowed difference of one event's cam angle (rad).
    """
    a, b = np.asarray(angles_last, dtype=float), np.asarray(angles_previous, dtype=float)
    return a.size == b.size and (a.size == 0 or float(np.max(np.abs(a - b))) <= tol)
