"""One entry point for every model level: ``simulate(scene, model) -> SimulationResult``.

Levels (docs/architecture.md, fidelity ladder): ``kinematic`` (cam as input), ``rigid`` (eqs 1-11),
``elastic`` (eqs 12-19), and ``auto`` (the cheapest level the scene needs, labtool.models.dynamics.auto).
``LEVELS`` is the registry: a level's module is imported when a run needs it (the compiled models
load numba; a kinematic run does not), always downwards: no level imports this module.
Every result's dataset gets the scene's provenance (labtool.models.dynamics.provenance) and the level
that ran, and why.

``indicators(scene, model)`` is the path for sweeps and fits that need the paper's indicators
only: the same loops and the same values as ``simulate(...).indicators`` (tests/test_indicators.py),
without building a Dataset (the Dataset and its output kinematics cost 2-5x the loop).
"""
from __future__ import annotations

import time

from labtool.common.errors import InputError
from labtool.models.dynamics.provenance import scene_attributes
from labtool.models.dynamics.result import INDICATORS, SimulationResult  # noqa: F401  (the public names)
from labtool.models.dynamics.scene import Scene


def _kinematic(scene: Scene, **options) -> SimulationResult:
    from labtool.models.dynamics import kinematic
    return kinematic.simulate(scene)


def _rigid(scene: Scene, **options) -> SimulationResult:
    from labtool.models.dynamics import rigid
    return rigid.simulate(scene, **options)


def _elastic(scene: Scene, **options) -> SimulationResult:
    from labtool.models.dynamics import elastic
    return elastic.simulate(scene, **options)


def _auto(scene: Scene, **options) -> SimulationResult:
    from labtool.models.dynamics import auto
    return auto.simulate_auto(scene, **options)


LEVELS = {"kinematic": _kinematic, "rigid": _rigid, "elastic": _elastic}


def _rigid_indicators(scene: Scene, **options) -> dict:
    from labtool.models.dynamics import rigid
    return rigid.simulate_indicators(scene, **options)


def _elastic_indicators(scene: Scene, **options) -> dict:
    from labtool.models.dynamics import elastic
    return elastic.simulate_indicators(scene, **options)


# levels with a Dataset-free indicator path; the others (kinematic, auto) read simulate()'s
INDICATOR_PATHS = {"rigid": _rigid_indicators, "elastic": _elastic_indicators}


def simulate(scene: Scene, model: str = "auto", **options) -> SimulationResult:
    """Run ``model`` (or the cheapest level the scene needs, for ``auto``) on ``scene``.

    ``options`` go to the level (rigid, elastic: solver=, preset=, stats=; see their simulate)."""
    t0 = time.perf_counter()
    if model == "auto":
        result = _auto(scene, **options)            # sets model and reason itself
    elif model in LEVELS:
        result = LEVELS[model](scene, **options)
        result.model, result.reason = model, f"requested --model {model}"
    else:
        raise InputError(f"unknown model '{model}'; known: auto, {', '.join(LEVELS)}")
    result.wall_s = time.perf_counter() - t0
    result.attrs.update(scene_attributes(scene))             # into the Dataset, built or not yet
    result.attrs.update(model=result.model, model_reason=result.reason)
    result.attrs.setdefault("validity_warnings", "[]")
    return result


def indicators(scene: Scene, model: str = "auto", **options) -> dict:
    """The indicators of ``simulate(scene, model, **options)`` (its ``indicators`` dict: the keys of
    result.INDICATORS, None where the level does not compute one, and the level's own), plus
    ``model`` (the level that ran) and ``wall_s``; for rigid and elastic without building the
    Dataset (same loops, same samples, same values; the same refusals and SolverErrors)."""
    t0 = time.perf_counter()
    if model in INDICATOR_PATHS:
        ind = dict(INDICATOR_PATHS[model](scene, **options))
    else:
        result = simulate(scene, model, **options)
        ind, model = dict(result.indicators), result.model
    ind.update(model=model, wall_s=time.perf_counter() - t0)
    return ind
