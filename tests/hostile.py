"""Helpers of the hostile-input suite (tests/test_hostile_*.py).

``cli`` runs labtool in this process (fast; a traceback fails the test), ``run`` in a real child
process (a segfault, a hang, a signal or a second process are real there). Both return the exit
code and stderr; ``one_error_line`` asserts docs/architecture.md's contract for user errors: exit 2 and exactly
one line ``labtool: error: ...`` on stderr.
"""
from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]          # the checkout under test (its own labtool)
SAMPLE = ROOT / "sample_data"
MECHANISM = ROOT / "models" / "data" / "stb216.toml"
REFERENCE = Path("/work/shared/reference") if Path("/work/shared/reference").is_dir() else ROOT / "reference"


def cli(args: list, capsys) -> tuple[int, str]:
    """labtool in-process: (exit code, stderr)."""
    from labtool.cli import main

    capsys.readouterr()
    code = main([os.fsdecode(a) for a in args])
    return code, capsys.readouterr().err


def env() -> dict:
    e = dict(os.environ, PYTHONPATH=str(ROOT), COLUMNS="200", MPLBACKEND="Agg", LC_ALL="C.UTF-8")
    e.pop("LABTOOL_DEBUG", None)
    return e


def command(args: list) -> list:
    return [sys.executable, "-m", "labtool", *[os.fsdecode(a) for a in args]]


CHILD_MEMORY = 8 << 30     # address-space limit of every child: a runaway request fails, the machine stays


def default_signals():
    """In a child before exec: SIGINT, SIGHUP and SIGTERM back to their default actions. An ignored
    signal is inherited across exec, and labtool rightly keeps it ignored (``nohup labtool ...``);
    a suite started under nohup or as a background job of a script (SIGINT ignored) would
    otherwise send its test signals to children that ignore them."""
    for sig in (signal.SIGINT, signal.SIGHUP, signal.SIGTERM):
        signal.signal(sig, signal.SIG_DFL)


def _prepare_child():
    """preexec_fn of every labtool child: default signal actions and the CHILD_MEMORY limit."""
    default_signals()
    resource.setrlimit(resource.RLIMIT_AS, (CHILD_MEMORY, CHILD_MEMORY))


def run(args: list, cwd=None, timeout: float = 240) -> tuple[int, str]:
    """labtool in a child process: (exit code, stderr); a timeout is a test failure (a hang)."""
    proc = subprocess.run(command(args), cwd=cwd, env=env(), capture_output=True, timeout=timeout,
                          preexec_fn=_prepare_child)
    return proc.returncode, proc.stderr.decode("utf-8", "replace")


def start(args: list, cwd=None) -> subprocess.Popen:
    return subprocess.Popen(command(args), cwd=cwd, env=env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            preexec_fn=_prepare_child)


def one_error_line(code: int, err: str) -> str:
    """The ``labtool: error:`` line that ends a user error (exit 2); fails otherwise. Progress
    lines before it are allowed (``report: drawing the figures (3 s)``), a traceback is not."""
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, f"exit {code}, stderr: {err[-2000:]}"
    assert lines and lines[-1].startswith("labtool: error: "), f"stderr: {err[-2000:]}"
    assert sum(line.startswith("labtool: error: ") for line in lines) == 1, f"stderr: {err[-2000:]}"
    assert not any(line.startswith(("Traceback", "HDF5-DIAG", "  File ")) for line in lines), err[-2000:]
    return lines[-1]


def wait_for(predicate, timeout: float = 120.0, every: float = 0.005) -> bool:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if predicate():
            return True
        time.sleep(every)
    return False


def hidden(folder: Path) -> list[str]:
    """Names of hidden entries (temporaries, staging folders) in ``folder``."""
    return sorted(p.name for p in Path(folder).iterdir() if p.name.startswith("."))


@pytest.fixture(scope="session")
def measured_nc(tmp_path_factory) -> Path:
    """A measured.nc processed from the sample recording, once per session (import it to use it)."""
    path = tmp_path_factory.mktemp("hostile") / "measured.nc"
    code, err = run(["process", SAMPLE / "run_180rpm.h5", "-o", path])
    assert code == 0, err
    return path


REPORT_FAST = ["--models", "kinematic", "--omega1", "const"]
