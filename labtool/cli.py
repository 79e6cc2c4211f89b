"""The ``labtool`` command line: wires the layers, holds no physics.

Every user error ends with one line ``labtool: error: ...`` on stderr and exit code 2
(docs/architecture.md, Conventions). Exit 1 means "ran fine, a check failed".
"""
from __future__ import annotations

import importlib
import os
import signal
import sys
from pathlib import Path

import typer

from labtool.common.invocation import running

try:  # typer >= 0.29 vendors click; older typer uses the click package
    from typer._click import exceptions as click_exc
except ImportError:  # pragma: no cover
    from click import exceptions as click_exc

from labtool.common.errors import Interrupted, LabtoolError, OutputError, interrupt_cause
from labtool.common.files import (command_scope, describe_disk_error, disk_error, inside_another_command,
                          lost_interrupt, signals_interrupt)
from labtool.common.names import shown

_app = typer.Typer(
    name="labtool",
    help="Cam-follower test stand: acquire, process, simulate, DOE, report.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    # plain click help: rich markup would read units such as "[mm]" or "[s/m]" as style tags and
    # drop them, and its option table cuts long option names at 80 columns
    rich_markup_mode=None,
    context_settings={"help_option_names": ["-h", "--help"]},
)

# One module per command group; each exposes ``register(app)``.
COMMAND_MODULES = (
    "labtool.commands.kinematics",
    "labtool.commands.simulate",
    "labtool.commands.demo",
    "labtool.commands.report",
    "labtool.commands.fit",
    "labtool.commands.suggest",
    "labtool.commands.doe",
    "labtool.commands.acquire",
    "labtool.commands.devices",
    "labtool.commands.calibrate",
    "labtool.commands.process",
    "labtool.commands.export",
    "labtool.commands.bench",
    "labtool.commands.campaign",
    "labtool.commands.warmup",
)


_REGISTERED: list[str] = []      # command modules registered on _app, in order


def _register_all() -> None:
    """Every command on the app, in COMMAND_MODULES' order (which --help lists)."""
    if _REGISTERED == list(COMMAND_MODULES):
        return
    if _REGISTERED:              # one group registered alone before: start again, in order
        _app.registered_commands.clear()
        _app.registered_groups.clear()
        _REGISTERED.clear()
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(_app)
        _REGISTERED.append(name)


def _register_for(args: list[str]) -> None:
    """Register what the command line ``args`` needs: the module of its command group alone when
    the first argument names one (``labtool doe run ...`` imports none of the other commands'
    modules: ~0.1-0.2 s of the command's start), else every command (``--help``, an unknown or
    misspelt command: its error lists them as before; a command that is not a group)."""
    module = f"labtool.commands.{args[0]}" if args else None
    if module not in COMMAND_MODULES:
        _register_all()
    elif module not in _REGISTERED and _REGISTERED != list(COMMAND_MODULES):
        importlib.import_module(module).register(_app)
        _REGISTERED.append(module)
        if not _app.registered_groups and len(_app.registered_commands) == 1:
            _register_all()      # typer would run a lone command as the app itself ("labtool kinematics"
                                 # reading "kinematics" as an extra argument): only groups go alone


def __getattr__(name: str):
    """``labtool.cli.app``: the app with every command registered (tests, documentation tools)."""
    if name == "app":
        _register_all()
        return _app
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def main(argv: list[str] | None = None) -> int:
    """Console entry point; returns the process exit code.

    Every way a command can end is one line: ``labtool: error: ...`` and exit 2 for what the user
    can fix (LabtoolError, bad options, files: OSError, a full or read-only disk), ``labtool:
    interrupted`` and 128 + signal for Ctrl-C, SIGTERM and SIGHUP (cleanups run first), and
    ``labtool: internal error: ...`` with exit 70 for a bug (LABTOOL_DEBUG=1 shows the traceback).
    """
    _tolerant_stdio()
    _STATE["exit_at_disk_error"] = argv is None
    hook = sys.unraisablehook
    sys.unraisablehook = _quiet_interrupts(hook)
    code = None
    try:
        with command_scope(), signals_interrupt():
            code = _run(argv)
            lost = lost_interrupt()
            if lost is not None and code == 0:   # its Interrupted was dropped where Python ignores errors
                if inside_another_command():     # as _run does: the command that runs this one ends too
                    raise Interrupted(lost) if lost != signal.SIGINT else KeyboardInterrupt()
                code = _interrupted(lost)
    finally:
        # after an interruption, objects the signal left half-built (an h5netcdf File stopped in its
        # __init__) may fail in their finalizers at exit: that is no bug to report, so it stays quiet
        if argv is None and code is not None and code > 128:
            _STATE["interrupted"] = True
        else:
            sys.unraisablehook = hook
    if argv is None:
        _exit_without_teardown(code)
        sys.exit(code)
    return code


