"""Cycle statistics: every complete cam revolution resampled on a phi1 grid; mean and scatter.

A revolution is one mark-to-mark interval (cam_angle.py); it enters the statistics only when it
is complete, within one segment, and free of clipped samples and NaN. Sums and sums of squares are
accumulated, so memory does not grow with the recording's length.
"""
from __future__ import annotations

import math

import numpy as np


def phi1_grid(n: int = 720) -> np.ndarray:
    """Cam angles (rad) of the cycle-average grid, 2 pi k / n."""
    return 2.0 * math.pi * np.arange(n) / n


def resample_revolution(frac_pos: np.ndarray, values: np.ndarray, grid: np.ndarray, outside: float | None = None):
    """``values`` (n_names, n_samples) at the cam angles ``frac_pos`` (rad, increasing) linearly
    interpolated at ``grid`` (rad): an array (n_names, n_grid). Grid points past the samples take
    the nearest sample's value, or ``outside`` (e.g. NaN) when given."""
    j = np.clip(np.searchsorted(frac_pos, grid, side="right") - 1, 0, len(frac_pos) - 2)
    w = np.clip((grid - frac_pos[j]) / (frac_pos[j + 1] - frac_pos[j]), 0.0, 1.0)
    v = values[:, j] * (1.0 - w) + values[:, j + 1] * w
    if outside is not None:
        v[:, (grid < frac_pos[0]) | (grid > frac_pos[-1])] = outside
    return v


class CycleAccumulator:
    def __init__(self, names: list[str], n_grid: int = 720):
        self.grid = phi1_grid(n_grid)
        self.names = list(names)
        # (n_names, n_grid) arrays (kernels.add_cycles adds to them), seen per name as views
        self.sums = np.zeros((len(self.names), n_grid))
        self.sumsqs = np.zeros((len(self.names), n_grid))
        self.sum = {k: self.sums[i] for i, k in enumerate(self.names)}
        self.sumsq = {k: self.sumsqs[i] for i, k in enumerate(self.names)}
        self.count = 0
        self.rejected = 0

    def add(self, frac_pos: np.ndarray, values: dict[str, np.ndarray]) -> bool:
        """Add one revolution: ``frac_pos`` = phi1 (rad, increasing from ~0 to ~2 pi) of its samples."""
        vals = np.stack([np.asarray(values[k], dtype=float) for k in self.names])
        if not np.isfinite(vals).all():
            self.rejected += 1
            return False
        v = resample_revolution(frac_pos, vals, self.grid)     # one search for all variables
        for i, k in enumerate(self.names):
            self.sum[k] += v[i]
            self.sumsq[k] += v[i] * v[i]
        self.count += 1
        return True


    def result(self) -> dict[str, np.ndarray]:
        """{name_mean, name_std} (std with n - 1; NaN if fewer than two revolutions)."""
        out = {}
        n = self.count
        for k in self.names:
            mean = self.sum[k] / n if n else np.full_like(self.grid, np.nan)
            if n >= 2:
                var = np.maximum(self.sumsq[k] - n * mean**2, 0.0) / (n - 1)
                std = np.sqrt(var)
            else:
                std = np.full_like(self.grid, np.nan)
            out[f"{k}_mean"] = mean
            out[f"{k}_std"] = std
        return out
