"""Threshold files: parsing, the direction of bare limits, signed metrics, scopes, bad entries."""
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from labtool.common.errors import InputError
from labtool.reports.metrics import METRICS
from labtool.reports.thresholds import evaluate, load_thresholds, parse_thresholds


def _comp(model="elastic", mode="const", signal="omega2", overall=None, revs=()):
    return {"model": model, "requested_model": model, "omega1": mode, "signal": signal,
            "overall": overall or {}, "per_revolution": list(revs)}


def test_bare_numbers_are_minimums_for_scores_and_maximums_for_errors():
    th = parse_thresholds({"omega2": {"iso_rating": 0.6, "nrmse": 0.1}})
    lim = {l.metric: l for l in th.limits}
    assert lim["iso_rating"].min == 0.6 and lim["iso_rating"].max is None
    assert lim["nrmse"].max == 0.1 and lim["nrmse"].min is None
    rows = evaluate(th, [_comp(overall={"iso_rating": 0.7, "nrmse": 0.2})])
    assert [(r["metric"], r["passed"]) for r in rows] == [("iso_rating", True), ("nrmse", False)]


def test_signed_metrics_are_limited_in_absolute_value():
    th = parse_thresholds({"epsilon2": {"sg_magnitude": 0.2, "lag_deg": {"max": 2}}})
    rows = evaluate(th, [_comp(signal="epsilon2", overall={"sg_magnitude": -0.3, "lag_deg": -1.5})])
    assert [r["passed"] for r in rows] == [False, True]


def test_apply_selects_models_and_modes_and_each_revolution_takes_the_worst():
    th = parse_thresholds({"omega2": {"iso_rating": 0.8}, "apply": {"models": ["rigid"], "omega1": "var",
                                                                      "scope": "each_revolution"}})
    comps = [_comp("elastic", "var", revs=[{"iso_rating": 0.1}]),
             _comp("rigid", "const", revs=[{"iso_rating": 0.1}]),
             _comp("rigid", "var", overall={"iso_rating": 0.99}, revs=[{"iso_rating": 0.9}, {"iso_rating": 0.7}])]
    rows = evaluate(th, comps)
    assert len(rows) == 1 and rows[0]["value"] == 0.7 and rows[0]["passed"] is False


def test_non_finite_values_fail():
    th = parse_thresholds({"omega2": {"nrmse": 1.0}})
    assert evaluate(th, [_comp(overall={"nrmse": float("nan")})])[0]["passed"] is False


def test_load_reports_missing_file(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_thresholds(tmp_path / "none.toml")


@settings(max_examples=50, deadline=None)
@given(name=st.text(alphabet="abcdefghijklmnopqrstuvwxyz_0123456789", min_size=1, max_size=20))
def test_any_unknown_metric_name_is_input_error(name):
    if name in METRICS:
        return
    with pytest.raises(InputError, match="unknown metric"):
        parse_thresholds({"omega2": {name: 0.5}}, source="th.toml")


@settings(max_examples=30, deadline=None)
@given(value=st.one_of(st.text(max_size=5), st.booleans(), st.just(float("inf")), st.lists(st.integers(), max_size=2)))
def test_non_numeric_limits_are_input_error(value):
    with pytest.raises(InputError):
        parse_thresholds({"omega2": {"nrmse": value}})