def _quiet_interrupts(hook):
    """sys.unraisablehook that drops a stop signal's exception raised where Python cannot raise it
    (a weakref callback, a __del__) instead of printing its traceback: the signal is kept
    (labtool.common.files.lost_interrupt) and ends the command at its next check."""
    def quiet(unraisable):
        if isinstance(unraisable.exc_value, KeyboardInterrupt) or _STATE["interrupted"]:
            return
        hook(unraisable)
    return quiet


def _exit_without_teardown(code: int) -> None:
    """End the console command at once when nothing is left to finish; else return, and the normal
    exit runs.

    Once compiled models are loaded, the interpreter's teardown frees numba's and LLVM's objects
    one by one: ~0.3 s after every such command, against ~0.02 s after numpy alone
    (docs/performance.md). The command's own cleanups have run (``command_scope``). The normal exit
    is kept when something still needs it: a thread that is not a daemon (the exit waits for it), a
    child process, an HDF5 file still open (HDF5 closes its files at the C library's exit, which
    ``os._exit`` skips). Otherwise the rest of what the teardown would do is done here: every open
    Python file flushed, the atexit handlers run (logging's flush, multiprocessing's finalizers),
    the standard streams flushed."""
    import atexit
    import gc
    import io
    import threading

    if any(t is not threading.main_thread() and not t.daemon and t.is_alive() for t in threading.enumerate()):
        return
    mp = sys.modules.get("multiprocessing")
    if mp is not None and mp.active_children():
        return
    h5py = sys.modules.get("h5py")
    if h5py is not None and h5py.h5f.get_obj_count(h5py.h5f.OBJ_ALL, h5py.h5f.OBJ_FILE):
        return
    for obj in gc.get_objects():                 # ~35 ms: the files that the teardown would flush
        if isinstance(obj, (io.TextIOWrapper, io.BufferedWriter, io.BufferedRandom)):
            try:
                if not obj.closed:
                    obj.flush()
            except (OSError, ValueError):        # a broken pipe, a full disk: the teardown ignores it too
                pass
    atexit._run_exitfuncs()          # what Py_Finalize runs first (CPython's, there since 3.0)
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except (OSError, ValueError):
        pass
    os._exit(code)


_STATE = {"exit_at_disk_error": False, "interrupted": False}


def _disk_error_seen(code: int) -> int:
    """After a full disk, HDF5 can crash the process (exit 139) when the objects of the failed
    write are freed with the exception or at the interpreter's exit: the console command ends here,
    the one line printed and the outputs already cleaned up (in-process callers get the code)."""
    if _STATE["exit_at_disk_error"]:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code


def _invoke(argv):
    """Run the command without typer's own top-level handler (typer 0.29 turns Ctrl-C into a
    silent exit 130, so no cleanup message and no way to tell SIGTERM from SIGINT)."""
    args = sys.argv[1:] if argv is None else list(argv)
    _register_for(args)
    command = typer.main.get_command(_app)
    with running(args), command.make_context("labtool", args) as ctx:
        from labtool.warmup import announce_for
        announce_for(args)          # a command about to compile says so at once (labtool.warmup)
        return command.invoke(ctx)


def _interrupted(signum: int, exc: BaseException | None = None) -> int:
    """The interrupted line on stderr; the exit code 128 + signal. The exception's notes
    (labtool.common.errors.interruption: what was kept, how to resume) replace the default text."""
    notes = [str(n) for n in getattr(exc, "__notes__", ()) if str(n).strip()]
    said = "; ".join(notes) if notes else "no output was left half-written"
    typer.echo(f"labtool: interrupted ({signal.Signals(signum).name}); {_one_line(said)}", err=True)
    return 128 + int(signum)


