"""``labtool doe run`` and ``labtool doe analyze``: the simulated experiment (paper sec. 2.2, 3.1).

``run`` simulates every run of a full factorial (Table 1 by default) and writes a CSV shaped like
Tables 2/3 plus a NetCDF with the factors as coordinates. ``analyze`` reads such a CSV and prints
the ANOVA (Fisher's F) and the reduced effect models in the paper's matrix form (eqs 20-28).
"""
from __future__ import annotations

import contextlib
import json
from pathlib import Path
from typing import List, Optional

import typer

from labtool.common.budget import LONG_RUN_S
from labtool.common.files import atomic_write, check_output_path
from labtool.common.invocation import command_line
from labtool.reports.effects import heading as _heading
from labtool.reports.effects import level as _level

doe_app = typer.Typer(
    help="Simulated experiments: full factorial runs (Tables 2-3) and their ANOVA (eqs 20-28).",
    no_args_is_help=True,
)


def register(app: typer.Typer) -> None:
    app.add_typer(doe_app, name="doe")


# a design whose estimated time exceeds this asks for confirmation (terminal) or --yes (s)
CONFIRM_ABOVE_S = LONG_RUN_S


@doe_app.command("run")
def run(
    output: Path = typer.Option(..., "-o", "--output", help="results CSV to write (columns of Table 2/3)"),
    model: str = typer.Option("rigid", help="model level: rigid (Table 2), elastic (Table 3) or kinematic"),
    law: str = typer.Option("sine", help="motion law: sine, cosine, poly345, ..."),
    omega1: str = typer.Option("var", help="cam speed: var (motor characteristic, as the paper's tables) or const"),
    factors: Optional[Path] = typer.Option(None, help="factor file, CSV (factor,symbol,unit,level_1,...) "
                                                      "or TOML ([[factor]] tables); default: Table 1"),
    accuracy: str = typer.Option("standard", help="solver preset: fast, standard, reference"),
    elastic_gap: str = typer.Option("physical", help="elastic model: physical (the follower crosses the backlash j) or "
                                                     "closed (no gap: the convention that reproduces Table 3)"),
    scheduler: Optional[str] = typer.Option(None, help="Dask scheduler address (tcp://host:8786) for a design whose "
                                                       "measured work is over 10 s (a smaller one runs in this "
                                                       "process, faster; it says so); default: local processes"),
    scheduler_always: bool = typer.Option(False, "--scheduler-always",
                                          help="send every design to --scheduler, however small its measured work"),
    workers: Optional[int] = typer.Option(None, help="local worker processes (default: all cores when the measured "
                                                     "work is over 3 s, else this process; 1 = in-process)"),
    chunk_runs: Optional[int] = typer.Option(None, help="runs per task (default: sized from the measured per-run "
                                                        "cost, about 1 s of work per task)"),
    fresh: bool = typer.Option(False, help="discard the finished chunks of an interrupted run into this output "
                                           "(default: a rerun of the same design resumes from them)"),
    yes: bool = typer.Option(False, "--yes", "-y", help=f"run a design estimated at more than "
                                                        f"{CONFIRM_ABOVE_S / 60:.0f} min or 100 MB on disk without "
                                                        "asking (off a terminal such a design is refused without it)"),
    netcdf: Optional[Path] = typer.Option(None, help="NetCDF to write (default: the CSV's name with .nc)"),
    force: bool = typer.Option(False, help="overwrite existing output files"),
) -> None:
    """Simulate the full factorial of the factors and write the results table and its NetCDF.

    Runs go in chunks to this process, local processes or a Dask cluster; each finished chunk is
    written to OUTPUT.parts/ at once, so an interrupted run (Ctrl-C, a kill, a full disk) keeps
    them and the same command again resumes where it stopped. A design estimated (runs x measured
    per-run cost / workers) at more than 10 min, or using more than 100 MB of disk, asks for
    confirmation, or needs --yes when not on a terminal.
    """
    import labtool
    from labtool.common.errors import SolverError
    from labtool.execution.progress import BarProgress, LineProgress
    from labtool.output import terminal_confirm, terminal_console

    err = terminal_console(stderr=True)        # None off a terminal: rich is not loaded for a pipe or a log
    label = f"doe run ({model})"
    if err is not None:
        def say(text):
            err.print(text, highlight=False, markup=False, soft_wrap=True)
        bar = BarProgress(label, err, None)
    else:
        def say(text):
            typer.echo(text, err=True)
        bar = contextlib.nullcontext(LineProgress(label, say))
    with bar as progress:
        res = labtool.run_design(output, model=model, law=law, omega1=omega1, factors=factors, accuracy=accuracy,
                                 elastic_gap=elastic_gap, scheduler=scheduler, scheduler_always=scheduler_always,
                                 workers=workers, chunk_runs=chunk_runs, fresh=fresh, yes=yes,
                                 confirm=terminal_confirm(), netcdf=netcdf, force=force, progress=progress, say=say,
                                 history=command_line())
    if res.n_runs <= 64:  # the table itself, as in the paper; large designs only get the summary line
        import pandas as pd
        gap_note = f", gap {elastic_gap}" if model == "elastic" else ""
        _print_results(pd.read_csv(output), f"{model} model, {law} law, omega1 {omega1}, accuracy {accuracy}{gap_note}",
                       res.factors)
    per_run = "" if res.cost_s is None else f", {res.cost_s * 1e3:.3g} ms per run"
    resumed = f"; {res.resumed} runs resumed from {res.parts}" if res.resumed else ""
    typer.echo(f"wrote {output} and {res.netcdf}: {res.n_runs} runs of the {model} model "
               f"({res.where}, {res.wall_s:.2f} s{per_run}{resumed})")
    if model == "elastic" and elastic_gap == "physical":
        typer.echo("note: the follower crosses the backlash here; the paper's Table 3 counts (1 jump, 0 impacts) "
                   "come from --elastic-gap closed (docs/models.md)")
    if res.n_failed:
        first = min(res.failures)
        raise SolverError(f"{res.n_failed} of {res.n_runs} runs failed and are left empty in {output} "
                          f"(run {first}: {res.failures[first]})")


