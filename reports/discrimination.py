"""Where a measurement would tell models apart: the cam speed at which their predictions differ most
against what a measurement resolves (docs/reports.md, "The verdict").

``discriminate(op, candidates, scatter, measured_rpm)`` simulates each candidate model at a handful
of cam speeds within the models' range (the drive's synchronous speed,
``Mechanism.default().max_cam_speed_rpm``), cheaply (the fast preset, a few revolutions), puts each
on the report's cam-angle grid with the report's conditioning, and returns per speed how far every
pair's omega2 and epsilon2 cycles lie apart in units of the measurement's resolution:

    distance = rms over the revolution of (model a - model b) / rms of the measured scatter

where the measured scatter is the per-grid-point standard deviation of the measured revolutions.
At another speed the scatter is taken to scale as the signal does (omega2 with n1, epsilon2 with
n1^2: the same relative scatter); a recording there has its own. A distance above 2 means the two
predictions are further apart than two revolutions of the measurement typically are.

Pure: plain arguments in, plain data out, nothing written (``labtool suggest`` calls it too).
"""
from __future__ import annotations

import dataclasses
import itertools
import math
from typing import Mapping, Sequence

import numpy as np

from labtool.common.errors import LabtoolError

SIGNALS = ("omega2", "epsilon2")
SCALE_POWER = {"omega2": 1.0, "epsilon2": 2.0}   # how the law's signal, and so its scatter, grows with n1
TELLS_APART = 2.0                                 # distance (in measured scatters) that a recording resolves
N_SPEEDS = 6
REVOLUTIONS = 3.0
LOWEST_FRACTION = 0.1                             # the slowest speed tried, a fraction of the fastest


@dataclasses.dataclass
class Discrimination:
    """How far the candidates' predictions lie apart at each speed.

    speeds_rpm   the cam speeds tried [rpm], increasing (the measured speed among them)
    pairs        [(label a, label b)]
    distance     signal -> array (n_speeds, n_pairs) [-]: rms difference over the rms measured scatter
    best_rpm     the speed where the closest pair (the smallest epsilon2 distance over the pairs)
                 lies furthest apart [rpm]
    measured_rpm the measurement's speed [rpm]
    failed       label -> why its simulation failed at some speed (that speed's distance is NaN)
    """

    speeds_rpm: np.ndarray
    pairs: list
    distance: dict
    best_rpm: float
    measured_rpm: float
    failed: dict = dataclasses.field(default_factory=dict)

    def worst_pair(self, signal: str = "epsilon2") -> np.ndarray:
        """Per speed, the distance of the pair that lies closest (NaN where a simulation failed)."""
        d = self.distance[signal]
        return np.min(d, axis=1) if d.shape[1] else np.full(d.shape[0], np.nan)

    def at(self, rpm: float, signal: str = "epsilon2") -> float:
        return float(self.worst_pair(signal)[int(np.argmin(np.abs(self.speeds_rpm - rpm)))])

    def as_dict(self) -> dict:
        return {"speeds_rpm": self.speeds_rpm.tolist(), "pairs": [list(p) for p in self.pairs],
                "epsilon2_distance": self.distance["epsilon2"].tolist(), "omega2_distance": self.distance["omega2"].tolist(),
                "best_rpm": self.best_rpm, "measured_rpm": self.measured_rpm, "tells_apart": TELLS_APART,
                "failed": dict(self.failed), "sentence": self.sentence()}

    def sentence(self) -> str:
        """What would tell the candidates apart, in words."""
        from labtool.reports.verdict import names
        who = names(dict.fromkeys(lab for p in self.pairs for lab in p))
        here = self.at(self.measured_rpm)
        best = self.at(self.best_rpm)
        if not math.isfinite(best):
            return f"no cam speed was found where the predictions of {who} could be compared"
        if best < TELLS_APART:
            return (f"no cam speed up to {self.speeds_rpm.max():.0f} rpm would tell {who} apart: their epsilon2 cycles "
                    f"differ by at most {best:.2g} x the measured scatter (at {self.best_rpm:.0f} rpm; "
                    f"{here:.2g} x at the measured {self.measured_rpm:.0f} rpm)")
        return (f"what would tell {who} apart: a recording at {self.best_rpm:.0f} rpm, where their predicted epsilon2 "
                f"cycles differ most, by {best:.2g} x the measured scatter ({here:.2g} x at the measured "
                f"{self.measured_rpm:.0f} rpm; omega2 {self.at(self.best_rpm, 'omega2'):.2g} x)")


