"""``labtool simulate``: one scene through any model level (kinematic, rigid, elastic, auto).

Dispatches through ``labtool.models.dynamics.simulate.simulate(scene, model)``; prints the paper's indicators as a
table, or with ``--json`` one JSON object (docs/architecture.md: the indicator keys of Tables 2-3, then
``model``, ``accuracy``, ``wall_s``); prints the model's validity warnings on stderr
(``labtool: warning: ...``); writes the time series as NetCDF with ``-o``, with the whole scene,
the mechanism's source and labtool's version among its attributes (labtool.models.dynamics.provenance) and
the command line in ``history``.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Optional

import typer

from labtool.common import budget
from labtool.common.files import check_output_path, write_netcdf
from labtool.common.units import MM

PROBE_ABOVE_REVOLUTIONS = 10       # smaller requests take seconds: no estimate needed


def register(app: typer.Typer) -> None:
    app.command("simulate")(simulate)


def _json_value(v):
    if v is None:
        return None
    if isinstance(v, (bool, int)):
        return v
    v = float(v)
    return v if math.isfinite(v) else None


def simulate(
    model: str = typer.Option("auto", help="model level: auto, kinematic, rigid, elastic"),
    law: Optional[str] = typer.Option(None, help="motion law: sine, cosine, poly345, poly4567, modtrap, modsine "
                                      "(default: the mechanism's [program] law, sine for the STB-216)"),
    rpm: float = typer.Option(180.0, help="nominal cam speed n1 [rpm]"),
    fu: float = typer.Option(0.0, "--fu", help="load Fu at point N [N], opposing the rod's sliding"),
    backlash_mm: float = typer.Option(0.016, help="groove backlash j [mm]"),
    jt_factor: float = typer.Option(1.0, help="inertia factor of the follower side Jt [-] (paper: 1 or 4)"),
    omega1: str = typer.Option("var", help="cam speed: var (motor characteristic, eq. 3) or const (cam as input at n1)"),
    accuracy: str = typer.Option("standard", help="solver preset: fast, standard, reference"),
    restitution: float = typer.Option(1.0, help="Newton's restitution coefficient k in [0, 1] (rigid model)"),
    revolutions: float = typer.Option(1.0, help="cam revolutions to simulate [-]"),
    contact_length_mm: float = typer.Option(6.0, help="roller-groove contact length lw [mm] for Kc = 8.05e4 lw^(8/9) (elastic model)"),
    kc_factor: float = typer.Option(1.0, help="multiplier of the contact stiffness Kc [-] (elastic model)"),
    contact_damping: float = typer.Option(0.0, help="Hunt-Crossley contact damping [s/m]; 0 = none, as in the paper (elastic model)"),
    elastic_gap: str = typer.Option("physical", help="how the backlash enters the elastic model: physical (the follower "
                                                     "crosses the gap j) or closed (no gap: the convention of the paper's Table 3)"),
    rise_only: bool = typer.Option(True, "--rise-only/--full-cycle",
                                   help="simulate the rise only (as the paper's tables) or whole revolutions"),
    mechanism: Optional[Path] = typer.Option(None, help="mechanism TOML file (default: the paper's STB-216)"),
    output: Optional[Path] = typer.Option(None, "-o", "--output", help="NetCDF file to write (SI units)"),
    as_json: bool = typer.Option(False, "--json", help="print the indicators as one JSON object on stdout"),
    force: bool = typer.Option(False, help="overwrite an existing output file"),
    max_seconds: float = typer.Option(budget.DEFAULT_MAX_SECONDS, help="refuse (on a terminal: ask) when the "
                                      "estimated run time of many --revolutions is longer [s]"),
) -> None:
    """Simulate the mechanism at one operating point and report the jump indicators."""
    from labtool.common.errors import InputError
    from labtool.models.dynamics.scene import Scene
    from labtool.models.dynamics.simulate import INDICATORS
    from labtool.models.dynamics.simulate import simulate as run
    from labtool.models.mechanism import Mechanism

    if output is not None:
        check_output_path(output, force)
    for name, value in (("--rpm", rpm), ("--fu", fu), ("--backlash-mm", backlash_mm), ("--jt-factor", jt_factor),
                        ("--restitution", restitution), ("--revolutions", revolutions),
                        ("--contact-length-mm", contact_length_mm), ("--kc-factor", kc_factor),
                        ("--contact-damping", contact_damping)):
        if not math.isfinite(value):
            raise InputError(f"{name} must be a finite number, got {value}")
    mech = Mechanism.from_toml(mechanism) if mechanism else Mechanism.default()
    if law is None:     # the file's [program] law: it was replaced by "sine" without a word
        law = mech.program.get("law", "sine")
    scene = Scene(law=law, cam_speed_rpm=rpm, Fu=fu, backlash=backlash_mm * MM, jt_factor=jt_factor,
                  omega1_mode=omega1, restitution=restitution, accuracy=accuracy, revolutions=revolutions,
                  rise_only=rise_only, contact_length=contact_length_mm * MM, kc_factor=kc_factor,
                  contact_damping=contact_damping, elastic_gap=elastic_gap, mechanism=mech)
    budget.check_limit(max_seconds)
    if revolutions > PROBE_ABOVE_REVOLUTIONS:
        _check_budget(scene, model, revolutions, max_seconds, output is not None)
    result = run(scene, model)
    for warning in result.warnings:
        typer.echo(f"labtool: warning: {warning}", err=True)

    if as_json:
        out = {k: _json_value(result.indicators.get(k)) for k in INDICATORS}
        out.update(model=result.model, accuracy=scene.accuracy, wall_s=round(result.wall_s, 4))
        typer.echo(json.dumps(out))
        typer.echo(f"labtool simulate: {result.model} model ({result.reason})", err=True)
    else:
        _print(result, scene)
    if output is not None:
        from labtool.common import cf

        ds = result.dataset
        command = " ".join([
            f"labtool simulate --model {model} --law {law} --rpm {rpm!r} --fu {fu!r}",
            f"--backlash-mm {backlash_mm!r} --jt-factor {jt_factor!r} --omega1 {omega1} --accuracy {accuracy}",
            f"--restitution {restitution!r} --revolutions {revolutions!r} --contact-length-mm {contact_length_mm!r}",
            f"--kc-factor {kc_factor!r} --contact-damping {contact_damping!r} --elastic-gap {elastic_gap}",
            "--rise-only" if rise_only else "--full-cycle",
            *([f"--mechanism {mechanism}"] if mechanism else []), f"-o {output}"])
        # CF-1.10 (labtool.common.cf): UDUNITS units, Conventions/title/source; the command line in history
        cf.apply(ds, title=f"labtool simulation, {result.model} model", source=f"labtool {result.model} model",
                 history=command)
        write_netcdf(ds, output)
        typer.echo(f"wrote {output}", err=as_json)


def _check_budget(scene, model: str, revolutions: float, max_seconds: float, writes: bool) -> None:
    """Refuse (or ask, on a terminal) a run estimated over ``max_seconds`` or the memory there is,
    from the same scene at 2 and 4 revolutions (peak memory ~2x the Dataset, +1x for the NetCDF)."""
    from labtool.models.dynamics.simulate import simulate as run

    est = budget.probe_linear(lambda n: run(scene.replace(revolutions=float(n)), model).dataset,
                              (2, 4), revolutions, "revolution",
                              nbytes=lambda ds: ds.nbytes * (3.0 if writes else 2.0))
    from labtool.output import terminal_confirm

    budget.check(est, f"--revolutions {revolutions:g}", max_seconds, "use fewer --revolutions", terminal_confirm())


_LABELS = {
    "MR13D_max_Nm": ("(MR13D)max over the rise", "N m", "{:.3f}"),
    "MR13D_min_Nm": ("(MR13D)min over the rise", "N m", "{:.3f}"),
    "dphi2_max_deg": ("(phi2rcj - phi2rfj)max", "deg", "{:.4f}"),
    "domega2_max_rad_s": ("(omega2rcj - omega2rfj)max", "rad/s", "{:.4f}"),
    "domega1_max_rad_s": ("(omega1rcj - omega1rfj)max", "rad/s", "{:.5f}"),
    "percussion_max_Ns": ("(Percussion_int)max", "N s", "{:.4f}"),
    "jumps": ("jumps on the rise", "", "{:d}"),
    "impacts": ("impacts on the rise", "", "{:d}"),
    "xel_max_mm": ("(x_el)max", "mm", "{:.5f}"),
    "xel_min_mm": ("(x_el)min", "mm", "{:.5f}"),
}


def _print(result, scene) -> None:
    from labtool.output import console
    from rich.table import Table

    title = (f"simulate ({result.model}): {scene.law} law, {scene.cam_speed_rpm:g} rpm, Fu = {scene.Fu:g} N, "
             f"j = {scene.backlash * 1e3:g} mm, Jt x{scene.jt_factor:g}, omega1 {scene.omega1_mode}")
    table = Table(title=title, min_width=len(title))     # a title wider than the table would wrap
    table.add_column("indicator")
    table.add_column("value", justify="right")
    table.add_column("unit")
    for key, (label, unit, fmt) in _LABELS.items():
        v = result.indicators.get(key)
        if v is None:
            continue
        table.add_row(label, fmt.format(int(v)) if fmt == "{:d}" else fmt.format(v), unit)
    console = console()
    console.print(table)
    console.print(f"model: {result.model} ({result.reason}); accuracy {scene.accuracy}; {result.wall_s:.2f} s",
                  markup=False, highlight=False)
