"""Joint fits over several measurements: the logic on the stand-in model of tests/test_fit.py.

The stand-in's backlash shifts the kinematic cycle by 0.05 ln(j / 0.2 mm) rad; a synthetic
measurement delayed by 0.05 ln(j_f / 0.2) rad is therefore one "whose backlash is j_f", so three
files can share one j or disagree about it, exactly and at no model cost. The real models at
three speeds are in tests/test_fit_stand.py (slow).
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from labtool.common.errors import InputError
from labtool.common.files import write_netcdf
from labtool.identification.fit import load_fit
from labtool.identification.joint import JointRequest, combine, consistency, identify_joint, parse_shared
from labtool.identification.parameters import parse_free
from labtool.reports.synthetic import synthetic_measured
from tests.test_fit import stand_in


def _files(tmp_path, backlashes, noise=0.01):
    paths = []
    for i, j in enumerate(backlashes):
        p = tmp_path / f"m{i}.nc"
        write_netcdf(synthetic_measured(noise=noise, revolutions=4.3, seed=i,
                                        lag_deg=math.degrees(0.05 * math.log(j / 0.2))), p)
        paths.append(p)
    return paths


def _joint(paths, **kw):
    return identify_joint(JointRequest(paths, "rigid", "backlash,restitution", accuracy="fast", **kw)).summary


@pytest.mark.slow
def test_files_that_share_one_backlash_give_it_with_an_interval_that_holds_it(tmp_path, monkeypatch):
    import labtool
    stand_in(monkeypatch)
    # through the Python API: several files make a joint fit
    s = labtool.fit(_files(tmp_path, (0.2, 0.2, 0.2)), model="rigid", free="backlash,restitution", shared="backlash",
                    accuracy="fast").summary
    j = s["parameters"]["backlash_mm"]
    lo, hi = j["ci95"]
    assert lo <= 0.2 <= hi and j["value"] == pytest.approx(0.2, rel=0.01) and j["identifiable"]
    assert s["consistent"] and s["consistency"]["backlash_mm"]["consistent"]
    assert j["ci95"] == j["ci95_joint"]          # agreeing files: not widened
    # the joint interval is narrower than any file's alone (three times the data)
    widths = [f["ci95"][1] - f["ci95"][0] for f in s["consistency"]["backlash_mm"]["files"]]
    assert hi - lo < min(widths)
    # the restitution is fitted per file, each near its truth
    assert [f["restitution"]["value"] for f in s["per_file_parameters"]] == pytest.approx([0.5] * 3, abs=0.01)
    assert s["shared"] == ["backlash_mm"] and s["per_file"] == ["restitution"]
    json.dumps(s, allow_nan=False)


@pytest.mark.slow
def test_files_that_disagree_about_the_backlash_are_flagged_and_the_interval_widened(tmp_path, monkeypatch):
    stand_in(monkeypatch)
    s = _joint(_files(tmp_path, (0.17, 0.2, 0.235)), shared="backlash")
    test = s["consistency"]["backlash_mm"]
    assert not s["consistent"] and test["consistent"] is False and test["p_value"] < 0.05
    assert "disagree about backlash_mm beyond their intervals" in test["verdict"]
    assert "the model misses something" in test["verdict"]
    j = s["parameters"]["backlash_mm"]
    (a, b), (c, d) = j["ci95_joint"], j["ci95"]
    assert c < a and d > b                        # widened by the Birge ratio
    # each file alone finds its own backlash
    assert [f["value"] for f in test["files"]] == pytest.approx([0.17, 0.2, 0.235], rel=0.01)


@pytest.mark.slow
def test_the_cli_fits_jointly_writes_the_json_and_exits_1_when_the_files_disagree(tmp_path, monkeypatch, capsys):
    from labtool.cli import main
    stand_in(monkeypatch)
    paths = [str(p) for p in _files(tmp_path, (0.17, 0.2, 0.235))]
    out = tmp_path / "joint.json"
    rc = main(["fit", *paths, "--model", "rigid", "--free", "backlash,restitution", "--shared", "backlash",
               "--accuracy", "fast", "-o", str(out)])
    text = capsys.readouterr().out
    assert rc == 1 and out.exists() and (tmp_path / "joint.png").stat().st_size > 10_000
    assert "these measurements disagree about backlash_mm" in text and "alone:" in text
    doc = json.loads(out.read_text())
    assert doc["format"] == "labtool.fit.joint" and len(doc["single_fits"]) == 3
    # a joint result is not a fit 'labtool report --fit' draws: one line that says what to give it
    with pytest.raises(InputError, match="joint fit of 3 measurements.*labtool fit"):
        load_fit(out)


def test_the_shared_parameters_default_to_the_stands_properties():
    free = parse_free("backlash,restitution", "rigid")
    assert parse_shared(None, free).tolist() == [True, False]
    assert parse_shared("restitution,backlash", free).tolist() == [True, True]
    with pytest.raises(InputError, match="'delay' is not among the free parameters"):
        parse_shared("delay", free)
    with pytest.raises(InputError, match="none of the free parameters is a property of the stand"):
        parse_shared(None, parse_free("restitution", "rigid"))


@pytest.mark.parametrize("args, fragment", [
    (["--shared", "backlash"], "--shared needs several measured files"),
])
def test_shared_without_several_files_is_refused(tmp_path, capsys, args, fragment):
    from labtool.cli import main
    p = _files(tmp_path, (0.2,))[0]
    rc = main(["fit", str(p), "--model", "rigid", "--free", "backlash", *args])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and fragment in err[0]


def test_a_file_given_twice_and_a_speed_for_all_are_refused(tmp_path):
    p, q = _files(tmp_path, (0.2, 0.2))
    with pytest.raises(InputError, match="given twice"):
        _joint([p, p])
    with pytest.raises(InputError, match="--rpm: a joint fit takes each file's measured cam speed"):
        identify_joint(JointRequest([p, q], "rigid", "backlash", overrides={"cam_speed": 20.0}))


def test_the_consistency_test_is_chi_square_on_f_minus_1_degrees_of_freedom():
    # three estimates 1 sd apart on either side of the mean: chi2 = 2 on 2 dof, p = exp(-1)
    t = consistency(np.array([0.4, 0.5, 0.6]), np.array([0.1, 0.1, 0.1]), 0.5)
    assert t["chi2"] == pytest.approx(2.0) and t["dof"] == 2 and t["p_value"] == pytest.approx(math.exp(-1.0))
    assert t["consistent"] and t["birge_ratio"] == 1.0
    t = consistency(np.array([0.2, 0.5, 0.8]), np.array([0.1, 0.1, 0.1]), 0.5)
    assert t["chi2"] == pytest.approx(18.0) and not t["consistent"] and t["birge_ratio"] == pytest.approx(3.0)
    # a file that does not identify the parameter (no finite sd) does not count
    t = consistency(np.array([0.4, 0.6, 0.9]), np.array([0.1, 0.1, np.inf]), 0.5)
    assert t["files_used"] == 2 and t["dof"] == 1


def _summary(value, ci, file, rpm=180.0, identifiable=True):
    return {"measured": {"file": file, "cam_speed_rpm_measured": rpm},
            "parameters": {"restitution": {"value": value, "ci95": ci, "bounds": [0.0, 1.0],
                                           "identifiable": identifiable}}}


def test_combining_fits_is_the_inverse_variance_mean_on_the_search_scale():
    # linear scale (restitution): sd 0.05 and 0.1 -> weights 400 and 100
    a = _summary(0.4, [0.4 - 1.959964 * 0.05, 0.4 + 1.959964 * 0.05], "a.nc")
    b = _summary(0.5, [0.5 - 1.959964 * 0.1, 0.5 + 1.959964 * 0.1], "b.nc")
    c = combine([a, b], ["restitution"])["restitution"]
    assert c["value"] == pytest.approx((400 * 0.4 + 100 * 0.5) / 500)
    half = 1.959964 / math.sqrt(500)
    assert c["ci95_combined"] == pytest.approx([c["value"] - half, c["value"] + half])
    assert c["consistency"]["consistent"]
    # files far apart: the Birge-widened interval is held to the bounds (0-1)
    e = _summary(0.05, [0.05 - 1.959964 * 0.01, 0.05 + 1.959964 * 0.01], "e.nc")
    f = _summary(0.95, [0.95 - 1.959964 * 0.01, 0.95 + 1.959964 * 0.01], "f.nc")
    wide = combine([e, f], ["restitution"])["restitution"]
    assert not wide["consistency"]["consistent"] and wide["ci95"] == pytest.approx([0.0, 1.0])
    # a fit that does not identify it is listed but not used
    d = _summary(0.9, [None, None], "d.nc", identifiable=False)
    assert combine([a, b, d], ["restitution"])["restitution"]["value"] == pytest.approx(c["value"])


@pytest.mark.slow
def test_a_disagreement_that_widens_past_half_the_bounds_is_not_identifiable(tmp_path, monkeypatch):
    # files at 0.05 and 0.4 mm: the Birge-widened joint interval spans more than half the log bounds
    stand_in(monkeypatch)
    s = _joint(_files(tmp_path, (0.05, 0.4)), shared="backlash")
    j = s["parameters"]["backlash_mm"]
    assert not s["consistent"] and not j["identifiable"] and j["verdict"] == "not identifiable"
    assert any("widened" in n for n in j["notes"])
    # held to the search bounds as a single fit's interval is; the widening as computed is kept
    lo, hi = j["bounds"]
    assert lo <= j["ci95"][0] <= j["ci95"][1] <= hi
    a, b = j["ci95_unbounded"]
    assert (a is None or a <= j["ci95"][0]) and (b is None or b >= j["ci95"][1])
    assert (a is None or a < lo) or (b is None or b > hi), "this disagreement widens past the bounds"


def test_a_missing_file_is_refused_before_any_file_is_fitted(tmp_path, monkeypatch):
    calls = []
    stand_in(monkeypatch, calls=calls)
    p = _files(tmp_path, (0.2,))[0]
    with pytest.raises(InputError, match="measured file .*none.nc not found"):
        _joint([p, tmp_path / "none.nc"])
    assert calls == []
