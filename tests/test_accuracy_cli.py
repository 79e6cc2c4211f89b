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


@pytest.mark.slow
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


def _work_precision_module():
    import importlib.util
    import pathlib

    path = pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "work_precision.py"
    spec = importlib.util.spec_from_file_location("work_precision", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_cost_at_error_reads_a_power_law_exactly_and_never_extrapolates():
    wp = _work_precision_module()
    # a solver of order 5: error = cost^-5 (log-log straight line), ladder of 4 tolerances
    ladder = [(c ** -5.0, c) for c in (1.0, 2.0, 4.0, 8.0)]
    assert wp.cost_at_error(ladder, 3.0 ** -5.0) == pytest.approx(3.0, rel=1e-12)
    assert wp.cost_at_error(ladder, 1.0) == pytest.approx(1.0)          # the cheapest point
    assert wp.cost_at_error(ladder, 10.0) == 1.0                       # even the cheapest is as accurate
    assert wp.cost_at_error(ladder, 8.0 ** -5.0 / 2) is None           # beyond the ladder
    assert wp.cost_at_error([], 1e-6) is None
    # unsorted input, a zero error ignored
    assert wp.cost_at_error(ladder[::-1] + [(0.0, 0.5)], 3.0 ** -5.0) == pytest.approx(3.0, rel=1e-12)
