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
