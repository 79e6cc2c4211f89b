"""The misfit verdict: an impact-law parameter fitted where the model leaves much of the
measurement unexplained stands in for what the model misses, and a parameter whose estimate moves
with it is no more the stand's than it is (labtool.identification.fit.inherit_misfit;
docs/identification.md, coverage).

The stand case (slow): the twin (compliant flanks, a bending mode; docs/twin.md) at 204 rpm under
36 N with a 0.0908 mm groove, fitted with the rigid model. Its backlash interval, 0.0426-0.0574
mm, misses the truth by 40 %, and the restitution it moves with (r = -0.76) is misfit: the fit
must not call that backlash identified."""
from __future__ import annotations

import numpy as np
import pytest

from stand_data import without_statements
from labtool.cli import main
from labtool.identification.fit import MISFIT_CORRELATION, FitRequest, identify, inherit_misfit


def _entries(j_verdict: str, k_verdict: str) -> dict:
    return {"backlash_mm": {"verdict": j_verdict, "misfit": False, "notes": []},
            "restitution": {"verdict": k_verdict, "misfit": k_verdict == "misfit", "notes": ["misfit: ..."]}}


@pytest.mark.parametrize("r, k_verdict, expected", [
    (-0.76, "misfit", "misfit"),                   # moves with a misfit parameter
    (MISFIT_CORRELATION, "misfit", "misfit"),      # at the threshold
    (0.3, "misfit", "identified"),                 # a tenth of its variance shared: its own
    (-0.9, "not identifiable", "identified"),      # the other is merely unseen, not biased
    (-0.9, "identified", "identified"),
    (float("nan"), "misfit", "identified"),        # a correlation the fit could not compute
])
def test_a_parameter_inherits_misfit_from_the_one_it_moves_with(r, k_verdict, expected):
    corr = np.array([[1.0, r], [r, 1.0]])
    out = inherit_misfit(_entries("identified", k_verdict), corr)
    assert out["backlash_mm"]["verdict"] == expected
    assert out["restitution"]["verdict"] == k_verdict          # the other's verdict is its own
    if expected == "misfit":
        assert out["backlash_mm"]["misfit"] and "restitution's" in out["backlash_mm"]["notes"][-1]


def test_a_parameter_already_not_identifiable_keeps_its_verdict():
    corr = np.array([[1.0, -0.8], [-0.8, 1.0]])
    assert inherit_misfit(_entries("not identifiable", "misfit"), corr)["backlash_mm"]["verdict"] == "not identifiable"


@pytest.mark.slow
def test_the_twins_loaded_case_whose_interval_misses_is_not_called_identified(tmp_path):
    h5, full, nc = tmp_path / "r.h5", tmp_path / "stated.nc", tmp_path / "m.nc"
    assert main(["acquire", "--device", "sim", "--fast", "--duration", "4", "--rpm", "203.7", "--fu", "35.7",
                 "--backlash-mm", "0.0908", "--contact-damping", "27.2", "--seed", "0", "-o", str(h5)]) == 0
    assert main(["process", str(h5), "-o", str(full)]) == 0
    without_statements(full, nc)
    s = identify(FitRequest(nc, "rigid", "backlash,restitution")).summary
    j, k = s["parameters"]["backlash_mm"], s["parameters"]["restitution"]
    print(j["value"], j["ci95"], j["verdict"], k["verdict"], s["correlation"]["backlash_mm"]["restitution"])
    lo, hi = j["ci95"]
    if lo <= 0.0908 <= hi:
        pytest.skip("the interval holds the truth here: nothing to flag")   # not this test's case any more
    assert k["verdict"] == "misfit"
    assert j["verdict"] != "identified", "an interval that misses the truth by 40 % called identified"
