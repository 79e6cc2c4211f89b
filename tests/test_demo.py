"""labtool demo (what `make demo` runs): the whole pipeline on the simulated stand's default truth."""
import json

import pytest

from labtool.cli import main


@pytest.mark.slow
def test_demo_runs_the_whole_pipeline_and_prints_where_the_report_is(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    for name in ("kinematics_180rpm.nc", "table1_kinematic_vs_table3.csv", "recording_180rpm.h5", "measured_180rpm.nc",
                 "report.html", "summary.json", "report.pdf", "report_curves.csv", "report_curves.nc"):
        assert (out / name).exists(), name
    assert f"report: {(out / 'report.html').resolve()}" in printed
    summary = json.loads((out / "summary.json").read_text())
    assert summary["measured"]["source"] == "recording"
    got = {(c["requested_model"], c["omega1"], c["signal"]) for c in summary["comparisons"]}
    assert got == {(m, w, s) for m in ("rigid", "elastic") for w in ("const", "var") for s in ("omega2", "epsilon2")}
    # each model's agreement with the measured omega2 and epsilon2 is in the headline, printed and in the page
    assert len(summary["headline"]) == 4
    for h in summary["headline"]:
        assert 0.0 <= h["omega2_iso_rating"] <= 1.0 and 0.0 <= h["epsilon2_iso_rating"] <= 1.0
        assert h["label"] in printed
    assert summary["closest"] in {h["label"] for h in summary["headline"]}
    assert f"closest to the measurement: {summary['closest']}" in printed
    # the verdict's robustness: both presets, both lengths, and it is said
    rows = summary["robustness"]["rows"]
    assert {(r["accuracy"], r["revolutions"]) for r in rows} == {("fast", 6.0), ("fast", 3.0), ("standard", 6.0),
                                                                  ("standard", 3.0)}
    # what the measurement can tell: the verdict names the runs it cannot tell apart (the rigid model's two
    # omega1 modes rate within 0.0003 of each other on the twin's recording) and the speed that would
    verdict = summary["verdict"]
    assert verdict["sentence"] in printed
    assert verdict["cannot_tell_apart"] and "cannot tell" in verdict["sentence"]
    for group in verdict["cannot_tell_apart"]:
        assert all(lab in verdict["sentence"] for lab in group)
    assert verdict["discrimination"]["best_rpm"] > 0 and "rpm" in verdict["discrimination"]["sentence"]
    # measured events with the summary's keys, and the same keys predicted per model
    ev = summary["measured"]["events"]
    for key in ("impacts_per_rev", "jumps_per_rev", "first_impact_deg", "impact_angles_deg", "threshold_rad_s"):
        assert key in ev
    for row in summary["events"]:
        for key in ("impacts_per_rev", "jumps_per_rev", "first_impact_deg", "impact_angles_deg",
                    "detectable_impacts_per_rev"):
            assert key in row
    html = (out / "report.html").read_text()
    assert "elastic, ω1 = var." in html and "rigid, ω1 = ct." in html and 'id="robustness"' in html
