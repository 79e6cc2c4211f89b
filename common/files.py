"""Writing result files safely: atomic, with the user's umask, as sets, and one line on a full disk.

Every output of labtool goes through here:

- :func:`check_output_path` before any work: refuses an existing file without ``--force``, a
  folder (even with ``--force``), a missing or read-only folder;
- :class:`OutputSet` for the files one command writes together (report.html + .pdf + .json,
  kinematics' NetCDF + groove CSV): each is written to a hidden temporary name beside its final
  name, all are renamed at the end, and on any failure, Ctrl-C or SIGTERM every temporary is
  removed and no final name is changed (files replaced with ``--force`` are restored);
- :func:`atomic_write` / :func:`write_netcdf` for one file (an OutputSet of one);
- :func:`staged_folder` for a command that fills a folder (``labtool demo -o out/``): built in a
  hidden folder beside it, its files moved in at the end, all or none.

Temporary names are ``.NAME.<host>-<pid>-<token>.part.<ext>`` (the extension kept for writers that
choose the format by it). A process killed with SIGKILL cannot clean up; the next write to the
same name removes the temporaries of dead processes of this host.

Files are created with mode 0666 & ~umask (and the folder's default ACL), as ``open()`` would:
colleagues on a shared lab drive can read them. A full disk (ENOSPC, EDQUOT, EFBIG) or a read-only
file system (EROFS) becomes :class:`labtool.common.errors.OutputError`, one line saying what was kept.
NetCDF is built in memory and written with plain writes: HDF5 never meets a full disk itself (it
crashes the process when a metadata flush fails, HDF5 2.0 / h5py 3.16).
"""
from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import secrets
import shutil
import signal
import socket
import threading
from pathlib import Path
from typing import Callable, Iterable

from labtool.common.errors import InputError, Interrupted, OutputError
from labtool.common.names import shown

DISK_FULL = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG}
_DISK_TEXT = {"No space left on device": errno.ENOSPC, "errno = 28": errno.ENOSPC,
              "Disk quota exceeded": errno.EDQUOT, "Read-only file system": errno.EROFS,
              "errno = 30": errno.EROFS, "File too large": errno.EFBIG}
_HOST = hashlib.sha1(socket.gethostname().encode("utf-8", "surrogateescape")).hexdigest()[:6]
NETCDF_IN_MEMORY_MAX = 1 << 30     # larger datasets are written directly, after a free-space check


# --- checks before any work ------------------------------------------------------------------
def read_only(folder: Path) -> bool:
    """Whether ``folder`` lies on a file system mounted read-only."""
    try:
        return bool(os.statvfs(folder).f_flag & os.ST_RDONLY)
    except OSError:
        return False


def check_output_path(path: Path, force: bool = False, option: str | None = None) -> None:
    """Refuse an existing file without --force, a folder, and a folder that cannot be written."""
    path = Path(path)
    name = shown(path)
    given = f" ({option})" if option else ""
    if path.is_dir():
        raise InputError(f"{name}{given} is a folder; give a file name to write")
    if (path.exists() or path.is_symlink()) and not force:
        raise InputError(f"{name} already exists; use --force to overwrite it")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"cannot write {name}: folder {shown(parent)} does not exist")
    if read_only(parent):
        raise OutputError(f"cannot write {name}: {shown(parent)} is on a read-only file system; "
                          "choose a folder you can write to", errno.EROFS)
    if not os.access(parent, os.W_OK):
        raise InputError(f"cannot write {name}: folder {shown(parent)} is not writable")


def check_outputs(named: dict, force: bool = False) -> None:
    """check_output_path for each ``{option: path}`` given (None = not asked for), and refuse two
    options naming one file (``-o X --groove-csv X`` wrote one over the other)."""
    given = [(opt, Path(p)) for opt, p in named.items() if p is not None and str(p) != "-"]
    for i, (opt, path) in enumerate(given):
        for other_opt, other in given[:i]:
            if _same_file_key(path) == _same_file_key(other):
                raise InputError(f"{other_opt} and {opt} name the same file {shown(path)}; "
                                 "give each output its own name")
    for opt, path in given:
        check_output_path(path, force, opt)


