"""``labtool fit``: identify a model's parameters from a measurement (labtool.identification.fit),
or from several at once (labtool.identification.joint).

Prints the identified parameters with their 95 % intervals, whether this measurement identifies
them, the objective and the grades before and after; ``-o fit.json`` writes the result (and the
figure beside it, ``fit.png``, unless ``--figure`` names another file); ``--json`` prints the
result as one JSON object on stdout. With several files the ``--shared`` parameters are fitted
once for all and the others per file, and the files' own estimates are tested against the joint
one. Exit 0: the fit ran (its notes say what it could not identify); exit 1: a joint fit whose
measurements disagree about a shared parameter beyond their intervals; exit 2: bad input or a
model that fails everywhere, one line, nothing written.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Optional

import typer

from labtool.options import given, op_option


def register(app: typer.Typer) -> None:
    app.command("fit")(fit)


def fit(
    measured: list[Path] = typer.Argument(..., help="measured.nc written by 'labtool process'; several files: a joint "
                                          "fit (--shared)"),
    model: str = typer.Option(..., help="model to identify: rigid or elastic"),
    free: str = typer.Option(..., help="parameters to identify, comma-separated: backlash [mm], restitution [-] (rigid), "
                             "contact_damping [s/m], contact_length [mm] (elastic), ka_gain [-] (true Ka / the Ka "
                             "processing used), delay [ms] (acceleration channels behind the tacho)"),
    omega1: str = typer.Option("const", "--omega1", help="cam speed of the model: const (cam as input) or var (motor "
                               "characteristic)"),
    accuracy: str = typer.Option("standard", help="solver preset of the final evaluation: fast or standard (the search "
                                 "always runs at fast)"),
    bounds: Optional[str] = typer.Option(None, help="search bounds in edge units, e.g. backlash=0.02:0.4,restitution=0:1 "
                                         "(default: backlash 0.01:0.6 mm, restitution 0:1, contact_damping 0:400 s/m, "
                                         "contact_length 1:30 mm, ka_gain 0.5:2, delay -5:5 ms)"),
    start: str = typer.Option("scan", help="scan (a coarse scan of the bounds, default), scene (the scene's values) or "
                              "name=value,... (edge units): searched from first, beside the scan's best points"),
    shared: Optional[str] = typer.Option(None, help="with several files: the free parameters fitted once for all "
                                         "of them, comma-separated (the others are fitted per file); default: those "
                                         "that are the stand's properties (backlash, contact_length, ka_gain, delay)"),
    scan: bool = typer.Option(True, "--scan/--no-scan", help="also search from the coarse scan's best points (with "
                              "--no-scan a given start alone: the answer may then depend on it)"),
    rpm: Optional[float] = op_option("cam_speed", default_note="default: the measured mean speed of the whole "
                                     "revolutions; a value more than 10 % off it is refused"),
    law: Optional[str] = op_option("law", file_first=True),
    fu: Optional[float] = op_option("Fu", file_first=True),
    jt_factor: Optional[float] = op_option("jt_factor", file_first=True),
    backlash_mm: Optional[float] = op_option("backlash", "fixed, or the search's start when free", file_first=True),
    restitution: Optional[float] = op_option("restitution", "fixed, or the search's start when free"),
    contact_damping: Optional[float] = op_option("contact_damping", "fixed, or the search's start when free"),
    contact_length_mm: Optional[float] = op_option("contact_length", "fixed, or the search's start when free"),
    kc_factor: Optional[float] = op_option("kc_factor"),
    elastic_gap: Optional[str] = op_option("elastic_gap"),
    ka_gain: float = typer.Option(1.0, help="true Ka / the Ka processing used [-] when not free"),
    delay_ms: float = typer.Option(0.0, help="delay of the acceleration channels behind the tacho [ms] when not free"),
    revolutions: int = typer.Option(3, help="cam revolutions each model run simulates [-] (the first is the start-up)"),
    max_runs: int = typer.Option(200, help="model runs the search may use before it stops [-]"),
    output: Optional[Path] = typer.Option(None, "-o", "--output", help="fit result to write (JSON)"),
    figure: Optional[Path] = typer.Option(None, help="figure of the fit and the profiles (PNG; default: beside -o)"),
    as_json: bool = typer.Option(False, "--json", help="print the result as one JSON object on stdout"),
    force: bool = typer.Option(False, help="overwrite existing output files"),
) -> None:
    """Identify backlash, restitution, contact damping/length, Ka gain or delay from a measurement:
    least squares of the model's cycle statistics against the measured ones, with 95 % intervals."""
    import labtool
    from labtool.api.fitting import figure_path
    from labtool.common.files import check_interrupted
    from labtool.identification.parameters import parse_assignments
    from labtool.output import ProgressLines, console

    overrides = given(cam_speed=rpm, law=law, Fu=fu, backlash=backlash_mm, jt_factor=jt_factor,
                      restitution=restitution, contact_damping=contact_damping, contact_length=contact_length_mm,
                      kc_factor=kc_factor, elastic_gap=elastic_gap)
    err = console(stderr=True)
    with (err.status("fit") if err.is_terminal else ProgressLines(sys.stderr, "fit")) as status:
        def progress(msg: str) -> None:
            check_interrupted()        # a Ctrl-C that Python dropped (in a weakref callback) stops the search here
            status.update(msg)
        outcome = labtool.fit(list(measured), model=model, free=free, shared=shared, omega1=omega1, accuracy=accuracy,
                              revolutions=revolutions, bounds=parse_assignments(bounds, "--bounds", ranges=True),
                              start=start if start in ("scan", "scene") else parse_assignments(start, "--start"),
                              scan=scan, max_runs=max_runs, ka_gain=ka_gain, delay_ms=delay_ms, output=output,
                              figure=figure, force=force, progress=progress, **overrides)
    joint = len(measured) > 1
    if as_json:
        typer.echo(json.dumps(outcome.summary, indent=1, allow_nan=False))
    else:
        for line in (joint_lines(outcome.summary) if joint else summary_lines(outcome.summary)):
            typer.echo(line)
        wrote = [str(p) for p in (output, figure_path(output, figure)) if p is not None]
        if wrote:
            typer.echo("wrote " + ", ".join(wrote))
    if joint and not outcome.summary["consistent"]:
        raise typer.Exit(1)


