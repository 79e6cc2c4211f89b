"""The groove: pitch curve (roller-centre path) in the cam frame, both flanks, their radii of
curvature, the pressure angle and the base-circle diameters Db1, Db2 of eq. (18).

The cam turns by phi1 with sense ``sense`` (+1 counter-clockwise, -1 clockwise) seen in the fixed
frame. A point fixed in the fixed frame at C(phi1) traces, in the cam frame, P = Rot(-sense*phi1) C.
With ' = d/dphi1:   P' = Rot(.)(C' - sense*kxC),   P'' = Rot(.)(C'' - 2 sense*kxC' - C).
The inner flank lies R inside the pitch curve (towards A), the outer flank R + j outside.
"""
from __future__ import annotations

import math

import numpy as np

from labtool.common.errors import InputError
from labtool.models.mechanism import Mechanism
from labtool.models.mechanism.memo import cached
from labtool.models.mechanism.motion_laws import CamProgram


def _rotate(v, angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def pitch_geometry(xD, yD, l, sense, phi2, dpsi, ddpsi):
    """The pitch curve at follower angles phi2 (rad, the roller centre C on a circle of radius
    l m about D = (xD, yD) m) with the stroke's derivatives dpsi (rad/rad) and ddpsi (rad/rad^2),
    the cam turning with ``sense`` (module doc): (C_x, C_y m; the unit normal n_x, n_y, oriented
    away from the cam axis A; the signed radius of curvature rho m; the pressure angle alpha rad,
    folded to (-pi/2, pi/2]; Db1, Db2 m of eq. (18); the curvature's sign). Plain arithmetic on
    arrays or floats, so that compiled code (labtool.models.dynamics.elastic) runs this same source."""
    rx, ry = l * np.cos(phi2), l * np.sin(phi2)
    Cx, Cy = xD + rx, yD + ry
    dCx, dCy = dpsi * -ry, dpsi * rx                        # C' = psi' perp(r)
    ddCx, ddCy = ddpsi * -ry - dpsi**2 * rx, ddpsi * rx - dpsi**2 * ry
    tx, ty = dCx + sense * Cy, dCy - sense * Cx             # pitch-curve tangent, fixed-frame components
    sx, sy = ddCx + 2.0 * sense * dCy - Cx, ddCy - 2.0 * sense * dCx - Cy     # its second derivative
    speed = np.hypot(tx, ty)
    nx, ny = -ty / speed, tx / speed
    outward = nx * Cx + ny * Cy
    flip = np.sign(outward) + (outward == 0)                # orient the normal away from A
    nx, ny = nx * flip, ny * flip
    bend = tx * sy - ty * sx
    rho = speed**3 / bend                                   # signed radius of curvature of the pitch curve
    # pressure angle: between the contact normal and the velocity of C on the follower
    wx, wy = -(Cy - yD) / l, (Cx - xD) / l
    alpha = np.arctan2(wx * ny - wy * nx, wx * nx + wy * ny)
    alpha = (alpha + math.pi / 2) % math.pi - math.pi / 2   # a line's direction: fold to (-90, 90] deg
    Db1 = 2.0 * abs(nx * Cy - ny * Cx)                      # twice the distance from A to the normal line
    Db2 = 2.0 * abs(nx * (Cy - yD) - ny * (Cx - xD))        # ... and from D
    return Cx, Cy, nx, ny, rho, alpha, Db1, Db2, np.sign(bend) * sense


def _geometry(mech, program, phi1, sense, motion=None):
    psi, dpsi, ddpsi, _ = program(phi1) if motion is None else motion
    phi2 = mech.phiD + mech.psi0 + psi
    Cx, Cy, nx, ny, rho, alpha, Db1, Db2, bend = pitch_geometry(mech.xD, mech.yD, mech.l, sense, phi2, dpsi, ddpsi)
    return dict(C=np.stack([Cx, Cy]), normal=np.stack([nx, ny]), rho_pitch=rho, pressure_angle=alpha,
                Db1=Db1, Db2=Db2, phi2=phi2, curvature_sign=bend)


def choose_sense(mech: Mechanism, program: CamProgram) -> int:
    """The cam's sense of rotation the paper leaves implicit: the one with the smaller peak pressure
    angle over the rise (a designer's choice; docs/mechanism.md)."""
    phi = np.linspace(0.0, program.rise_angle, 721)
    peaks = {s: np.abs(_geometry(mech, program, phi, s)["pressure_angle"]).max() for s in (1, -1)}
    return min(peaks, key=peaks.get)


def cached_sense(mech: Mechanism, program: CamProgram) -> int:
    """``choose_sense`` remembered per (mechanism, program) (labtool.models.mechanism.memo.cached): it costs
    two 721-point geometry passes and every contact-geometry call needs it."""
    return cached(("cam_sense", mech.cache_key, program), lambda: choose_sense(mech, program))


def contact_geometry(mech: Mechanism, program: CamProgram, phi1, sense: int | None = None,
                     backlash: float = 0.0, motion=None) -> dict:
    """Pressure angle (rad), Db1, Db2 (m), radii of curvature of pitch curve and flanks (m, signed:
    positive where the curve is convex seen from outside the cam) at cam angles phi1.
    ``motion`` = program(phi1) when the caller has it already."""
    sense = cached_sense(mech, program) if sense is None else int(sense)
    if sense not in (1, -1):
        raise InputError("cam sense of rotation must be +1 (counter-clockwise) or -1 (clockwise)")
    g = _geometry(mech, program, np.asarray(phi1, dtype=float), sense, motion)
    rho = g["rho_pitch"]
    g["rho_inner"] = rho - mech.R
    g["rho_outer"] = rho + mech.R + backlash
    g["sense"] = sense
    return g


def groove(mech: Mechanism, program: CamProgram, n_points: int = 1440, backlash: float = 0.0,
           sense: int | None = None) -> dict:
    """Pitch curve and both flanks in the cam frame over one revolution (arrays (2, n), m),
    with the cam angle phi1 (rad) and the radii of curvature."""
    if n_points < 720:
        raise InputError("a groove export needs at least 720 points")
    phi1 = np.linspace(0.0, 2.0 * math.pi, n_points, endpoint=False)
    g = contact_geometry(mech, program, phi1, sense, backlash)
    back = -g["sense"] * phi1
    pitch = _rotate(g["C"], back)
    n = _rotate(g["normal"], back)
    inner = pitch - mech.R * n
    outer = pitch + (mech.R + backlash) * n
    return dict(phi1=phi1, pitch=pitch, inner=inner, outer=outer, rho_pitch=g["rho_pitch"],
                rho_inner=g["rho_inner"], rho_outer=g["rho_outer"], sense=g["sense"])


def undercut(mech: Mechanism, program: CamProgram, backlash: float = 0.0) -> dict:
    """Undercut check: the inner flank is undercut where the pitch curve is convex with a radius
    below R; the outer flank where it is concave with a radius below R + j. Returns the minimum
    margins in m (negative means undercut)."""
    gr = groove(mech, program, 2880, backlash)
    rho = gr["rho_pitch"]
    convex = rho > 0
    inner_margin = np.min(rho[convex] - mech.R) if np.any(convex) else np.inf
    outer_margin = np.min(-rho[~convex] - (mech.R + backlash)) if np.any(~convex) else np.inf
    return {"inner_margin_m": float(inner_margin), "outer_margin_m": float(outer_margin),
            "undercut": bool(inner_margin < 0 or outer_margin < 0)}


def export_groove_csv(path, mech: Mechanism, program: CamProgram, n_points: int = 1440,
                      backlash: float = 0.0) -> int:
    """Write the roller-centre path and both flanks as a CSV point table in mm (for CAD/FEA import).

    Columns: phi1_deg, pitch_x_mm, pitch_y_mm, inner_x_mm, inner_y_mm, outer_x_mm, outer_y_mm,
    rho_pitch_mm. Returns the number of rows.
    """
    gr = groove(mech, program, n_points, backlash)
    table = np.column_stack([
        np.degrees(gr["phi1"]), gr["pitch"][0] * 1e3, gr["pitch"][1] * 1e3, gr["inner"][0] * 1e3,
        gr["inner"][1] * 1e3, gr["outer"][0] * 1e3, gr["outer"][1] * 1e3, gr["rho_pitch"] * 1e3,
    ])
    header = "phi1_deg,pitch_x_mm,pitch_y_mm,inner_x_mm,inner_y_mm,outer_x_mm,outer_y_mm,rho_pitch_mm"
    np.savetxt(path, table, delimiter=",", header=header, comments="", fmt="%.6f")
    return table.shape[0]
