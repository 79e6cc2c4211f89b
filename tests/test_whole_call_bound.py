"""The prototype behind benchmarks/whole_call_bound.py (the bound on the elastic whole call):
its "peer outputs" call must make the same numbers as ``simulate`` at the uniform output instants,
or the bound it measures would be the cost of something else."""
from __future__ import annotations

import numpy as np
import pytest

from benchmarks.whole_call_bound import peer_outputs_call
from labtool.models.study.paper import paper_scene
from labtool.models.dynamics.simulate import simulate
from labtool.common.units import RPM


@pytest.mark.parametrize("rpm,fu,j_mm,jt", [(200.0, 0.0, 0.016, 1.0), (300.0, 75.0, 0.128, 4.0)])
def test_peer_outputs_equal_the_dataset_at_the_uniform_instants(rpm, fu, j_mm, jt):
    scene = paper_scene(cam_speed=rpm * RPM, Fu=fu, backlash=j_mm * 1e-3, jt_factor=jt, omega1_mode="var")
    full = simulate(scene, "elastic").dataset
    lean = peer_outputs_call(scene)
    on_grid = np.isin(full["time"].values, lean["time"].values)
    assert on_grid.sum() == lean["time"].size > 100          # every uniform instant, and only those
    for name in ("omega2", "MR13D", "x_el"):
        np.testing.assert_array_equal(lean[name].values, full[name].values[on_grid], err_msg=name)
    for name in ("event_time", "event_kind", "event_percussion"):
        np.testing.assert_array_equal(lean[name].values, full[name].values, err_msg=name)
