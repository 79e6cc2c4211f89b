"""``labtool.kinematics``: the mechanism's kinematics over one cam revolution at constant cam speed."""
from __future__ import annotations

import dataclasses
from pathlib import Path

from labtool.common import budget
from labtool.common.units import RPM

PROBE_ABOVE_POINTS = 200_000        # smaller requests take under ~3 s: no estimate needed


@dataclasses.dataclass
class Kinematics:
    """A kinematic analysis, as :func:`labtool.kinematics` returns it.

    Attributes
    ----------
    dataset : xarray.Dataset
        Over ``phi1`` [rad]: ``phi2`` [rad], ``omega2`` [rad/s], ``epsilon2`` [rad/s^2], points C,
        E, N [m], ``aE_t``, ``aE_n`` [m/s^2], reduced inertias [kg m^2], the pressure angle [rad],
        the groove's curvature and the kinetostatic ``MR13D`` [N m] (CF attributes).
    summary : dict
        Over the rise: ``MR13D_max_Nm``, ``MR13D_min_Nm`` [N m], ``sign_change``,
        ``omega2_max_rad_s``, ``epsilon2_max_rad_s2``, ``pressure_angle_max_deg`` [deg].
    undercut : dict
        Whether the groove is undercut, and its ``inner_margin_m`` and ``outer_margin_m`` [m].
    law : str
        The motion law's description.
    cam_speed_rpm : float
        The cam speed [rpm], as tables show it.
    groove_points : int or None
        Points of the groove CSV written [-] (None: none written).
    """

    dataset: object
    summary: dict
    undercut: dict
    law: str
    cam_speed_rpm: float
    groove_points: int | None


def kinematics(*, law: str | None = None, cam_speed: float = 180.0 * RPM, Fu: float = 0.0, jt_factor: float = 1.0,
               rise: float | None = None, stroke: float | None = None, points: int = 1441, mechanism=None,
               output=None, groove_csv=None, force: bool = False, max_seconds: float = budget.DEFAULT_MAX_SECONDS,
               confirm=None, history: str = "") -> Kinematics:
    """Kinematics over one cam revolution at constant cam speed (the cam as input).

    Parameters
    ----------
    law : str, optional
        The motion law: sine, cosine, poly345, poly4567, modtrap, modsine (default: the
        mechanism's ``[program]`` law, sine for the STB-216).
    cam_speed : float
        The cam speed [rad/s], constant.
    Fu : float
        The load at point N [N], opposing the rod's sliding.
    jt_factor : float
        Inertia factor of the follower side Jt [-] (the paper: 1 or 4).
    rise : float, optional
        The cam angle of the rise phi_u [rad] (default: the mechanism's ``[program]`` rise).
    stroke : float, optional
        The follower's stroke psi_a [rad] (default: the mechanism's).
    points : int
        Points per cam revolution [-], at least 16.
    mechanism : path or labtool.models.mechanism.Mechanism, optional
        A mechanism TOML file or object (default: the paper's STB-216).
    output : path, optional
        The NetCDF to write (SI, CF-1.10, the mechanism's source and labtool's version as attributes).
    groove_csv : path, optional
        The pitch curve and both flanks [mm] to write as CSV. ``output`` and ``groove_csv`` are
        written as one set: both, or neither.
    force : bool
        Overwrite existing output files.
    max_seconds : float
        Refuse a large ``points`` whose estimated run time is longer [s] (``confirm`` may allow it).
    confirm : callable, optional
        ``confirm(question) -> bool`` asked before such a run.
    history : str
        The NetCDF's ``history`` (the command line that made it).

    Returns
    -------
    Kinematics
    """
    from labtool.common.errors import InputError
    from labtool.common.files import OutputSet, check_outputs
    from labtool.models.mechanism import Mechanism
    from labtool.models.mechanism.cam_profile import export_groove_csv, undercut
    from labtool.models.mechanism.kinematics import analyze, rise_summary
    from labtool.models.mechanism.motion_laws import CamProgram, get_law

    check_outputs({"-o": output, "--groove-csv": groove_csv}, force)
    budget.check_limit(max_seconds)
    if points < 16:
        raise InputError(f"--points must be at least 16 per revolution, got {points}")
    if isinstance(mechanism, Mechanism):
        mech = mechanism
    else:
        mech = Mechanism.from_toml(Path(mechanism)) if mechanism else Mechanism.default()
    # an option not given is the mechanism file's own value: its [program] law and rise_deg and its
    # psi_a_deg were replaced by the paper's sine, 58 deg and 15 deg without a word
    mech = mech.replace(psi_a=stroke) if stroke is not None else mech
    rpm = round(cam_speed / RPM, 9)         # 180.0, not 180.00000000000003: tables and messages show it
    mech.check_cam_speed(rpm)
    if law is None:
        law = mech.program.get("law", "sine")
    program = CamProgram.for_mechanism(mech, law=get_law(law), rise=rise, stroke=mech.psi_a)
    if points > PROBE_ABOVE_POINTS:
        # measured (docs/robustness.md): peak memory 2.1x the Dataset, plus the NetCDF image when
        # written; the time per point at 1e6-3e6 points is ~2x that at 5e4
        est = budget.probe_linear(lambda n: analyze(mech, program, rpm, Fu, jt_factor, n_points=int(n)),
                                  (2_000, 50_000), points, "point",
                                  nbytes=lambda d: d.nbytes * (3.1 if output is not None else 2.1), large_factor=2.0)
        budget.check(est, f"--points {points}", max_seconds, "use fewer --points", confirm)
    ds = analyze(mech, program, rpm, Fu, jt_factor, n_points=points)
    summary, cut = rise_summary(ds), undercut(mech, program)
    if output is not None:
        from labtool.common import cf
        from labtool.models.dynamics.provenance import labtool_version, mechanism_attributes

        ds.attrs.update(mechanism_attributes(mech), labtool_version=labtool_version(), points=points)
        # CF-1.10 (labtool.common.cf): UDUNITS units, Conventions/title/source; the command line in history
        cf.apply(ds, title="labtool kinematic analysis", source="labtool kinematics (motion law and linkage)",
                 history=history)
    n = None
    # one output set: both files, or neither (a full disk left a truncated groove CSV)
    with OutputSet() as out:
        if groove_csv is not None:
            n = out.write(Path(groove_csv), lambda tmp: export_groove_csv(tmp, mech, program), "--groove-csv")
        if output is not None:
            out.write_netcdf(Path(output), ds, "-o")
    return Kinematics(ds, summary, cut, program.segments[0].law.description, rpm, n)
