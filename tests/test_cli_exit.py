"""The console command skips the interpreter's teardown only when nothing is left to finish
(labtool.cli._exit_without_teardown): the atexit handlers run, open files are flushed, the output
is complete, the exit code is the command's; a thread still working, or an HDF5 file still open,
gets the normal exit. Each case is a new interpreter started the way the console script starts."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import h5py
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _console(before: str, args: list[str]) -> subprocess.CompletedProcess:
    """Run ``before``, then labtool's console entry point with ``args``."""
    code = textwrap.dedent(before) + textwrap.dedent(f"""
        import sys
        import labtool.cli
        real = labtool.cli._exit_without_teardown
        def spy(code):
            print("fast exit tried", file=sys.stderr)
            real(code)                                  # returns only when the normal exit is kept
            print("normal exit", file=sys.stderr)
            globals().get("after_normal_exit_kept", lambda: None)()
        labtool.cli._exit_without_teardown = spy
        sys.argv = ["labtool", *{args!r}]
        labtool.cli.main()
        """)
    return subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)


@pytest.mark.slow
def test_atexit_handlers_run_and_open_files_are_flushed(tmp_path):
    before = f"""
        import atexit
        out = {str(tmp_path)!r}
        atexit.register(lambda: open(out + "/atexit.txt", "w").write("ran"))
        held = open(out + "/held.txt", "w")          # open, referenced, never closed by anyone
        held.write("x" * 100)                        # still in the file object's buffer
        """
    proc = _console(before, ["--help"])
    assert proc.returncode == 0, proc.stderr
    assert "fast exit tried" in proc.stderr and "normal exit" not in proc.stderr     # the fast exit was taken
    assert "kinematics" in proc.stdout and "campaign" in proc.stdout          # the whole help, flushed
    assert (tmp_path / "atexit.txt").read_text() == "ran"
    assert (tmp_path / "held.txt").read_text() == "x" * 100


@pytest.mark.slow
def test_the_exit_code_is_the_commands():
    proc = _console("", ["kinematics", "--law", "parabolic"])
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines()[0].startswith("labtool: error: unknown motion law 'parabolic'")
    assert "fast exit tried" in proc.stderr and "normal exit" not in proc.stderr


@pytest.mark.slow
def test_a_working_thread_gets_the_normal_exit(tmp_path):
    # The thread works until the exit has been decided, however slow the machine: a fixed sleep
    # could end before the command does, and then the fast exit would be right.
    before = f"""
        import threading
        decided = threading.Event()
        after_normal_exit_kept = decided.set
        def work():
            decided.wait(timeout=60)
            open({str(tmp_path / "thread.txt")!r}, "w").write("done")
        threading.Thread(target=work).start()       # not a daemon: the normal exit waits for it
        """
    proc = _console(before, ["--help"])
    assert proc.returncode == 0, proc.stderr
    assert "normal exit" in proc.stderr
    assert (tmp_path / "thread.txt").read_text() == "done"


@pytest.mark.slow
def test_an_open_hdf5_file_gets_the_normal_exit(tmp_path):
    path = tmp_path / "open.h5"
    before = f"""
        import h5py, numpy as np
        f = h5py.File({str(path)!r}, "w")             # left open: HDF5 closes it at its own exit
        f["x"] = np.arange(1000.0)
        """
    proc = _console(before, ["--help"])
    assert proc.returncode == 0, proc.stderr
    assert "normal exit" in proc.stderr
    with h5py.File(path, "r") as f:
        assert np.array_equal(f["x"][()], np.arange(1000.0))


@pytest.mark.slow
@pytest.mark.hostile("interrupted")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "Ctrl-C"])
def test_a_signal_dropped_in_a_weakref_callback_still_ends_the_command(tmp_path, sig):
    """A signal's exception (Interrupted, KeyboardInterrupt) raised inside a garbage-collector
    callback is printed by Python ("Exception ignored in ...") and dropped: without labtool keeping
    the signal, the command would run on, write its outputs and exit 0. The handler keeps it: the
    next commit refuses to publish, and the command ends 128 + signal, quietly."""
    out = tmp_path / "kin.nc"
    code = f"""
        import os, signal, sys, weakref
        import labtool.common.files as files
        real_commit = files.OutputSet.commit
        def commit(self):
            class Thing: pass
            t = Thing()
            weakref.finalize(t, os.kill, os.getpid(), {int(sig)})
            del t                                  # the signal arrives inside the finalizer
            return real_commit(self)
        files.OutputSet.commit = commit
        sys.argv = ["labtool", "kinematics", "--points", "200", "-o", {str(out)!r}]
        import labtool.cli
        labtool.cli.main()
        """
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          cwd=ROOT, timeout=300, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.returncode == 128 + sig, proc.stderr[-2000:]
    assert f"interrupted ({signal.Signals(sig).name})" in proc.stderr and not out.exists()
    assert "Traceback" not in proc.stderr and "Exception ignored" not in proc.stderr, proc.stderr


@pytest.mark.slow
def test_a_sigterm_dropped_in_a_step_after_its_commit_ends_the_command_that_runs_it(tmp_path):
    # CI found it: in labtool demo's acquire step the signal was dropped after the step's last
    # commit; the step ended 143 by itself and the demo reported "demo step 'acquire' failed",
    # exit 2. A step inside another command raises instead, as an Interrupted it catches does.
    out = tmp_path / "kin.nc"
    code = f"""
        import os, signal, sys, weakref
        import labtool.common.files as files
        real_commit = files.OutputSet.commit
        def commit(self):
            real_commit(self)
            class Thing: pass
            t = Thing()
            weakref.finalize(t, os.kill, os.getpid(), signal.SIGTERM)
            del t                                  # the signal arrives inside the finalizer
        files.OutputSet.commit = commit
        import labtool.cli
        with files.command_scope(), files.signals_interrupt():     # as labtool demo runs a step
            try:
                rc = labtool.cli.main(["kinematics", "--points", "200", "-o", {str(out)!r}])
            except KeyboardInterrupt as exc:
                print("raised", getattr(exc, "signum", None))
            else:
                print("returned", rc)
        """
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          cwd=ROOT, timeout=300, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.stdout.strip().splitlines()[-1] == f"raised {int(signal.SIGTERM)}", proc.stderr[-2000:]
