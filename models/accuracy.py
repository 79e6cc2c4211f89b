"""Accuracy presets ``fast`` / ``standard`` / ``reference``: which solver runs, with which
tolerances, and the error each one was MEASURED to make against an independent reference solution.

The reference solution (``reference_run``) is scipy's DOP853 (8th order, a different method from
the compiled Dormand-Prince 5(4)) at rtol 1e-12 on the model's own equations: for the rigid model
its ``reference`` preset (DOP853, rtol 1e-12, max step 1/4000 of the rise); for the elastic model
DOP853 at rtol 1e-12, atol (1e-16 m, 1e-12 m/s), 16 steps per contact period at most.

``fast`` and ``standard`` run the compiled loops of ``models.kernels`` (numba) with the model's
tolerances (``models.rigid.PRESETS``, ``models.elastic.PRESETS``); ``reference`` runs the scipy
``solve_ivp`` path. ``MEASURED`` holds the worst error over the 16 runs of Table 1 (omega1
variable, sine law) of each preset against the reference solution, as written by
``benchmarks/work_precision.py`` (its CSV is benchmarks/results/work_precision.csv):

    err_omega2      max |omega2 - omega2_ref| / max |omega2_ref| over the rise, samples closer than
                    two output steps to an event excluded (there the jump itself is compared, below)
    err_MR13D       the same for MR13D (N m)
    err_event_time  max |t_event - t_event_ref| (s) over the events, matched in order
    d_events        max |number of events - reference's|
    err_indicators  max relative error of the Table 2/3 indicators (MR13D max/min, dphi2, domega2,
                    domega1, percussion, xel max/min) against the reference's, floor 1e-9 of scale

``bound(model, preset)`` is what the tests hold a preset to: the measured figure times 3 (margin for
other scenes than Table 1's), never below 1e-9.
"""
from __future__ import annotations

import contextlib
import dataclasses
import functools
import importlib
import inspect
import math
import threading

import numpy as np

from models.errors import InputError

MODELS = ("rigid", "elastic")
PRESET_NAMES = ("fast", "standard", "reference")

# which loop runs each preset: "compiled" = models.kernels (numba DP5(4)), "scipy" = solve_ivp
SOLVER = {
    ("rigid", "fast"): "compiled", ("rigid", "standard"): "compiled", ("rigid", "reference"): "scipy",
    ("elastic", "fast"): "compiled", ("elastic", "standard"): "compiled", ("elastic", "reference"): "scipy",
}

# the independent reference solution: scipy DOP853 at rtol 1e-12
REFERENCE_SOLUTION = {
    "rigid": dict(method="DOP853", rtol=1e-12, max_step=1 / 4000, samples=16000, v_settle=1e-7, max_events=20000),
    "elastic": dict(method="DOP853", rtol=1e-12, atol_x=1e-16, atol_v=1e-12, steps_per_period=16.0),
}

# worst case over Table 1's 16 runs, written by benchmarks/work_precision.py (see docs/performance.md)
MEASURED: dict = {
    "rigid": {
        "fast": dict(err_omega2=None, err_MR13D=None, err_event_time=None, d_events=None, err_indicators=None),
        "standard": dict(err_omega2=None, err_MR13D=None, err_event_time=None, d_events=None, err_indicators=None),
        "reference": dict(err_omega2=None, err_MR13D=None, err_event_time=None, d_events=None, err_indicators=None),
    },
    "elastic": {
        "fast": dict(err_omega2=None, err_MR13D=None, err_event_time=None, d_events=None, err_indicators=None),
        "standard": dict(err_omega2=None, err_MR13D=None, err_event_time=None, d_events=None, err_indicators=None),
        "reference": dict(err_omega2=None, err_MR13D=None, err_event_time=None, d_events=None, err_indicators=None),
    },
}
SAFETY = 3.0
FLOOR = 1e-9


def _check(model: str, preset: str):
    if model not in MODELS:
        raise InputError(f"accuracy presets exist for {', '.join(MODELS)}, not '{model}'")
    if preset not in PRESET_NAMES:
        raise InputError(f"accuracy must be one of {', '.join(PRESET_NAMES)}, got '{preset}'")


def bound(model: str, preset: str, key: str) -> float:
    """The error bound a preset is held to (tests): measured worst case x SAFETY, >= FLOOR."""
    _check(model, preset)
    value = MEASURED[model][preset][key]
    if value is None:
        return math.inf
    if key == "d_events":
        return float(value)
    return max(SAFETY * float(value), FLOOR)


def solver(model: str, preset: str) -> str:
    """'compiled' or 'scipy' for a (model, preset)."""
    _check(model, preset)
    return SOLVER[(model, preset)]


def integrator(model: str, preset: str):
    """The integration loop a (model, preset) runs: the compiled twin or the model's scipy loop."""
    if solver(model, preset) == "compiled":
        return importlib.import_module(f"models.kernels.{model}_nb").integrate
    return importlib.import_module(f"models.{model}").__dict__["integrate"]


# ------------------------------------------------------------------------------------------
# running a model with a given loop and tolerances
# ------------------------------------------------------------------------------------------
_PATCH_LOCK = threading.Lock()