def in_units(table, factors):
    """The result table with each level column (``A_Fu_level``: 1, 2) shown as the factor's value
    in its unit (``Fu [N]``: 0, 65); the file keeps the level indices (the paper's tables)."""
    table = table.copy()
    for f in factors:
        if f.column in table:
            at = table.columns.get_loc(f.column)
            values = table.pop(f.column).map(lambda k, f=f: f.levels[int(k) - 1] if k == k and 1 <= k <= len(f.levels)
                                              else float("nan"))
            table.insert(at, f.heading, values)
    return table


def _print_results(table, title: str, factors=()) -> None:
    from rich.table import Table

    from labtool.output import console

    table = in_units(table, factors)
    t = Table(title=title, title_justify="left")
    for c in table.columns:
        t.add_column(c, justify="right")
    for row in table.itertuples(index=False):
        t.add_row(*["" if v != v else (f"{v:.5g}" if isinstance(v, float) else str(v)) for v in row])
    console().print(t)


@doe_app.command("analyze")
def analyze(
    results: Path = typer.Argument(..., help="results CSV (as written by 'labtool doe run', or Tables 2/3)"),
    alpha: float = typer.Option(0.05, help="significance level of Fisher's F test"),
    max_order: Optional[int] = typer.Option(None, help="highest interaction order tested; higher ones are "
                                                       "pooled as error (default: 2 without replicates)"),
    response: Optional[List[str]] = typer.Option(None, help="analyze only this response (repeatable)"),
    json_out: bool = typer.Option(False, "--json", help="print one JSON object: response -> term -> "
                                                        "{coefficient, F, p, significant}"),
    plot: Optional[Path] = typer.Option(None, "-o", "--plot", help="main-effects and interaction plot (PNG)"),
    factors: Optional[Path] = typer.Option(None, help="factor file of the design (CSV or TOML, as 'doe run' takes), "
                                           "so that levels show as values in N, mm, rpm; default Table 1 when the "
                                           "table's factors are Table 1's"),
    digits: int = typer.Option(7, help="significant digits of the printed coefficients"),
    force: bool = typer.Option(False, help="overwrite an existing plot file"),
) -> None:
    """Effects in the paper's +-1 coding, ANOVA with Fisher's F, reduced models (eqs 20-28)."""
    from labtool.models.study import anova

    anova.check_alpha(alpha)
    if not 1 <= digits <= 17:
        raise typer.BadParameter(f"must lie in 1..17, got {digits}", param_hint="--digits")
    if plot is not None:
        check_output_path(plot, force)
    data = anova.read_results(results)
    physical = physical_factors(data, factors)
    out = anova.analyze(data, alpha=alpha, max_order=max_order, responses=response)
    if plot is not None:
        from labtool.reports.effects import plot_effects
        atomic_write(plot, lambda tmp: plot_effects(data, out, tmp, physical))
    if json_out:
        typer.echo(json.dumps(anova.to_json(out)))
        return
    _print_text(data, out, digits, physical)
    if plot is not None:
        typer.echo(f"wrote {plot}")


