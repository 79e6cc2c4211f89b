"""``labtool report``: model vs measurement, as one self-contained HTML file (+ PDF, + JSON summary).

Exit 0: report written and every threshold holds (or none given); exit 1: report written and a
threshold failed; exit 2: bad input (one line on stderr), nothing written.
"""
from __future__ import annotations

import sys
from pathlib import Path
from typing import List, Optional

import typer

from labtool.common import budget
from labtool.options import given, op_option


def register(app: typer.Typer) -> None:
    app.command("report")(report)


def _split(value: str) -> list[str]:
    return [v.strip() for v in value.split(",") if v.strip()]


def report(
    measured: Path = typer.Argument(..., help="measured.nc written by 'labtool process'"),
    output: Path = typer.Option(..., "-o", "--output", help="HTML report to write (self-contained)"),
    models: str = typer.Option("rigid,elastic", help="models to compare, comma-separated: rigid, elastic, kinematic"),
    omega1: str = typer.Option("const,var", "--omega1", help="cam speed modes, comma-separated: const, var"),
    thresholds: Optional[Path] = typer.Option(None, help="TOML file of limits on the metrics (exit 1 if one fails)"),
    pdf: Optional[Path] = typer.Option(None, "--pdf", help="also write the report as PDF"),
    json_path: Optional[Path] = typer.Option(None, "--json", help="also write the JSON summary to this file ('-' = stdout)"),
    rpm: Optional[float] = op_option("cam_speed", default_note="default: the measured mean speed of the whole "
                                     "revolutions; a value more than 10 % off it is refused"),
    law: Optional[str] = op_option("law", file_first=True),
    fu: Optional[float] = op_option("Fu", file_first=True),
    backlash_mm: Optional[float] = op_option("backlash", file_first=True),
    jt_factor: Optional[float] = op_option("jt_factor", file_first=True),
    restitution: Optional[float] = op_option("restitution"),
    contact_damping: Optional[float] = op_option("contact_damping"),
    contact_length_mm: Optional[float] = op_option("contact_length"),
    kc_factor: Optional[float] = op_option("kc_factor"),
    elastic_gap: Optional[str] = op_option("elastic_gap"),
    accuracy: str = typer.Option("standard", help="solver preset of the models: fast, standard, reference"),
    revolutions: int = typer.Option(6, help="cam revolutions to simulate [-]: the last one is compared when the model's "
                                    "motion is periodic, else the cycle statistics of revolutions 2..N"),
    robustness: bool = typer.Option(True, help="also check the verdict at the other solver preset and half the length"),
    harmonics: int = typer.Option(60, help="low-pass of both sides: harmonics of the cam frequency kept [-]"),
    grid: int = typer.Option(720, help="cam-angle grid points per revolution [-]"),
    fit: Optional[List[Path]] = typer.Option(None, "--fit", help="a 'labtool fit' result (fit.json): the identified "
                                            "model is compared beside the nominal ones, as '<model> (fitted)'; repeatable"),
    curves: bool = typer.Option(True, help="also write the compared curves beside the page: <name>_curves.csv and "
                                "<name>_curves.nc (measured mean, std and each revolution, every model; rad/s, rad/s²)"),
    discriminate: bool = typer.Option(True, help="when the measurement cannot tell models apart, simulate them at a "
                                      "few cam speeds (fast preset) and name the speed [rpm] that would"),
    force: bool = typer.Option(False, help="overwrite existing output files"),
    max_seconds: float = typer.Option(budget.DEFAULT_MAX_SECONDS, help="refuse (on a terminal: ask) when the "
                                      "estimated run time of many --revolutions is longer [s]"),
) -> None:
    """Compare a measurement with the rigid and elastic models (omega1 constant and variable):
    Sprague & Geers, ISO/TS 18571, NRMSE, peak and timing errors, per revolution and overall."""
    import labtool
    from labtool.output import ProgressLines, console, terminal_confirm
    from labtool.reports.outputs import curves_beside
    from labtool.reports.pipeline import headline, verdict_lines

    overrides = given(cam_speed=rpm, law=law, Fu=fu, backlash=backlash_mm, jt_factor=jt_factor,
                      restitution=restitution, contact_damping=contact_damping, contact_length=contact_length_mm,
                      kc_factor=kc_factor, elastic_gap=elastic_gap)
    err = console(stderr=True)
    with (err.status("report") if err.is_terminal else ProgressLines(sys.stderr, "report")) as status:
        rep = labtool.report(measured, output, models=_split(models), omega1=_split(omega1), thresholds=thresholds,
                             pdf=pdf, json=json_path, accuracy=accuracy, revolutions=revolutions, robustness=robustness,
                             harmonics=harmonics, grid_points=grid, fits=fit or (), curves=curves,
                             discriminate=discriminate, force=force, max_seconds=max_seconds,
                             confirm=terminal_confirm(), progress=lambda msg: status.update(msg), **overrides)
    if json_path is not None and str(json_path) == "-":
        from labtool.reports.summary import to_json
        typer.echo(to_json(rep))
    else:
        for row in headline(rep):
            typer.echo(f"{row['label']:28s} omega2 ISO {row['omega2_iso_rating']:.3f} ({row['omega2_iso_grade']}), "
                       f"epsilon2 ISO {row['epsilon2_iso_rating']:.3f} ({row['epsilon2_iso_grade']})")
        for line in verdict_lines(rep) + [f"note: {n}" for n in rep.notes]:
            typer.echo(line)
        typer.echo(f"wrote {output}" + (f", {pdf}" if pdf else "") + (f", {json_path}" if json_path else "")
                   + "".join(f", {p}" for p in (curves_beside(output) if curves else {}).values()))
    failed = [r for r in rep.threshold_rows if not r["passed"]]
    if failed:
        typer.echo(f"labtool: {len(failed)} of {len(rep.threshold_rows)} threshold checks failed "
                   f"(first: {failed[0]['requested_model']} {failed[0]['omega1']}: {failed[0]['limit']}, "
                   f"value {failed[0]['value']:.4g})", err=True)
        raise typer.Exit(1)
