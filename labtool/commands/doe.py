"""``labtool doe run`` and ``labtool doe analyze``: the simulated experiment (paper sec. 2.2, 3.1).

``run`` simulates every run of a full factorial (Table 1 by default) and writes a CSV shaped like
Tables 2/3 plus a NetCDF with the factors as coordinates. ``analyze`` reads such a CSV and prints
the ANOVA (Fisher's F) and the reduced effect models in the paper's matrix form (eqs 20-28).
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import List, Optional

import typer

from common.files import atomic_write, check_output_path, write_netcdf
from common.names import shown

doe_app = typer.Typer(
    help="Simulated experiments: full factorial runs (Tables 2-3) and their ANOVA (eqs 20-28).",
    no_args_is_help=True,
)


def register(app: typer.Typer) -> None:
    app.add_typer(doe_app, name="doe")


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
    scheduler: Optional[str] = typer.Option(None, help="Dask scheduler address (tcp://host:8786); "
                                                       "default: local processes"),
    workers: Optional[int] = typer.Option(None, help="local worker processes (default: all cores; 1 = in-process)"),
    netcdf: Optional[Path] = typer.Option(None, help="NetCDF to write (default: the CSV's name with .nc)"),
    force: bool = typer.Option(False, help="overwrite existing output files"),
) -> None:
    """Simulate the full factorial of the factors and write the results table and its NetCDF."""
    from models.study.doe import read_factors, responses_for, run_design, table1_factors
    from common.errors import SolverError
    from models.dynamics.scene import Scene

    responses_for(model)
    nc_path = netcdf if netcdf is not None else output.with_suffix(".nc")
    if nc_path == output:
        raise typer.BadParameter("the NetCDF path must differ from the CSV path", param_hint="--netcdf")
    for p in (output, nc_path):
        check_output_path(p, force)
    if workers is not None and workers < 1:
        raise typer.BadParameter(f"must be >= 1, got {workers}", param_hint="--workers")
    fset = read_factors(factors) if factors is not None else table1_factors()
    base = Scene(law=law, omega1_mode=omega1, accuracy=accuracy, elastic_gap=elastic_gap)
    n_runs = math.prod(len(f.levels) for f in fset)

    from labtool.output import console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
    err = console(stderr=True)
    with Progress(TextColumn(f"doe run ({model})"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  console=err, disable=not err.is_terminal, transient=True) as bar:
        task = bar.add_task("runs", total=n_runs)
        result = run_design(fset, base, model, workers=workers, scheduler=scheduler,
                            progress=lambda done, total: bar.update(task, completed=done))

    table = result.table()
    for c in ("jumps", "impacts"):  # counts print as integers when every run has one
        if c in table and table[c].notna().all():
            table[c] = table[c].round().astype(int)
    atomic_write(output, lambda tmp: table.to_csv(tmp, index=False, float_format="%.10g"))
    ds = result.dataset()
    ds.attrs["history"] = (f"labtool doe run --model {model} --law {law} --omega1 {omega1} "
                           f"--accuracy {accuracy}" + (f" --elastic-gap {elastic_gap}" if model == "elastic" else "")
                           + (f" --factors {factors}" if factors else ""))
    write_netcdf(ds, nc_path)
    if len(table) <= 64:  # the table itself, as in the paper; large designs only get the summary line
        gap_note = f", gap {elastic_gap}" if model == "elastic" else ""
        _print_results(table, f"{model} model, {law} law, omega1 {omega1}, accuracy {accuracy}{gap_note}")
    typer.echo(f"wrote {output} and {nc_path}: {n_runs} runs of the {model} model "
               f"({result.where}, {result.wall_s:.1f} s)")
    if model == "elastic" and elastic_gap == "physical":
        typer.echo("note: the follower crosses the backlash here; the paper's Table 3 counts (1 jump, 0 impacts) "
                   "come from --elastic-gap closed (docs/models.md)")
    if result.failures:
        first = min(result.failures)
        raise SolverError(f"{len(result.failures)} of {n_runs} runs failed and are left empty in {output} "
                          f"(run {first}: {result.failures[first]})")


def _print_results(table, title: str) -> None:
    from rich.table import Table

    from labtool.output import console

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
    digits: int = typer.Option(7, help="significant digits of the printed coefficients"),
    force: bool = typer.Option(False, help="overwrite an existing plot file"),
) -> None:
    """Effects in the paper's +-1 coding, ANOVA with Fisher's F, reduced models (eqs 20-28)."""
    from models.study import anova

    anova.check_alpha(alpha)
    if not 1 <= digits <= 17:
        raise typer.BadParameter(f"must lie in 1..17, got {digits}", param_hint="--digits")
    if plot is not None:
        check_output_path(plot, force)
    data = anova.read_results(results)
    out = anova.analyze(data, alpha=alpha, max_order=max_order, responses=response)
    if plot is not None:
        atomic_write(plot, lambda tmp: plot_effects(data, out, tmp))
    if json_out:
        typer.echo(json.dumps(anova.to_json(out)))
        return
    _print_text(data, out, digits)
    if plot is not None:
        typer.echo(f"wrote {plot}")


def _print_text(data, out, digits: int) -> None:
    from rich.table import Table

    from labtool.output import console
    from models.study.anova import matrix_form

    con = console()
    names = ", ".join(f"{f.name} = {f.symbol} ({len(f.levels)} levels)" for f in data.factors)
    con.print(f"{data.source}: {len(data.frame)} runs, full factorial of {names}, "
              f"{data.replicates} run(s) per level combination", highlight=False, soft_wrap=True)
    con.print("Coding: effect at level 1 = mean at level 1 - grand mean (the paper's +-1 coding, level 1 -> +1); "
              "A_X is the level-indicator vector of factor X.", highlight=False, soft_wrap=True)
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


def plot_effects(data, out, path: Path) -> None:
    """One row per response: main effects (mean at each level of each factor, Minitab style) and
    one interaction panel per pair of factors (cell means); significant terms are drawn solid."""
    import itertools

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from models.study.anova import RESPONSE_UNITS, cell_means

    factors = data.factors
    pairs = list(itertools.combinations(range(len(factors)), 2))
    ncol = 1 + len(pairs)
    nrow = len(out)
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.0 + 2.4 * ncol, 2.6 * nrow), squeeze=False)
    for row, (resp, res) in enumerate(out.items()):
        m = cell_means(data, resp)
        ax = axes[row][0]
        x0, ticks, labels = 0, [], []
        for i, f in enumerate(factors):
            other = tuple(a for a in range(m.ndim) if a != i)
            means = m.mean(axis=other) if other else m
            xs = np.arange(x0, x0 + len(f.levels))
            sig = res.terms[f.name].significant
            ax.plot(xs, means, "o-" if sig else "o--", color=f"C{i}", label=f"{f.name} ({f.symbol})")
            ticks += list(xs)
            labels += [f"{f.name}{k + 1}" for k in range(len(f.levels))]
            x0 += len(f.levels) + 1
        ax.axhline(res.mean, color="0.5", lw=0.8)
        ax.set_xticks(ticks, labels, fontsize=6)
        ax.set_ylabel(f"{resp} [{RESPONSE_UNITS.get(resp, '')}]", fontsize=8)
        ax.set_title("main effects (solid: significant)", fontsize=8)
        ax.legend(fontsize=6, loc="best")
        for j, (a, b) in enumerate(pairs, 1):
            ax = axes[row][j]
            other = tuple(k for k in range(m.ndim) if k not in (a, b))
            cm = m.mean(axis=other) if other else m
            name = factors[a].name + factors[b].name
            term = res.terms.get(name)
            style = "-" if term is not None and term.significant else "--"
            for lb in range(cm.shape[1]):
                ax.plot(np.arange(1, cm.shape[0] + 1), cm[:, lb], "o" + style, label=f"{factors[b].name}{lb + 1}")
            ax.set_xticks(np.arange(1, cm.shape[0] + 1))
            ax.set_xlabel(f"{factors[a].name} ({factors[a].symbol}) level", fontsize=7)
            ax.set_title(f"{name}" + (" (pooled)" if term is not None and term.pooled else
                                      " *" if term is not None and term.significant else ""), fontsize=8)
            ax.tick_params(labelsize=6)
            ax.legend(fontsize=6)
    # the file name is text, not mathtext ('$x^$' in a name raised a ParseException) nor markup
    fig.suptitle(f"{shown(data.source)}: main effects and two-factor interactions (cell means)", fontsize=9,
                 parse_math=False)
    fig.tight_layout()
    fig.savefig(path, format="png", dpi=90)
    plt.close(fig)
