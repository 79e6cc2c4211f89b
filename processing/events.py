"""Impacts and jumps as acceleration spikes.

A spike is a short burst in the wide-band acceleration that the motion law cannot explain: the
residual r = (Ka-scaled, unfiltered) - (low-passed) acceleration, i.e. the content above the
processing band. A sample is a spike peak when |r| exceeds ``k_sigma`` robust standard deviations
of r (1.4826 MAD, estimated over the processing window) and also ``floor_fraction`` of the window's
peak |low-passed acceleration| (so that a clean signal does not turn its quantization into spikes);
peaks closer than ``refractory_s`` are one event. Each spike is labelled with the cam phase it
falls in (rise, return, dwell): impacts show at the dwell ends, jumps inside the motion where the
reaction changes sign.
"""
from __future__ import annotations

import numpy as np

from labtool.processing import kernels

DEFAULT_K_SIGMA = 8.0
DEFAULT_FLOOR_FRACTION = 0.05
DEFAULT_REFRACTORY_S = 0.002


def detect_spikes(residual: np.ndarray, lowpassed: np.ndarray, fs: float, k_sigma: float = DEFAULT_K_SIGMA,
                  floor_fraction: float = DEFAULT_FLOOR_FRACTION, refractory_s: float = DEFAULT_REFRACTORY_S,
                  valid: np.ndarray | None = None):
    """(indices, signed peak residuals, threshold) of the spikes in one channel's window."""
    r = np.asarray(residual, dtype=float)
    if valid is not None:
        r = np.where(valid, r, 0.0)
    sub = r[::8] if len(r) > 4096 else r  # the scale estimate needs no more than every 8th sample
    med = np.median(sub)
    sigma = 1.4826 * np.median(np.abs(sub - med))
    thr = max(k_sigma * sigma, floor_fraction * float(np.max(np.abs(lowpassed))) if len(lowpassed) else 0.0)
    if thr <= 0 or len(r) < 3:
        return np.empty(0, dtype=np.int64), np.empty(0), thr
    mag = np.abs(r - med)
    if not (mag > thr).any():  # the usual case: nothing to look for
        return np.empty(0, dtype=np.int64), np.empty(0), float(thr)
    peaks = kernels.find_peaks(mag, float(thr), float(max(1, int(refractory_s * fs))))
    return peaks, r[peaks], float(thr)
