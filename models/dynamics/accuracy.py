"""Accuracy presets ``fast`` / ``standard`` / ``reference``: which solver runs, with which
tolerances, and the error each one was MEASURED to make against an independent reference solution.

A preset is defined by its accuracy, not by its tolerance: ``STATED`` is what a user may rely on
(the worst relative error in omega2 over Table 1's runs, with no event lost or added), ``MEASURED``
the figures that justify it and the tolerances they were measured with. A tolerance change in a
model without a new measurement fails ``tests/test_accuracy.py``.

The reference solution (``reference_run``) is scipy's DOP853 (8th order, a different method from
the compiled Dormand-Prince 5(4)) at rtol 1e-12 on the model's own equations, with the step limits
of the model's ``reference`` preset and its absolute tolerances scaled to rtol 1e-12.

``fast`` and ``standard`` run the shared compiled loop (labtool.models.dynamics.kernels.dopri5, numba) with the
model's tolerances (``labtool.models.dynamics.rigid.PRESETS``, ``labtool.models.dynamics.elastic.PRESETS``); ``reference``
runs the scipy ``solve_ivp`` loop (labtool.models.dynamics.reference) over the same compiled equations. ``MEASURED`` holds the worst error over the 16 runs of Table 1 (omega1
variable, sine law) of each preset against the reference solution, as written by
``benchmarks/work_precision.py`` (its CSV is benchmarks/results/work_precision.csv):

    err_omega2      max |omega2 - omega2_ref| / max |omega2_ref| over the rise, samples closer than
                    two output steps to an event excluded (there the jump itself is compared, below)
    err_MR13D       the same for MR13D (N m)
    err_event_time  max |t_event - t_event_ref| (s) over the event instants, matched in order
    d_events        max |number of event instants - reference's| (a rebound's contact and
                    separation are one instant)
    err_indicators  max relative error of the Table 2/3 indicators (MR13D max/min, dphi2, domega2,
                    domega1, percussion, xel max/min) against the reference's, floor 1e-9 of scale

``bound(model, preset)`` is what the tests hold a preset to: the measured figure times 3 (margin for
other scenes than Table 1's), never below 1e-9.
"""
from __future__ import annotations

import math

import numpy as np

from labtool.common.errors import InputError
from labtool.models.dynamics import elastic, events, rigid

MODELS = ("rigid", "elastic")
PRESET_NAMES = ("fast", "standard", "reference")

_MODULES = {"rigid": rigid, "elastic": elastic}

# the independent reference solution: scipy DOP853 at rtol 1e-12 (absolute tolerances: the
# model's 'reference' ones scaled by 1e-12 / its rtol; step limits and output: its 'reference' ones)
REFERENCE_RTOL = 1e-12
REFERENCE_METHOD = "DOP853"

