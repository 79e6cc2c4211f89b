"""Cycle statistics: revolutions on a cam-angle grid, their mean, scatter and count per grid point.

The one averager of revolutions: ``CycleAccumulator`` takes revolutions already on the grid (rows)
or resamples one (``add``), keeps per grid point the count, the mean and the sum of squared
deviations (M2), and merges each batch of rows into them with Chan, Golub and LeVeque's pairwise
update, so memory does not grow with the recording's length and a single batch gives what
``numpy.mean`` and ``numpy.std`` give for it. ``keep=True`` also keeps the rows (the per-revolution
matrix). ``cycle_statistics`` is that for one matrix of revolutions.

``labtool process`` feeds it every complete revolution free of clipped samples and NaN (one
mark-to-mark interval, cam_angle.py, within one segment); the report's measured and simulated
cycles (labtool.reports.align), their curves files and the identification's targets read their
statistics from it.
"""
from __future__ import annotations

import dataclasses
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


@dataclasses.dataclass(frozen=True)
class CycleStatistics:
    """Statistics over revolutions at each grid point: ``mean`` and ``std`` (the signal's unit,
    shape (n_grid,)), ``count`` revolutions; ``std`` is NaN where count <= ddof."""

    mean: np.ndarray
    std: np.ndarray
    count: int


class CycleAccumulator:
    """Count, mean and scatter per grid point of the revolutions of several signals.

    Parameters
    ----------
    names : list of str
        The signals, in the order of the rows' first axis.
    n_grid : int
        Grid points per revolution (``phi1_grid``).
    keep : bool
        Keep every row added (``revolutions``).
    """

    def __init__(self, names: list[str], n_grid: int = 720, keep: bool = False):
        self.grid = phi1_grid(n_grid)
        self.names = list(names)
        self.means = np.zeros((len(self.names), n_grid))   # the signals' unit
        self.m2s = np.zeros((len(self.names), n_grid))     # sum of squared deviations from the mean
        self.count = 0
        self.rejected = 0
        self._rows = [] if keep else None

    def add(self, frac_pos: np.ndarray, values: dict[str, np.ndarray]) -> bool:
        """Add one revolution: ``frac_pos`` = phi1 (rad, increasing from ~0 to ~2 pi) of its samples.
        A revolution holding a non-finite value is counted as rejected and left out."""
        vals = np.stack([np.asarray(values[k], dtype=float) for k in self.names])
        if not np.isfinite(vals).all():
            self.rejected += 1
            return False
        self.add_rows(resample_revolution(frac_pos, vals, self.grid)[None])     # one search for all variables
        return True

    def add_rows(self, rows: np.ndarray) -> None:
        """Add revolutions already on the grid: ``rows`` (n_rev, n_names, n_grid)."""
        rows = np.asarray(rows, dtype=float)
        nb = rows.shape[0]
        if nb == 0:
            return
        mb = rows.mean(axis=0)
        m2b = ((rows - mb) ** 2).sum(axis=0)
        na = self.count
        if na == 0:
            self.means[...], self.m2s[...] = mb, m2b
        else:
            n = na + nb
            delta = mb - self.means
            self.means += delta * (nb / n)
            self.m2s += m2b + delta**2 * (na * nb / n)
        self.count += nb
        if self._rows is not None:
            self._rows.append(rows)

    def statistics(self, name: str, ddof: int = 1) -> CycleStatistics:
        """Mean, standard deviation (with ``ddof``) and count of signal ``name`` per grid point."""
        i = self.names.index(name)
        n = self.count
        nan = np.full_like(self.grid, np.nan)
        mean = self.means[i].copy() if n else nan
        std = np.sqrt(self.m2s[i] / (n - ddof)) if n > ddof else nan.copy()
        return CycleStatistics(mean, std, n)

    def revolutions(self, name: str) -> np.ndarray:
        """Every row of signal ``name`` added (n_rev, n_grid); only with ``keep=True``."""
        if self._rows is None:
            raise ValueError("the accumulator was made without keep=True: it keeps no rows")
        i = self.names.index(name)
        return np.concatenate([r[:, i] for r in self._rows]) if self._rows else np.empty((0, self.grid.size))

    def result(self, ddof: int = 1) -> dict[str, np.ndarray]:
        """{name_mean, name_std} (std with ``ddof``, n - 1 by default; NaN if too few revolutions)."""
        out = {}
        for k in self.names:
            st = self.statistics(k, ddof)
            out[f"{k}_mean"], out[f"{k}_std"] = st.mean, st.std
        return out


def cycle_statistics(revolutions: np.ndarray, ddof: int = 0) -> CycleStatistics:
    """Mean, standard deviation and count per grid point of one matrix of revolutions.

    Parameters
    ----------
    revolutions : array_like
        (n_rev, n_grid): one revolution of a signal per row, on a common cam-angle grid.
    ddof : int
        Delta degrees of freedom of the standard deviation (0: the revolutions are the population).
    """
    rows = np.asarray(revolutions, dtype=float)
    acc = CycleAccumulator(["x"], rows.shape[-1])
    acc.add_rows(rows[:, None, :])
    return acc.statistics("x", ddof)
