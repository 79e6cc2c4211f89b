"""The Dataset-free indicator path: ``labtool.models.dynamics.simulate.indicators(scene, model)``
gives the indicators of ``simulate(scene, model).indicators`` exactly (the same loops, the same
output samples, the same arithmetic), raises what ``simulate`` raises, and is what ``doe run``
uses."""
from __future__ import annotations

import math

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from labtool.common.errors import LabtoolError
from labtool.models.dynamics.result import INDICATORS
from labtool.models.dynamics.scene import Scene
from labtool.models.study.paper import paper_scene
from labtool.models.dynamics.simulate import indicators, simulate
from labtool.models.study.paper import table1_runs
from labtool.common.units import RPM

RUNS = list(table1_runs().itertuples())


def _scene(run, **kw) -> Scene:
    return paper_scene(cam_speed=run.n1_rpm * RPM, Fu=run.Fu_N, backlash=run.j_mm * 1e-3, jt_factor=run.Jt_factor,
                 omega1_mode="var", **kw)


def _same(a: dict, b: dict, where: str) -> None:
    for key in INDICATORS:
        assert a[key] == b[key], f"{where}: {key} {a[key]!r} (dataset path) != {b[key]!r} (indicator path)"


@pytest.mark.parametrize("model,gap", [("rigid", "physical"), ("elastic", "physical"), ("elastic", "closed")])
@pytest.mark.parametrize("preset", ["fast", "standard"])
@pytest.mark.slow
def test_table1_indicators_equal_the_dataset_paths(model, gap, preset):
    for run in RUNS:
        scene = _scene(run, accuracy=preset, elastic_gap=gap)
        _same(simulate(scene, model).indicators, indicators(scene, model), f"{model} {gap} {preset} run {run.run}")


@pytest.mark.slow
@pytest.mark.parametrize("model,gap", [("rigid", "physical"), ("elastic", "physical"), ("elastic", "closed")])
def test_table1_indicators_equal_the_dataset_paths_at_the_reference_preset(model, gap):
    for run in RUNS:
        scene = _scene(run, accuracy="reference", elastic_gap=gap)
        _same(simulate(scene, model).indicators, indicators(scene, model), f"{model} {gap} reference run {run.run}")


def test_the_indicator_path_says_which_level_ran():
    scene = _scene(RUNS[0])
    assert indicators(scene, "rigid")["model"] == "rigid"
    assert indicators(scene, "elastic")["model"] == "elastic"
    # levels without a Dataset-free path answer through simulate(): auto says what it chose
    auto = indicators(scene, "auto")
    assert auto["model"] == simulate(scene, "auto").model
    _same(simulate(scene, "auto").indicators, auto, "auto")
    _same(simulate(scene, "kinematic").indicators, indicators(scene, "kinematic"), "kinematic")


def _outcome(fn, scene, model):
    try:
        return "ok", fn(scene, model)
    except LabtoolError as exc:            # the same refusal, word for word
        return type(exc).__name__, str(exc)


@pytest.mark.hostile("silent_wrong")
@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(model=st.sampled_from(["rigid", "elastic"]), rpm=st.floats(60, 400), Fu=st.floats(0, 300),
       j=st.sampled_from([0.0, 1e-6, 0.016e-3, 0.064e-3, 0.3e-3]), jt=st.sampled_from([0.5, 1.0, 4.0]),
       mode=st.sampled_from(["const", "var"]), k=st.sampled_from([0.0, 0.5, 1.0]),
       gap=st.sampled_from(["physical", "closed"]), kc=st.sampled_from([1e-4, 0.1, 1.0, 10.0]),
       law=st.sampled_from(["sine", "cosine"]), preset=st.sampled_from(["fast", "standard"]))
@pytest.mark.slow
def test_random_scenes_give_the_same_indicators_or_the_same_error(model, rpm, Fu, j, jt, mode, k, gap, kc, law,
                                                                    preset):
    scene = paper_scene(law=law, cam_speed=rpm * RPM, Fu=Fu, backlash=j, jt_factor=jt, omega1_mode=mode, restitution=k,
                  elastic_gap=gap, kc_factor=kc, accuracy=preset)
    a, b = _outcome(simulate, scene, model), _outcome(indicators, scene, model)
    assert a[0] == b[0], (a, b)
    if a[0] == "ok":
        _same(a[1].indicators, b[1], repr(scene))
    else:
        assert a[1] == b[1]


def test_doe_rows_are_the_indicator_paths():
    from labtool.models.study import doe
    scene = _scene(RUNS[5])
    for model in ("rigid", "elastic"):
        res = doe.simulate_run(scene, model)
        assert res["ok"]
        ind = simulate(scene, model).indicators
        for key in doe.responses_for(model):
            assert res["indicators"][key] == (None if ind[key] is None else float(ind[key]))
    assert math.isfinite(res["wall_s"])


@pytest.mark.parametrize("reading", ["consistent", "literal"])
def test_the_compiled_indicator_pass_is_the_general_path(reading):
    """``elastic.simulate_indicators`` runs tables to counts in one compiled pass; the general path
    (``_solve``, the loop's arrays, numpy) gives the same numbers or the same refusal."""
    from labtool.models.dynamics import elastic

    def general(scene):
        return elastic._general_indicators(scene, reading, None, None, None)

    def compiled(scene):
        return elastic.simulate_indicators(scene, reading=reading)

    for run in RUNS:
        for gap in ("physical", "closed"):
            scene = _scene(run, elastic_gap=gap)
            a, b = _outcome(lambda s, _: general(s), scene, None), _outcome(lambda s, _: compiled(s), scene, None)
            assert a == b, (run.run, gap, a, b)


@pytest.mark.slow
def test_a_drive_zero_at_the_start_goes_to_the_general_path(monkeypatch):
    """The compiled pass leaves a run that starts at rest (no drive at t = 0, kernels.elastic_nb.start)
    to the general path, which begins it with an AtRest phase; the answer is the general path's."""
    import numpy as np

    from labtool.models.dynamics import elastic

    scene = _scene(RUNS[0])
    real = elastic._angle_block
    rows = {name: k for k, name in enumerate(elastic._ANGLE_ROWS)}

    def unloaded_start(scene, span, n_points):
        block = np.array(real(scene, span, n_points))
        for name in ("dpsi", "ddpsi", "M_gravity", "m_load"):     # MR13D = 0 at the first two angles
            block[rows[name], :2] = 0.0
        return block

    monkeypatch.setattr(elastic, "_angle_block", unloaded_start)
    calls = []
    monkeypatch.setattr(elastic, "_general_indicators", lambda *a: calls.append(a) or {"general": True})
    assert elastic.simulate_indicators(scene) == {"general": True} and len(calls) == 1
