"""Every interruption resumes as documented: ``acquire``, ``campaign run``, ``doe run`` and ``fit``
run as real child processes and stopped by SIGINT, SIGTERM or SIGKILL at three moments (early,
mid-way, near the end: seen on disk, in their progress or in the CPU time they used, never
guessed by a sleep), then run again with the same command line. Each case checks that the interrupted run exits 128 + signal, names
only files that exist and leaves no recording marked complete that is short; that the rerun
finishes without being told anything more (no --force, --redo or --fresh); and that its results
equal an uninterrupted run's, value for value."""
from __future__ import annotations

import json
import os
import re
import resource
import signal
import subprocess
import threading
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import xarray as xr

from hostile import ROOT, SAMPLE, _prepare_child, command, env, measured_nc, run, wait_for  # noqa: F401
from test_campaign_run import CAL, same_outputs

pytestmark = [pytest.mark.slow, pytest.mark.hostile("interrupted")]

SIGNALS = [signal.SIGINT, signal.SIGTERM, signal.SIGKILL]
MOMENTS = ["early", "mid", "late"]
CASES = [pytest.param(sig, moment, id=f"{signal.Signals(sig).name}-{moment}") for sig in SIGNALS for moment in MOMENTS]


class Child:
    """A labtool child process whose stderr lines are collected as they come (a thread drains it)."""

    def __init__(self, args: list):
        self.proc = subprocess.Popen(command(args), env=env(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                     text=True, errors="replace", preexec_fn=_prepare_child)
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.proc.stderr:
            self.lines.append(line)

    def stop_when(self, ready, sig: int, timeout: float = 240.0) -> tuple[int, str]:
        """Send ``sig`` as soon as ``ready()`` holds; (exit code, stderr) once the process ended.
        Fails when the process ended before the moment came (the moment was not reached)."""
        try:
            reached = wait_for(lambda: self.proc.poll() is not None or ready(), timeout=timeout, every=0.002)
            assert reached and self.proc.poll() is None, f"ended before the moment: {''.join(self.lines)[-3000:]}"
            self.proc.send_signal(sig)
            self.proc.wait(timeout=120)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()
        self._reader.join(timeout=30)
        return self.proc.returncode, "".join(self.lines)

    def saw(self, pattern: str, times: int = 1) -> bool:
        return sum(pattern in line for line in list(self.lines)) >= times


def rows(path: Path) -> int:
    """Rows of ``signals`` flushed so far in a recording being written (0 while unreadable)."""
    try:
        with h5py.File(path, "r", swmr=True) as f:
            return int(f["signals"].shape[0])
    except (OSError, KeyError, ValueError, RuntimeError):
        return 0


def check_interrupted(code: int, err: str, sig: int, root: Path) -> None:
    """128 + signal (a SIGKILL ends the process itself); the interrupted line, one, names only
    files that exist; never a traceback."""
    assert "Traceback" not in err and "internal error" not in err, err[-3000:]
    if sig == signal.SIGKILL:
        assert code == -signal.SIGKILL, err[-3000:]
        return
    assert code == 128 + sig, err[-3000:]
    lines = [line for line in err.splitlines() if line.startswith("labtool: interrupted")]
    assert len(lines) == 1 and f"({signal.Signals(sig).name})" in lines[0], err[-3000:]
    for named in re.findall(re.escape(str(root)) + r"[^\s;,:()]*", lines[0]):
        assert Path(named).exists(), f"{named} is named but does not exist: {lines[0]}"


def no_short_complete_recording(path: Path, target: int) -> None:
    """A recording marked complete holds every sample asked for."""
    if not path.exists():
        return
    try:
        f = h5py.File(path, "r", swmr=True)
    except OSError:                  # created and killed before its first flush: not marked anything
        return
    with f:
        if bool(f.attrs.get("complete", False)):
            assert f["signals"].shape[0] == target, f"{path} is marked complete with {f['signals'].shape[0]} of {target} samples"


def no_hidden_files(folder: Path) -> None:
    left = [p for p in folder.rglob(".*") if p.name not in (".lock",)]
    assert left == [], left


# --- acquire -----------------------------------------------------------------------------------
ACQUIRE_S, ACQUIRE_ROWS = 3.0, 30000          # 10 kHz; flushed every 0.5 s: 5000 rows at a time


def _acquire(path: Path, fast: bool = False) -> list:
    return ["acquire", "--duration", str(ACQUIRE_S), "--seed", "5", "--status-every", "0", "-o", path,
            *(["--fast"] if fast else [])]


@pytest.fixture(scope="module")
def acquired(tmp_path_factory) -> np.ndarray:
    """The samples of an uninterrupted recording (the simulated stand gives the same paced or not)."""
    path = tmp_path_factory.mktemp("acquire") / "reference.h5"
    code, err = run(_acquire(path, fast=True))
    assert code == 0, err
    with h5py.File(path, "r") as f:
        return f["signals"][...]


ACQUIRE_MOMENTS = {"early": 1, "mid": ACQUIRE_ROWS // 2, "late": ACQUIRE_ROWS - 5000}


@pytest.mark.parametrize("sig, moment", CASES)
def test_an_interrupted_acquire_is_recorded_again_by_the_same_command(tmp_path, acquired, sig, moment):
    path = tmp_path / "rec.h5"
    code, err = Child(_acquire(path)).stop_when(lambda: rows(path) >= ACQUIRE_MOMENTS[moment], sig)
    check_interrupted(code, err, sig, tmp_path)
    no_short_complete_recording(path, ACQUIRE_ROWS)
    whole = False
    if sig != signal.SIGKILL:        # closed cleanly with what it holds, and says so
        with h5py.File(path, "r") as f:
            whole = bool(f.attrs["complete"])
            reason, n = f.attrs["stop_reason"], f["signals"].shape[0]
        if whole:                    # the signal came after the last sample: nothing is left to record
            assert n == ACQUIRE_ROWS and reason == "duration reached" and f"{path} is closed and complete" in err
        else:
            assert 0 < n < ACQUIRE_ROWS and reason.startswith("stopped by the user")
            assert "marked incomplete; the same command records it again" in err
    if not whole:
        code, err = run(_acquire(path))
        assert code == 0, err
        assert "recording over" in err and "unfinished recording" in err
    with h5py.File(path, "r") as f:
        assert f.attrs["complete"] and int(f.attrs["n_samples"]) == ACQUIRE_ROWS
        np.testing.assert_array_equal(f["signals"][...], acquired)
    no_hidden_files(tmp_path)


# --- campaign run -------------------------------------------------------------------------------
PLAN = """[campaign]
name = "interrupted"
[test]
test_id = "T-2"
operator = "tester"
[device]
seed = 3
pacing = "realtime"
[calibration]
files = ["{cal}"]
[defaults]
revolutions = 2
[[points]]
rpm = 180.0
[[points]]
rpm = 300.0
duration_s = 1.5
[compare]
models = ["kinematic"]
omega1 = ["const"]
"""
POINT_ROWS = {"01_180rpm": round(3.5 * 60 / 180 * 10000), "02_300rpm": 15000}


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """The plan (in real time: its recordings last 1.2 and 1.5 s) and its uninterrupted run."""
    d = tmp_path_factory.mktemp("campaign")
    plan = d / "plan.toml"
    plan.write_text(PLAN.format(cal=CAL))
    code, err = run(["campaign", "run", plan, "-o", d / "reference"], timeout=600)
    assert code == 0, err
    return plan, d / "reference"


@pytest.mark.parametrize("sig, moment", CASES)
def test_an_interrupted_campaign_resumes_without_redo(tmp_path, campaign, sig, moment):
    plan, reference = campaign
    out = tmp_path / "camp"
    first, second = (out / "points" / name / "recording.h5" for name in POINT_ROWS)
    child = Child(["campaign", "run", plan, "-o", out])
    ready = {"early": lambda: rows(first) >= 1,                        # recording point 1
             "mid": lambda: rows(second) >= 5000,                      # recording point 2
             "late": lambda: child.saw("process: done", 2)}[moment]    # comparing point 2
    code, err = child.stop_when(ready, sig)
    check_interrupted(code, err, sig, tmp_path)
    for name, target in POINT_ROWS.items():
        no_short_complete_recording(out / "points" / name / "recording.h5", target)
    res = subprocess.run(command(["campaign", "run", plan, "-o", out]), env=env(), capture_output=True, text=True,
                         timeout=600, preexec_fn=_prepare_child)
    assert res.returncode == 0, res.stderr
    assert "--redo" not in res.stderr and "2 of 2 points done" in res.stderr
    same_outputs(out, reference)
    for name in POINT_ROWS:
        assert "acquiring" not in json.loads((out / "points" / name / "point.json").read_text())
    no_hidden_files(out)


# --- doe run ------------------------------------------------------------------------------------
FACTORS = """factor,symbol,unit,level_1,level_2,level_3,level_4,level_5,level_6
A,Fu,N,0,20,40,65,80,100
B,j,mm,0.016,0.03,0.05,0.08,0.1,0.128
C,n1,rpm,180,200,240,260,280,300
D,Jt,-,1,1.5,2,2.5,3,4
"""
DOE_RUNS = 6 ** 4


def _doe(folder: Path) -> list:
    return ["doe", "run", "--model", "rigid", "--factors", folder.parent / "factors.csv", "--workers", "1",
            "--chunk-runs", "16", "-o", folder / "results.csv"]


@pytest.fixture(scope="module")
def design(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("doe")
    (d / "factors.csv").write_text(FACTORS)
    (d / "reference").mkdir()
    code, err = run(_doe(d / "reference"), timeout=600)
    assert code == 0, err
    return d


def _runs_in_parts(folder: Path) -> int:
    parts = folder / "results.csv.parts"
    try:
        names = [p.name for p in parts.iterdir()]
    except OSError:
        return -1
    return sum(int(b) - int(a) + 1 for a, b in (re.findall(r"\d{9,}", n) for n in names if n.startswith("items-")))


@pytest.mark.parametrize("sig, moment", CASES)
def test_an_interrupted_design_resumes_from_its_finished_chunks(tmp_path, design, sig, moment):
    out = design / f"{signal.Signals(sig).name}-{moment}"
    out.mkdir()
    ready = {"early": lambda: _runs_in_parts(out) == 0,                # the store is open, no run kept yet
             "mid": lambda: _runs_in_parts(out) >= 0.4 * DOE_RUNS,
             "late": lambda: _runs_in_parts(out) >= 0.9 * DOE_RUNS}[moment]
    code, err = Child(_doe(out)).stop_when(ready, sig)
    check_interrupted(code, err, sig, out)
    parts = out / "results.csv.parts"
    if sig != signal.SIGKILL and parts.exists():
        assert f"are finished and kept in {parts}; the same command resumes" in err
    assert not (out / "results.csv").exists()
    code, err = run(_doe(out), timeout=600)
    assert code == 0, err
    reference = design / "reference"
    assert (out / "results.csv").read_bytes() == (reference / "results.csv").read_bytes()
    a = xr.open_dataset(out / "results.nc", engine="h5netcdf").load()
    b = xr.open_dataset(reference / "results.nc", engine="h5netcdf").load()
    assert a.attrs.pop("history") == " ".join(map(str, ["labtool", *_doe(out)]))   # its own command line
    b.attrs.pop("history")
    xr.testing.assert_identical(a.drop_vars("wall_s"), b.drop_vars("wall_s"))
    assert not parts.exists() and sorted(p.name for p in out.iterdir()) == ["results.csv", "results.nc"]


# --- fit ----------------------------------------------------------------------------------------
def _fit(measured: Path, out: Path) -> list:
    return ["fit", measured, "--model", "rigid", "--free", "backlash", "--accuracy", "fast", "--revolutions", "4",
            "-o", out / "fit.json"]


def _fit_result(out: Path) -> dict:
    doc = json.loads((out / "fit.json").read_text())
    for key in ("wall_s", "model_time_s"):
        doc.pop(key)
    return doc


def _cpu_children() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _cpu_s(pid: int) -> float:
    """CPU time (s) process ``pid`` has used so far (Linux /proc; 0 once it is gone)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


@pytest.fixture(scope="module")
def fitted(tmp_path_factory, measured_nc) -> tuple[Path, dict, float]:
    """The measurement, an uninterrupted fit's result and the CPU time it took (s): the fit's own
    measure of how far a run has gone, whatever the machine's load (its progress lines come every
    few seconds of wall time, and a quick fit prints none)."""
    d = tmp_path_factory.mktemp("fit")
    cpu0 = _cpu_children()
    code, err = run(_fit(measured_nc, d), timeout=600)
    assert code == 0, err
    return measured_nc, _fit_result(d), _cpu_children() - cpu0


def _has_open(pid: int, path: Path) -> bool:
    """Whether process ``pid`` holds ``path`` open (Linux /proc)."""
    try:
        fds = os.listdir(f"/proc/{pid}/fd")
    except OSError:
        return False
    for fd in fds:
        try:
            if os.readlink(f"/proc/{pid}/fd/{fd}") == str(path):
                return True
        except OSError:
            pass
    return False


@pytest.mark.parametrize("sig, moment", CASES)
def test_an_interrupted_fit_is_redone_by_the_same_command(tmp_path, fitted, sig, moment):
    measured, result, cpu = fitted
    child = Child(_fit(measured, tmp_path))
    ready = {"early": lambda: _has_open(child.proc.pid, measured.resolve()),   # reading the measurement
             "mid": lambda: _cpu_s(child.proc.pid) >= 0.6 * cpu,                 # searching: 60 % of the work done
             "late": lambda: any(p.name.startswith(".fit.") for p in tmp_path.iterdir())}[moment]   # writing
    code, err = child.stop_when(ready, sig)
    check_interrupted(code, err, sig, tmp_path)
    assert not (tmp_path / "fit.json").exists() and not (tmp_path / "fit.png").exists()
    code, err = run(_fit(measured, tmp_path), timeout=600)
    assert code == 0, err
    assert _fit_result(tmp_path) == result
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fit.json", "fit.png"]