# worst case over Table 1's 16 runs (omega1 variable, sine law), measured with
# benchmarks/work_precision.py and accuracy.compare over Table 1 (benchmarks/results/work_precision_summary.json;
# docs/performance.md, "Measured presets"). ``tolerances``: the model's preset at the time of the measurement; the
# tests fail when a model's preset changes, so that the figures are measured again.
MEASURED: dict = {
    "rigid": {
        # step caps set to what the stated accuracy needs: fast rise/50 (3.8e-6, 5.9e-13, 2.6e-11 s
        # at rise/250), standard rise/20 (1.5e-8, 4.4e-13, 6.0e-11 s at rise/1000); the indicators'
        # error is the output sampling, the same at every cap
        "fast": dict(tolerances=dict(method="RK45", rtol=1e-6, max_step=1 / 50, samples=1000),
                     err_omega2=6.1e-6, err_MR13D=8.6e-10, err_event_time=8.7e-9, d_events=0, err_indicators=2.3e-3),
        "standard": dict(tolerances=dict(method="RK45", rtol=1e-9, max_step=1 / 20, samples=4000),
                         err_omega2=1.9e-8, err_MR13D=1.1e-8, err_event_time=9.7e-10, d_events=0, err_indicators=8.7e-4),
        # the reference preset is the reference solution (DOP853 rtol 1e-12): 0 against itself;
        # the DOP853 ladder agrees with it to 5e-10 in omega2 at rtol 1e-10 (the comparison's floor)
        "reference": dict(tolerances=dict(method="DOP853", rtol=1e-12, max_step=1 / 4000, samples=16000),
                          err_omega2=5e-10, err_MR13D=1e-12, err_event_time=2e-11, d_events=0, err_indicators=1e-6),
    },
    "elastic": {
        # flights not capped at the contact's step: 12 % fewer steps than with the cap, at about
        # the same errors (capped: fast 2.2e-3, 9.0e-2, 5.1e-5 s, 7.9e-4; standard 2.6e-5, 5.2e-4,
        # 4.0e-7 s, 1.0e-4, measured in the same run)
        "fast": dict(tolerances=dict(rtol=1e-6, atol=1e-5, steps_per_period=4.0, cap_flight=False),
                     err_omega2=2.3e-3, err_MR13D=9.0e-2, err_event_time=5.1e-5, d_events=0, err_indicators=7.9e-4),
        "standard": dict(tolerances=dict(rtol=1e-8, atol=1e-7, steps_per_period=8.0, cap_flight=False),
                         err_omega2=2.6e-5, err_MR13D=5.2e-4, err_event_time=3.7e-7, d_events=0, err_indicators=1.0e-4),
        # DOP853 (RK45 gave 2.7e-6 in omega2, 2.6e-8 s in event times)
        "reference": dict(tolerances=dict(rtol=1e-10, atol=1e-9, steps_per_period=16.0, cap_flight=True,
                                          method="DOP853"),
                          err_omega2=6.9e-7, err_MR13D=2.7e-5, err_event_time=8.5e-9, d_events=0, err_indicators=1.3e-4),
    },
}
# the stated accuracy of each preset (docs/performance.md): the order of the measured worst
# error in omega2 over Table 1, what a user may rely on
STATED = {
    "rigid": {"fast": 1e-5, "standard": 1e-7, "reference": 1e-9},
    "elastic": {"fast": 1e-2, "standard": 1e-4, "reference": 1e-6},
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
    """'compiled' or 'scipy': the loop a (model, preset) runs (the model's SOLVERS)."""
    _check(model, preset)
    return _MODULES[model].SOLVERS[preset]


def run_model(scene, model: str, solver: str | None = None, preset: dict | None = None, stats: dict | None = None):
    """``labtool.models.dynamics.<model>.simulate(scene)`` with an explicit loop ("compiled" or "scipy") and
    preset dict (None: what ``scene.accuracy`` selects). ``stats`` (dict) receives loop_s, the wall
    time in the integration loops (s), nfev and n_steps."""
    _check(model, scene.accuracy)
    return _MODULES[model].simulate(scene, solver=solver, preset=preset, stats=stats)


def scaled_preset(preset: dict, rtol: float | None = None, step_factor: float = 1.0) -> dict:
    """A copy of a model's preset with rtol set (every atol* key scaled by the same ratio) and the
    step limit multiplied by ``step_factor`` (max_step, or steps_per_period divided)."""
    out = dict(preset)
    if rtol is not None:
        ratio = rtol / preset["rtol"]
        out["rtol"] = rtol
        for key, value in preset.items():
            if key.startswith("atol"):
                out[key] = value * ratio if np.isscalar(value) else tuple(np.asarray(value) * ratio)
    if "max_step" in out:
        out["max_step"] = out["max_step"] * step_factor
    if "steps_per_period" in out:
        out["steps_per_period"] = out["steps_per_period"] / step_factor
    return out


def halved(model: str, preset: str) -> dict:
    """The preset with its step limit halved and its tolerances divided by 2^5 = 32 (a 5th-order
    method's local error for half the step): the 'halve the step' check of the extremes suite."""
    _check(model, preset)
    base = _MODULES[model].PRESETS[preset]
    return scaled_preset(base, rtol=base["rtol"] / 32.0, step_factor=0.5)


def reference_run(scene, model: str):
    """The reference solution of ``scene`` (scipy DOP853, rtol 1e-12)."""
    _check(model, "reference")
    preset = scaled_preset(_MODULES[model].PRESETS["reference"], rtol=REFERENCE_RTOL)
    preset["method"] = REFERENCE_METHOD
    return run_model(scene.replace(accuracy="reference"), model, solver="scipy", preset=preset)


# ------------------------------------------------------------------------------------------
# errors of one solution against another
# ------------------------------------------------------------------------------------------
INDICATOR_KEYS = ("MR13D_max_Nm", "MR13D_min_Nm", "dphi2_max_deg", "domega2_max_rad_s", "domega1_max_rad_s",
                  "percussion_max_Ns", "xel_max_mm", "xel_min_mm")


def event_times(ds) -> np.ndarray:
    """The event instants (s) of a model's dataset, from its event record (labtool.models.dynamics.events),
    each instant once: a rigid rebound is two rows (a contact, then a separation) at one instant."""
    t = np.asarray(events.read(ds)["event_time"].values, dtype=float)
    return t[np.concatenate([[True], np.diff(t) > 0])] if t.size else t


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
