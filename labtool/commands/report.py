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
from labtool.common.files import check_outputs
from labtool.options import given, op_option

PROBE_ABOVE_REVOLUTIONS = 20     # the default 6 takes well under a minute: no estimate needed


def register(app: typer.Typer) -> None:
    app.command("report")(report)


def _check_budget(models, modes, accuracy, revolutions, robustness, max_seconds) -> None:
    """Estimate the simulations of a long report from each dynamic model at 2 and 4 revolutions
    (the paper's operating point; the file's may differ, so this is an order of magnitude) times
    the runs it makes (models x omega1 modes, x2 with the robustness check at the other preset)."""
    from labtool.models.dynamics.scene import Scene
    from labtool.models.dynamics.simulate import simulate

    seconds, peak, bases = 0.0, 0.0, []
    for model in [m for m in models if m in ("rigid", "elastic")]:
        scene = Scene(accuracy=accuracy, rise_only=False)
        est = budget.probe_linear(lambda n: simulate(scene.replace(revolutions=float(n)), model).dataset,
                                  (2, 4), revolutions, "revolution", nbytes=lambda ds: 2.0 * ds.nbytes)
        runs = len(modes) * (2 if robustness else 1)
        seconds += runs * est.seconds
        peak = max(peak, est.bytes * len(modes))
        bases.append(f"{model}: {est.basis}, {runs} runs")
    if seconds > 0:
        from labtool.output import terminal_confirm

        budget.check(budget.Estimate(seconds, peak, "; ".join(bases)), f"--revolutions {revolutions}", max_seconds,
                     "use fewer --revolutions", terminal_confirm())


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
    from labtool.output import ProgressLines, console

    from labtool.reports.align import Conditioning
    from labtool.reports.pipeline import build_report, headline, verdict_lines
    from labtool.reports.thresholds import load_thresholds

    from labtool.reports.outputs import curves_beside, write_report

    curve_paths = curves_beside(output) if curves else {}
    check_outputs({"-o": output, "--pdf": pdf, "--json": json_path,
                   **{f"curves ({f})": p for f, p in curve_paths.items()}}, force)
    budget.check_limit(max_seconds)
    if revolutions > PROBE_ABOVE_REVOLUTIONS:
        _check_budget(_split(models), _split(omega1), accuracy, revolutions, robustness, max_seconds)
    th = load_thresholds(thresholds) if thresholds else None
    fitted = None
    if fit:
        from labtool.identification.fit import load_fit
        fitted = [load_fit(p) for p in fit]
    cond = Conditioning(n_grid=grid, n_harmonics=harmonics)
    overrides = given(cam_speed=rpm, law=law, Fu=fu, backlash=backlash_mm, jt_factor=jt_factor,
                      restitution=restitution, contact_damping=contact_damping, contact_length=contact_length_mm,
                      kc_factor=kc_factor, elastic_gap=elastic_gap)
    err = console(stderr=True)
    quiet = json_path is not None and str(json_path) == "-"
    with (err.status("report") if err.is_terminal else ProgressLines(sys.stderr, "report")) as status:
        rep = build_report(measured, _split(models), _split(omega1), th, overrides, accuracy, revolutions, cond,
                           progress=lambda msg: status.update(msg), robustness=robustness, fitted=fitted,
                           discriminate=discriminate)
        # the HTML, PDF, JSON and curves are one set: all written, or none (a full disk, Ctrl-C)
        text = write_report(rep, output, pdf, json_path, progress=lambda msg: status.update(msg), curves=curve_paths)
        if json_path is not None and str(json_path) == "-":
            typer.echo(text)
    if not quiet:
        for row in headline(rep):
            typer.echo(f"{row['label']:28s} omega2 ISO {row['omega2_iso_rating']:.3f} ({row['omega2_iso_grade']}), "
                       f"epsilon2 ISO {row['epsilon2_iso_rating']:.3f} ({row['epsilon2_iso_grade']})")
        for line in verdict_lines(rep):
            typer.echo(line)
        for n in rep.notes:
            typer.echo(f"note: {n}")
        typer.echo(f"wrote {output}" + (f", {pdf}" if pdf else "") + (f", {json_path}" if json_path else "")
                   + "".join(f", {p}" for p in curve_paths.values()))
    failed = [r for r in rep.threshold_rows if not r["passed"]]
    if failed:
        typer.echo(f"labtool: {len(failed)} of {len(rep.threshold_rows)} threshold checks failed "
                   f"(first: {failed[0]['requested_model']} {failed[0]['omega1']}: {failed[0]['limit']}, "
                   f"value {failed[0]['value']:.4g})", err=True)
        raise typer.Exit(1)
