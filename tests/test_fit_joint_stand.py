"""Joint fits on the simulated stand with the real rigid model (slow): recordings at three speeds
that share one backlash give it back, and recordings whose backlash differs are flagged.

The recordings: ``labtool acquire --device sim --truth rigid --backlash-mm J --restitution 0.3
--rpm N --duration 3 --fast``, then ``labtool process``, with the backlash the recording states
removed from the processed file (a worn groove's j is what nobody states). The logic on a
stand-in: tests/test_fit_joint.py.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from labtool.cli import main
from labtool.identification.joint import JointRequest, identify_joint
from stand_data import without_statements

pytestmark = pytest.mark.slow
SPEEDS = (180.0, 240.0, 300.0)


def _recording(folder: Path, rpm: float, backlash_mm: float) -> Path:
    h5, full, nc = (folder / f"{rpm:g}_{backlash_mm:g}{ext}" for ext in (".h5", "_stated.nc", ".nc"))
    assert main(["acquire", "--device", "sim", "--truth", "rigid", "--backlash-mm", str(backlash_mm),
                 "--restitution", "0.3", "--rpm", f"{rpm:g}", "--duration", "3", "--fast", "--seed", str(int(rpm)),
                 "-o", str(h5)]) == 0
    assert main(["process", str(h5), "-o", str(full)]) == 0
    without_statements(full, nc)
    return nc


def _joint(files):
    return identify_joint(JointRequest(files, "rigid", "backlash,restitution", shared="backlash",
                                       accuracy="fast")).summary


def test_three_speeds_with_one_backlash_give_it_within_10_percent(tmp_path):
    s = _joint([_recording(tmp_path, rpm, 0.15) for rpm in SPEEDS])
    j = s["parameters"]["backlash_mm"]
    lo, hi = j["ci95"]
    print("joint", j["value"], j["ci95"], j["notes"], s["consistency"]["backlash_mm"]["verdict"],
          [(f["value"], f["ci95"], f["identifiable"]) for f in s["consistency"]["backlash_mm"]["files"]])
    assert abs(j["value"] / 0.15 - 1.0) < 0.10 and lo <= 0.15 <= hi and j["verdict"] == "identified"
    assert s["consistent"]
    for f in s["per_file_parameters"]:
        assert abs(f["restitution"]["value"] - 0.3) < 0.1


def test_three_speeds_with_three_backlashes_are_flagged(tmp_path):
    s = _joint([_recording(tmp_path, rpm, j) for rpm, j in zip(SPEEDS, (0.1, 0.15, 0.22))])
    test = s["consistency"]["backlash_mm"]
    print([f["value"] for f in test["files"]], test["verdict"])
    assert not s["consistent"] and test["p_value"] < 0.05
    assert "these measurements disagree about backlash_mm beyond their intervals" in test["verdict"]
    # each file alone finds its own backlash
    assert [f["value"] for f in test["files"]] == pytest.approx([0.1, 0.15, 0.22], rel=0.15)