def physical_factors(data, path: Optional[Path]) -> list:
    """The design's factors with their values and units (labtool.models.study.doe.Factor), in the
    table's order: from ``path``, else Table 1's when the table's letters, symbols and level counts
    are Table 1's; a factor not found keeps its level numbers (None in the list)."""
    from labtool.common.errors import InputError
    from labtool.models.study.doe import read_factors, table1_factors

    given = read_factors(path) if path is not None else table1_factors()
    by = {(f.name, f.symbol): f for f in given}
    out = [by.get((d.name, d.symbol)) for d in data.factors]
    out = [f if f is not None and len(f.levels) == len(d.levels) else None for f, d in zip(out, data.factors)]
    if path is not None and not any(out):
        raise InputError(f"{path}: none of its factors ({', '.join(f'{f.name} = {f.symbol}' for f in given)}) is a "
                         f"factor of the table ({', '.join(f'{d.name} = {d.symbol}' for d in data.factors)})")
    return out


def _print_text(data, out, digits: int, physical=None) -> None:
    from rich.table import Table

    from labtool.output import console
    from labtool.models.study.anova import matrix_form

    con = console()
    physical = physical or [None] * len(data.factors)
    names = ", ".join(f"{d.name} = {_heading(d, f)}: " + (", ".join(f"{v:g}" for v in f.levels) if f is not None else
                                                          f"{len(d.levels)} levels") for d, f in zip(data.factors, physical))
    con.print(f"{data.source}: {len(data.frame)} runs, full factorial of {names}, "
              f"{data.replicates} run(s) per level combination", highlight=False, markup=False, soft_wrap=True)
    con.print("Coding: effect at level 1 = mean at level 1 - grand mean (the paper's +-1 coding, level 1 -> +1: "
              + ", ".join(_level(d, f, 1) for d, f in zip(data.factors, physical))
              + "); A_X is the level-indicator vector of factor X.",
              highlight=False, soft_wrap=True)
    for res in out.values():
        con.print()
        t = Table(title=f"{res.response}: ANOVA, Fisher's F test at alpha = {res.alpha:g}", title_justify="left")
        for col, just in (("term", "left"), ("effect at level 1", "right"), ("df", "right"),
                          ("sum of squares", "right"), ("F", "right"), ("p", "right"), ("significant", "left")):
            t.add_column(col, justify=just)
        for term in res.terms.values():
            if term.pooled:
                t.add_row(term.name, f"{term.coefficient:.{digits}g}", str(term.df), f"{term.ss:.4g}",
                          "", "", "pooled")
            else:
                t.add_row(term.name, f"{term.coefficient:.{digits}g}", str(term.df), f"{term.ss:.4g}",
                          f"{term.F:.4g}", f"{term.p:.4f}", "yes" if term.significant else "no")
        t.add_row("error", "", str(res.error_df), f"{res.error_ss:.4g}", "", "", "")
        con.print(t)
        con.print(f"Error: {res.error_source}.", highlight=False, soft_wrap=True)
        if res.note:
            con.print(f"Note: {res.note}.", highlight=False, soft_wrap=True)
        r2 = "" if res.r2_reduced is None else f" (R^2 = {res.r2_reduced:.4f})"
        con.print(f"Reduced model, significant terms only{r2}:", highlight=False, soft_wrap=True)
        con.print(matrix_form(res, digits), highlight=False, markup=False, soft_wrap=True)
