"""The CLI's contract: help works, errors are one line with exit code 2."""
from labtool.cli import main


def test_help_exits_zero(capsys):
    assert main(["--help"]) == 0
    assert "kinematics" in capsys.readouterr().out


def test_unknown_law_is_one_line_exit_2(capsys):
    assert main(["kinematics", "--law", "parabolic"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("labtool: error: unknown motion law 'parabolic'")


def test_bad_option_value_is_one_line_exit_2(capsys):
    assert main(["kinematics", "--rpm", "fast"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("labtool: error:")


def test_tables_written_to_a_pipe_keep_every_column_whole(capsys, monkeypatch):
    """Redirected to a file or a CI log, rich would cut a table to 80 columns and elide the
    numbers ("MR13…", "0.00…"); the commands' console is wide there (labtool.output.console)."""
    import pandas as pd

    from labtool.commands.doe import _print_results

    monkeypatch.delenv("COLUMNS", raising=False)
    cols = ["run", "A_Fu_level", "B_j_level", "C_n1_level", "D_Jt_level", "MR13D_max_Nm",
            "MR13D_min_Nm", "xel_max_mm", "xel_min_mm", "jumps", "impacts"]
    row = [1, 1, 1, 1, 1, 5.196161224, -5.176029775, 0.000514680026, -0.0005609431328, 1, 0]
    _print_results(pd.DataFrame([row], columns=cols), "elastic model")
    out = capsys.readouterr().out
    assert "…" not in out
    for text in cols + ["5.1962", "-5.176", "0.00051468", "-0.00056094"]:
        assert text in out


def test_columns_set_by_the_user_are_kept(monkeypatch):
    from labtool.output import PIPE_WIDTH, console

    monkeypatch.setenv("COLUMNS", "100")
    assert console().width == 100
    monkeypatch.delenv("COLUMNS")
    assert console().width == PIPE_WIDTH
