"""labtool demo (what `make demo` runs): the whole pipeline, and its behaviour when a piece is missing."""
import json

import pytest

from labtool import demo_steps
from labtool.cli import main
from reports import pipeline


@pytest.mark.slow
def test_demo_runs_the_whole_pipeline_and_prints_where_the_report_is(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    for name in ("kinematics_180rpm.nc", "table1_kinematic_vs_table3.csv", "report.html", "summary.json", "report.pdf"):
        assert (out / name).exists(), name
    assert f"report: {(out / 'report.html').resolve()}" in printed
    summary = json.loads((out / "summary.json").read_text())
    got = {(c["requested_model"], c["omega1"], c["signal"]) for c in summary["comparisons"]}
    assert got == {(m, w, s) for m in ("rigid", "elastic") for w in ("const", "var") for s in ("omega2", "epsilon2")}
    # each model's agreement with the measured omega2 and epsilon2 is in the headline, printed and in the page
    assert len(summary["headline"]) == 4
    for h in summary["headline"]:
        assert 0.0 <= h["omega2_iso_rating"] <= 1.0 and 0.0 <= h["epsilon2_iso_rating"] <= 1.0
        assert h["label"] in printed
    assert summary["closest"] in {h["label"] for h in summary["headline"]}
    assert f"closest to the measurement: {summary['closest']}" in printed
    html = (out / "report.html").read_text()
    assert "elastic, w1 = var." in html and "rigid, w1 = ct." in html
    if (out / "recording_180rpm.h5").exists():       # the stand and processing are installed
        assert summary["measured"]["source"] == "recording"
        assert (out / "measured_180rpm.nc").exists()


@pytest.mark.slow
def test_demo_skips_missing_pieces_and_says_so(tmp_path, capsys, monkeypatch):
    """Without acquisition, processing and the dynamic models the demo still ends with a report, on a
    synthetic measurement and the kinematic level, and says which steps it skipped."""
    real_have = demo_steps._have
    monkeypatch.setattr(demo_steps, "_have", lambda m: False if m.split(".")[0] in ("acquisition", "processing") or
                        m in ("labtool.commands.acquire", "labtool.commands.process", "models.dynamics.rigid", "models.dynamics.elastic")
                        else real_have(m))
    monkeypatch.setattr(demo_steps, "SAMPLE_DATA", tmp_path / "no_samples")
    monkeypatch.setattr(pipeline, "model_available", lambda name: name == "kinematic")
    out = tmp_path / "demo"
    assert main(["demo", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "step skipped: acquisition on the simulated stand" in printed
    assert "step skipped: processing" in printed
    assert "SYNTHETIC measurement" in printed
    assert "kinematic level stands in" in printed
    summary = json.loads((out / "summary.json").read_text())
    assert summary["measured"]["source"] == "synthetic"
    assert {s["model"] for s in summary["simulations"]} == {"kinematic"}
    assert any("SYNTHETIC" in n for n in summary["notes"])
    assert "SYNTHETIC" in (out / "report.html").read_text()
