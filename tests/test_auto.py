"""``--model auto``: the cheapest level of the ladder, the same indicators as the full model.

Cost is counted in right-hand-side evaluations of the compiled loops (not in time): the full rigid
model integrates the backlash run and the no-backlash run from phi1 = 0; auto integrates the
no-backlash run once and the backlash run only from just before the flank force changes sign, and
runs no dynamic model at all where the kinematic level is the exact answer.
"""
import numpy as np
import pytest

from labtool.models.dynamics import accuracy
from labtool.models.dynamics.auto import CONTACT_OUTPUTS, choose_level, simulate_auto
from labtool.models.study.paper import table1_runs
from labtool.models.study.paper import paper_scene
from labtool.models.dynamics.simulate import simulate
from labtool.common.units import RPM

KEYS = ("MR13D_max_Nm", "MR13D_min_Nm", "dphi2_max_deg", "domega2_max_rad_s", "domega1_max_rad_s",
        "percussion_max_Ns")


def _table1_scenes(mode="var"):
    return [(int(r.run), paper_scene(cam_speed=r.n1_rpm * RPM, Fu=r.Fu_N, backlash=r.j_mm * 1e-3, jt_factor=r.Jt_factor,
                               omega1_mode=mode)) for r in table1_runs().itertuples()]


def test_auto_matches_the_full_rigid_model_on_table1_at_a_fraction_of_the_cost():
    cost_auto = cost_full = 0
    tol = max(accuracy.bound("rigid", "standard", "err_indicators"), 1e-6)
    for run, scene in _table1_scenes():
        stats = {}
        full = accuracy.run_model(scene, "rigid", stats=stats)
        auto = simulate(scene, "auto")
        assert auto.model == "rigid" and auto.reason, run
        assert auto.indicators["jumps"] == full.indicators["jumps"], run
        assert auto.indicators["impacts"] == full.indicators["impacts"], run
        for key in KEYS:
            a, b = auto.indicators[key], full.indicators[key]
            scale = max(abs(full.indicators["MR13D_max_Nm"]), 1.0) if key.startswith("MR13D") else max(abs(b), 1e-9)
            assert abs(a - b) <= tol * scale, (run, key, a, b)
        n_auto = auto.dataset.attrs["auto_rhs_evaluations"]
        assert 0 < n_auto <= stats["nfev"], run
        cost_auto += n_auto
        cost_full += stats["nfev"]
    # measured 0.85 (docs/performance.md; 0.72 with a step cap of rise/1000 instead of rise/20, made
    # the full model 14x cheaper): the shared 1-DOF prefix is integrated once
    assert cost_auto / cost_full < 0.9


def test_no_sign_change_at_constant_speed_runs_no_dynamic_model():
    # Table 1 run 9 (Fu = 65 N, 180 rpm): MR13D stays positive over the rise
    scene = paper_scene(cam_speed=180.0 * RPM, Fu=65.0, backlash=0.016e-3, omega1_mode="const")
    level, reason = choose_level(scene)
    assert level == "kinematic" and "keeps its sign" in reason
    res = simulate(scene, "auto")
    assert res.model == "kinematic" and res.dataset.attrs["auto_rhs_evaluations"] == 0
    assert res.indicators["jumps"] == 0 and res.indicators["impacts"] == 0
    full = simulate(scene, "rigid").indicators
    assert full["jumps"] == 0 and full["impacts"] == 0 and full["dphi2_max_deg"] == 0.0
    # with the cam as input and no contact loss the rigid model is the kinematic model
    assert res.indicators["MR13D_max_Nm"] == pytest.approx(full["MR13D_max_Nm"], rel=2e-3)
    assert res.indicators["MR13D_min_Nm"] == pytest.approx(full["MR13D_min_Nm"], rel=2e-3)


def test_no_backlash_at_constant_speed_is_kinematic_even_with_a_sign_change():
    scene = paper_scene(cam_speed=180.0 * RPM, Fu=0.0, backlash=0.0, omega1_mode="const")
    level, reason = choose_level(scene)
    assert level == "kinematic" and "no backlash" in reason
    full = simulate(scene, "rigid").indicators
    assert full["jumps"] == 0
    res = simulate(scene, "auto")
    assert res.indicators["MR13D_min_Nm"] < 0 < res.indicators["MR13D_max_Nm"]
    assert res.indicators["MR13D_min_Nm"] == pytest.approx(full["MR13D_min_Nm"], rel=2e-3)


