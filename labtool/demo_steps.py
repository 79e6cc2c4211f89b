"""The steps of ``labtool demo``, each writing into one output folder.

1. kinematics of the paper's mechanism at 180 rpm (table, NetCDF, plot);
2. the 16 runs of Table 1: kinematic MR13D against the paper's Table 3;
3. the simulated stand records the paper's experiment (sine law, Fu = 0 N, j = 0.128 mm, 180 rpm)
   with its default truth: ``labtool acquire --device sim --fast``;
4. ``labtool process`` turns it into measured.nc (omega2, epsilon2, cam angle, spectra);
5. ``labtool report``: the rigid and elastic models, omega1 constant and variable, against it,
   with labtool's default model options (the stand's restitution and contact damping,
   labtool.common.operating_point), the robustness check and the measured impacts.

A step that fails ends the demo with its error.
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.markup import escape  # paths are the user's, not markup
from rich.table import Table

from labtool.output import console as new_console
from labtool.common.files import write_netcdf
from labtool.common.operating_point import FIELD

# the paper's experiment (sec. 2.4 and 3.3) at the operating point's defaults
EXPERIMENT_RPM = FIELD["cam_speed"].default_edge
EXPERIMENT_BACKLASH_MM = FIELD["backlash"].default_edge
EXPERIMENT_FU_N = FIELD["Fu"].default_edge
RECORD_SECONDS = 3.0           # 9 cam revolutions at 180 rpm
DEMO_TEST_ID = "DEMO-180"      # what the report's title block and the curves' header show
DEMO_OPERATOR = "labtool demo"


def run_demo(out: Path, shown_as: Path | None = None):
    """Run every step writing into ``out``; returns the function that prints where the results
    are (called once they are in place; ``shown_as`` is the folder they are then in)."""
    console = new_console()
    t0 = time.perf_counter()
    kin_path = step_kinematics(out, console)
    table_path = step_table1_kinematic(out, console)
    recording = step_acquire(out, console)
    measured = step_process(out, console, recording)
    html, rows = step_report(out, console, measured, recording)
    elapsed = time.perf_counter() - t0

    def final(path: Path) -> Path:
        return (shown_as / path.relative_to(out)) if shown_as is not None else path

    def announce() -> None:
        console.print(f"\n[bold]demo done[/bold] in {elapsed:.0f} s: kinematics {escape(str(final(kin_path)))}, "
                      f"Table 1 comparison {escape(str(final(table_path)))}")
        console.print(f"[bold]report: {escape(str(final(html).resolve()))}[/bold]  (open it in a browser; "
                      "summary.json, report.pdf and the curves report_curves.csv, .nc beside it)", soft_wrap=True)
        for line in rows:
            console.print("  " + line, highlight=False, markup=False, soft_wrap=True)
    return announce


def _cli(args: list[str], step: str) -> None:
    """Run a labtool command; a non-zero exit ends the demo with the step's name."""
    from labtool.common.errors import LabtoolError
    from labtool.cli import main
    rc = main(args)
    if rc != 0:
        raise LabtoolError(f"demo step '{step}' failed (labtool {args[0]} exit {rc}); its message is above")


def step_kinematics(out: Path, console: Console) -> Path:
    from matplotlib.figure import Figure

    from labtool.models.mechanism.kinematics import analyze, rise_summary

    ds = analyze(rpm=180.0)
    s = rise_summary(ds)
    path = out / "kinematics_180rpm.nc"
    write_netcdf(ds, path)
    phi = np.degrees(ds["phi1"].values)
    fig = Figure(figsize=(8, 9), layout="constrained")
    axes = fig.subplots(4, 1, sharex=True)
    for ax, name, scale, unit in [(axes[0], "psi", 180 / math.pi, "deg"), (axes[1], "omega2", 1, "rad/s"),
                                  (axes[2], "epsilon2", 1, "rad/s²"), (axes[3], "MR13D", 1, "N·m")]:
        ax.plot(phi, ds[name].values * scale)
        ax.set_ylabel(f"{name} [{unit}]")
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("cam angle φ1 [deg]")
    fig.suptitle("Kinematics of the STB-216 yarn-catcher cam, sine law, 180 rpm")
    fig.savefig(out / "kinematics_180rpm.png", dpi=110)
    console.print(f"kinematics at 180 rpm: MR13D {s['MR13D_min_Nm']:.3f} .. {s['MR13D_max_Nm']:.3f} N m, "
                  f"omega2 max {s['omega2_max_rad_s']:.3f} rad/s, pressure angle max {s['pressure_angle_max_deg']:.1f} deg")
    return path


