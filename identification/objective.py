"""The objective of a fit: weighted residuals of a model's cycle statistics against the measured.

The measurement side (``Target``) is computed once: the whole measured revolutions aligned and
conditioned as the report does (labtool.reports.align.read_measured), their cycle average and its standard
error, the processing low-pass re-applied to the simulations, the measured impacts and jumps.
The model side (``Evaluator``) runs the model through the report's own path
(labtool.reports.pipeline.run_simulation: periodic steady state or band statistics, conditioned like the
measurement) and keeps each run's cycle, keyed by the scene parameters, so the chain parameters
(Ka gain, delay: labtool.reports.align.as_measured) and repeated points cost no model run.

Residuals (dimensionless; docs/identification.md), at a resolution ``Level`` of H harmonics of the
cam frequency (the conditioning's, or fewer for the search's first, smoothed stage):

* omega2 and epsilon2 on every ``step``-th point of the report grid, ``step`` = n_grid // (2 H + 1):
  the band-limited cycle is fully described by 2 H + 1 samples, so these residuals are as close to
  independent as the grid allows and none of the information is lost. Each is
  (model - measured mean) / sigma with sigma^2 = (scatter / sqrt(n_rev))^2 + (MODEL_FLOOR * rms)^2:
  the measured cycle average's standard error, and a floor at the reproducibility of a model cycle
  (1 % of the signal's rms; a damped model's last two revolutions differ by 0.1-2 %).
* where the measurement shows impacts: the first impact angle (deg) over FIRST_IMPACT_TOL_DEG and
  the visible impacts per revolution over max(COUNT_TOL * measured, 1): the detector's stated
  tolerances (1 deg, 25 %; the angle's doubled). A model that predicts no visible impact
  adds 0 to the angle's term and its count's shortfall to the count's.
"""
from __future__ import annotations

import dataclasses
import math
import time
from collections import OrderedDict
from pathlib import Path

import numpy as np

from labtool.common.operating_point import SOURCE_SUFFIX
from labtool.common.errors import LabtoolError
from labtool.identification.parameters import Space
from labtool.processing.cycles import cycle_statistics
from labtool.reports import align, events, pipeline

SIGNALS = pipeline.SIGNALS
MODEL_FLOOR = 0.01            # of the measured signal's rms: how well a model cycle repeats itself
FIRST_IMPACT_TOL_DEG = 2.0
COUNT_TOL = 0.25
PENALTY = 4.0                 # a failed model run counts this many times the worst objective seen
CACHE_SIZE = 256


@dataclasses.dataclass
class Level:
    """The measured cycle at one resolution: harmonics 0..``harmonics`` of the cam frequency kept,
    sampled on ``sub`` (indices of the report grid), with the residuals' scale ``sigma``."""

    harmonics: int
    sub: np.ndarray
    mean: dict
    sigma: dict

    def view(self, signal: np.ndarray, full_harmonics: int) -> np.ndarray:
        """A conditioned cycle (full resolution) at this level, on ``sub``."""
        if self.harmonics < full_harmonics:
            signal = align.harmonic_lowpass(signal, self.harmonics)
        return signal[..., self.sub]


@dataclasses.dataclass
class Target:
    """The measurement side, computed once (SI; ``op`` in the report's edge units)."""

    path: str
    dataset: object
    cycles: align.MeasuredCycles
    cond: align.Conditioning
    time_filter: align.TimeFilter | None
    op: dict
    detector: object
    events: dict | None
    notes: list
    levels: dict = dataclasses.field(default_factory=dict)

    @property
    def n_revolutions(self) -> int:
        return len(self.cycles.revolutions)

    @property
    def has_impacts(self) -> bool:
        ev = self.events
        return bool(ev and ev.get("impacts_per_rev") and ev.get("first_impact_deg") is not None)

    def level(self, harmonics: int | None = None) -> Level:
        """The measured cycle at ``harmonics`` (default: the conditioning's), built once."""
        h = self.cond.n_harmonics if harmonics is None else min(int(harmonics), self.cond.n_harmonics)
        if h not in self.levels:
            self.levels[h] = _level(self.cycles, self.cond, h)
        return self.levels[h]


