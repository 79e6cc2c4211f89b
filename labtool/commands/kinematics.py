"""``labtool kinematics``: kinematic analysis of the paper's mechanism at constant cam speed, through
``labtool.kinematics`` (labtool/api/kinematics.py)."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from labtool.common import budget
from labtool.common.units import DEG, RPM


def register(app: typer.Typer) -> None:
    app.command("kinematics")(kinematics)


def kinematics(
    law: Optional[str] = typer.Option(None, help="motion law: sine, cosine, poly345, poly4567, modtrap, modsine "
                                      "(default: the mechanism's [program] law, sine for the STB-216)"),
    rpm: float = typer.Option(180.0, help="cam speed n1 [rpm], constant (cam as input)"),
    fu: float = typer.Option(0.0, "--fu", help="load Fu at point N [N], opposing the rod's sliding"),
    jt_factor: float = typer.Option(1.0, help="inertia factor of the follower side Jt [-] (paper: 1 or 4)"),
    rise_deg: Optional[float] = typer.Option(None, help="cam angle of the rise phi_u [deg] (default: the "
                                             "mechanism's [program] rise_deg, 58 for the STB-216)"),
    stroke_deg: Optional[float] = typer.Option(None, help="follower stroke psi_a [deg] (default: the mechanism's "
                                               "psi_a_deg, 15 for the STB-216)"),
    points: int = typer.Option(1441, help="points per cam revolution [-]"),
    mechanism: Optional[Path] = typer.Option(None, help="mechanism TOML file (default: the paper's STB-216)"),
    groove_csv: Optional[Path] = typer.Option(None, help="also write the pitch curve and both flanks [mm] as CSV"),
    output: Optional[Path] = typer.Option(None, "-o", "--output", help="NetCDF file to write (SI units)"),
    force: bool = typer.Option(False, help="overwrite existing output files"),
    max_seconds: float = typer.Option(budget.DEFAULT_MAX_SECONDS, help="refuse (on a terminal: ask) when the "
                                      "estimated run time of a large --points is longer [s]"),
) -> None:
    """Kinematics over one cam revolution: phi2, omega2, epsilon2, points C/E/N, aE_t/aE_n,
    reduced inertias, pressure angle, groove curvature and the kinetostatic MR13D."""
    import labtool
    from rich.table import Table

    from labtool.common.invocation import command_line
    from labtool.output import console, terminal_confirm

    k = labtool.kinematics(law=law, cam_speed=rpm * RPM, Fu=fu, jt_factor=jt_factor,
                           rise=None if rise_deg is None else rise_deg * DEG,
                           stroke=None if stroke_deg is None else stroke_deg * DEG, points=points, mechanism=mechanism,
                           output=output, groove_csv=groove_csv, force=force, max_seconds=max_seconds,
                           confirm=terminal_confirm(), history=command_line())
    s, ds, cut = k.summary, k.dataset, k.undercut
    title = f"Kinematics: {k.law}, {rpm:g} rpm, Fu = {fu:g} N, Jt x{jt_factor:g}"
    table = Table(title=title, min_width=len(title))     # a title wider than the table would wrap
    for col, justify in (("quantity", "left"), ("value", "right"), ("unit", "left")):
        table.add_column(col, justify=justify)
    rows = [
        ("MR13D max over the rise", f"{s['MR13D_max_Nm']:.3f}", "N m"),
        ("MR13D min over the rise", f"{s['MR13D_min_Nm']:.3f}", "N m"),
        ("MR13D changes sign (follower may jump)", "yes" if s["sign_change"] else "no", ""),
        ("omega2 max", f"{s['omega2_max_rad_s']:.3f}", "rad/s"),
        ("epsilon2 max", f"{s['epsilon2_max_rad_s2']:.1f}", "rad/s^2"),
        ("pressure angle max (rise)", f"{s['pressure_angle_max_deg']:.2f}", "deg"),
        ("J''red (follower side) at rise start", f"{ds['J_red_follower'].values[0] * 1e6:.1f}", "1e-6 kg m^2"),
        ("aE_t peak (ideal sensor)", f"{abs(ds['aE_t']).max().item():.1f}", "m/s^2"),
        ("groove undercut", "yes" if cut["undercut"] else f"no (margin {1e3 * min(cut['inner_margin_m'], cut['outer_margin_m']):.2f} mm)", ""),
    ]
    for r in rows:
        table.add_row(*r)
    console().print(table)
    if groove_csv is not None:
        typer.echo(f"wrote {groove_csv} ({k.groove_points} points, mm)")
    if output is not None:
        typer.echo(f"wrote {output}")