@contextlib.contextmanager
def _patched(model: str, integrate, preset: dict | None, name: str):
    """Run ``models.<model>`` with another integration loop / preset for one call (used only while
    the model's ``simulate`` has no ``integrate=``/``preset=`` arguments)."""
    mod = importlib.import_module(f"models.{model}")
    with _PATCH_LOCK:
        old_int, old_preset = mod.integrate, mod.PRESETS[name]
        try:
            if integrate is not None:
                mod.integrate = integrate
            if preset is not None:
                mod.PRESETS[name] = preset
            yield mod
        finally:
            mod.integrate, mod.PRESETS[name] = old_int, old_preset


def run_model(scene, model: str, integrate=None, preset: dict | None = None, stats: dict | None = None):
    """``models.<model>.simulate(scene)`` with an explicit integration loop and preset dict (None:
    what ``scene.accuracy`` selects). ``stats`` collects nfev/n_steps of compiled loops."""
    mod = importlib.import_module(f"models.{model}")
    loop = integrate if integrate is not None else integrator(model, scene.accuracy)
    if stats is not None and loop in (_kernel(model),):
        base = loop

        def loop(*a, **k):  # noqa: F811 - count the cost of every call
            return base(*a, stats=stats, **k)
    params = inspect.signature(mod.simulate).parameters
    if "integrate" in params and "preset" in params:
        return mod.simulate(scene, integrate=loop, preset=preset)
    with _patched(model, loop, preset, scene.accuracy):
        return mod.simulate(scene)


def _kernel(model):
    return importlib.import_module(f"models.kernels.{model}_nb").integrate


def reference_run(scene, model: str):
    """The reference solution of ``scene`` (scipy DOP853, rtol 1e-12)."""
    mod = importlib.import_module(f"models.{model}")
    preset = dict(mod.PRESETS["reference"], **REFERENCE_SOLUTION[model])
    loop = mod.integrate
    if model == "elastic":   # its simulate does not pass a method: DOP853 is set on the loop
        loop = functools.partial(mod.integrate, method=preset["method"])
    return run_model(scene.replace(accuracy="reference"), model, integrate=loop, preset=preset)


# ------------------------------------------------------------------------------------------
# errors of one solution against another
# ------------------------------------------------------------------------------------------
INDICATOR_KEYS = ("MR13D_max_Nm", "MR13D_min_Nm", "dphi2_max_deg", "domega2_max_rad_s", "domega1_max_rad_s",
                  "percussion_max_Ns", "xel_max_mm", "xel_min_mm")


def event_times(ds) -> np.ndarray:
    """Contact event times (s) of a model's dataset (rigid: event_time; elastic: event_times_s)."""
    if "event_time" in ds:
        return np.asarray(ds["event_time"].values, dtype=float)
    return np.atleast_1d(np.asarray(ds.attrs.get("event_times_s", []), dtype=float))


def _series_error(ds, ref, name: str, exclude: np.ndarray) -> float:
    """Max |y - y_ref| / max |y_ref| at the output times both datasets share (to 1e-11 s: the
    models sample on uniform grids whose points coincide; interpolating one into the other would
    measure the interpolation, not the solver), samples within two output steps of an event of
    either solution excluded."""
    t, tr = ds["time"].values, ref["time"].values
    y, yr = ds[name].values, ref[name].values
    i = np.clip(np.searchsorted(tr, t), 1, tr.size - 1)
    i = np.where(np.abs(tr[i - 1] - t) < np.abs(tr[i] - t), i - 1, i)
    keep = np.abs(tr[i] - t) <= 1e-11
    dt = max(np.max(np.diff(tr)) if tr.size > 1 else 0.0, np.max(np.diff(t)) if t.size > 1 else 0.0)
    for te in exclude:
        keep &= np.abs(t - te) > 2.0 * dt
    if not keep.any():
        return 0.0
    scale = max(np.max(np.abs(yr)), 1e-300)
    return float(np.max(np.abs(y[keep] - yr[i[keep]])) / scale)


def compare(result, reference) -> dict:
    """Errors of a SimulationResult against the reference one (definitions in the module doc)."""
    ds, rf = result.dataset, reference.dataset
    te, tr = event_times(ds), event_times(rf)
    n = min(te.size, tr.size)
    exclude = np.concatenate([te, tr])
    err_ind = 0.0
    mr_scale = max(abs(reference.indicators.get("MR13D_max_Nm") or 0.0),
                   abs(reference.indicators.get("MR13D_min_Nm") or 0.0), 1e-12)
    x_scale = max(abs(reference.indicators.get("xel_max_mm") or 0.0),
                  abs(reference.indicators.get("xel_min_mm") or 0.0), 1e-12)
    for key in INDICATOR_KEYS:
        a, b = result.indicators.get(key), reference.indicators.get(key)
        if a is None or b is None:
            continue
        # MR13D and xel extremes are scaled by the larger of max and min (a minimum near zero
        # has no meaningful relative error); the other indicators by themselves
        scale = mr_scale if key.startswith("MR13D") else x_scale if key.startswith("xel") else max(abs(b), 1e-12)
        err_ind = max(err_ind, abs(a - b) / scale)
    return dict(
        err_omega2=_series_error(ds, rf, "omega2", exclude),
        err_MR13D=_series_error(ds, rf, "MR13D", exclude),
        err_event_time=float(np.max(np.abs(te[:n] - tr[:n]))) if n else 0.0,
        d_events=int(abs(te.size - tr.size)),
        err_indicators=float(err_ind),
        n_events=int(te.size), n_events_ref=int(tr.size),
    )


@dataclasses.dataclass
class Measurement:
    model: str
    preset: str
    run: int
    errors: dict
    wall_s: float
    nfev: int
