"""``labtool kinematics``: kinematic analysis of the paper's mechanism at constant cam speed."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from labtool.common import budget
from labtool.common.files import OutputSet, check_outputs
from labtool.common.units import DEG

PROBE_ABOVE_POINTS = 200_000        # smaller requests take under ~3 s: no estimate needed


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
    from labtool.output import console
    from rich.table import Table

    from labtool.models.mechanism.cam_profile import export_groove_csv, undercut
    from labtool.models.mechanism.kinematics import analyze, rise_summary
    from labtool.models.mechanism import Mechanism
    from labtool.models.mechanism.motion_laws import CamProgram, get_law
    from labtool.common.errors import InputError

    check_outputs({"-o": output, "--groove-csv": groove_csv}, force)
    budget.check_limit(max_seconds)
    if points < 16:
        raise InputError(f"--points must be at least 16 per revolution, got {points}")
    mech = Mechanism.from_toml(mechanism) if mechanism else Mechanism.default()
    # an option not given is the mechanism file's own value: its [program] law and rise_deg and its
    # psi_a_deg were replaced by the paper's sine, 58 deg and 15 deg without a word
    mech = mech.replace(psi_a=stroke_deg * DEG) if stroke_deg is not None else mech
    mech.check_cam_speed(rpm)
    if law is None:
        law = mech.program.get("law", "sine")
    program = CamProgram.for_mechanism(mech, law=get_law(law), rise=None if rise_deg is None else rise_deg * DEG,
                                       stroke=mech.psi_a)
    rise_deg, stroke_deg = round(program.rise_angle / DEG, 9), round(mech.psi_a / DEG, 9)   # 58.0, not 58.00000000000001
    if points > PROBE_ABOVE_POINTS:
        # measured (docs/robustness.md): peak memory 2.1x the Dataset, plus the NetCDF image when
        # written; the time per point at 1e6-3e6 points is ~2x that at 5e4
        est = budget.probe_linear(lambda n: analyze(mech, program, rpm, fu, jt_factor, n_points=int(n)),
                                  (2_000, 50_000), points, "point",
                                  nbytes=lambda d: d.nbytes * (3.1 if output is not None else 2.1), large_factor=2.0)
        from labtool.output import terminal_confirm

        budget.check(est, f"--points {points}", max_seconds, "use fewer --points", terminal_confirm())
    ds = analyze(mech, program, rpm, fu, jt_factor, n_points=points)
    s = rise_summary(ds)
    cut = undercut(mech, program)

    title = f"Kinematics: {program.segments[0].law.description}, {rpm:g} rpm, Fu = {fu:g} N, Jt x{jt_factor:g}"
    table = Table(title=title, min_width=len(title))     # a title wider than the table would wrap
    table.add_column("quantity")
    table.add_column("value", justify="right")
    table.add_column("unit")
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
    if output is not None:
        from labtool.models.dynamics.provenance import labtool_version, mechanism_attributes

        ds.attrs.update(mechanism_attributes(mech), labtool_version=labtool_version(), points=points)
        from labtool.common import cf

        from labtool.common.invocation import command_line

        # CF-1.10 (labtool.common.cf): UDUNITS units, Conventions/title/source; the command line in history
        cf.apply(ds, title="labtool kinematic analysis", source="labtool kinematics (motion law and linkage)",
                 history=command_line())
    # one output set: both files, or neither (a full disk left a truncated groove CSV)
    with OutputSet() as out:
        if groove_csv is not None:
            n = out.write(groove_csv, lambda tmp: export_groove_csv(tmp, mech, program), "--groove-csv")
        if output is not None:
            out.write_netcdf(output, ds, "-o")
    if groove_csv is not None:
        typer.echo(f"wrote {groove_csv} ({n} points, mm)")
    if output is not None:
        typer.echo(f"wrote {output}")
