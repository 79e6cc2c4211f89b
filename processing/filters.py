"""SOS filters: zero-phase offline (whole or chunked with overlap) and stateful causal streaming.

Pure functions of arrays; frequencies in Hz, samples along axis 0.

Band limits (chosen from the cam speed, see docs/processing.md): the upper edge is a low-pass at
``harmonics`` times the cam frequency f1 = n1/60 (default 100 f1: 300 Hz at 180 rpm, 833 Hz at
500 rpm), capped at 0.4 fs; it keeps the motion law's content (the sine law's acceleration spectrum
falls as 1/f^3 past 1/T_rise) and removes sensor noise and chain resonances above. The lower edge
is not an IIR high-pass (the normal acceleration has a real mean, omega2^2 DE > 0): the offset and
the AC-coupling droop are removed by referencing the signal to the dwells (follower.py), which acts
as a high-pass at about f1/2.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import signal

from common.errors import InputError

DEFAULT_HARMONICS = 100.0
DEFAULT_ORDER = 4


def lowpass_cutoff_hz(cam_speed_rpm: float, fs: float, harmonics: float = DEFAULT_HARMONICS) -> float:
    """The low-pass corner (Hz): ``harmonics`` x cam frequency, at most 0.4 fs."""
    if not (math.isfinite(cam_speed_rpm) and cam_speed_rpm > 0):
        raise InputError(f"cam speed {cam_speed_rpm!r} rpm is not usable to choose the filter band")
    return float(min(harmonics * cam_speed_rpm / 60.0, 0.4 * fs))


def lowpass_sos(fs: float, cutoff_hz: float, order: int = DEFAULT_ORDER) -> np.ndarray:
    """Butterworth low-pass as second-order sections; cutoff in Hz, below fs/2."""
    if not (0 < cutoff_hz < fs / 2):
        raise InputError(f"low-pass cutoff {cutoff_hz} Hz must lie in (0, {fs / 2}) Hz")
    return signal.butter(order, cutoff_hz, btype="lowpass", fs=fs, output="sos")


def settle_samples(sos: np.ndarray, tol: float = 1e-9) -> int:
    """Samples after which the filter's impulse response stays below ``tol`` of its peak.

    The overlap that makes chunked zero-phase filtering equal to whole-array filtering.
    """
    # the slowest pole sets the decay: |p|^n < tol
    poles = np.concatenate([np.roots(s[3:]) for s in sos])
    r = float(np.max(np.abs(poles)))
    if r >= 1:
        raise InputError("unstable filter")
    return int(math.ceil(math.log(tol) / math.log(r))) + 3 * len(sos)


def padlen(sos: np.ndarray) -> int:
    """Odd-extension length at each end of a zero-phase pass (scipy's filtfilt default)."""
    return 3 * (2 * len(sos) + 1)


def zero_phase(sos: np.ndarray, x: np.ndarray, axis: int = 0) -> np.ndarray:
    """Forward-backward SOS filtering (zero phase, squared magnitude), odd padding at the ends."""
    x = np.asarray(x, dtype=float)
    n = x.shape[axis]
    pad = min(padlen(sos), n - 1)
    if n < 2:
        return x.copy()
    return signal.sosfiltfilt(sos, x, axis=axis, padlen=max(pad, 0))


class StreamingSOS:
    """Causal SOS filter that keeps its state between blocks (live acquisition, streaming).

    ``process(block)`` with block shape (n, n_channels); the first block initialises the state to
    the steady state of its first sample, so a constant input passes without a start transient.
    Feeding a signal in any split gives exactly what one ``sosfilt`` over the whole signal gives.
    """

    def __init__(self, sos: np.ndarray):
        self.sos = np.asarray(sos, dtype=float)
        self.zi = None

    def process(self, block: np.ndarray) -> np.ndarray:
        block = np.asarray(block, dtype=float)
        if block.ndim == 1:
            block = block[:, None]
        if block.shape[0] == 0:
            return block.copy()
        if self.zi is None:
            zi0 = signal.sosfilt_zi(self.sos)  # (n_sections, 2)
            self.zi = zi0[:, :, None] * block[0][None, None, :]
        y, self.zi = signal.sosfilt(self.sos, block, axis=0, zi=self.zi)
        return y

    def reset(self) -> None:
        self.zi = None