def speeds(measured_rpm: float, top_rpm: float, n: int = N_SPEEDS) -> np.ndarray:
    """``n`` speeds from LOWEST_FRACTION x ``top_rpm`` to ``top_rpm`` [rpm], and the measured one."""
    s = np.linspace(LOWEST_FRACTION * top_rpm, top_rpm, n).round(6)
    return np.unique(np.minimum(np.append(s, measured_rpm), top_rpm))


def discriminate(op: dict, candidates: Sequence[tuple[str, str, str]], scatter: Mapping[str, np.ndarray],
                 measured_rpm: float, speeds_rpm: Sequence[float] | None = None, accuracy: str = "fast",
                 revolutions: float = REVOLUTIONS, cond=None) -> Discrimination:
    """Simulate every candidate at each speed and measure how far their predictions lie apart.

    Parameters
    ----------
    op : dict
        The operating point (labtool.reports.pipeline.operating_point's dict, edge units); only
        the cam speed changes between the runs.
    candidates : sequence of (label, model, omega1)
        The runs to tell apart: a label for the result, the model level (rigid, elastic,
        kinematic) and the omega1 mode (const, var).
    scatter : mapping
        Per signal (omega2 [rad/s], epsilon2 [rad/s^2]) the measured per-grid-point standard
        deviation over the revolutions, on ``cond``'s grid.
    measured_rpm : float
        The cam speed of the measurement [rpm], where ``scatter`` was measured.
    speeds_rpm : sequence of float, optional
        The speeds to try [rpm]; default ``speeds(measured_rpm, max cam speed)``.
    accuracy, revolutions
        The models' preset and simulated revolutions (cheap by default).
    cond : labtool.reports.align.Conditioning, optional
        The comparison's grid and low-pass (default the report's).
    """
    from labtool.models.mechanism import Mechanism
    from labtool.reports import align
    from labtool.reports.simulation import no_load_factor, run_simulation

    cond = cond or align.Conditioning()
    top = Mechanism.default().max_cam_speed_rpm
    rpm = np.asarray(speeds(measured_rpm, top) if speeds_rpm is None else speeds_rpm, dtype=float)
    rpm = np.sort(np.minimum(rpm[rpm > 0], top))
    pairs = list(itertools.combinations([c[0] for c in candidates], 2))
    sigma = {s: float(np.sqrt(np.mean(np.square(scatter[s])))) for s in SIGNALS}
    dist = {s: np.full((rpm.size, len(pairs)), np.nan) for s in SIGNALS}
    failed = {}
    nlf = no_load_factor()
    for i, n1 in enumerate(rpm):
        at = dict(op, cam_speed_rpm=float(n1), omega1_var_n1_rpm=float(n1) / nlf)
        curves = {}
        for label, model, mode in candidates:
            try:
                # no processing low-pass: its cutoff follows the cam speed; the harmonic one is common
                curves[label] = run_simulation(at, model, mode, accuracy, revolutions, cond, None).cycle.signals
            except (LabtoolError, ValueError, ArithmeticError) as exc:
                failed[label] = f"{n1:.0f} rpm: {exc}"
        for s in SIGNALS:
            scale = sigma[s] * (n1 / measured_rpm) ** SCALE_POWER[s]
            for j, (a, b) in enumerate(pairs):
                if a in curves and b in curves and scale > 0:
                    dist[s][i, j] = float(np.sqrt(np.mean(np.square(curves[a][s] - curves[b][s])))) / scale
    worst = np.min(dist["epsilon2"], axis=1) if pairs else np.full(rpm.size, np.nan)
    best = float(rpm[int(np.nanargmax(worst))]) if np.isfinite(worst).any() else math.nan
    return Discrimination(rpm, pairs, dist, best, float(measured_rpm), failed)
