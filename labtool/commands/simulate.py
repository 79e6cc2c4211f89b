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
from labtool.common.invocation import command_line
from labtool.options import given, op_option


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
    law: Optional[str] = op_option("law", default_note="default: the mechanism file's [program] law, sine for "
                                   "the STB-216"),
    rpm: Optional[float] = op_option("cam_speed"),
    fu: Optional[float] = op_option("Fu"),
    backlash_mm: Optional[float] = op_option("backlash"),
    jt_factor: Optional[float] = op_option("jt_factor"),
    omega1: Optional[str] = op_option("omega1_mode"),
    accuracy: Optional[str] = op_option("accuracy"),
    restitution: Optional[float] = op_option("restitution"),
    revolutions: float = typer.Option(1.0, help="cam revolutions to simulate [-]"),
    contact_length_mm: Optional[float] = op_option("contact_length"),
    kc_factor: Optional[float] = op_option("kc_factor"),
    contact_damping: Optional[float] = op_option("contact_damping"),
    elastic_gap: Optional[str] = op_option("elastic_gap"),
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
    import labtool
    from labtool.models.dynamics.simulate import INDICATORS
    from labtool.output import terminal_confirm

    values = given(law=law, cam_speed=rpm, Fu=fu, backlash=backlash_mm, jt_factor=jt_factor, omega1_mode=omega1,
                   accuracy=accuracy, restitution=restitution, contact_length=contact_length_mm, kc_factor=kc_factor,
                   contact_damping=contact_damping, elastic_gap=elastic_gap)
    sim = labtool.simulate(model=model, revolutions=revolutions, rise_only=rise_only, mechanism=mechanism,
                           output=output, force=force, max_seconds=max_seconds, confirm=terminal_confirm(),
                           history=command_line("labtool.simulate"), option_source=lambda f: f"option {f.option}",
                           **values)
    for warning in sim.warnings:
        typer.echo(f"labtool: warning: {warning}", err=True)
    if as_json:
        out = {k: _json_value(sim.indicators.get(k)) for k in INDICATORS}
        out.update(model=sim.model, accuracy=sim.scene.accuracy, wall_s=round(sim.wall_s, 4))
        typer.echo(json.dumps(out))
        typer.echo(f"labtool simulate: {sim.model} model ({sim.reason})", err=True)
    else:
        _print(sim, sim.scene, sim.sourced)
    if output is not None:
        typer.echo(f"wrote {output}", err=as_json)


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


def _print(result, scene, sourced) -> None:
    from labtool.output import console
    from rich.markup import escape
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
    where = Table(title="operating point and model options", title_justify="left", box=None)
    for col in ("", "value", "from"):
        where.add_column(col)
    for row in sourced.rows():
        where.add_row(*map(escape, row))
    console.print(where)