def check_output_dir(path: Path) -> None:
    """A folder to write into: existing or creatable, not a file, writable, not read-only."""
    path = Path(path)
    name = shown(path)
    if path.exists() and not path.is_dir():
        raise InputError(f"{name} is a file, not a folder; give a folder for the outputs (-o)")
    probe = path
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if not probe.is_dir():
        raise InputError(f"cannot create folder {name}: {shown(probe)} is a file")
    if read_only(probe):
        raise OutputError(f"cannot write into {name}: {shown(probe)} is on a read-only file system; "
                          "choose a folder you can write to", errno.EROFS)
    if not os.access(probe, os.W_OK | os.X_OK):
        raise InputError(f"cannot write into {name}: folder {shown(probe)} is not writable")


def free_bytes(folder: Path) -> int:
    """Bytes an unprivileged process may still write on the file system of ``folder``."""
    st = os.statvfs(folder)
    return st.f_bavail * st.f_frsize


def _size(n: float) -> str:
    for unit, scale in (("GB", 1 << 30), ("MB", 1 << 20), ("kB", 1 << 10)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{int(n)} bytes"


def ensure_free_space(path: Path, need_bytes: float, kept: str = "nothing was written") -> None:
    """OutputError before writing ``need_bytes`` to ``path`` if its file system has less free.

    For writers that stream (HDF5 recordings, processed NetCDF): check before each block, so HDF5
    itself never meets ENOSPC. ``kept`` says what stays as it is."""
    path = Path(path)
    folder = path if path.is_dir() else (path.parent if str(path.parent) else Path("."))
    free = free_bytes(folder)
    if free < need_bytes:
        raise OutputError(f"cannot write {shown(path)}: it needs about {_size(need_bytes)} and "
                          f"{shown(folder)} has {_size(free)} free; {kept}; free some space or "
                          "write elsewhere", errno.ENOSPC)


def disk_error(exc: BaseException) -> int | None:
    """The errno (ENOSPC, EDQUOT, EFBIG, EROFS) behind ``exc`` or its causes, else None.

    HDF5 and zlib report a full disk as OSError with an errno, as RuntimeError text, or chained."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, OSError) and exc.errno in DISK_FULL | {errno.EROFS}:
            return exc.errno
        text = str(exc)
        for fragment, code in _DISK_TEXT.items():
            if fragment in text:
                return code
        exc = exc.__cause__ or exc.__context__
    return None


def describe_disk_error(code: int, path: Path, kept: str) -> str:
    """The one line for a full or read-only disk while writing ``path``."""
    folder = Path(path).parent if str(Path(path).parent) else Path(".")
    if code == errno.EROFS:
        return f"cannot write {shown(path)}: {shown(folder)} is on a read-only file system; {kept}"
    what = {errno.EDQUOT: "disk quota exceeded", errno.EFBIG: "file too large for this file system"}.get(
        code, "no space left on device")
    try:
        free = f" ({_size(free_bytes(folder))} free in {shown(folder)})"
    except OSError:
        free = ""
    return f"cannot write {shown(path)}: {what}{free}; {kept}; free some space or write elsewhere"


# --- temporary names -------------------------------------------------------------------------
def _temp_name(final: Path) -> Path:
    name = final.name
    ext = "".join(s for s in final.suffixes[-2:] if len(s) <= 10)
    stem = name[:200]
    return final.with_name(f".{stem}.{_HOST}-{os.getpid()}-{secrets.token_hex(4)}.part{ext}")


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_temporaries(final: Path) -> list[Path]:
    """Remove ``.NAME.<host>-<pid>-*.part*`` left by dead processes of this host (SIGKILL, power)."""
    final = Path(final)
    removed = []
    folder = final.parent if str(final.parent) else Path(".")
    prefix = f".{final.name[:200]}.{_HOST}-"
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        if not entry.name.startswith(prefix) or ".part" not in entry.name:
            continue
        pid_text = entry.name[len(prefix):].split("-", 1)[0]
        if not pid_text.isdigit() or _pid_alive(int(pid_text)):
            continue
        with contextlib.suppress(OSError):
            if entry.is_dir(follow_symlinks=False):
                shutil.rmtree(entry.path)
            else:
                os.unlink(entry.path)
            removed.append(Path(entry.path))
    return removed


def _create_empty(path: Path) -> None:
    """Create ``path`` as open() would: mode 0666 filtered by the umask and the folder's ACL."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    os.close(fd)


def _umask_mode() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def _fsync(path: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


# --- signals ---------------------------------------------------------------------------------
_COMMAND_DEPTH = [0]         # labtool commands running in this process (one that another runs: 2)


@contextlib.contextmanager
def command_scope():
    """The extent of one labtool command (labtool.cli.main); commands that a command runs (as
    ``labtool demo`` runs ``acquire``) nest."""
    _COMMAND_DEPTH[0] += 1
    try:
        yield
    finally:
        _COMMAND_DEPTH[0] -= 1


def inside_another_command() -> bool:
    """Does another labtool command run this one? Then a signal must end that command too, not
    only what this one would stop (a recording)."""
    return _COMMAND_DEPTH[0] > 1


@contextlib.contextmanager
def signals_interrupt(signals: Iterable[int] = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)):
    """Inside the block, SIGTERM and SIGHUP raise :class:`Interrupted` (like Ctrl-C raises
    KeyboardInterrupt), so that ``finally`` and rollbacks run; Ctrl-C still raises KeyboardInterrupt,
    and is kept too. Handlers set by others are kept."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {}

    def handler(signum, frame):
        # kept as well as raised: raised inside a weakref callback or a __del__ (the garbage
        # collector's), the exception is printed and dropped, and the command would go on (found by
        # CI: a SIGTERM during labtool demo's acquire step, exit 0; a Ctrl-C in labtool fit's search,
        # exit 0 with its outputs written); commit() and check_interrupted() raise it again
        _LOST_SIGNAL[0] = signum
        raise KeyboardInterrupt() if signum == signal.SIGINT else Interrupted(signum)

    for s in signals:
        with contextlib.suppress(ValueError, OSError):
            default = signal.default_int_handler if s == signal.SIGINT else signal.SIG_DFL
            if signal.getsignal(s) in (default, None):
                old[s] = signal.signal(s, handler)
    if old:
        _LOST_SIGNAL[0] = None
    try:
        yield
    finally:
        for s, h in old.items():
            with contextlib.suppress(ValueError, OSError):
                signal.signal(s, h)
        if old:
            _LOST_SIGNAL[0] = None


_LOST_SIGNAL = [None]     # the signal signals_interrupt's handler last raised, while it is installed


def lost_interrupt() -> int | None:
    """The signal that ``signals_interrupt`` turned into an exception in its block, if any (None
    otherwise): the exception may have been dropped where Python ignores exceptions."""
    return _LOST_SIGNAL[0]


def check_interrupted() -> None:
    """Raise again the stop signal whose exception was dropped (``lost_interrupt``): long work
    calls it between its steps (a progress report), so that a dropped Ctrl-C still stops it there."""
    if _LOST_SIGNAL[0] is not None:
        signum = _LOST_SIGNAL[0]
        raise KeyboardInterrupt() if signum == signal.SIGINT else Interrupted(signum)


@contextlib.contextmanager
def _signals_held(signals=(signal.SIGINT, signal.SIGTERM, signal.SIGHUP)):
    """Block ``signals`` inside the block; one that arrived meanwhile is delivered at its end."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, signals)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


# --- sets of outputs -------------------------------------------------------------------------
class OutputSet:
    """Files written together: all of them, or none (see the module docstring).

    ::

        with OutputSet() as out:
            out.write_text(html_path, html)
            out.write(pdf_path, lambda tmp: write_pdf(rep, tmp))   # a writer given the temp path
            out.write_netcdf(nc_path, ds)
        # here every file is in place; an exception above left none of them changed

    ``add(path, option)`` refuses two outputs with the same name (``-o X --groove-csv X``).
    ``kept`` (e.g. "the recording is untouched") is added to the one line of a disk error.
    """

    def __init__(self, kept: str = ""):
        self._items: list[tuple[Path, Path, str | None]] = []   # (final, temp, option)
        self._kept = kept
        self._mode = _umask_mode()
        self._signals = None

    # -- registering --
    def add(self, final: Path, option: str | None = None) -> Path:
        """Register ``final``; returns the temporary path to write it to (created empty)."""
        final = Path(final)
        key = _same_file_key(final)
        for other, _tmp, other_option in self._items:
            if _same_file_key(other) == key:
                a = f"{other_option} and {option}" if other_option and option else "two outputs"
                raise InputError(f"{a} name the same file {shown(final)}; give each output its own name")
        remove_stale_temporaries(final)
        tmp = _temp_name(final)
        self._items.append((final, tmp, option))   # first: a signal right after the create still removes it
        try:
            _create_empty(tmp)
        except OSError as exc:
            self._items.pop()
            self._raise_for(exc, final)
        return tmp

    @property
    def finals(self) -> list[Path]:
        return [f for f, _t, _o in self._items]

    # -- writing --
    def write(self, final: Path, writer: Callable[[Path], object], option: str | None = None):
        """Call ``writer(tmp)`` (it writes the file at ``tmp``); its result is returned."""
        tmp = self.add(final, option)
        try:
            return writer(tmp)
        except BaseException as exc:
            self._raise_for(exc, final)

    def write_bytes(self, final: Path, data, option: str | None = None) -> None:
        """Write ``data`` (bytes, memoryview) to ``final``; refused before writing if it cannot fit."""
        data = memoryview(data)
        folder = Path(final).parent if str(Path(final).parent) else Path(".")
        with contextlib.suppress(OSError):
            if free_bytes(folder) < data.nbytes:
                self._fail_disk(errno.ENOSPC, Path(final))

        def writer(tmp: Path):
            with open(tmp, "wb") as f:
                f.write(data)
        self.write(final, writer, option)

    def write_text(self, final: Path, text: str, option: str | None = None) -> None:
        """Write ``text`` as UTF-8 (a lone surrogate from a non-UTF-8 file name is escaped)."""
        self.write_bytes(final, text.encode("utf-8", "backslashreplace"), option)

    def write_netcdf(self, final: Path, ds, option: str | None = None) -> None:
        """Write an xarray Dataset as NetCDF4 (h5netcdf); see :func:`write_netcdf`."""
        ds = _utf8_safe_attrs(ds)
        if ds.nbytes <= NETCDF_IN_MEMORY_MAX:
            self.write_bytes(final, _netcdf_image(ds), option)
            return
        ensure_free_space(final, 1.1 * ds.nbytes + (1 << 20), self._kept_text(final))
        self.write(final, lambda tmp: ds.to_netcdf(tmp, engine="h5netcdf"), option)

    # -- ending --
    def commit(self) -> None:
        """Rename every temporary onto its final name; on failure restore what was there. Signals
        wait until the renames are done (a few ms), so a set is never left half renamed. A SIGTERM
        or SIGHUP whose Interrupted was dropped (``signals_interrupt``) is raised here instead,
        before anything is renamed."""
        with _signals_held():
            if _LOST_SIGNAL[0] is not None:
                self._raise_for(Interrupted(_LOST_SIGNAL[0]), None)
            self._commit()

    def _commit(self) -> None:
        done: list[tuple[Path, Path | None]] = []
        try:
            for final, tmp, _option in self._items:
                os.chmod(tmp, self._mode)        # a writer may have re-created the file
                _fsync(tmp)
            for final, tmp, _option in self._items:
                backup = _backup(final) if len(self._items) > 1 else None
                os.replace(tmp, final)
                done.append((final, backup))
        except BaseException as exc:
            failed = self._items[len(done)][0] if len(done) < len(self._items) else None
            for final, backup in reversed(done):
                with contextlib.suppress(OSError):
                    if backup is not None:
                        os.replace(backup, final)
                    else:
                        final.unlink()
            self._raise_for(exc, failed)
        finally:
            for _final, backup in done:
                if backup is not None:
                    with contextlib.suppress(OSError):
                        backup.unlink()
        folders = {f.parent for f, _t, _o in self._items}
        self._items = []
        for folder in folders:
            _fsync(folder if str(folder) else Path("."))

    def rollback(self) -> None:
        """Remove every temporary; no final name is touched."""
        for _final, tmp, _option in self._items:
            with contextlib.suppress(OSError):
                tmp.unlink()
        self._items = []

    def __enter__(self) -> "OutputSet":
        self._signals = signals_interrupt()
        self._signals.__enter__()
        return self

    def __exit__(self, kind, exc, tb) -> bool:
        try:
            if kind is None:
                self.commit()
            else:
                self.rollback()
        finally:
            self._signals.__exit__(None, None, None)
        return False

    # -- errors --
    def _kept_text(self, final: Path | None) -> str:
        """What stays as it was, e.g. "none of r.html, r.pdf was written (r.html unchanged)"."""
        paths = self.finals + ([Path(final)] if final is not None and Path(final) not in self.finals else [])
        names = [shown(p.name) for p in paths]
        existing = [shown(p.name) for p in paths if p.exists()]
        text = f"none of {', '.join(names)} was written" if len(names) > 1 else "nothing was written"
        if existing:
            text += f" ({', '.join(existing)} unchanged)"
        return f"{text}; {self._kept}" if self._kept else text

    def _fail_disk(self, code: int, final: Path):
        kept = self._kept_text(final)
        self.rollback()                     # first, so that the free space said is the real one
        raise OutputError(describe_disk_error(code, final, kept), code)

    def _raise_for(self, exc: BaseException, final: Path | None):
        """Roll back, then re-raise ``exc`` as one OutputError line if the disk is the cause."""
        code = disk_error(exc) if isinstance(exc, Exception) else None
        if code is None and isinstance(exc, OSError) and final is not None:
            code = _nearly_full(final)
        if code is not None and final is not None:
            self._fail_disk(code, final)
        kept = self._kept_text(final)
        self.rollback()
        if isinstance(exc, OSError) and final is not None:
            raise OutputError(f"cannot write {shown(final)}: {exc.strerror or exc}; {kept}") from None
        raise exc


def _nearly_full(final: Path) -> int | None:
    """ENOSPC when a writer failed on a file system with (almost) nothing left (zlib, libraries
    that lose the errno); None otherwise."""
    folder = Path(final).parent if str(Path(final).parent) else Path(".")
    try:
        return errno.ENOSPC if free_bytes(folder) < (64 << 10) else None
    except OSError:
        return None


def _same_file_key(path: Path):
    path = Path(path)
    try:
        st = path.stat()
        return ("inode", st.st_dev, st.st_ino)
    except OSError:
        return ("path", os.path.normcase(os.path.abspath(path)))


def _backup(final: Path) -> Path | None:
    """A hard link to the file about to be replaced, to put it back if the set fails."""
    if not final.exists():
        return None
    backup = final.with_name(f".{final.name[:200]}.{_HOST}-{os.getpid()}-{secrets.token_hex(4)}.part.old")
    try:
        os.link(final, backup)
    except OSError:
        return None
    return backup


def _netcdf_image(ds) -> memoryview:
    """The NetCDF4 file of ``ds`` built in memory (h5netcdf)."""
    return ds.to_netcdf(engine="h5netcdf")


def _utf8_safe_attrs(ds):
    """``ds`` with every string attribute writable as UTF-8 (lone surrogates of a non-UTF-8 file
    name escaped as \\xff); the Dataset itself is not modified."""
    def clean(attrs: dict) -> dict:
        return {k: (v.encode("utf-8", "backslashreplace").decode("utf-8") if isinstance(v, str) else v)
                for k, v in attrs.items()}

    def dirty(attrs: dict) -> bool:
        return any(isinstance(v, str) and not v.isascii() and _has_surrogate(v) for v in attrs.values())

    if not (dirty(ds.attrs) or any(dirty(v.attrs) for v in ds.variables.values())):
        return ds
    ds = ds.copy(deep=False)
    ds.attrs = clean(ds.attrs)
    for name in ds.variables:
        ds[name].attrs = clean(ds[name].attrs)
    return ds


def _has_surrogate(text: str) -> bool:
    return any("\ud800" <= c <= "\udfff" for c in text)


# --- one file --------------------------------------------------------------------------------
def atomic_write(path: Path, writer: Callable[[Path], object], kept: str = "") -> None:
    """Call ``writer(tmp_path)`` then rename onto ``path``: a crash leaves no partial file behind,
    a full disk is one OutputError line."""
    with OutputSet(kept=kept) as out:
        out.write(path, writer)


def write_text(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    with OutputSet() as out:
        out.write_text(path, text)


def write_netcdf(ds, path: Path) -> None:
    """Write an xarray Dataset as NetCDF4 (h5netcdf engine), atomically.

    Built in memory and written with plain writes (up to NETCDF_IN_MEMORY_MAX; larger after a
    free-space check), so a full disk is one line instead of an HDF5 crash."""
    with OutputSet() as out:
        out.write_netcdf(path, ds)


# --- a folder of outputs ---------------------------------------------------------------------
@contextlib.contextmanager
def staged_folder(final: Path):
    """Yield a hidden staging folder beside ``final``; at the end of the block move every file in
    it into ``final`` (created if needed; files there with the same names replaced), all or none.

    On any exception, Ctrl-C or SIGTERM the staging folder is removed and ``final`` is unchanged;
    a full or read-only disk is one OutputError line. Files of ``final`` not produced again stay."""
    check_output_dir(Path(final))
    final = Path(final).absolute()
    remove_stale_temporaries(final)
    stage = final.with_name(f".{final.name[:200]}.{_HOST}-{os.getpid()}-{secrets.token_hex(4)}.part")
    kept = f"nothing was written into {shown(final)}"
    try:
        stage.mkdir()
    except OSError as exc:
        code = disk_error(exc)
        if code is not None:
            raise OutputError(describe_disk_error(code, final, kept), code) from None
        raise
    try:
        with signals_interrupt():
            yield stage
            _move_folder(stage, final)
    except BaseException as exc:
        shutil.rmtree(stage, ignore_errors=True)
        code = exc.errno if isinstance(exc, OutputError) else disk_error(exc) if isinstance(exc, Exception) else None
        if code is not None:
            raise OutputError(describe_disk_error(code, final / "", kept), code) from None
        raise
    shutil.rmtree(stage, ignore_errors=True)


def _move_folder(stage: Path, final: Path) -> None:
    """Move the files under ``stage`` to the same places under ``final`` as one OutputSet commit."""
    files = [p for p in sorted(stage.rglob("*")) if p.is_file() or p.is_symlink()]
    final.mkdir(parents=True, exist_ok=True)
    out = OutputSet()
    for path in files:
        target = final / path.relative_to(stage)
        target.parent.mkdir(parents=True, exist_ok=True)
        out._items.append((target, path, None))     # already written: only the commit is left
    out.commit()
