"""``labtool warmup`` compiles what the commands run, and a command about to compile says so first
(labtool.warmup)."""
import json
import os
import subprocess
import sys

import pytest

from labtool import warmup
from labtool.models.dynamics import compiling

LABTOOL = [sys.executable, "-m", "labtool"]


@pytest.mark.parametrize("args,expected", [
    (["simulate", "--model", "elastic"], ["the elastic model"]),
    (["simulate"], ["the rigid model"]),                                   # auto starts with the rigid model
    (["simulate", "--model=kinematic"], []),
    (["report", "m.nc"], ["the rigid model", "the elastic model", "the processing kernels", "the report's metrics"]),
    (["report", "m.nc", "--models", "elastic"], ["the elastic model", "the processing kernels", "the report's metrics"]),
    (["process", "r.h5", "-o", "m.nc"], ["the processing kernels"]),
    (["acquire", "--device", "sim", "-o", "r.h5"], ["the stand's twin"]),
    (["acquire", "--device", "nidaqmx:Dev1/ai0", "-o", "r.h5"], []),
    (["doe", "run", "--model", "elastic", "-o", "r.csv"], ["the elastic model"]),
    (["doe", "analyze", "r.csv"], []),
    (["simulate", "--model", "elastic", "--help"], []),
    (["kinematics"], []),
    ([], []),
])
def test_what_a_command_line_will_compile(args, expected):
    assert warmup.needs(args) == expected


def test_every_step_of_the_warmup_is_one_of_the_probed_things_and_runs_in_a_folder():
    assert [step.what for step in warmup.STEPS] == list(warmup.PROBES)
    assert all(callable(step.run) for step in warmup.STEPS)


def test_a_command_about_to_compile_says_so_before_it_starts(monkeypatch, capsys):
    monkeypatch.setitem(compiling._state, "quiet", 0)
    monkeypatch.setitem(compiling._state, "announced", set())
    cached = {"the rigid model"}
    monkeypatch.setattr(warmup, "missing", lambda whats: [w for w in whats if w not in cached])
    warmup.announce_for(["report", "m.nc"])
    warmup.announce_for(["simulate", "--model", "elastic"])        # announced already: once a process
    about = compiling.estimate_text("the elastic model", "the processing kernels", "the report's metrics")
    assert about.startswith("about ") and about.endswith(" s")
    assert capsys.readouterr().err.splitlines() == [
        "labtool: compiling the elastic model, the processing kernels and the report's metrics for this machine "
        f"({about}, once: later runs load them from numba's cache)"]
    cached.update(warmup.PROBES)
    monkeypatch.setitem(compiling._state, "announced", set())
    warmup.announce_for(["report", "m.nc"])                        # all in the cache: nothing said
    assert capsys.readouterr().err == ""


@pytest.mark.slow
def test_warmup_from_an_empty_cache_leaves_nothing_for_the_commands_to_compile(tmp_path):
    """The install step's promise: after ``labtool warmup`` into an empty cache, the commands of the
    demo (the simulated stand, processing, report) and both models compile nothing; a second
    warmup finds everything in the cache."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), LABTOOL_COMPILE_NOTICES="1")

    def run(*args):
        proc = subprocess.run(LABTOOL + list(args), cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=1800)
        assert proc.returncode == 0, proc.stderr[-2000:]
        return proc

    first = run("warmup")
    assert [line.split(":")[0] for line in first.stdout.splitlines()[:5]] == list(warmup.PROBES)
    assert all("compiled" in line for line in first.stdout.splitlines()[:5])
    again = run("warmup")
    assert all("in the cache already" in line for line in again.stdout.splitlines()[:5]), again.stdout
    run("acquire", "--device", "sim", "--duration", "2", "--fast", "-o", "r.h5")
    for args in (["process", "r.h5", "-o", "m.nc"], ["report", "m.nc", "-o", "r.html"],
                 ["simulate", "--model", "elastic", "--json"], ["simulate", "--model", "rigid", "--json"]):
        proc = run(*args)
        assert "labtool: compiling" not in proc.stderr, (args, proc.stderr)
    assert json.loads(run("simulate", "--model", "elastic", "--json").stdout)["model"] == "elastic"
