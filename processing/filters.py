"""SOS filters: zero-phase offline (whole or chunked with overlap) and stateful causal streaming.

Pure functions of arrays; frequencies in Hz, samples along axis 0.

Band limits (chosen from the cam speed, see docs/processing.md): the upper edge is a low-pass at
``harmonics`` times the cam frequency f1 = n1/60 (default 100 f1: 300 Hz at 180 rpm, 833 Hz at
500 rpm), capped at 0.4 fs; it keeps the motion law's content (the sine law's acceleration spectrum
falls as 1/f^3 past 1/T_rise) and removes sensor noise and chain resonances above. The lower edge
is not an IIR high-pass (the normal acceleration has a real mean, omega2^2 DE > 0): the offset and
the AC-coupling droop are removed by referencing the signal to the dwells (follower.py), which acts
as a high-pass at about f1/2.

No scipy.signal here (nor anywhere on ``labtool process``'s path): importing it costs 0.6 s of CPU
and 57 MB of resident memory (it pulls scipy.stats, optimize, interpolate), a tenth of processing
an hour and a fifth of its memory bound, for three small functions. The Butterworth design, the
step-response state and the filtering are written here and in kernels.py, and tested equal to
scipy.signal.butter, sosfilt_zi, sosfiltfilt and sosfilt (tests/test_proc_dsp.py, test_proc_kernels.py).
"""
from __future__ import annotations

import math

import numpy as np

from labtool.common.errors import InputError
from labtool.processing import kernels

DEFAULT_HARMONICS = 100.0
DEFAULT_ORDER = 4


def lowpass_cutoff_hz(cam_speed_rpm: float, fs: float, harmonics: float = DEFAULT_HARMONICS) -> float:
    """The low-pass corner (Hz): ``harmonics`` x cam frequency, at most 0.4 fs."""
    if not (math.isfinite(cam_speed_rpm) and cam_speed_rpm > 0):
        raise InputError(f"cam speed {cam_speed_rpm!r} rpm is not usable to choose the filter band")
    return float(min(harmonics * cam_speed_rpm / 60.0, 0.4 * fs))


def lowpass_sos(fs: float, cutoff_hz: float, order: int = DEFAULT_ORDER) -> np.ndarray:
    """Butterworth low-pass as second-order sections (n_sections, 6); cutoff in Hz, below fs/2.

    scipy.signal.butter(order, cutoff_hz, fs=fs, output="sos")'s design: the analog prototype's
    poles at the prewarped corner, the bilinear transform, every zero at z = -1, sections ordered
    with the poles closest to the unit circle last, the gain in the first section.
    """
    if not (0 < cutoff_hz < fs / 2):
        raise InputError(f"low-pass cutoff {cutoff_hz} Hz must lie in (0, {fs / 2}) Hz")
    order = int(order)
    if order < 1:
        raise InputError(f"filter order {order} must be at least 1")
    # the same arithmetic as scipy: frequencies normalised to Nyquist, bilinear transform at fs = 2
    warped = 4.0 * math.tan(math.pi * (2.0 * cutoff_hz / fs) / 2.0)
    p = warped * -np.exp(1j * np.pi * np.arange(-order + 1, order, 2) / (2 * order))
    k = warped**order
    pz = (4.0 + p) / (4.0 - p)
    k = k * np.real(1.0 / np.prod(4.0 - p))
    sections = [[1.0, 2.0, 1.0, 1.0, -2.0 * q.real, (q * np.conj(q)).real] for q in pz if q.imag > 0]
    worst = [abs(1.0 - abs(q)) for q in pz if q.imag > 0]
    for q in pz:
        if q.imag == 0:  # the real pole of an odd order
            sections.append([1.0, 1.0, 0.0, 1.0, -q.real, 0.0])
            worst.append(abs(1.0 - abs(q.real)))
    sos = np.array([sections[i] for i in np.argsort(worst)[::-1]])
    sos[0, :3] *= k
    return sos


def sosfilt_zi(sos: np.ndarray) -> np.ndarray:
    """Initial state (n_sections, 2) of the sections' steady state for a unit step input
    (scipy.signal.sosfilt_zi): each section's lfilter_zi, scaled by the DC gain before it."""
    sos = np.asarray(sos, dtype=float)
    zi = np.empty((len(sos), 2))
    scale = 1.0
    for i, (b0, b1, b2, a0, a1, a2) in enumerate(sos):
        b0, b1, b2, a1, a2 = b0 / a0, b1 / a0, b2 / a0, a1 / a0, a2 / a0
        # (I - companion(a).T) z = b[1:] - a[1:] b0, solved in closed form for 2 x 2
        r0, r1 = b1 - a1 * b0, b2 - a2 * b0
        z0 = (r0 + r1) / (1.0 + a1 + a2)
        zi[i] = scale * z0, scale * (r1 - a2 * z0)
        scale *= (b0 + b1 + b2) / (1.0 + a1 + a2)
    return zi


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
    """Forward-backward SOS filtering (zero phase, squared magnitude), odd padding at the ends:
    scipy.signal.sosfiltfilt(sos, x, axis, padlen=min(padlen(sos), n - 1)), compiled."""
    x = np.asarray(x, dtype=float)
    n = x.shape[axis]
    if n < 2:
        return x.copy()
    sos = np.ascontiguousarray(sos, dtype=float)
    moved = np.moveaxis(x, axis, 0)
    flat = np.ascontiguousarray(moved.reshape(n, -1))
    y = kernels.sosfiltfilt(sos, sosfilt_zi(sos), flat, min(padlen(sos), n - 1))
    return np.moveaxis(y.reshape(moved.shape), 0, axis)


class StreamingSOS:
    """Causal SOS filter that keeps its state between blocks (live acquisition, streaming).

    ``process(block)`` with block shape (n, n_channels); the first block initialises the state to
    the steady state of its first sample, so a constant input passes without a start transient.
    Feeding a signal in any split gives exactly what one ``sosfilt`` over the whole signal gives.
    """

    def __init__(self, sos: np.ndarray):
        self.sos = np.ascontiguousarray(sos, dtype=float)
        self.z = None

    def process(self, block: np.ndarray) -> np.ndarray:
        block = np.asarray(block, dtype=float)
        if block.ndim == 1:
            block = block[:, None]
        if block.shape[0] == 0:
            return block.copy()
        block = np.ascontiguousarray(block)
        if self.z is None:  # (n_channels, n_sections, 2): the steady state of the first sample
            self.z = np.ascontiguousarray(sosfilt_zi(self.sos)[None, :, :] * block[0][:, None, None])
        out = np.empty_like(block)
        kernels.sos_pass_state(self.sos, self.z, block, out, False)
        return out

    def reset(self) -> None:
        self.z = None
