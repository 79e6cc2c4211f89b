"""Mistakes that got a traceback or advice that did not work: a measured variable that holds text,
a second acquire onto a recording in progress, a campaign's ``revolutions``, a factor level no
model takes, and requests far larger than meant (``--duration 2000`` meant as ms). Each ends in
one line (tests/hostile.py ``one_error_line``) whose advice, followed, works."""
from __future__ import annotations

import os
import pty
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest
import xarray as xr

from hostile import (REPORT_FAST, SAMPLE, _prepare_child, cli, command, env, measured_nc,  # noqa: F401
                     one_error_line, run, start, wait_for)
from test_campaign_run import CAL

REPORT_QUICK = [*REPORT_FAST, "--no-robustness"]


# --- traceback: a measured variable that holds text ------------------------------------------
def _with_text(tmp_path, measured_nc, name: str):
    """The measured file with variable ``name`` replaced by the text 'abc' in each cell."""
    ds = xr.open_dataset(measured_nc, engine="h5netcdf", decode_times=False).load()
    v = ds[name]
    text = np.full(v.shape, "abc", dtype=object)
    if name in ds.coords:
        ds = ds.assign_coords({name: (v.dims, text, v.attrs)})
    else:
        ds[name] = (v.dims, text, v.attrs)
    path = tmp_path / f"{name}.nc"
    ds.to_netcdf(path, engine="h5netcdf")
    return path


# every variable report, fit and campaign report read as numbers (the spectra: the report's figure)
READ_AS_NUMBERS = ["omega2", "epsilon2", "phi1", "time", "aE_n", "revolution_start_time", "frequency", "aE_t_psd"]


@pytest.mark.slow
@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("name", READ_AS_NUMBERS)
def test_a_measured_variable_that_holds_text_is_refused_by_report(tmp_path, capsys, measured_nc, name):
    """omega2 holding text was an internal error (ValueError: could not convert string to float,
    exit 70) in labtool report; so were epsilon2, phi1, time, aE_n, revolution_start_time, frequency."""
    path = _with_text(tmp_path, measured_nc, name)
    line = one_error_line(*cli(["report", path, *REPORT_QUICK, "-o", tmp_path / "r.html"], capsys))
    assert f"{name} holds text, not numbers" in line and "process the recording again" in line
    assert not (tmp_path / "r.html").exists()


@pytest.mark.slow
@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("command_line", [["fit", "--model", "rigid", "--free", "backlash", "--accuracy", "fast"],
                                          ["campaign", "report", "--models", "kinematic", "--omega1", "const"]])
def test_a_measured_omega2_that_holds_text_is_refused_by_fit_and_campaign_report(tmp_path, capsys, measured_nc,
                                                                                   command_line):
    path = _with_text(tmp_path, measured_nc, "omega2")
    args = [*command_line[:2], path, *command_line[2:]] if command_line[0] == "campaign" else \
        [command_line[0], path, *command_line[1:]]
    if command_line[0] == "campaign":
        args += ["-o", tmp_path / "c.html"]
    line = one_error_line(*cli(args, capsys))
    assert "omega2 holds text, not numbers" in line


@pytest.mark.slow
def test_the_advice_for_a_measured_file_that_holds_text_works(tmp_path, capsys, measured_nc):
    """'process the recording again': the sample recording processed again is reported."""
    again = tmp_path / "again.nc"
    assert cli(["process", SAMPLE / "run_180rpm.h5", "-o", again], capsys)[0] == 0
    code, err = cli(["report", again, *REPORT_QUICK, "-o", tmp_path / "r.html"], capsys)
    assert code == 0, err


# --- advice: a second acquire onto a recording in progress -----------------------------------
def _rows(path) -> int:
    try:
        with h5py.File(path, "r", swmr=True) as f:
            return int(f["signals"].shape[0])
    except (OSError, KeyError):
        return 0


@pytest.mark.slow
@pytest.mark.hostile("concurrency")
def test_a_second_acquire_onto_a_recording_in_progress_is_not_advised_to_force(tmp_path):
    """It said 'already exists; use --force to overwrite it', and --force was then refused."""
    f = tmp_path / "f.h5"
    first = start(["acquire", "--duration", "30", "--status-every", "0", "-o", f])
    try:
        assert wait_for(lambda: _rows(f) >= 5000, timeout=60)
        line = one_error_line(*run(["acquire", "--fast", "--duration", "1", "-o", f]))
        assert "being recorded by another process" in line and "use --force" not in line
        line_forced = one_error_line(*run(["acquire", "--fast", "--duration", "1", "--force", "-o", f]))
        assert line_forced == line
        first.send_signal(signal.SIGINT)
        first.communicate(timeout=60)
    finally:
        if first.poll() is None:
            first.kill()
    assert first.returncode == 128 + signal.SIGINT
    # the first run's recording, stopped short: the same command records it again without --force
    code, err = run(["acquire", "--fast", "--duration", "1", "-o", f])
    assert code == 0 and "recording over" in err, err


