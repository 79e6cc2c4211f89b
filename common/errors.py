"""Errors a user can cause and fix.

Every layer raises these; the CLI turns them into one line
``labtool: error: <what, where, what to do>`` and exit code 2.
They live in ``common``, the bottom layer every other layer may import.
"""
import signal


class LabtoolError(Exception):
    """Base of all user-facing errors (bad file, bad option, impossible parameters, solver failure)."""


class InputError(LabtoolError, ValueError):
    """A parameter, option or file content that cannot be used as given."""


class SolverError(LabtoolError, RuntimeError):
    """A model could not be integrated to the requested accuracy; the message names the limit."""


class FileFormatError(LabtoolError, ValueError):
    """A file that is corrupt, truncated, of another format or missing required content."""


class OutputError(LabtoolError):
    """An output that could not be written (full disk, read-only file system, permission); the
    message says what was kept (docs/architecture.md: nothing is left half-written without saying so).
    ``errno``: ENOSPC, EDQUOT, EFBIG or EROFS when the disk was the cause, else None."""

    def __init__(self, message: str, errno: int | None = None):
        super().__init__(message)
        self.errno = errno


class Interrupted(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised like Ctrl-C's KeyboardInterrupt so that cleanups run."""

    def __init__(self, signum: int):
        super().__init__(f"signal {signum}")
        self.signum = signum


def interruption(signum: int, note: str = "") -> KeyboardInterrupt:
    """The exception that ends a command stopped by ``signum`` (KeyboardInterrupt for Ctrl-C,
    Interrupted for the others), raised after the command kept what it could; ``note`` (what was
    kept, how to resume) is printed on the CLI's interrupted line (labtool.cli)."""
    exc = KeyboardInterrupt() if signum == signal.SIGINT else Interrupted(signum)
    if note:
        exc.add_note(note)
    return exc


def interrupt_cause(exc: BaseException) -> KeyboardInterrupt | None:
    """The KeyboardInterrupt (Ctrl-C) or Interrupted (SIGTERM, SIGHUP) at the root of ``exc``'s chain,
    else None. A signal inside a numba-compiled function surfaces as a SystemError ("returned a
    result with an exception set") chained to it: code that catches Exception to go on (one failed
    run of many) must raise this instead, or a Ctrl-C becomes a failed run and the work goes on."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None