def _level(cycles: align.MeasuredCycles, cond: align.Conditioning, h: int) -> Level:
    n = len(cycles.revolutions)
    step = max(1, cond.n_grid // (2 * h + 1))
    sub = np.arange(0, cond.n_grid, step)
    mean, sigma = {}, {}
    for s in SIGNALS:
        revs = cycles.signals[s] if h >= cond.n_harmonics else align.harmonic_lowpass(cycles.signals[s], h)
        stats = cycle_statistics(revs)
        m = stats.mean
        rms = float(np.sqrt(np.mean(m ** 2)))
        sem = stats.std / math.sqrt(n) if n >= 2 else np.zeros_like(m)
        floor = MODEL_FLOOR * rms if rms > 0 else 1.0
        mean[s], sigma[s] = m[sub], np.sqrt(sem ** 2 + floor ** 2)[sub]
    return Level(h, sub, mean, sigma)


def load_target(path: Path, cond: align.Conditioning | None = None, overrides: dict | None = None) -> Target:
    """Read and condition ``measured.nc`` once: the measured cycles, their weights and events."""
    cond = cond or align.Conditioning()
    ds = pipeline.load_measured(path)
    cycles = align.read_measured(ds, SIGNALS, cond, extra=("aE_n",))
    op = pipeline.operating_point(ds, cycles.cam_speed_rpm, overrides or {})
    tf = align.processing_filter(ds)
    det = pipeline.detector_for(tf, ds)
    notes = []
    if tf is None:
        notes.append("the file records no processing low-pass: the models see only the common harmonic low-pass, "
                     "and no impacts are measured (the fit uses the cycles alone)")
    if op.get("assumed"):   # a default the file does not state changes the identified values: say so
        notes.append(pipeline.assumed_note(op))
    meas_ev = pipeline.measured_events(cycles, det, op)
    if len(cycles.revolutions) < 2:
        notes.append("one whole revolution only: its scatter is unknown, every point weighs alike "
                     f"(sigma = {100 * MODEL_FLOOR:g} % of the signal's rms)")
    return Target(str(path), ds, cycles, cond, tf, op, det, meas_ev, notes)


def event_residuals(target: Target, predicted: dict | None, delay_deg: float = 0.0) -> np.ndarray:
    """The events' residuals (empty when the measurement shows no impact)."""
    if not target.has_impacts:
        return np.empty(0)
    m = target.events
    s_angle = FIRST_IMPACT_TOL_DEG
    s_count = max(COUNT_TOL * float(m["impacts_per_rev"]), 1.0)
    p = predicted or {}
    count = p.get("detectable_impacts_per_rev")
    first = p.get("first_impact_deg")
    r_count = ((count if count is not None else 0.0) - float(m["impacts_per_rev"])) / s_count
    r_angle = 0.0 if first is None else (first + delay_deg - float(m["first_impact_deg"])) / s_angle
    return np.array([r_angle, r_count])


class Scored:
    """What a search reads of an evaluation: ``ok`` (no ``error``) and the ``objective``, the sum of
    its squared ``residuals``."""

    @property
    def ok(self) -> bool:
        return self.error is None

    @property
    def objective(self) -> float:
        return float(self.residuals @ self.residuals)


@dataclasses.dataclass
class Evaluation(Scored):
    """One point of the objective: residuals, the model's cycle as the chain shows it, its events."""

    residuals: np.ndarray
    cycle: object | None              # align.SimulatedCycles with the chain parameters applied
    events: dict | None
    error: str | None = None
    model_run: bool = False           # a new model run was needed (not in the cache)


def _hashable(v):
    """A cache-key form of an operating-point value (floats rounded; lists, e.g. the assumed keys, as tuples)."""
    if isinstance(v, float):
        return round(v, 12)
    if isinstance(v, (list, tuple)):
        return tuple(_hashable(x) for x in v)
    if isinstance(v, dict):
        return tuple(sorted((k, _hashable(x)) for k, x in v.items()))
    return v


class Evaluator:
    """The model side: residuals at a point of the search space, with a cache of model runs.

    ``fixed``: the operating point and the values of the parameters that are not free (edge units,
    labtool.reports.pipeline.operating_point's keys plus ``ka_gain`` and ``delay_ms``)."""

    def __init__(self, target: Target, model: str, omega1: str, revolutions: int, space: Space, fixed: dict):
        self.target, self.model, self.omega1, self.revolutions = target, model, omega1, int(revolutions)
        self.space, self.fixed = space, dict(fixed)
        self.cache: OrderedDict = OrderedDict()
        self.model_runs = 0
        self.evaluations = 0
        self.failures: list[dict] = []
        self.worst: dict = {}          # harmonics -> the worst objective seen (the failure penalty's scale)
        self.visited: dict = {}        # (preset, x rounded) -> x: every point evaluated, once
        self.run_s = 0.0

    # ------------------------------------------------------------------ points
    def values(self, x_edge) -> dict:
        """Every parameter's value (edge units) at the free values ``x_edge``."""
        out = dict(self.fixed)
        for p, v in zip(self.space.params, np.asarray(x_edge, float)):
            out[p.op_key] = float(v)
        return out

    def _scene_key(self, vals: dict, preset: str) -> tuple:
        # what the model run depends on: every value but the chain's and the texts saying where a value came from
        keys = sorted(k for k in vals if k not in pipeline.CHAIN_KEYS and not k.endswith(SOURCE_SUFFIX)
                      and k not in ("assumed", "source_notes"))
        return (preset,) + tuple((k, _hashable(vals[k])) for k in keys)

    def _model_run(self, vals: dict, preset: str):
        key = self._scene_key(vals, preset)
        if key in self.cache:
            self.cache.move_to_end(key)
            return self.cache[key], False
        t0 = time.perf_counter()
        try:
            scene_vals = {k: v for k, v in vals.items() if k not in pipeline.CHAIN_KEYS}
            run = pipeline.run_simulation(scene_vals, self.model, self.omega1, preset, self.revolutions, self.target.cond,
                                          self.target.time_filter)
            cycle = run.cycle
            if not all(np.all(np.isfinite(cycle.signals[s])) for s in SIGNALS):
                raise FloatingPointError("non-finite omega2/epsilon2")
            pred = None
            if self.target.has_impacts:
                pred = events.predicted(run.dataset, run.steady, self.target.detector,
                                        self.target.events["threshold_rad_s"])
            entry = (cycle, pred, None)
        except (LabtoolError, ArithmeticError, ValueError) as exc:
            msg = str(exc).splitlines()[0] if str(exc) else ""
            entry = (None, None, f"{type(exc).__name__}: {msg}")
        self.run_s += time.perf_counter() - t0
        self.model_runs += 1
        self.cache[key] = entry
        if len(self.cache) > CACHE_SIZE:
            self.cache.popitem(last=False)
        return entry, True

    def blocks(self, harmonics: int | None = None) -> list[tuple[int, int]]:
        """(start, end) of each signal's residuals, then the events', at ``harmonics``."""
        n = self.target.level(harmonics).sub.size
        out = [(k * n, (k + 1) * n) for k in range(len(SIGNALS))]
        if self.target.has_impacts:
            out.append((len(SIGNALS) * n, len(SIGNALS) * n + 2))
        return out

    def cached(self, x_edge, preset: str) -> bool:
        """Whether the model run at ``x_edge`` is in the cache (no new run needed)."""
        return self._scene_key(self.values(x_edge), preset) in self.cache

    def evaluate(self, x_edge, preset: str, harmonics: int | None = None) -> Evaluation:
        """The residuals at ``x_edge`` (free values, edge units) with the model at ``preset``, the
        cycles compared at ``harmonics`` (default: all the conditioning keeps). A model that fails
        gives a penalty (PENALTY x the worst objective so far, spread evenly) and is recorded in
        ``failures``; the search moves away from it."""
        self.evaluations += 1
        x = np.asarray(x_edge, float)
        self.visited.setdefault((preset, tuple(np.round(x, 12))), x)
        vals = self.values(x)
        lev = self.target.level(harmonics)
        n_res = len(SIGNALS) * lev.sub.size + (2 if self.target.has_impacts else 0)
        (cycle, pred, error), new = self._model_run(vals, preset)
        if error is not None:
            if new:
                self.failures.append({"at": self.space.as_dict(x), "accuracy": preset, "error": error})
            level = PENALTY * max(self.worst.get(lev.harmonics, 0.0), float(n_res))
            return Evaluation(np.full(n_res, math.sqrt(level / n_res)), None, None, error, new)
        shown = pipeline.chain_view(cycle, vals)
        ev = Evaluation(self._residuals(shown.signals, pred, vals, lev), shown, pred, None, new)
        self.worst[lev.harmonics] = max(self.worst.get(lev.harmonics, 0.0), ev.objective)
        return ev

    def _residuals(self, signals: dict, pred: dict | None, vals: dict, lev: Level) -> np.ndarray:
        delay_deg = vals.get("delay_ms", 0.0) * 1e-3 * vals["cam_speed_rpm"] * 6.0
        full = self.target.cond.n_harmonics
        parts = [(lev.view(signals[s], full) - lev.mean[s]) / lev.sigma[s] for s in SIGNALS]
        parts.append(event_residuals(self.target, pred, delay_deg))
        return np.concatenate(parts)

    def acceptable(self, preset: str, limit: float) -> np.ndarray:
        """Every point evaluated at ``preset`` whose full-resolution objective is at most ``limit``
        (rows of free values, edge units), from the cached runs: no new run."""
        rows = []
        for (p, _), x in list(self.visited.items()):
            if p == preset and self.cached(x, preset):
                e = self.evaluate(x, preset)
                if e.ok and e.objective <= limit:
                    rows.append(x)
        return np.array(rows).reshape(-1, len(self.space.params))

    def revolution_residuals(self, x_edge, e: Evaluation) -> list[np.ndarray]:
        """The residuals at ``x_edge`` with each of the model run's revolutions after the first as
        its cycle (the same run, no new one): how much the model's own revolution-to-revolution
        variation moves the objective. Empty for a run without separate revolutions."""
        revs = getattr(e.cycle, "revolutions", None)
        if not e.ok or revs is None:
            return []
        vals, lev = self.values(x_edge), self.target.level(None)
        k = next(iter(revs.values())).shape[0]
        return [self._residuals({s: revs[s][i] for s in SIGNALS}, e.events, vals, lev) for i in range(1, k)]
