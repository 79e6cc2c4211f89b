"""``labtool suggest``: the operating point to record next (labtool.identification.design).

``--goal identify``: fits the measurements given (one alone, several jointly) and rates candidate
cam speeds and loads by how much a recording there would narrow the shared parameters' intervals;
``--goal discriminate``: where the candidate models' predictions differ most against the
measurement's scatter. Prints the point, the expected gain and a ``[[points]]`` snippet for a
campaign plan; ``-o next.json`` writes the result and the figure of the criterion against speed
beside it (``next.png``, or ``--figure``). Exit 0: a point was suggested; exit 2: bad input, one
line, nothing written.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Optional

import typer



def register(app: typer.Typer) -> None:
    app.command("suggest")(suggest)


def suggest(
    measured: list[Path] = typer.Argument(..., help="measured.nc files written by 'labtool process' (one or more)"),
    goal: str = typer.Option("identify", help="identify: the point whose recording is expected to narrow the shared intervals most; "
                             "discriminate: where the --models' predictions differ most against the measured scatter"),
    model: str = typer.Option("rigid", help="the model whose parameters are identified: rigid or elastic"),
    models: str = typer.Option("rigid,elastic", help="--goal discriminate: the models to tell apart; --goal identify: the first "
                                                     "other than --model scales the misfit expected at each candidate "
                                                     "(--models with --model alone: none), comma-separated"),
    free: str = typer.Option("backlash,restitution", help="the parameters identified, comma-separated (as labtool fit "
                             "--free)"),
    shared: Optional[str] = typer.Option(None, help="the free parameters every recording shares (the others are each "
                                         "recording's own); default: the stand's properties (backlash, "
                                         "contact_length, ka_gain, delay)"),
    rpm_range: str = typer.Option("120:600:20", help="candidate cam speeds lo:hi:step [rpm], within the models' range"),
    loads: Optional[str] = typer.Option(None, help="candidate loads Fu, comma-separated [N] (default: the measured "
                                        "ones; at a load never measured the model may misfit far more than the "
                                        "expected gain assumes)"),
    accuracy: str = typer.Option("fast", help="solver preset of the fit and of the candidates' runs: fast or standard"),
    max_runs: int = typer.Option(200, help="model runs the fit's search may use [-]"),
    output: Optional[Path] = typer.Option(None, "-o", "--output", help="the suggestion to write (JSON)"),
    figure: Optional[Path] = typer.Option(None, help="figure of the criterion against speed (PNG; default: beside -o)"),
    as_json: bool = typer.Option(False, "--json", help="print the result as one JSON object on stdout"),
    force: bool = typer.Option(False, help="overwrite existing output files"),
) -> None:
    """Suggest the next operating point (cam speed, load) to record: where a recording would narrow
    the identified parameters' 95 % intervals most."""
    import labtool
    from labtool.api.fitting import result_files
    from labtool.output import ProgressLines, console

    figure = result_files(output, figure, force)
    lo_hi_step, load_values = _candidates(rpm_range, loads)
    err = console(stderr=True)
    with (err.status("suggest") if err.is_terminal else ProgressLines(sys.stderr, "suggest")) as status:
        outcome = labtool.suggest(list(measured), goal=goal, model=model, free=free, shared=shared,
                                  models=tuple(m.strip() for m in models.split(",") if m.strip()),
                                  rpm_range=lo_hi_step, loads=load_values, accuracy=accuracy, max_runs=max_runs,
                                  output=output, figure=figure, force=force, progress=lambda msg: status.update(msg))
    if as_json:
        typer.echo(json.dumps(outcome.summary, indent=1, allow_nan=False))
        return
    for line in summary_lines(outcome.summary):
        typer.echo(line)
    wrote = [str(p) for p in (output, figure) if p is not None]
    if wrote:
        typer.echo("wrote " + ", ".join(wrote))


def _candidates(rpm_range: str, loads: Optional[str]):
    """--rpm-range lo:hi[:step] [rpm] and --loads [N] as numbers; InputError naming the option."""
    from labtool.common.errors import InputError

    parts = rpm_range.split(":")
    try:
        lo, hi, step = (float(v) for v in parts) if len(parts) == 3 else (float(parts[0]), float(parts[1]), 20.0)
    except ValueError:
        raise InputError(f"--rpm-range must be lo:hi:step in rpm (e.g. 120:600:20), got '{rpm_range}'") from None
    if loads is None:
        return (lo, hi, step), None
    try:
        load_values = tuple(float(v) for v in loads.split(",") if v.strip())
    except ValueError:
        raise InputError(f"--loads must be numbers in N, comma-separated (e.g. 0,65), got '{loads}'") from None
    if not load_values:
        raise InputError("--loads names no load; give e.g. --loads 0,65")
    return (lo, hi, step), load_values


def summary_lines(s: dict) -> list[str]:
    """The suggestion in plain lines: today's intervals, the point, the gain, the best candidates."""
    if s["goal"] == "discriminate":
        return _discriminate_lines(s)
    p = s["point"]
    lines = [f"{s['model']} model, shared {', '.join(s['shared'])}; measured: "
             + ", ".join(f"{m['cam_speed_rpm']:.1f} rpm (Fu = {m['Fu_N']:g} N)" for m in s["measured"])]
    for k, c in s["current"].items():
        lo, hi = c["ci95"]
        lines.append(f"  today: {k} = {c['value']:.4g}, 95 % [{lo:.4g}, {hi:.4g}]" if lo is not None and hi is not None
                     else f"  today: {k} = {c['value']:.4g}, no interval")
    lines.append(f"next point: {p['cam_speed_rpm']:g} rpm, Fu = {p['Fu_N']:g} N")
    lines.append(f"  {s['expected']['sentence']} (criterion {s['expected']['criterion']:.3g})")
    good = sorted((c for c in s["candidates"] if c["criterion"] is not None), key=lambda c: -c["criterion"])
    lines.append("  best candidates: " + ", ".join(f"{c['cam_speed_rpm']:g} rpm / {c['Fu_N']:g} N ({c['criterion']:.3g})"
                                                  for c in good[:5]))
    left = [c for c in s["candidates"] if c["error"] is not None]
    if left:
        lines.append(f"  left out: {len(left)} candidate(s) the model refused or doubted, or whose recording would "
                     f"clip (first: {left[0]['cam_speed_rpm']:g} rpm, Fu = {left[0]['Fu_N']:g} N: {left[0]['error']})")
    lines.append("a campaign plan takes it as its next point:")
    lines += ["  " + line for line in s["plan_points_toml"].strip().splitlines()]
    return lines


def _discriminate_lines(s: dict) -> list[str]:
    p, m = s["point"], s["measured"][0]
    lines = [f"models {', '.join(s['models'])}; measured: {m['cam_speed_rpm']:.1f} rpm (Fu = {m['Fu_N']:g} N)",
             f"next point: {p['cam_speed_rpm']:g} rpm, Fu = {p['Fu_N']:g} N",
             f"  {s['expected']['sentence']}"]
    good = sorted((c for c in s["candidates"] if c["epsilon2_distance"] is not None),
                  key=lambda c: -c["epsilon2_distance"])
    lines.append("  best candidates: " + ", ".join(f"{c['cam_speed_rpm']:g} rpm / {c['Fu_N']:g} N "
                                                  f"({c['epsilon2_distance']:.3g})" for c in good[:5]))
    for what, why in s["failed"].items():
        lines.append(f"  {what} failed at {why}")
    lines.append("a campaign plan takes it as its next point:")
    lines += ["  " + line for line in s["plan_points_toml"].strip().splitlines()]
    return lines