# --- silent wrong: a campaign's revolutions ---------------------------------------------------
@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_revolutions_n_in_a_plan_averages_n_whole_revolutions(tmp_path):
    """revolutions = 8 gave '7 revolutions averaged' at every speed (the simulated stand starts at
    a tacho mark, which has no edge to be seen)."""
    plan = tmp_path / "plan.toml"
    plan.write_text(f'[calibration]\nfiles = ["{CAL}"]\n[defaults]\nrevolutions = 8\n[grid]\n'
                    'rpm = [180.0, 300.0, 500.0]\n[compare]\nmodels = ["kinematic"]\nomega1 = ["const"]\n')
    code, err = run(["campaign", "run", plan, "-o", tmp_path / "camp", "--no-report"], timeout=600)
    assert code == 0, err
    assert err.count("8 revolutions averaged") == 3, err


# --- silent wrong: a factor level no model takes ----------------------------------------------
@pytest.mark.hostile("silent_wrong")
def test_a_backlash_level_that_undercuts_the_groove_is_refused_before_any_run(tmp_path, capsys):
    """j = 8 mm ran the design and left its runs empty ('2 of 4 runs failed'), after the others ran."""
    path = tmp_path / "f.csv"
    path.write_text("factor,symbol,unit,level_1,level_2\nA,Fu,N,0,65\nB,j,mm,0.016,8\n")
    line = one_error_line(*cli(["doe", "run", "--factors", path, "-o", tmp_path / "r.csv"], capsys))
    assert line.startswith("labtool: error: factor B (j) level 2 = 8 mm: the groove's outer flank would be undercut")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.csv"]
    largest = float(line.split("takes a backlash up to ")[1].split(" mm")[0])
    assert 0.128 < largest < 8
    # the advice: a level below it runs, as simulate does, and simulate refuses just past it
    path.write_text(f"factor,symbol,unit,level_1,level_2\nA,Fu,N,0,65\nB,j,mm,0.016,{0.999 * largest:.6g}\n")
    code, err = cli(["doe", "run", "--factors", path, "-o", tmp_path / "r.csv"], capsys)
    assert code == 0, err
    assert cli(["simulate", "--model", "rigid", "--backlash-mm", f"{1.001 * largest:.6g}"], capsys)[0] == 2


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("row, said", [
    ("C,n1,rpm,180,2000", "factor C (n1) level 2 = 2000 rpm: cam speed 2000 rpm is outside the range"),
    ("C,k,-,0.5,1.5", "factor C (k) level 2 = 1.5: restitution k must be in [0, 1]"),
    ("C,j,mm,-1,0.128", "factor C (j) level 1 = -1 mm: backlash j must be in [0, 10] mm"),
])
def test_a_factor_level_past_the_models_bounds_is_named_with_its_unit(tmp_path, capsys, row, said):
    path = tmp_path / "f.csv"
    path.write_text(f"factor,symbol,unit,level_1,level_2\nA,Fu,N,0,65\nB,Jt,-,1,4\n{row}\n")
    line = one_error_line(*cli(["doe", "run", "--factors", path, "-o", tmp_path / "r.csv"], capsys))
    assert said in line
    assert "(--" not in line            # a factor file's level is not set by a command-line option
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.csv"]


def test_a_design_is_validated_by_the_library_before_its_first_run(tmp_path):
    """run_design refuses the design before any run (no parts folder), whoever calls it."""
    from labtool.common.errors import InputError
    from labtool.execution.design import run_design
    from labtool.models.dynamics.scene import Scene
    from labtool.models.study.doe import Design, Factor

    design = Design((Factor("A", "Fu", "N", (0.0, 65.0)), Factor("B", "j", "mm", (0.016, 8.0))), Scene(), "rigid")
    calls = []
    with pytest.raises(InputError, match="factor B \\(j\\) level 2 = 8 mm"):
        run_design(design, tmp_path / "r.csv", tmp_path / "r.nc", progress=lambda *a: calls.append(a))
    assert calls == [] and list(tmp_path.iterdir()) == []


# --- budgets: a request far larger than meant -------------------------------------------------
@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_an_acquisition_of_240_mb_is_refused_when_piped(tmp_path):
    """acquire --duration 2000 (meant as ms) wrote 240 MB in 98 s without a word."""
    t0 = time.monotonic()
    line = one_error_line(*run(["acquire", "--fast", "--duration", "2000", "-o", tmp_path / "r.h5"],
                               timeout=60))
    assert "--duration 2000 s at 10000 Hz would write about 240 MB" in line and "pass --yes" in line
    assert "in seconds" in line and list(tmp_path.iterdir()) == [] and time.monotonic() - t0 < 60


@pytest.mark.hostile("silent_wrong")
def test_a_paced_acquisition_over_ten_minutes_is_refused_when_piped(tmp_path, capsys):
    line = one_error_line(*cli(["acquire", "--duration", "700", "-o", tmp_path / "r.h5"], capsys))
    assert "would take about 12 min" in line and "pass --yes" in line
    assert list(tmp_path.iterdir()) == []