def step_table1_kinematic(out: Path, console: Console) -> Path:
    from labtool.models.study.paper import kinematic_vs_table3

    df = kinematic_vs_table3()
    path = out / "table1_kinematic_vs_table3.csv"
    df.to_csv(path, index=False)
    t = Table(title="Kinematic MR13D over the rise vs the paper's Table 3 (cam at the drive's no-load speed)")
    for col in ["run", "MR13D_max_Nm", "paper_max", "max_diff_pct", "MR13D_min_Nm", "paper_min", "min_diff_pct", "sign_change_matches"]:
        t.add_column(col, justify="right")
    for _, r in df.iterrows():
        t.add_row(str(int(r.run)), f"{r.MR13D_max_Nm:.3f}", f"{r.paper_max:.3f}", f"{r.max_diff_pct:+.1f}",
                  f"{r.MR13D_min_Nm:.3f}", f"{r.paper_min:.3f}", f"{r.min_diff_pct:+.1f}", str(bool(r.sign_change_matches)))
    console.print(t)
    return path


def step_acquire(out: Path, console: Console) -> Path:
    """The simulated stand (its default truth) records the paper's experiment."""
    path = out / "recording_180rpm.h5"
    path.unlink(missing_ok=True)
    console.print(f"[bold]acquisition on the simulated stand[/bold] (default truth): sine law, Fu = {EXPERIMENT_FU_N:g} N, "
                  f"j = {EXPERIMENT_BACKLASH_MM} mm, {EXPERIMENT_RPM:g} rpm, {RECORD_SECONDS:g} s at 10 kHz (--fast)")
    _cli(["acquire", "--device", "sim", "--rpm", f"{EXPERIMENT_RPM:g}", "--duration", f"{RECORD_SECONDS:g}",
          "--fast", "--seed", "1", "--law", "sine", "--fu", f"{EXPERIMENT_FU_N:g}",
          "--backlash-mm", f"{EXPERIMENT_BACKLASH_MM:g}", "--test-id", DEMO_TEST_ID, "--operator", DEMO_OPERATOR,
          "-o", str(path)], "acquire")
    return path


def step_process(out: Path, console: Console, recording: Path) -> Path:
    path = out / "measured_180rpm.nc"
    path.unlink(missing_ok=True)
    console.print(f"[bold]processing (labtool process)[/bold]: {escape(recording.name)} -> {escape(path.name)}")
    _cli(["process", str(recording), "-o", str(path)], "process")
    return path


def step_report(out: Path, console: Console, measured: Path, recording: Path) -> tuple[Path, list[str]]:
    """The report: both models, both omega1 modes, 'fast' preset, with the robustness check."""
    from labtool.reports.outputs import write_report
    from labtool.reports.pipeline import build_report, headline, verdict_lines

    html_path, json_path, pdf_path = out / "report.html", out / "summary.json", out / "report.pdf"
    console.print(f"[bold]report[/bold]: {escape(measured.name)} against the rigid and elastic models, omega1 constant and "
                  "variable, with labtool's default model options")
    rep = build_report(measured, ("rigid", "elastic"), ("const", "var"), accuracy="fast",
                       progress=lambda msg: console.print(f"  {msg}", highlight=False), stand_in_on_failure=True)
    # the page, the PDF, the JSON and the curves (report_curves.csv, .nc) as one set
    write_report(rep, html_path, pdf_path, json_path)
    rows = [f"measured: {len(rep.cycles.revolutions)} whole revolutions at {rep.cycles.cam_speed_rpm:.1f} rpm "
            f"({rep.measured.attrs.get('source', 'recording')})"]
    for h in headline(rep):
        rows.append(f"{h['label']:36s} omega2: ISO {h['omega2_iso_rating']:.2f} ({h['omega2_iso_grade']}), "
                    f"S&G C {h['omega2_sg_comprehensive']:.2f}; epsilon2: ISO {h['epsilon2_iso_rating']:.2f} "
                    f"({h['epsilon2_iso_grade']}), S&G C {h['epsilon2_sg_comprehensive']:.2f}; {h['motion']}")
    rows += verdict_lines(rep)
    rows += [f"note: {n}" for n in rep.notes]
    return html_path, rows
