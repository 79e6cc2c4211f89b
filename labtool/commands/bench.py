"""``labtool bench accuracy``: work-precision of the dynamic models' solvers and presets.

Runs ``benchmarks/work_precision.py`` of the source checkout (error in omega2, MR13D, event times
and event count against the reference solution, vs wall time; CSV + PNG + JSON summary) and prints
the worst error of each preset and the speed-up of ``standard`` over scipy DOP853 at the same
achieved accuracy. Speed is measured here, never asserted in tests.
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

import typer

from labtool.common.errors import InputError

bench_app = typer.Typer(help="Benchmarks: solver work-precision (accuracy vs wall time).", no_args_is_help=True)

BENCH_DIR = Path(__file__).resolve().parents[2] / "benchmarks"


def register(app: typer.Typer) -> None:
    app.add_typer(bench_app, name="bench")


def _load_work_precision():
    path = BENCH_DIR / "work_precision.py"
    if not path.is_file():
        raise InputError(f"{path} not found: 'labtool bench' runs from a source checkout of labtool")
    spec = importlib.util.spec_from_file_location("labtool_work_precision", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def parse_runs(text: str) -> list[int]:
    """'1,5,12' -> [1, 5, 12]; each a Table 1 run number 1..16 (InputError otherwise)."""
    runs = []
    for item in filter(None, (s.strip() for s in text.split(","))):
        try:
            n = int(item)
        except ValueError:
            raise InputError(f"--runs: '{item}' is not a run number (1..16)") from None
        if not 1 <= n <= 16:
            raise InputError(f"--runs: run {n} is not in Table 1 (1..16)")
        runs.append(n)
    return runs


@bench_app.command("accuracy")
def accuracy(
    runs: str = typer.Option("1,8,12,16", help="Table 1 runs for the presets, e.g. 1,5,12 ('' = all 16)"),
    ladder_runs: str = typer.Option("1,12", help="Table 1 runs for the tolerance ladders"),
    models: str = typer.Option("rigid,elastic", help="models to measure: rigid, elastic"),
    output: Path = typer.Option(Path("benchmarks/results"), "-o", "--output", help="directory for CSV, PNG, JSON"),
    one_core: bool = typer.Option(True, "--one-core/--all-cores", help="pin the process to one core while measuring"),
) -> None:
    """Work-precision data of every model x solver x tolerance (CSV, PNG) and the presets' errors."""
    names = [m.strip() for m in models.split(",") if m.strip()]
    bad = [m for m in names if m not in ("rigid", "elastic")]
    if bad or not names:
        raise InputError(f"--models: unknown model(s) {', '.join(bad) or '(none)'}; known: rigid, elastic")
    run_list, ladder_list = parse_runs(runs), parse_runs(ladder_runs)
    if output.exists() and not output.is_dir():
        raise InputError(f"--output {output} exists and is not a directory")
    wp = _load_work_precision()
    argv = ["--runs", ",".join(map(str, run_list)), "--ladder-runs", ",".join(map(str, ladder_list)),
            "--models", ",".join(names), "--out", str(output)] + ([] if one_core else ["--all-cores"])
    summary = wp.main(argv, quiet=True)
    _print_summary(summary, names, output)


def _print_summary(summary: dict, names: list, output: Path) -> None:
    """Each preset's worst errors as a table, then the speed-up over scipy DOP853 per model."""
    from rich.markup import escape
    from rich.table import Table

    from labtool.output import console

    table = Table(title=f"Work-precision ({output}/work_precision.csv, .png)")
    for col in ("model", "preset", "err omega2", "err MR13D", "err t_event [s]", "d events", "err indicators",
                "loop [s]"):
        table.add_column(escape(col), justify="right")     # "[s]" is not rich markup
    for model in names:
        for preset, e in summary[model]["presets"].items():
            table.add_row(model, preset, f"{e['err_omega2']:.1e}", f"{e['err_MR13D']:.1e}", f"{e['err_event_time']:.1e}",
                          f"{e['d_events']:g}", f"{e['err_indicators']:.1e}", f"{e['loop_s_total']:.3f}")
    console = console()
    console.print(table)
    for model in names:
        sp = summary[model]["speedup_vs_DOP853"]
        if "loop_speedup" in sp:
            console.print(f"{model}: standard vs scipy DOP853 (rtol {sp['dop853_rtol']:g}, errors within "
                          f"{sp['same_accuracy_factor']:g}x): {sp['loop_speedup']:.0f}x (integration loop), "
                          f"{sp['wall_speedup']:.0f}x (whole simulate)", highlight=False)
        elif sp:
            console.print(f"{model}: {sp.get('note', '')}")
        ip = summary[model].get("speedup_vs_DOP853_interpolated", {})
        if "loop_speedup" in ip:
            console.print(f"{model}: standard vs scipy DOP853 interpolated to standard's own errors: "
                          f"{ip['loop_speedup']:.0f}x (integration loop), {ip['wall_speedup']:.0f}x (whole simulate)",
                          highlight=False)
        elif ip:
            console.print(f"{model}: {ip.get('note', '')}", highlight=False)