def _on_a_terminal(args, answer: bytes, timeout: float = 120) -> tuple[int, str]:
    """labtool with stdin, stdout and stderr on a pseudo-terminal; ``answer`` typed at the prompt."""
    main, child = pty.openpty()
    proc = subprocess.Popen(command(args), env=env(), stdin=child, stdout=child, stderr=child,
                            preexec_fn=_prepare_child)
    os.close(child)
    seen = b""
    try:
        deadline = time.monotonic() + timeout
        while b"Run it?" not in seen and time.monotonic() < deadline and proc.poll() is None:
            try:
                seen += os.read(main, 4096)
            except OSError:
                break
        os.write(main, answer + b"\n")
        while True:
            try:
                chunk = os.read(main, 4096)
            except OSError:
                break
            if not chunk:
                break
            seen += chunk
        proc.wait(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
        os.close(main)
    return proc.returncode, seen.decode("utf-8", "replace")


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_a_large_acquisition_is_asked_for_on_a_terminal(tmp_path):
    code, out = _on_a_terminal(["acquire", "--fast", "--duration", "2000", "-o", tmp_path / "r.h5"], b"n")
    assert "would write about 240 MB" in out and "Run it?" in out
    assert code == 2 and "labtool: error: not run:" in out and list(tmp_path.iterdir()) == []


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_a_large_campaign_is_refused_before_its_folder_is_made(tmp_path, capsys):
    plan = tmp_path / "plan.toml"
    plan.write_text(f'[device]\npacing = "realtime"\n[calibration]\nfiles = ["{CAL}"]\n[[points]]\nrpm = 180.0\n'
                    'duration_s = 700.0\n[compare]\nmodels = ["kinematic"]\nomega1 = ["const"]\n')
    line = one_error_line(*cli(["campaign", "run", plan, "-o", tmp_path / "camp"], capsys))
    assert line.startswith("labtool: error: this campaign would take about 12 min") and "pass --yes" in line
    assert "1 point(s) to record in real time" in line and not (tmp_path / "camp").exists()
    plan.write_text(plan.read_text().replace('"realtime"', '"fast"').replace("700.0", "3000.0"))
    line = one_error_line(*cli(["campaign", "run", plan, "-o", tmp_path / "camp"], capsys))
    assert "would write about" in line and "MB" in line and "take about" not in line


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_a_design_that_writes_over_100_mb_is_refused_when_piped(tmp_path):
    """400 000 kinematic runs: ~125 MB of parts and results (and minutes on two workers)."""
    levels = ",".join(f"level_{k}" for k in range(1, 11))
    rows = [f"{n},{s},{u}," + ",".join(str(v0 + dv * k) for k in range(10))
            for n, s, u, v0, dv in [("A", "Fu", "N", 0, 5), ("B", "n1", "rpm", 150, 10), ("C", "Jt", "-", 1, 0.5),
                                    ("D", "j", "mm", 0.016, 0.016), ("E", "k", "-", 0.1, 0.05)]]
    rows.append("F,lw,mm," + ",".join(str(4 + 0.5 * k) for k in range(4)) + ",,,,,,")
    (tmp_path / "f.csv").write_text(f"factor,symbol,unit,{levels}\n" + "\n".join(rows) + "\n")
    line = one_error_line(*run(["doe", "run", "--model", "kinematic", "--factors", tmp_path / "f.csv",
                                "-o", tmp_path / "r.csv"], timeout=300))
    assert line.startswith("labtool: error: this design of 400000 runs would") and "write about" in line
    assert "pass --yes" in line and sorted(p.name for p in tmp_path.iterdir()) == ["f.csv"]


# --- silent wrong: a recording clipped at every impact ------------------------------------------
@pytest.mark.hostile("silent_wrong")
@pytest.mark.slow
def test_a_recording_clipped_in_every_revolution_is_said_and_the_advice_works(tmp_path, capsys):
    """The 480C02 at gain x10 (Ka 86.43) clips at every impact: process wrote "0 revolutions
    averaged" with exit 0, and report and fit then said "the measured file holds no whole cam
    revolution", naming neither the file nor why. The advice (a larger range in m/s^2) is
    followed and the report runs."""
    rec, nc = tmp_path / "k10.h5", tmp_path / "k10.nc"
    acq = ["acquire", "--device", "sim", "--fast", "--duration", "2", "--seed", "3"]
    assert cli([*acq, "--ka", "86.43", "-o", rec], capsys)[0] == 0
    code, err = cli(["process", rec, "-o", nc], capsys)
    assert code == 0 and "no revolution averaged: each of the" in err and "acquire --ka 8643" in err
    line = one_error_line(*cli(["report", nc, "-o", tmp_path / "r.html", *REPORT_QUICK], capsys))
    assert f"{nc}: it holds no whole cam revolution" in line and "not finite (clipped" in line
    advice = line.split("on the simulated stand ")[1].split(")")[0].split()
    assert advice[:2] == ["acquire", "--ka"]
    assert cli([*acq, *advice[1:], "-o", tmp_path / "k1.h5"], capsys)[0] == 0
    assert cli(["process", tmp_path / "k1.h5", "-o", tmp_path / "k1.nc"], capsys)[0] == 0
    code, err = cli(["report", tmp_path / "k1.nc", "-o", tmp_path / "r.html", *REPORT_QUICK], capsys)
    assert code == 0, err
