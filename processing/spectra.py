"""Amplitude spectrum and Welch PSD, accumulated block by block (bounded memory).

Both use Hann-windowed segments of ``nperseg`` samples with 50 % overlap, each detrended by its
mean ("translated" data), one-sided. The amplitude spectrum is the mean over segments of
2|X(f)|/sum(w): a sinusoid of amplitude A (m/s^2) shows as A at its frequency (Figure 11a-b).
The PSD is Welch's estimate in (m/s^2)^2/Hz (scipy's 'density' scaling), so that
sum(psd) * df equals the signal's variance. Segments that touch a flagged (clipped) sample are
left out of both.
"""
from __future__ import annotations

import numpy as np
import scipy.fft as sfft

from labtool.processing import kernels


def default_nperseg(fs: float, n_samples: int, seconds: float = 4.0) -> int:
    """Power of two nearest ``seconds`` of signal, at most the recording's length, at least 16."""
    target = max(16, int(2 ** round(np.log2(max(fs * seconds, 16)))))
    while target > n_samples and target > 16:
        target //= 2
    return int(target)


class WelchAccumulator:
    """Feed (n, n_channels) blocks in order; read ``frequency``, ``amplitude``, ``psd`` at the end."""

    def __init__(self, fs: float, nperseg: int, n_channels: int):
        self.fs = float(fs)
        self.nperseg = int(nperseg)
        self.hop = self.nperseg // 2
        self.window = np.hanning(self.nperseg + 1)[:-1]  # periodic Hann, as scipy's 'hann'
        self._wfft = np.fft.rfft(self.window)
        self._w32 = self.window.astype(np.float32)
        self.nch = n_channels
        self.sum_amp = np.zeros((self.nperseg // 2 + 1, n_channels))
        self.sum_pow = np.zeros_like(self.sum_amp)
        self.count = 0
        self.skipped = 0
        self._wfft32 = self._wfft.astype(np.complex64)
        # the samples not yet in a full segment and the next block, channel-major float32 (the form
        # the transforms use), and the windowed segments: reused from block to block (no allocation
        # per block but the transform's output; see workspace.py for why that matters)
        self._ring = np.empty((n_channels, 0), dtype=np.float32)
        self._ring_bad = np.empty(0, dtype=bool)
        self._nbuf = 0
        self._win = np.empty((n_channels, 0, self.nperseg), dtype=np.float32)

    def reset_continuity(self) -> None:
        """Drop the carried-over samples (a gap: segments must not straddle it)."""
        self._nbuf = 0

    def _append(self, x: np.ndarray, bad: np.ndarray) -> int:
        n = self._nbuf + len(x)
        if self._ring.shape[1] < n:
            ring = np.empty((self.nch, n), dtype=np.float32)
            ring_bad = np.empty(n, dtype=bool)
            ring[:, :self._nbuf], ring_bad[:self._nbuf] = self._ring[:, :self._nbuf], self._ring_bad[:self._nbuf]
            self._ring, self._ring_bad = ring, ring_bad
        self._ring[:, self._nbuf:n] = x.T
        self._ring_bad[self._nbuf:n] = bad
        return n

    def feed(self, x: np.ndarray, bad: np.ndarray | None = None) -> None:
        x = np.asarray(x).reshape(len(x), self.nch)
        bad = np.zeros(len(x), dtype=bool) if bad is None else np.asarray(bad, dtype=bool)
        n = self._append(x, bad)
        buf, badbuf = self._ring[:, :n], self._ring_bad[:n]
        nseg = 0 if n < self.nperseg else 1 + (n - self.nperseg) // self.hop
        if nseg:
            starts = np.arange(nseg) * self.hop
            if badbuf.any():
                badcum = np.concatenate([[0], np.cumsum(badbuf)])
                ok = (badcum[starts + self.nperseg] - badcum[starts]) == 0
                self.skipped += int((~ok).sum())
                starts = starts[ok]
            # detrending by the segment mean commutes with the FFT: X((x - m) w) = X(x w) - m W;
            # float32 transforms of all the block's segments in one call (~4x faster than float64
            # one by one, and far more precise than needed)
            if len(starts):
                view = np.lib.stride_tricks.sliding_window_view(buf, self.nperseg, axis=1)
                # every segment: a strided view; some left out (clipped): a copy of the others
                segs = view[:, ::self.hop][:, :nseg] if len(starts) == nseg else view[:, starts]
                if self._win.shape[1] < len(starts):
                    self._win = np.empty((self.nch, len(starts), self.nperseg), dtype=np.float32)
                win = np.multiply(segs, self._w32, out=self._win[:, :len(starts)])
                spec = sfft.rfft(win, axis=-1)
                # |X - mean W| and its square summed over the segments (numpy: spec -= mean * W;
                # mag = abs(spec); sum_amp += mag.sum(axis=1, dtype=float64).T, the same for mag**2)
                kernels.welch_accumulate(spec, segs.mean(axis=-1), self._wfft32, self.sum_amp, self.sum_pow)
                self.count += len(starts)
            keep_from = nseg * self.hop
        else:
            keep_from = 0
        rest = n - keep_from
        self._ring[:, :rest] = self._ring[:, keep_from:n].copy()
        self._ring_bad[:rest] = self._ring_bad[keep_from:n].copy()
        self._nbuf = rest

    @property
    def frequency(self) -> np.ndarray:
        return np.fft.rfftfreq(self.nperseg, 1.0 / self.fs)

    def amplitude(self) -> np.ndarray:
        """Mean amplitude spectrum (same unit as the input), shape (n_freq, n_channels)."""
        scale = np.full(self.nperseg // 2 + 1, 2.0 / self.window.sum())
        scale[0] /= 2.0
        if self.nperseg % 2 == 0:
            scale[-1] /= 2.0
        return self.sum_amp / max(self.count, 1) * scale[:, None] if self.count else np.full_like(self.sum_amp, np.nan)

    def psd(self) -> np.ndarray:
        """Welch PSD (unit^2/Hz), one-sided, shape (n_freq, n_channels)."""
        if not self.count:
            return np.full_like(self.sum_pow, np.nan)
        scale = np.full(self.nperseg // 2 + 1, 2.0 / (self.fs * (self.window**2).sum()))
        scale[0] /= 2.0
        if self.nperseg % 2 == 0:
            scale[-1] /= 2.0
        return self.sum_pow / self.count * scale[:, None]


def _whole_array_welch(x: np.ndarray, fs: float, nperseg: int | None):
    """Feed a 1-D or (n, nch) array to one WelchAccumulator; returns (accumulator, was 1-D)."""
    x = np.asarray(x, dtype=float)
    x2 = x[:, None] if x.ndim == 1 else x
    acc = WelchAccumulator(fs, nperseg or default_nperseg(fs, len(x2)), x2.shape[1])
    acc.feed(x2)
    return acc, x.ndim == 1


def amplitude_spectrum(x: np.ndarray, fs: float, nperseg: int | None = None):
    """(frequency Hz, amplitude) of a 1-D or (n, nch) array, whole-array convenience."""
    acc, one_d = _whole_array_welch(x, fs, nperseg)
    amp = acc.amplitude()
    return acc.frequency, (amp[:, 0] if one_d else amp)


def welch_psd(x: np.ndarray, fs: float, nperseg: int | None = None):
    """(frequency Hz, PSD unit^2/Hz) of a 1-D or (n, nch) array."""
    acc, one_d = _whole_array_welch(x, fs, nperseg)
    p = acc.psd()
    return acc.frequency, (p[:, 0] if one_d else p)