def test_variable_speed_without_contact_loss_runs_only_the_one_dof_model():
    scene = paper_scene(cam_speed=180.0 * RPM, Fu=65.0, backlash=0.016e-3, omega1_mode="var")
    stats = {}
    full = accuracy.run_model(scene, "rigid", stats=stats)
    res = simulate(scene, "auto")
    assert res.model == "rigid" and "no backlash model was needed" in res.reason
    assert np.isnan(res.dataset.attrs["auto_escalation_phi1_rad"])
    assert res.dataset.attrs["auto_rhs_evaluations"] < 0.6 * stats["nfev"]
    for key in KEYS + ("jumps", "impacts"):
        assert res.indicators[key] == pytest.approx(full.indicators[key], rel=1e-9, abs=1e-12)


@pytest.mark.slow
def test_contact_outputs_escalate_to_the_elastic_model():
    scene = paper_scene()
    assert choose_level(scene, needs_contact_outputs=True)[0] == "elastic"
    res = simulate_auto(scene, outputs={"xel_max_mm"})
    assert res.model == "elastic" and "contact outputs" in res.reason
    assert res.indicators["xel_max_mm"] is not None
    assert "x_el" in CONTACT_OUTPUTS


def test_auto_reason_is_in_the_dataset():
    res = simulate(paper_scene(), "auto")
    assert res.dataset.attrs["model"] == res.model == "rigid"
    assert res.dataset.attrs["model_reason"] == res.reason
    assert "MR13D changes sign" in res.reason and "2-DOF" in res.reason


@pytest.mark.parametrize("kw", [
    dict(cam_speed=1000.0 * RPM, jt_factor=0.25, backlash=1e-6, restitution=1.0),
    dict(cam_speed=60.0 * RPM, jt_factor=10.0, backlash=1e-3, restitution=0.5),
    dict(cam_speed=500.0 * RPM, Fu=500.0, backlash=0.128e-3, restitution=0.0),
    dict(cam_speed=300.0 * RPM, backlash=0.016e-3, restitution=0.8, omega1_mode="const"),
])
def test_auto_matches_the_full_model_at_the_extremes(kw):
    scene = paper_scene(**kw)
    full = accuracy.run_model(scene, "rigid").indicators
    auto = simulate(scene, "auto")
    if auto.model == "kinematic":       # exact only where the rigid model never leaves the flank
        assert full["jumps"] == 0 and full["impacts"] == 0
        assert auto.indicators["MR13D_max_Nm"] == pytest.approx(full["MR13D_max_Nm"], rel=2e-3)
        return
    assert auto.indicators["jumps"] == full["jumps"] and auto.indicators["impacts"] == full["impacts"]
    for key in KEYS:
        assert auto.indicators[key] == pytest.approx(full[key], rel=1e-6, abs=1e-9 * abs(full["MR13D_max_Nm"])), key


def test_the_decision_reads_the_same_moment_range_as_the_kinematic_analysis():
    """auto decides from the shared cam-angle table (4001 angles over the rise) instead of a whole
    kinematic analysis (1441 over the revolution): the MR13D range is the same to the coarser
    grid's resolution, on every run of Table 1 at both omega1 modes."""
    from labtool.models.dynamics.auto import rise_moment_range
    from labtool.models.dynamics.simulate import _kinematic

    for r in table1_runs().itertuples():
        for mode in ("const", "var"):
            s = paper_scene(cam_speed=r.n1_rpm * RPM, Fu=r.Fu_N, backlash=r.j_mm * 1e-3, jt_factor=r.Jt_factor,
                      omega1_mode=mode)
            mn, mx = rise_moment_range(s)
            kin = _kinematic(s).indicators
            scale = max(abs(mn), abs(mx))
            assert mn <= kin["MR13D_min_Nm"] + 1e-9 * scale and mx >= kin["MR13D_max_Nm"] - 1e-9 * scale
            assert mn == pytest.approx(kin["MR13D_min_Nm"], abs=3e-3 * scale)
            assert mx == pytest.approx(kin["MR13D_max_Nm"], abs=3e-3 * scale)