def _run(argv) -> int:
    try:
        rv = _invoke(argv)
        return int(rv) if isinstance(rv, int) and not isinstance(rv, bool) else 0
    except LabtoolError as exc:
        if (isinstance(exc, OutputError) and exc.errno is not None) or disk_error(exc) is not None:
            return _disk_error_seen(_error(str(exc)))
        return _error(str(exc))
    except typer.Exit as exc:
        return exc.exit_code
    except (typer.Abort, KeyboardInterrupt) as exc:
        # click turns KeyboardInterrupt (and so Interrupted, for SIGTERM/SIGHUP) into Abort
        cause = exc if isinstance(exc, KeyboardInterrupt) else exc.__cause__ or exc.__context__
        signum = cause.signum if isinstance(cause, Interrupted) else signal.SIGINT
        if inside_another_command():      # a step of another command (labtool demo): that one ends too
            raise (cause if isinstance(cause, KeyboardInterrupt) else KeyboardInterrupt()) from None
        return _interrupted(signum, cause if isinstance(cause, KeyboardInterrupt) else None)
    except click_exc.UsageError as exc:
        hint = f" (see '{exc.ctx.command_path} --help')" if exc.ctx else ""
        return _error(f"{exc.format_message() or 'no command given'}{hint}")
    except click_exc.ClickException as exc:
        return _error(exc.format_message())
    except OSError as exc:
        code = _error(_os_error(exc))
        return _disk_error_seen(code) if disk_error(exc) is not None else code
    except UnicodeError as exc:
        if _surrogates(exc):
            return _error("a file name given is not valid UTF-8 and cannot be written into the outputs; "
                          "rename the file (e.g. with convmv) and run again")
        return _internal(exc)
    except Exception as exc:  # noqa: BLE001 - the last line of defence: one line, never a traceback
        root = interrupt_cause(exc) if isinstance(exc, SystemError) else None
        if root is not None:
            # a signal inside a numba-compiled loop surfaces as a chain of "returned a result with
            # an exception set" with the KeyboardInterrupt (Ctrl-C) or Interrupted at its root
            if inside_another_command():
                raise root from None
            return _interrupted(root.signum if isinstance(root, Interrupted) else signal.SIGINT, root)
        code = disk_error(exc)
        if code is not None:      # HDF5 and zlib say "errno = 28" in a RuntimeError or ValueError
            name = getattr(exc, "filename", None)
            text = (describe_disk_error(code, Path(os.fsdecode(name)), "the output may be incomplete") if name else
                    f"a write failed: {os.strerror(code).lower()}; the output may be incomplete; "
                    "free some space or write elsewhere")
            return _disk_error_seen(_error(text))
        return _internal(exc)


def _error(message: str) -> int:
    typer.echo(f"labtool: error: {_one_line(message)}", err=True)
    return 2


def _one_line(text) -> str:
    """The message on one line, whatever it quotes: a newline or another control character (in a
    file or channel name, a library's text) is shown escaped (labtool.common.names.shown)."""
    return shown(str(text).strip())


def _os_error(exc: OSError) -> str:
    """One line for an OSError that reached the top: what, which file, what to do."""
    path = exc.filename if exc.filename is not None else None
    code = disk_error(exc)
    if code is not None and path is not None:
        return describe_disk_error(code, Path(os.fsdecode(path)), "the output may be incomplete")
    where = f"{shown(path)}: " if path is not None else ""
    reason = exc.strerror or str(exc)
    return f"{where}{reason}"


def _surrogates(exc: UnicodeError) -> bool:
    obj = getattr(exc, "object", "")
    return isinstance(obj, str) and any("\ud800" <= c <= "\udfff" for c in obj)


def _internal(exc: BaseException) -> int:
    if os.environ.get("LABTOOL_DEBUG"):
        raise exc
    typer.echo(f"labtool: internal error: {type(exc).__name__}: {_one_line(exc)} (a bug in labtool; "
               "please report it with the command line; LABTOOL_DEBUG=1 shows the traceback)", err=True)
    return 70


def _tolerant_stdio() -> None:
    """Print file names that are not UTF-8 (escaped) instead of failing on them."""
    for stream in (sys.stdout, sys.stderr):
        if getattr(stream, "errors", None) == "strict" and hasattr(stream, "reconfigure"):
            try:
                stream.reconfigure(errors="backslashreplace")
            except (ValueError, OSError):  # pragma: no cover - a closed or replaced stream
                pass


if __name__ == "__main__":  # pragma: no cover
    main()
