"""Accuracy presets: defined by their measured error against the reference solution.

The figures in labtool.models.dynamics.accuracy.MEASURED come from benchmarks/work_precision.py on Table 1; here a
preset is run again on Table 1 runs and held to them, the tolerances they were measured with are
checked against the models' presets (a changed tolerance must be measured again), and the error
metrics are checked on known cases.
"""
import numpy as np
import pytest
import xarray as xr

from labtool.models.dynamics import accuracy, elastic, events, rigid
from labtool.common.errors import InputError
from labtool.models.study.paper import table1_runs
from labtool.models.study.paper import paper_scene
from labtool.models.dynamics.simulate import SimulationResult
from labtool.common.units import RPM


def _scene(run, **kw):
    r = table1_runs().iloc[run - 1]
    return paper_scene(cam_speed=r.n1_rpm * RPM, Fu=r.Fu_N, backlash=r.j_mm * 1e-3, jt_factor=r.Jt_factor, **kw)


@pytest.mark.parametrize("model, mod", [("rigid", rigid), ("elastic", elastic)])
@pytest.mark.parametrize("preset", accuracy.PRESET_NAMES)
def test_measured_with_the_models_current_tolerances(model, mod, preset):
    measured = accuracy.MEASURED[model][preset]["tolerances"]
    for key, value in measured.items():
        now = mod.PRESETS[preset].get(key)
        same = now == pytest.approx(value, rel=1e-12) if isinstance(value, float) else now == value
        assert same, (f"labtool.models.dynamics.{model}.PRESETS['{preset}']['{key}'] is {now}, measured with {value}: run "
                      "benchmarks/work_precision.py and update labtool.models.dynamics.accuracy.MEASURED")


@pytest.mark.slow
@pytest.mark.parametrize("model, run", [("rigid", 12), ("elastic", 6)])
def test_presets_measured_are_ordered_and_within_their_stated_accuracy(model, run):
    """Each preset run again against the reference solution (DOP853, rtol 1e-12): its error in
    omega2 is measured here, not restated: fast > standard >= reference, each within STATED, the
    same events as the reference."""
    scene = _scene(run)
    ref = accuracy.reference_run(scene, model)
    err = {p: accuracy.compare(accuracy.run_model(scene.replace(accuracy=p), model), ref) for p in accuracy.PRESET_NAMES}
    assert err["fast"]["err_omega2"] > err["standard"]["err_omega2"] >= err["reference"]["err_omega2"]
    for preset, e in err.items():
        assert e["d_events"] == 0 and e["n_events"] > 0, (preset, e)
        assert e["err_omega2"] <= accuracy.STATED[model][preset], (preset, e)


def test_solver_choice():
    assert accuracy.solver("rigid", "standard") == "compiled"
    assert accuracy.solver("elastic", "fast") == "compiled"
    assert accuracy.solver("rigid", "reference") == "scipy"
    assert accuracy.solver("elastic", "reference") == "scipy"
    with pytest.raises(InputError, match="accuracy must be one of"):
        accuracy.solver("rigid", "ultra")
    with pytest.raises(InputError, match="presets exist for"):
        accuracy.bound("kinematic", "fast", "err_omega2")


@pytest.mark.slow
@pytest.mark.parametrize("run", [6, 11])
def test_elastic_standard_and_fast_within_their_measured_error(run):
    scene = _scene(run)
    ref = accuracy.reference_run(scene, "elastic")
    for preset in ("fast", "standard"):
        err = accuracy.compare(accuracy.run_model(scene.replace(accuracy=preset), "elastic"), ref)
        assert err["d_events"] == 0
        for key in ("err_omega2", "err_MR13D", "err_event_time", "err_indicators"):
            assert err[key] <= accuracy.bound("elastic", preset, key), (preset, key, err)


@pytest.mark.slow
def test_rigid_standard_within_its_measured_error():
    scene = _scene(12)                      # Fu = 65 N, 300 rpm, Jt x4: 11 impacts
    ref = accuracy.reference_run(scene, "rigid")
    err = accuracy.compare(accuracy.run_model(scene, "rigid"), ref)
    assert err["d_events"] == 0 and err["n_events"] > 5
    for key in ("err_omega2", "err_MR13D", "err_event_time", "err_indicators"):
        assert err[key] <= accuracy.bound("rigid", "standard", key), (key, err)


def _result(t, omega2, mr, times):
    n = len(times)
    record = events.record(times, np.zeros(n), np.ones(n, dtype=int), np.zeros(n, dtype=int), np.zeros(n),
                           np.zeros(n), np.zeros(n), np.zeros(n, dtype=bool))
    ds = xr.Dataset({"omega2": ("time", omega2), "MR13D": ("time", mr), **record}, coords={"time": t})
    return SimulationResult(ds, {"MR13D_max_Nm": float(mr.max()), "MR13D_min_Nm": float(mr.min())}, "x")


def test_compare_measures_on_shared_times_and_skips_event_neighbourhoods():
    t = np.linspace(0.0, 1.0, 1001)
    w = np.sin(t)
    ref = _result(t, w, 2 * w, np.array([0.5]))
    same = accuracy.compare(ref, ref)
    assert same["err_omega2"] == 0 and same["d_events"] == 0 and same["err_event_time"] == 0
    # a coarser output grid whose points are a subset: no interpolation error enters
    tc = t[::4]
    coarse = _result(tc, np.sin(tc) * (1 + 1e-7), 2 * np.sin(tc), np.array([0.5 + 2e-9]))
    e = accuracy.compare(coarse, ref)
    assert e["err_omega2"] == pytest.approx(1e-7 * np.sin(1.0) / np.sin(1.0), rel=1e-3)
    assert e["err_event_time"] == pytest.approx(2e-9, rel=1e-6)
    # a jump at a shifted event time is excluded around the events (the event time error says it)
    w2 = np.where(t < 0.5, w, w + 1.0)
    w2s = np.where(t < 0.503, w, w + 1.0)
    e = accuracy.compare(_result(t, w2s, 2 * w, np.array([0.503])), _result(t, w2, 2 * w, np.array([0.5])))
    assert e["err_omega2"] < 1e-12 and e["err_event_time"] == pytest.approx(0.003)
    # an extra event counts
    e = accuracy.compare(_result(t, w, 2 * w, np.array([0.2, 0.5])), ref)
    assert e["d_events"] == 1


def test_halved_preset_halves_the_step_and_tightens_the_tolerances():
    h = accuracy.halved("rigid", "standard")
    assert h["max_step"] == rigid.PRESETS["standard"]["max_step"] / 2
    assert h["rtol"] == pytest.approx(rigid.PRESETS["standard"]["rtol"] / 32)
    e = accuracy.halved("elastic", "standard")
    assert e["steps_per_period"] == 2 * elastic.PRESETS["standard"]["steps_per_period"]
    assert e["atol"] == pytest.approx(elastic.PRESETS["standard"]["atol"] / 32)
