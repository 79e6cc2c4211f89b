"""``labtool bench accuracy``: bad input is one line and exit 2; a small run writes CSV, PNG, JSON."""
import csv
import json

import pytest

from labtool.cli import main


@pytest.mark.parametrize("args, message", [
    (["--models", "quantum"], "unknown model"),
    (["--runs", "17"], "not in Table 1"),
    (["--runs", "one"], "not a run number"),
])
def test_bad_input_is_one_line_exit_2(args, message, capsys, tmp_path):
    code = main(["bench", "accuracy", "-o", str(tmp_path / "out"), *args])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith("labtool: error:") and message in err and err.count("\n") == 1


def test_output_that_is_a_file_is_refused(tmp_path, capsys):
    f = tmp_path / "file.txt"
    f.write_text("x")
    assert main(["bench", "accuracy", "-o", str(f)]) == 2
    assert "not a directory" in capsys.readouterr().err


def test_small_run_writes_csv_png_and_summary(tmp_path):
    out = tmp_path / "wp"
    code = main(["bench", "accuracy", "--runs", "9", "--ladder-runs", "", "--models", "elastic",
                 "--all-cores", "-o", str(out)])
    assert code == 0
    rows = list(csv.DictReader(open(out / "work_precision.csv")))
    assert {r["preset"] for r in rows} == {"fast", "standard", "reference"}
    summary = json.loads((out / "work_precision_summary.json").read_text())
    e = summary["elastic"]["presets"]
    # the presets are ordered by their measured error in omega2
    assert e["standard"]["err_omega2"] < e["fast"]["err_omega2"]
    assert (out / "work_precision.png").stat().st_size > 1000
