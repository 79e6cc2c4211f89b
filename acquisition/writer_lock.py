"""One writer per recording: an exclusive lock held on the file for as long as it is recorded.

A recording is written in place (SWMR readers watch it grow), so a second ``acquire`` on the same
name, ``--force`` included, must be refused while the first one runs: replacing the file would
orphan the first run's data and make its summary lie. The lock is a kernel lock on the recording
itself, so it vanishes with the process that holds it (a SIGKILLed run leaves no stale lock):

- Linux: an open-file-description lock (``F_OFD_SETLK``) on one byte far past the end of the file.
  It does not interact with HDF5's own ``flock`` (so SWMR readers still open the file) and, unlike a
  classic POSIX lock, it is not released when HDF5 closes one of its own descriptors of the file.
- other POSIX systems: a classic ``lockf`` lock, which HDF5 keeps alive as long as it holds the file
  open (the recorder never reopens it while recording).
- Windows: no lock (documented in docs/acquisition.md); the refusal of an existing name without
  ``--force`` still applies.

Creating the file (check the old one's lock, remove it, create the new one, lock it) happens under
a ``flock`` of the folder, so two runs started together cannot both pass the check.
"""
from __future__ import annotations

import contextlib
import errno
import os
import struct
from pathlib import Path

from labtool.common.errors import InputError

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None

_LOCK_START = 2**62  # the locked byte: far beyond any real file, so no reader ever touches it


class RecordingBusy(InputError):
    """Another process is writing the recording right now."""


def _ofd():
    return fcntl is not None and hasattr(fcntl, "F_OFD_SETLK")


def _flock_struct(kind: int) -> bytes:
    # struct flock {short l_type; short l_whence; off_t l_start; off_t l_len; pid_t l_pid;} (native)
    return struct.pack("@hhqqi4x", kind, os.SEEK_SET, _LOCK_START, 1, 0)


def _try_lock(fd: int) -> bool:
    """Take the exclusive lock on fd; False if another process holds it."""
    try:
        if _ofd():
            fcntl.fcntl(fd, fcntl.F_OFD_SETLK, _flock_struct(fcntl.F_WRLCK))
        else:
            fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB, 1, _LOCK_START)
        return True
    except OSError as exc:
        if exc.errno in (errno.EACCES, errno.EAGAIN):
            return False
        raise


def is_being_written(path) -> bool:
    """Whether another process holds the writer lock of ``path`` (False if it does not exist)."""
    if fcntl is None:
        return False
    try:
        fd = os.open(path, os.O_RDWR)
    except FileNotFoundError:
        return False
    except OSError:  # a read-only file is nobody's recording in progress
        return False
    try:
        if _ofd():
            res = fcntl.fcntl(fd, fcntl.F_OFD_GETLK, _flock_struct(fcntl.F_WRLCK))
            return struct.unpack("@hhqqi4x", res)[0] != fcntl.F_UNLCK
        if _try_lock(fd):
            fcntl.lockf(fd, fcntl.LOCK_UN, 1, _LOCK_START)
            return False
        return True
    except OSError:
        return False
    finally:
        os.close(fd)


@contextlib.contextmanager
def _folder_lock(folder: Path):
    """Serialise check-and-create between processes in one folder (no-op where flock is missing)."""
    fd = None
    if fcntl is not None:
        with contextlib.suppress(OSError):
            fd = os.open(folder, os.O_RDONLY)
            fcntl.flock(fd, fcntl.LOCK_EX)
    try:
        yield
    finally:
        if fd is not None:
            os.close(fd)  # closing releases the flock


def busy_message(path) -> str:
    """The refusal of a recording in progress: its name, and that --force does not replace it."""
    return (f"{path} is being recorded by another process right now; --force does not replace a recording in "
            "progress: choose another name or stop that run first")


class WriterLock:
    """The lock of one recording being written; ``release()`` (or closing) ends it.

    ``WriterLock.create(path, replace)`` creates ``path`` empty (with the user's umask) and locks it;
    an existing file is replaced only if ``replace`` and nobody is writing it. ``held`` is False
    where the filesystem refused locks (``reason`` says why): the run goes on unprotected.
    """

    def __init__(self, fd: int | None, path: Path, held: bool, reason: str = ""):
        self._fd, self.path, self.held, self.reason = fd, path, held, reason

    @classmethod
    def create(cls, path, replace: bool) -> "WriterLock":
        path = Path(path)
        with _folder_lock(path.parent if str(path.parent) else Path(".")):
            if path.exists() or path.is_symlink():
                if is_being_written(path):
                    raise RecordingBusy(busy_message(path))
                if not replace:
                    raise InputError(f"{path} already exists; use --force to overwrite it")
                path.unlink()
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o666)
            try:
                held, reason = (_try_lock(fd), "") if fcntl is not None else (False, "no file locks on this system")
            except OSError as exc:  # e.g. ENOLCK on a filesystem without lock support
                held, reason = False, os.strerror(exc.errno) if exc.errno else str(exc)
            if fcntl is not None and not held and not reason:  # pragma: no cover - a race lost to O_EXCL's winner
                os.close(fd)
                raise RecordingBusy(f"{path} was just created by another process; choose another name")
        return cls(fd, path, held, reason)

    def release(self) -> None:
        if self._fd is not None:
            fd, self._fd = self._fd, None
            os.close(fd)

    def __del__(self):
        self.release()
