"""The verdict says what the measurement can tell: a model is ahead only by more than the
comparison resolves (revolution-to-revolution scatter, the presets' spread); closer models are
'cannot tell apart', and the speed that would tell them apart is named."""
import json
import math

import numpy as np
import pytest

from labtool.cli import main
from labtool.reports import verdict


def _head(label, r):
    return {"label": label, "omega2_iso_rating": r, "epsilon2_iso_rating": r}


def _comps(label, per_rev):
    return [{"label": label, "signal": s, "per_revolution": [{"iso_rating": v} for v in per_rev]}
            for s in ("omega2", "epsilon2")]


def _row(acc, revs, ratings):
    best = max(ratings, key=ratings.get)
    return {"accuracy": acc, "revolutions": revs, "closest": best, "models": [_head(k, v) for k, v in ratings.items()]}


def test_a_lead_larger_than_the_scatter_and_the_spread_is_robust():
    rng = np.random.default_rng(1)
    a = 0.90 + 0.002 * rng.standard_normal(8)
    b = a - 0.05 + 0.002 * rng.standard_normal(8)          # 0.05 behind, scatter ~0.003
    rows = [_row("fast", 6, {"A": 0.90, "B": 0.85}), _row("standard", 6, {"A": 0.905, "B": 0.852})]
    v = verdict.judge([_head("A", 0.90), _head("B", 0.85)], _comps("A", a) + _comps("B", b), rows, {})
    assert v["closest"] == "A" and v["runner_up"] == "B" and v["robust"] is True and v["cannot_tell_apart"] == []
    d = a - b
    assert v["scatter"] == pytest.approx(2 * np.std(d, ddof=1) / math.sqrt(8))     # the paired standard error
    assert v["spread"] == pytest.approx(0.003) and v["margin"] == pytest.approx(0.05)
    text = verdict.sentence(v)
    assert text.startswith("verdict robust: A is the closest, ahead of B by 0.05") and "cannot tell" not in text


def test_a_lead_inside_the_revolution_to_revolution_scatter_is_not_a_verdict():
    rng = np.random.default_rng(2)
    a = 0.90 + 0.02 * rng.standard_normal(5)
    b = 0.90 + 0.02 * rng.standard_normal(5)
    v = verdict.judge([_head("A", 0.902), _head("B", 0.899)], _comps("A", a) + _comps("B", b),
                      [_row("fast", 6, {"A": 0.902, "B": 0.899}), _row("standard", 6, {"A": 0.902, "B": 0.899})], {})
    assert v["cannot_tell_apart"] == [["A", "B"]] and v["robust"] is False
    assert verdict.sentence(v).startswith("verdict: this measurement cannot tell A and B apart")


def test_a_lead_that_the_other_preset_reverses_is_not_a_verdict():
    same = np.full(6, 0.9)
    v = verdict.judge([_head("A", 0.91), _head("B", 0.90)], _comps("A", same + 0.01) + _comps("B", same),
                      [_row("fast", 6, {"A": 0.91, "B": 0.90}), _row("standard", 6, {"A": 0.89, "B": 0.90})], {})
    # no scatter at all between revolutions, but the presets disagree by 0.02 on a 0.01 lead
    assert v["scatter"] == pytest.approx(0.0, abs=1e-12) and v["spread"] == pytest.approx(0.02)
    assert v["cannot_tell_apart"] == [["A", "B"]] and not v["robust"]


def test_groups_the_same_motion_once_and_says_which_others_tie():
    rng = np.random.default_rng(3)
    base = 0.9 + 0.001 * rng.standard_normal(6)
    comps = (_comps("E ct", base + 0.05) + _comps("E var", base + 0.05) + _comps("R ct", base)
             + _comps("R var", base + 1e-4 * rng.standard_normal(6)))
    head = [_head("E ct", 0.95), _head("E var", 0.95), _head("R ct", 0.9), _head("R var", 0.9001)]
    rows = [_row("fast", 6, {"E ct": 0.95, "E var": 0.95, "R ct": 0.9, "R var": 0.9001})]
    v = verdict.judge(head, comps, rows, {"E var": "E ct"})
    assert [lab for lab, _ in v["ranking"]] == ["E ct", "R var", "R ct"]
    assert v["robust"] is None                       # one preset row only: the presets were not checked
    assert v["cannot_tell_apart"] == [["R var", "R ct"]]
    text = verdict.sentence(v)
    assert "E ct is the closest" in text and "the other solver preset was not checked" in text
    assert "This measurement cannot tell R var and R ct apart" in text
    assert "E var is the same motion as E ct, counted once" in text


