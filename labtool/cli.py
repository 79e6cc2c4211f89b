"""The ``labtool`` command line: wires the layers, holds no physics.

Every user error ends with one line ``labtool: error: ...`` on stderr and exit code 2
(DESIGN.md, Conventions). Exit 1 means "ran fine, a check failed".
"""
from __future__ import annotations

import importlib
import sys

import typer

try:  # typer >= 0.29 vendors click; older typer uses the click package
    from typer._click import exceptions as click_exc
except ImportError:  # pragma: no cover
    from click import exceptions as click_exc

from common.errors import LabtoolError

app = typer.Typer(
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
    "labtool.commands.doe",
    "labtool.commands.acquire",
    "labtool.commands.devices",
    "labtool.commands.calibrate",
    "labtool.commands.process",
    "labtool.commands.export",
    "labtool.commands.bench",
)


def _register_all() -> None:
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(app)


_register_all()


INTERRUPTED = 130      # exit code after Ctrl-C (128 + SIGINT)


def _caused_by_interrupt(exc: BaseException) -> bool:
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def main(argv: list[str] | None = None) -> int:
    """Console entry point; returns the process exit code."""
    try:
        rv = app(args=argv, standalone_mode=False, prog_name="labtool")
        code = int(rv) if isinstance(rv, int) else 0
        if code == INTERRUPTED:      # typer returns Ctrl-C as a silent 130 when not standalone
            typer.echo("labtool: interrupted", err=True)
        if argv is None:
            sys.exit(code)
        return code
    except LabtoolError as exc:
        typer.echo(f"labtool: error: {exc}", err=True)
        code = 2
    except typer.Exit as exc:
        code = exc.exit_code
    except typer.Abort:
        typer.echo("labtool: interrupted", err=True)
        code = INTERRUPTED
    except click_exc.UsageError as exc:
        hint = f" (see 'labtool {exc.ctx.command_path.split(' ', 1)[-1]} --help')" if exc.ctx else ""
        typer.echo(f"labtool: error: {exc.format_message()}{hint}", err=True)
        code = 2
    except click_exc.ClickException as exc:
        typer.echo(f"labtool: error: {exc.format_message()}", err=True)
        code = 2
    except KeyboardInterrupt:
        typer.echo("labtool: interrupted", err=True)
        code = INTERRUPTED
    except SystemError as exc:
        # Ctrl-C inside a numba-compiled loop surfaces as a chain of "returned a result with an
        # exception set" with the KeyboardInterrupt at its root
        if not _caused_by_interrupt(exc):
            raise
        typer.echo("labtool: interrupted", err=True)
        code = INTERRUPTED
    if argv is None:
        sys.exit(code)
    return code


if __name__ == "__main__":  # pragma: no cover
    main()
