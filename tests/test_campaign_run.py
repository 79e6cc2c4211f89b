"""campaign run: one folder per point, resumable; killed for real (SIGKILL) and rerun, the outputs
equal an uninterrupted run's; a second run on the same folder refused; the plan's changes seen."""
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest
import xarray as xr

from labtool.cli import main

ROOT = Path(__file__).resolve().parents[1]
CAL = ROOT / "sample_data" / "calibration.toml"


def quick_plan(tmp_path, pacing="fast", second_duration=None, models='["kinematic"]', name="plan.toml", extra=""):
    second = f"\nduration_s = {second_duration}" if second_duration else ""
    text = f"""[campaign]
name = "quick"
[test]
test_id = "T-1"
operator = "tester"
[device]
seed = 3
pacing = "{pacing}"
[calibration]
files = ["{CAL}"]
[defaults]
revolutions = 3
[[points]]
rpm = 180.0
[[points]]
rpm = 300.0{second}
[compare]
models = {models}
omega1 = ["const"]
{extra}"""
    p = tmp_path / name
    p.write_text(text)
    return p


def cli(*args, timeout=600):
    return subprocess.run([sys.executable, "-m", "labtool", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT)


def recorded_sha(folder: Path, point: str, step: str, name: str) -> str:
    doc = json.loads((folder / "points" / point / "point.json").read_text())
    return doc["steps"][step]["outputs"][name]


def same_outputs(a: Path, b: Path) -> None:
    """Two campaign folders hold the same results: the cross-point CSV and JSON byte for byte, each
    point's samples, measured variables and report summary (less wall times and paths)."""
    assert (a / "campaign.csv").read_bytes() == (b / "campaign.csv").read_bytes()
    assert (a / "campaign.json").read_bytes() == (b / "campaign.json").read_bytes()
    for pa in sorted((a / "points").iterdir()):
        pb = b / "points" / pa.name
        with h5py.File(pa / "recording.h5") as fa, h5py.File(pb / "recording.h5") as fb:
            np.testing.assert_array_equal(fa["signals"][...], fb["signals"][...])
        # time is CF 'seconds since <the recording's start>': the same seconds, another start stamp
        ma = xr.open_dataset(pa / "measured.nc", engine="h5netcdf", decode_times=False).load()
        mb = xr.open_dataset(pb / "measured.nc", engine="h5netcdf", decode_times=False).load()
        xr.testing.assert_identical(ma.drop_attrs(), mb.drop_attrs())
        ma.close(), mb.close()
        sa, sb = (json.loads((p / "summary.json").read_text()) for p in (pa, pb))
        for s in (sa, sb):
            s.pop("wall_s")
            s["measured"].pop("file")
            s["measured"].pop("processing_history")
            for sim in s["simulations"]:
                sim.pop("wall_s")
        assert sa == sb


@pytest.mark.slow
def test_a_campaign_runs_every_point_and_a_rerun_keeps_them(tmp_path, capsys):
    # a limit no measurement meets (a noisy recording is never within 1e-6 of a model): the
    # campaign runs through every point, writes everything and exits 1
    (tmp_path / "limits.toml").write_text("[omega2]\nnrmse = { max = 1e-6 }\n[epsilon2]\nnrmse = { max = 10.0 }\n")
    plan = quick_plan(tmp_path, extra='thresholds = "limits.toml"\n')
    out = tmp_path / "camp"
    code = main(["campaign", "run", str(plan), "-o", str(out)])
    err = capsys.readouterr().err
    doc = json.loads((out / "campaign.json").read_text())
    assert code == 1 and doc["passed"] is False and "threshold checks failed at 2 point(s)" in err
    assert all(len(p["thresholds"]["rows"]) == 2 for p in doc["points"])
    assert "Threshold checks FAILED at" in (out / "campaign.html").read_text()
    assert "[1/2] 01_180rpm" in err and "[2/2] 02_300rpm" in err and "2 of 2 points done" in err
    for name in ("01_180rpm", "02_300rpm"):
        f = out / "points" / name
        assert {p.name for p in f.iterdir()} == {"recording.h5", "measured.nc", "report.html", "summary.json",
                                                 "cycles.nc", "point.json"}
        with h5py.File(f / "recording.h5") as h:
            assert h.attrs["complete"] and h.attrs["test_id"] == "T-1" and h.attrs["campaign_point"] == name
        m = xr.open_dataset(f / "measured.nc", engine="h5netcdf")
        assert "calibration.toml" in m.attrs["ka_source_aE_t"]
        m.close()
    table = pd.read_csv(out / "campaign.csv")
    assert list(table["point"]) == ["01_180rpm", "02_300rpm"] and list(table["rpm"]) == [180, 300]
    assert table["omega2_iso_rating"].between(0, 1).all() and table["closest"].all()
    assert doc["format"] == "labtool.campaign.summary" and [p["name"] for p in doc["points"]] == ["01_180rpm", "02_300rpm"]
    assert doc["test"]["test_id"] == "T-1" and doc["points"][0]["page"] == "points/01_180rpm/report.html"
    # rerun: nothing is redone, the files are untouched
    mtimes = {p: p.stat().st_mtime_ns for p in (out / "points").rglob("*") if p.is_file()}
    assert main(["campaign", "run", str(plan), "-o", str(out)]) == code
    err = capsys.readouterr().err
    assert err.count("finished earlier, kept") == 2 and "0 point(s) worked on, 2 kept" in err
    assert {p: p.stat().st_mtime_ns for p in (out / "points").rglob("*") if p.is_file()} == mtimes


@pytest.mark.slow
def test_changing_the_plan_redoes_what_depends_on_it_and_refuses_to_drop_a_recording(tmp_path, capsys):
    plan = quick_plan(tmp_path)
    out = tmp_path / "camp"
    assert main(["campaign", "run", str(plan), "-o", str(out), "--no-report"]) == 0
    rec = recorded_sha(out, "01_180rpm", "acquire", "recording.h5")
    # other models: only the compare step is redone
    plan2 = quick_plan(tmp_path, models='["kinematic", "rigid"]', name="plan2.toml")
    capsys.readouterr()
    assert main(["campaign", "run", str(plan2), "-o", str(out), "--no-report"]) == 0
    err = capsys.readouterr().err
    assert err.count("compare: done") == 2 and "acquire: done" not in err and "process: done" not in err
    assert recorded_sha(out, "01_180rpm", "acquire", "recording.h5") == rec
    assert len(json.loads((out / "points" / "01_180rpm" / "summary.json").read_text())["headline"]) == 2
    # another duration for point 2: its recording is not thrown away without --redo
    plan3 = quick_plan(tmp_path, second_duration=1.5, name="plan3.toml")
    assert main(["campaign", "run", str(plan3), "-o", str(out)]) == 2
    line = capsys.readouterr().err.strip().splitlines()
    assert len(line) == 1 and "02_300rpm" in line[0] and "duration_s" in line[0] and "--redo 02_300rpm" in line[0]
    assert main(["campaign", "run", str(plan3), "-o", str(out), "--redo", "02_300rpm", "--no-report"]) == 0
    err = capsys.readouterr().err
    assert "[2/2] 02_300rpm finished in" in err and "[1/2] 01_180rpm finished earlier" not in err.replace(
        "01_180rpm process", "")
    with h5py.File(out / "points" / "02_300rpm" / "recording.h5") as h:
        assert h["signals"].shape[0] == 15000
    assert main(["campaign", "run", str(plan3), "-o", str(out), "--redo", "nope"]) == 2
    assert "no such point" in capsys.readouterr().err


def _run_and_kill(plan, out, when: str) -> subprocess.CompletedProcess:
    """Start 'campaign run', SIGKILL it once its stderr shows ``when`` for the second point."""
    proc = subprocess.Popen([sys.executable, "-m", "labtool", "campaign", "run", str(plan), "-o", str(out)],
                            stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, cwd=ROOT)
    lines = []
    timer = threading.Timer(300, proc.kill)
    timer.start()
    try:
        second = False
        for line in proc.stderr:
            lines.append(line)
            second = second or line.startswith("[2/2]")
            if second and when in line:
                time.sleep(0.4 if when.startswith("[2/2]") else 0.0)
                os.kill(proc.pid, signal.SIGKILL)
                break
        proc.wait(timeout=60)
    finally:
        timer.cancel()
    assert proc.returncode == -signal.SIGKILL, "".join(lines)
    return lines


@pytest.fixture(scope="module")
def realtime(tmp_path_factory):
    """A plan paced in real time (the second point records 3 s of wall time) and its uninterrupted run."""
    d = tmp_path_factory.mktemp("realtime")
    plan = quick_plan(d, pacing="realtime", second_duration=3.0)
    res = cli("campaign", "run", plan, "-o", d / "uninterrupted")
    assert res.returncode == 0, res.stderr
    return plan, d / "uninterrupted"


@pytest.mark.slow
@pytest.mark.hostile("interrupted")
@pytest.mark.parametrize("when", ["[2/2]", "acquire: done"])
def test_a_campaign_killed_in_its_second_point_resumes_without_redoing_the_first(tmp_path, when, realtime):
    # realtime pacing: the second point's acquisition lasts 3 s of wall time, long enough to be
    # killed in the middle of it ("[2/2]"), or right after it ("acquire: done": in its processing)
    plan, ref = realtime
    out = tmp_path / "killed"
    _run_and_kill(plan, out, when)
    first = out / "points" / "01_180rpm"
    state = json.loads((first / "point.json").read_text())
    assert set(state["steps"]) == {"acquire", "process", "compare"}
    kept = {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in first.iterdir()}
    second = json.loads((out / "points" / "02_300rpm" / "point.json").read_text())["steps"] \
        if (out / "points" / "02_300rpm" / "point.json").exists() else {}
    assert "compare" not in second
    if when == "[2/2]":
        assert second == {}
        with h5py.File(out / "points" / "02_300rpm" / "recording.h5", "r", swmr=True) as h:
            assert not h.attrs["complete"]   # killed while recording
    res = cli("campaign", "run", plan, "-o", out)
    assert res.returncode == 0, res.stderr
    assert "[1/2] 01_180rpm finished earlier, kept" in res.stderr
    assert "[2/2] 02_300rpm finished in" in res.stderr
    if when == "[2/2]":
        assert "did not finish" in res.stderr and "acquire: done" in res.stderr
    else:
        assert "acquire: done" not in res.stderr and "process: done" in res.stderr
    assert {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in first.iterdir()} == kept
    assert not list(out.rglob(".*.part"))
    # the same plan run without a kill gives the same results
    same_outputs(out, ref)


@pytest.mark.slow
@pytest.mark.hostile("concurrency")
def test_a_second_run_on_the_same_folder_is_refused_while_the_first_works(tmp_path, realtime):
    plan, _ = realtime
    out = tmp_path / "camp"
    proc = subprocess.Popen([sys.executable, "-m", "labtool", "campaign", "run", str(plan), "-o", str(out)],
                            stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, cwd=ROOT)
    try:
        for line in proc.stderr:
            if line.startswith("[1/2]"):
                break
        second = cli("campaign", "run", plan, "-o", out)
        assert second.returncode == 2
        err = second.stderr.strip().splitlines()
        assert len(err) == 1 and "being run by another" in err[0] and f"pid {proc.pid}" in err[0]
        proc.stderr.read()
        assert proc.wait(timeout=600) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
    assert (out / "campaign.csv").exists()
    assert cli("campaign", "run", plan, "-o", out).returncode == 0     # the lock was released


@pytest.mark.slow
@pytest.mark.hostile("interrupted")
def test_a_failing_point_stops_the_campaign_with_one_line_and_keeps_the_finished(tmp_path, capsys, monkeypatch):
    from labtool.campaign import steps

    plan = quick_plan(tmp_path)
    out = tmp_path / "camp"
    real = steps.process

    def broken(plan_, point, *a, **k):
        if point.name == "02_300rpm":
            from labtool.common.errors import InputError
            raise InputError("simulated processing failure")
        return real(plan_, point, *a, **k)
    monkeypatch.setattr(steps, "process", broken)
    assert main(["campaign", "run", str(plan), "-o", str(out)]) == 2
    err = [x for x in capsys.readouterr().err.strip().splitlines() if x.startswith("labtool: error")]
    assert err == ["labtool: error: point 02_300rpm (process): simulated processing failure"]
    assert json.loads((out / "points" / "01_180rpm" / "point.json").read_text())["steps"].keys() == \
        {"acquire", "process", "compare"}
    monkeypatch.setattr(steps, "process", real)
    assert main(["campaign", "run", str(plan), "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "acquire: done" not in err and err.count("process: done") == 1


@pytest.mark.slow
@pytest.mark.hostile("full_disk")
def test_a_full_disk_stops_before_the_step_that_does_not_fit_and_resumes(tmp_path, small_disk):
    disk = small_disk(1000)
    plan = tmp_path / "plan.toml"
    plan.write_text(f'[calibration]\nfiles = ["{CAL}"]\n[defaults]\nrevolutions = 3\n[[points]]\nrpm = 180.0\n'
                    '[compare]\nmodels = ["kinematic"]\nomega1 = ["const"]\n')
    out = disk / "camp"
    res = cli("campaign", "run", plan, "-o", out)
    assert res.returncode == 2, res.stderr
    err = [x for x in res.stderr.strip().splitlines() if x.startswith("labtool: error")]
    assert len(err) == 1 and "(process)" in err[0] and "MB free" in err[0] and "kept" in err[0]
    state = json.loads((out / "points" / "01_180rpm" / "point.json").read_text())
    assert list(state["steps"]) == ["acquire"] and not list(out.rglob(".*.part"))
    # more room: the rerun keeps the recording and goes on
    subprocess.run(["mount", "-o", "remount,size=16m", str(disk)], check=True)
    res = cli("campaign", "run", plan, "-o", out)
    assert res.returncode == 0, res.stderr
    assert "acquire: done" not in res.stderr and "process: done" in res.stderr
    assert (out / "campaign.csv").exists()


@pytest.mark.slow
@pytest.mark.hostile("interrupted")
def test_a_run_stopped_between_a_recording_and_its_record_keeps_the_recording(tmp_path, capsys, monkeypatch):
    """A stop in the instant between the recording's end and its record in point.json left a
    complete recording that point.json did not record: the rerun stopped and asked for --redo. The
    record of the acquisition under way (its token, also in the recording) lets the rerun keep it."""
    from labtool.campaign.state import PointState

    plan = quick_plan(tmp_path)
    out = tmp_path / "camp"
    real = PointState.record

    def stopped(self, step, inputs, info):
        if step == "acquire" and self.name == "02_300rpm":
            raise KeyboardInterrupt          # after the recording closed, before its record
        return real(self, step, inputs, info)
    monkeypatch.setattr(PointState, "record", stopped)
    assert main(["campaign", "run", str(plan), "-o", str(out), "--no-report"]) == 130
    assert "camp keeps the finished points and steps; the same command resumes" in capsys.readouterr().err
    rec = out / "points" / "02_300rpm" / "recording.h5"
    with h5py.File(rec) as h:
        assert h.attrs["complete"] and len(h.attrs["campaign_acquisition"]) == 16
    before = rec.read_bytes()
    monkeypatch.setattr(PointState, "record", real)
    assert main(["campaign", "run", str(plan), "-o", str(out), "--no-report"]) == 0
    err = capsys.readouterr().err
    assert "its recording had finished when the run was stopped; kept" in err and "--redo" not in err
    assert rec.read_bytes() == before and err.count("process: done") == 1
    state = json.loads((out / "points" / "02_300rpm" / "point.json").read_text())
    assert "acquiring" not in state and set(state["steps"]) == {"acquire", "process", "compare"}