def _num(v, fmt=".4g") -> str:
    return "-" if v is None else format(v, fmt)


def _verdict(p: dict) -> str:
    """A parameter's verdict as a line prints it."""
    if not p["identifiable"]:
        return "NOT identifiable: " + "; ".join(p["notes"])
    if p.get("misfit"):
        return "NOT the stand's: " + "; ".join(n for n in p["notes"] if n.startswith("misfit"))
    return "identified"


def summary_lines(s: dict) -> list[str]:
    """The result in plain lines: each parameter with its interval and verdict, then the fit."""
    lines = [f"{s['model']} model, omega1 {s['omega1']}, {s['accuracy']} preset (search at {s['search_accuracy']}), "
             f"{s['measured']['whole_revolutions']} measured revolutions"]
    for key, p in s["parameters"].items():
        lo, hi = p["ci95"]
        bound = f", at its {p['bound']} bound" if p["bound_hit"] else ""
        lines.append(f"  {key:24s} {_num(p['value']):>10s}  95 % [{_num(lo)}, {_num(hi)}]{bound}  {_verdict(p)}")
    names = list(s["correlation"])
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            lines.append(f"  correlation {a} / {b}: {_num(s['correlation'][a][b], '+.3f')}")
    ob, oa = s["objective_before"], s["objective_after"]
    lines.append(f"objective {_num(ob)} -> {_num(oa)} ({s['degrees_of_freedom']:.0f} effective degrees of freedom), "
                 f"{s['evaluations']} model runs, {s['wall_s']:.1f} s")
    for sig in ("omega2", "epsilon2"):
        b, a = s["metrics_before"], s["metrics_after"]
        before = "-" if b is None else f"{b[sig]['iso_rating']:.3f} ({b[sig]['iso_grade']})"
        lines.append(f"  {sig:9s} ISO before {before}, after {a[sig]['iso_rating']:.3f} ({a[sig]['iso_grade']})")
    ev = s["metrics_after"]["events"]
    if ev.get("measured_impacts_per_rev") is not None:
        lines.append(f"  events: measured {_num(ev['measured_impacts_per_rev'], '.2f')} visible impacts/rev, first at "
                     f"{_num(ev['measured_first_impact_deg'], '.1f')} deg; fitted model {_num(ev['impacts_per_rev'], '.2f')}, "
                     f"first at {_num(ev['first_impact_deg'], '.1f')} deg")
    for n in s["notes"]:
        lines.append(f"note: {n}")
    return lines


def _interval(lo, hi) -> str:
    return f"[{_num(lo)}, {_num(hi)}]"


def joint_lines(s: dict) -> list[str]:
    """A joint fit in plain lines: each shared parameter, the files' own estimates and the test,
    then each file's own parameters."""
    lines = [f"{s['model']} model, omega1 {s['omega1']}, {s['accuracy']} preset, joint fit of {len(s['files'])} "
             f"measurements (shared: {', '.join(s['shared'])}; per file: {', '.join(s['per_file']) or '-'})"]
    for key, p in s["parameters"].items():
        lines.append(f"  {key:24s} {_num(p['value']):>10s}  95 % {_interval(*p['ci95'])}  {_verdict(p)}")
        if p["ci95"] != p["ci95_joint"]:
            lines.append(f"  {'':24s} {'':>10s}  (joint fit alone: {_interval(*p['ci95_joint'])})")
        for f in s["consistency"][key]["files"]:
            lines.append(f"    {f['file']} ({_num(f['cam_speed_rpm'], '.1f')} rpm) alone: {_num(f['value'])} "
                         f"{_interval(*f['ci95'])}{'' if f['identifiable'] else ' (not identifiable)'}")
        lines.append(f"    {s['consistency'][key]['verdict']}")
    for f, own in zip(s["files"], s["per_file_parameters"]):
        for key, p in own.items():
            lines.append(f"  {f}: {key} {_num(p['value'])} 95 % {_interval(*p['ci95'])} ({p['verdict']})")
    lines.append(f"objective {_num(s['objective_after'])} ({s['degrees_of_freedom']:.0f} effective degrees of freedom), "
                 f"{s['evaluations']} model runs, {s['wall_s']:.1f} s")
    for n in s["notes"]:
        lines.append(f"note: {n}")
    return lines
