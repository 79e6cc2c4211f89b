"""labtool suggest: the next experiment's D-optimal criterion on a stand-in whose backlash is most
visible at a known speed, and its bad input.

The stand-in (tests/test_fit.py) shifts the kinematic cycle by 0.05 ln(j / 0.2 mm) rad; here the
shift is also weighted by w(n1) = exp(-((n1 - 300) / 120)^2): a recording at 300 rpm sees the
backlash best, so the suggestion must be 300 rpm, and a second recording at the measured speed
must be expected to narrow a lone parameter's interval by 1 / sqrt(2) (twice the information).
The real models on the simulated stand are in benchmarks/suggest_loop.py.
"""
from __future__ import annotations

import json
import math

import pytest

from labtool.common.errors import InputError
from labtool.common.files import write_netcdf
from labtool.identification.design import SuggestRequest, information, suggest
from labtool.reports.synthetic import synthetic_measured
from tests.test_fit import stand_in


def weight(rpm: float) -> float:
    return math.exp(-((rpm - 300.0) / 120.0) ** 2)


def _stand_in(monkeypatch):
    stand_in(monkeypatch, shift=lambda op: 0.05 * math.log(op["backlash_mm"] / 0.2) * weight(op["cam_speed_rpm"])
             / weight(180.0))


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    path = tmp_path_factory.mktemp("suggest") / "measured.nc"
    write_netcdf(synthetic_measured(noise=0.01, revolutions=4.3), path)
    return path


@pytest.mark.slow
def test_the_suggestion_is_where_the_backlash_shows_most(measured, monkeypatch, tmp_path):
    _stand_in(monkeypatch)
    # the restitution at the stand-in's own 0.5, so that the model explains the measurement
    out = suggest(SuggestRequest([measured], free="backlash", shared="backlash", rpm_range=(120.0, 480.0, 30.0),
                                 loads=(0.0,), fit={"overrides": {"restitution": 0.5}}))
    s = out.summary
    assert s["point"] == {"cam_speed_rpm": 300.0, "Fu_N": 0.0, "law": "sine", "jt_factor": 1.0}
    by_rpm = {c["cam_speed_rpm"]: c for c in s["candidates"]}
    # a second recording like the first: twice the information, the interval / sqrt(2)
    assert by_rpm[180.0]["interval_width_ratio"]["backlash_mm"] == pytest.approx(1 / math.sqrt(2), rel=0.1)
    # at 300 rpm the shift per unit ln j is 1 / w(180) = 1.75 times larger: information x 3.1
    expected = 1 / math.sqrt(1 + (1 / weight(180.0)) ** 2)
    assert by_rpm[300.0]["interval_width_ratio"]["backlash_mm"] == pytest.approx(expected, rel=0.1)
    assert "[[points]]\nname = \"next_300rpm\"\nrpm = 300\nFu_N = 0\n" == s["plan_points_toml"]
    json.dumps(s, allow_nan=False)


@pytest.mark.slow
def test_the_cli_prints_the_point_and_writes_the_json_and_the_figure(measured, monkeypatch, tmp_path, capsys):
    from labtool.cli import main
    _stand_in(monkeypatch)
    out = tmp_path / "next.json"
    rc = main(["suggest", str(measured), "--free", "backlash", "--shared", "backlash", "--rpm-range", "180:420:60",
               "--loads", "0", "-o", str(out)])
    text = capsys.readouterr().out
    assert rc == 0 and "next point: 300 rpm, Fu = 0 N" in text and "[[points]]" in text
    assert json.loads(out.read_text())["format"] == "labtool.suggest"
    assert (tmp_path / "next.png").stat().st_size > 10_000


def test_information_ignores_a_parameter_the_fit_does_not_see():
    import numpy as np
    cov = np.array([[0.04, 0.0], [0.0, np.inf]])
    M = information(cov)
    assert M[0, 0] == pytest.approx(25.0) and M[1, 1] == 0.0


@pytest.mark.parametrize("args, fragment", [
    (["--goal", "discriminate", "--models", "rigid"], "--goal discriminate needs two or more of rigid, elastic"),
    (["--goal", "guess"], "--goal must be one of identify, discriminate"),
    (["--rpm-range", "300:200:10"], "--rpm-range must be lo:hi:step with 0 < lo <= hi"),
    (["--rpm-range", "a:b:c"], "--rpm-range must be lo:hi:step in rpm"),
    (["--rpm-range", "100:600:1"], "at most 201"),
    (["--loads", "x"], "--loads must be numbers in N"),
    (["--loads", "-5"], "a load must be a finite force >= 0 N"),
    (["--free", "contact_damping"], "not a parameter of the rigid model"),
    (["--shared", "restitution"], "'restitution' is not among the free parameters"),
])
def test_bad_options_end_in_one_line_and_exit_2(measured, capsys, args, fragment):
    from labtool.cli import main
    rc = main(["suggest", str(measured), "--free", "backlash", *args])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith("labtool: error:") and fragment in err[0], err


def test_speeds_the_models_do_not_take_are_refused(measured):
    with pytest.raises(InputError, match="holds no speed the models take"):
        suggest(SuggestRequest([measured], free="backlash", rpm_range=(0.1, 0.5, 0.1)))


@pytest.mark.slow
def test_discriminate_picks_a_speed_where_the_models_differ_more_than_at_180_rpm(tmp_path, capsys):
    # the simulated stand's twin at 180 rpm; rigid and elastic with their default options: where
    # does a recording tell them apart best? (the report's discrimination, at every candidate)
    from labtool.cli import main
    h5, nc = tmp_path / "twin.h5", tmp_path / "twin.nc"
    assert main(["acquire", "--device", "sim", "--rpm", "180", "--duration", "3", "--fast", "-o", str(h5)]) == 0
    assert main(["process", str(h5), "-o", str(nc)]) == 0
    capsys.readouterr()
    out = tmp_path / "next.json"
    assert main(["suggest", str(nc), "--goal", "discriminate", "--rpm-range", "120:600:120", "--loads", "0",
                 "-o", str(out)]) == 0
    assert "next point:" in capsys.readouterr().out
    s = json.loads(out.read_text())
    at = {c["cam_speed_rpm"]: c["epsilon2_distance"] for c in s["candidates"]}
    print(s["expected"]["sentence"])
    # the measured speed (179.99... rpm) is among the candidates; the point is another, where the
    # models' epsilon2 differ by more (twin, 3 s: 73 measured scatters at 600 rpm, 12 at 180)
    assert abs(s["point"]["cam_speed_rpm"] - 180.0) > 1.0
    assert s["expected"]["epsilon2_distance"] > 1.5 * s["expected"]["at_measured"]
    assert s["expected"]["epsilon2_distance"] == max(v for v in at.values() if v is not None)
    assert (tmp_path / "next.png").stat().st_size > 10_000
