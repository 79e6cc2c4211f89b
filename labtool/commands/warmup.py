"""``labtool warmup``: compile, once, the loops every command runs (labtool.warmup).

A progress bar on a terminal (a line per step elsewhere), then one line per step: compiled (how
many functions, in how long) or already in numba's cache. ``make install`` runs it.
"""
from __future__ import annotations

import typer


def register(app: typer.Typer) -> None:
    app.command("warmup")(warmup)


def warmup() -> None:
    """Compile the models, the stand's twin, the processing kernels and the report's metrics into
    numba's cache now, so that no later command waits for them (NUMBA_CACHE_DIR if set, else
    beside labtool's sources)."""
    import time

    from labtool.output import terminal_console
    from labtool.warmup import warm

    err = terminal_console(stderr=True)
    t0 = time.perf_counter()
    if err is not None:
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        with Progress(TextColumn("warmup: compiling {task.description}"), BarColumn(), MofNCompleteColumn(),
                      TimeElapsedColumn(), console=err, transient=True) as bar:
            task = bar.add_task("", total=None)

            def progress(done, total, what):
                bar.update(task, completed=done, total=total, description=what)
            done = warm(progress)
    else:
        def progress(done, total, what):
            if what:
                typer.echo(f"warmup: {done + 1}/{total} compiling {what}", err=True)
        done = warm(progress)
    for d in done:
        how = (f"compiled {d.compiled} functions in {d.seconds:.1f} s" if d.compiled
               else f"in the cache already ({d.seconds:.1f} s)")
        typer.echo(f"{d.what}: {how}")
    typer.echo(f"warmup done in {time.perf_counter() - t0:.1f} s")
