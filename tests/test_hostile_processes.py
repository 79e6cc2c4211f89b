"""Hostile processes: requests that ran for minutes, signals in the middle of a write,
and two labtool processes on one file. All in real child processes."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest
import xarray as xr

from hostile import REPORT_FAST, hidden, measured_nc, one_error_line, run, start, wait_for  # noqa: F401

# real child processes, tmpfs mounts and kills: seconds each (make test runs them)
pytestmark = pytest.mark.slow


# --- hang ------------------------------------------------------------------------------------
@pytest.mark.hostile("hang")
@pytest.mark.parametrize("args, fragment", [
    (["kinematics", "--points", "100000000"], "--points 100000000 would take about"),
    (["simulate", "--revolutions", "1e7", "--full-cycle"], "--revolutions 1e+07 would take about"),
    (["simulate", "--revolutions", "1e7", "--model", "rigid"], "--revolutions 1e+07 would take about"),
])
def test_huge_requests_are_estimated_and_refused_at_once(args, fragment):
    t0 = time.monotonic()
    code, err = run(args, timeout=90)
    msg = one_error_line(code, err)
    assert fragment in msg and "memory" in msg and "per " in msg, msg
    assert time.monotonic() - t0 < 90


@pytest.mark.hostile("hang")
def test_a_report_over_a_million_revolutions_is_refused_at_once(tmp_path, measured_nc):
    code, err = run(["report", measured_nc, "-o", tmp_path / "r.html", "--revolutions", "1000000"], timeout=120)
    msg = one_error_line(code, err)
    assert "--revolutions 1000000 would take about" in msg and "per revolution" in msg
    assert list(tmp_path.iterdir()) == []


@pytest.mark.hostile("hang")
def test_a_request_over_the_time_limit_says_how_to_run_it():
    code, err = run(["kinematics", "--points", "2000000", "--max-seconds", "0.5"], timeout=90)
    msg = one_error_line(code, err)
    assert "over the limit of 0.5 s: give --max-seconds" in msg and "or use fewer --points" in msg


@pytest.mark.hostile("hang")
def test_a_pipe_given_as_a_toml_file(tmp_path):
    fifo = tmp_path / "mech.toml"
    os.mkfifo(fifo)
    code, err = run(["kinematics", "--mechanism", fifo], timeout=60)
    assert "not a regular file" in one_error_line(code, err)


# --- interrupted -----------------------------------------------------------------------------
def _report(m, out, force=False):
    return ["report", m, "-o", out / "r.html", "--pdf", out / "r.pdf", "--json", out / "r.json",
            *REPORT_FAST, *(["--force"] if force else [])]


def _interrupt_while_writing(args, folder, sig):
    """Start ``args``, send ``sig`` once a temporary appears in ``folder``; (exit code, stderr)."""
    proc = start(args)
    try:
        seen = wait_for(lambda: any(".part" in n for n in hidden(folder)) or proc.poll() is not None, timeout=180)
        assert seen and proc.poll() is None, "the command ended before it wrote anything"
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    return proc.returncode, err.decode("utf-8", "replace")


@pytest.mark.hostile("interrupted")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP])
def test_a_signal_while_the_report_is_written_leaves_nothing(tmp_path, measured_nc, sig):
    """report left the HTML without its PDF/JSON; temporaries stayed as .NAME.xxxx.part."""
    code, err = _interrupt_while_writing(_report(measured_nc, tmp_path), tmp_path, sig)
    assert code == 128 + sig, err[-2000:]
    assert "labtool: interrupted" in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.hostile("interrupted")
def test_an_interrupted_force_keeps_the_previous_set(tmp_path, measured_nc):
    for name in ("r.html", "r.pdf", "r.json"):
        (tmp_path / name).write_text(f"previous {name}")
    code, err = _interrupt_while_writing(_report(measured_nc, tmp_path, force=True), tmp_path, signal.SIGTERM)
    assert code == 128 + signal.SIGTERM, err[-2000:]
    for name in ("r.html", "r.pdf", "r.json"):
        assert (tmp_path / name).read_text() == f"previous {name}"
    assert hidden(tmp_path) == []


@pytest.mark.hostile("interrupted")
def test_what_a_sigkill_leaves_is_removed_by_the_next_run(tmp_path, measured_nc):
    code, _ = _interrupt_while_writing(_report(measured_nc, tmp_path), tmp_path, signal.SIGKILL)
    assert code == -signal.SIGKILL
    assert not (tmp_path / "r.html").exists()          # no final name half-written
    code, err = run(_report(measured_nc, tmp_path))
    assert code in (0, 1), err
    assert hidden(tmp_path) == [] and sorted(p.name for p in tmp_path.iterdir()) == \
        ["r.html", "r.json", "r.pdf", "r_curves.csv", "r_curves.nc"]


def _staged(tmp_path, suffix: str) -> bool:
    stages = list(tmp_path.glob(".demo.*.part"))
    return bool(stages) and any(p.suffix == suffix for p in stages[0].iterdir())


@pytest.mark.hostile("interrupted")
@pytest.mark.slow
@pytest.mark.parametrize("during,suffix", [("kinematics", ".nc"), ("acquire", ".h5")])
def test_an_interrupted_demo_leaves_its_folder_as_it_was(tmp_path, during, suffix):
    """SIGTERM once the first file of a step is staged; during the acquire step the recording's
    own stop must not swallow it (found by CI: the demo went on and exited 0)."""
    out = tmp_path / "demo"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    proc = start(["demo", "-o", out])
    try:
        assert wait_for(lambda: _staged(tmp_path, suffix), timeout=300)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 128 + signal.SIGTERM, err[-2000:]
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"] and hidden(tmp_path) == []


# --- concurrency -----------------------------------------------------------------------------
@pytest.mark.hostile("concurrency")
def test_two_processes_writing_one_output_at_once(tmp_path):
    """Both finish; the file is one whole NetCDF (never a mix or a truncation); no temporaries."""
    out = tmp_path / "k.nc"
    for _ in range(2):
        procs = [start(["kinematics", "--points", "20000", "-o", out, "--force", "--rpm", rpm]) for rpm in ("180", "300")]
        results = [p.communicate(timeout=240) for p in procs]
        assert [p.returncode for p in procs] == [0, 0], [r[1][-1000:] for r in results]
        ds = xr.open_dataset(out, engine="h5netcdf")
        assert ds.sizes["phi1"] == 20000 and float(ds.attrs["cam_speed_rpm"]) in (180.0, 300.0)
        ds.close()
        assert hidden(tmp_path) == []


@pytest.mark.hostile("concurrency")
def test_a_reader_never_sees_a_partial_output(tmp_path):
    """A second process opens the output in a loop while labtool replaces it four times."""
    out, stop = tmp_path / "s.nc", tmp_path / "stop"
    code, err = run(["simulate", "--model", "kinematic", "-o", out])
    assert code == 0, err
    reader_code = ("import os, sys, xarray as xr\n"
                   "n = bad = 0\n"
                   "while not os.path.exists(sys.argv[2]) or n == 0:\n"
                   "    try:\n"
                   "        with xr.open_dataset(sys.argv[1], engine='h5netcdf') as ds:\n"
                   "            float(ds['omega2'].values.sum()); n += 1\n"
                   "    except Exception as exc:\n"
                   "        bad += 1; print(type(exc).__name__, exc, file=sys.stderr)\n"
                   "print(n, bad)\n")
    reader = subprocess.Popen([sys.executable, "-c", reader_code, str(out), str(stop)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        for rpm in ("200", "250", "300", "350"):
            code, err = run(["simulate", "--model", "kinematic", "--rpm", rpm, "-o", out, "--force"])
            assert code == 0, err
    finally:
        stop.write_text("")
        stdout, stderr = reader.communicate(timeout=120)
    n, bad = map(int, stdout.split())
    assert bad == 0 and n > 0, stderr.decode()[-2000:]
    assert hidden(tmp_path) == []


@pytest.mark.hostile("concurrency")
def test_two_reports_on_one_set_at_once(tmp_path, measured_nc):
    """The second starts while the first is writing: neither removes the other's temporaries,
    both finish, and the set on disk is whole (HTML, a PDF, JSON that parses)."""
    import json

    first = start(_report(measured_nc, tmp_path, force=True))
    try:
        assert wait_for(lambda: any(".part" in n for n in hidden(tmp_path)) or first.poll() is not None, timeout=180)
        second = start(_report(measured_nc, tmp_path, force=True))
        outs = [p.communicate(timeout=300) for p in (first, second)]
    finally:
        for p in (first,):
            if p.poll() is None:
                p.kill()
    assert [first.returncode, second.returncode] in ([0, 0], [1, 1]), [o[1][-1500:] for o in outs]
    assert (tmp_path / "r.pdf").read_bytes().startswith(b"%PDF")
    assert json.loads((tmp_path / "r.json").read_text())["headline"]
    assert (tmp_path / "r.html").read_text().rstrip().endswith("</html>")
    assert hidden(tmp_path) == []


@pytest.mark.hostile("concurrency")
@pytest.mark.slow
def test_two_demos_into_one_folder_at_once(tmp_path):
    """Each demo builds in its own staging folder: the second never reads the first one's
    half-written recording, both finish, and the folder holds one whole set."""
    import json

    out = tmp_path / "demo"
    procs = [start(["demo", "-o", out]) for _ in range(2)]
    results = [p.communicate(timeout=900) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [r[1][-1500:] for r in results]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["measured"]["source"] == "recording" and summary["headline"]
    ds = xr.open_dataset(out / "measured_180rpm.nc", engine="h5netcdf")
    assert ds.sizes["time"] > 0
    ds.close()
    assert hidden(tmp_path) == [] and hidden(out) == []