def test_one_revolution_resolves_nothing():
    v = verdict.judge([_head("A", 0.95), _head("B", 0.5)], _comps("A", [0.95]) + _comps("B", [0.5]), [], {})
    assert math.isinf(v["resolution"]) and v["cannot_tell_apart"] == [["A", "B"]]
    assert "revolution-to-revolution scatter unknown" in verdict.sentence(v)


@pytest.mark.slow
def test_the_discrimination_distance_is_the_rms_difference_over_the_measured_scatter():
    from labtool.reports import align, discrimination
    from labtool.reports.simulation import run_simulation
    op = {"law": "sine", "cam_speed_rpm": 180.0, "Fu_N": 0.0, "backlash_mm": 0.128, "jt_factor": 1.0,
          "restitution": 0.2, "contact_damping_s_per_m": 40.0, "contact_length_mm": 6.0, "kc_factor": 1.0,
          "elastic_gap": "physical", "omega1_var_n1_rpm": 180.0}
    cond = align.Conditioning()
    sigma = {"omega2": np.full(cond.n_grid, 0.01), "epsilon2": np.full(cond.n_grid, 2.0)}
    d = discrimination.discriminate(op, [("R", "rigid", "const"), ("E", "elastic", "const")], sigma, 180.0,
                                    speeds_rpm=[180.0, 600.0], cond=cond)
    assert list(d.speeds_rpm) == [180.0, 600.0] and d.pairs == [("R", "E")]
    a = run_simulation(dict(op, cam_speed_rpm=600.0), "rigid", "const", "fast", 3.0, cond).cycle.signals["epsilon2"]
    b = run_simulation(dict(op, cam_speed_rpm=600.0), "elastic", "const", "fast", 3.0, cond).cycle.signals["epsilon2"]
    # at 600 rpm the scatter is taken to grow as epsilon2 does, with n1^2
    want = np.sqrt(np.mean((a - b) ** 2)) / (2.0 * (600.0 / 180.0) ** 2)
    assert d.distance["epsilon2"][1, 0] == pytest.approx(want, rel=1e-9)
    assert d.best_rpm in (180.0, 600.0) and d.at(d.best_rpm) == np.nanmax(d.distance["epsilon2"][:, 0])
    assert "rpm" in d.sentence() and "R and E" in d.sentence()


@pytest.mark.slow
def test_a_rigid_truth_where_the_models_differ_names_rigid_closest_and_robust(tmp_path, capsys):
    """The simulated stand with the rigid model as its truth at 700 rpm, where the rigid and elastic
    predictions of epsilon2 differ by ~18 x the measured scatter: the rigid model (omega1 const, as
    the stand's drive) is the closest, ahead by more than the comparison resolves."""
    rec, meas = tmp_path / "r.h5", tmp_path / "m.nc"
    assert main(["acquire", "--device", "sim", "--truth", "rigid", "--rpm", "700", "--duration", "2", "--fast",
                 "--seed", "1", "-o", str(rec)]) == 0
    assert main(["process", str(rec), "-o", str(meas)]) == 0
    capsys.readouterr()
    assert main(["report", str(meas), "--accuracy", "fast", "-o", str(tmp_path / "r.html"),
                 "--json", str(tmp_path / "r.json")]) == 0
    printed = capsys.readouterr().out
    v = json.loads((tmp_path / "r.json").read_text())["verdict"]
    assert v["closest"] == "rigid, w1 = ct." and v["robust"] is True
    assert v["margin"] > v["resolution"] > 0
    assert v["sentence"].startswith("verdict robust: rigid, w1 = ct. is the closest")
    assert v["sentence"] in printed
