"""A drawing of the mechanism at one cam angle: the cam disc with its groove (both flanks and the
pitch curve), the roller in the groove, the follower from its pivot D through the roller centre C
to the sensor point E, and the rod through its slide block G (docs/mechanism.md's geometry,
labtool.models.mechanism). The report draws it at the first impact, so a reader sees where in the
groove the follower lands.
"""
from __future__ import annotations

import math

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Circle, FancyArrowPatch, Polygon


def _rotate(xy: np.ndarray, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.stack([c * xy[0] - s * xy[1], s * xy[0] + c * xy[1]])


def pose(mech, program, phi1: float, backlash: float = 0.0) -> dict:
    """Every drawn point and curve in the fixed frame (m; origin the cam axis A, y up) at cam angle
    ``phi1`` (rad): the groove's ``pitch``, ``inner`` and ``outer`` curves (2, n), the roller centre
    ``C``, the sensor point ``E``, the rod's end ``H``, the slide block ``G``, the pivot ``D``,
    ``phi2`` (rad) and the cam's ``sense``."""
    from labtool.models.mechanism.cam_profile import groove
    from labtool.models.mechanism.linkage import linkage_state

    g = groove(mech, program, 1440, backlash)
    turn = g["sense"] * phi1              # the cam frame turned to the fixed frame (cam_profile's module doc)
    psi = float(np.asarray(program(np.array([phi1]))[0]).ravel()[0])
    phi2 = mech.phiD + mech.psi0 + psi
    st = linkage_state(mech, phi2, 0.0, 0.0)
    return {"pitch": _rotate(g["pitch"], turn), "inner": _rotate(g["inner"], turn), "outer": _rotate(g["outer"], turn),
            "C": st.C[:, 0], "E": st.E[:, 0], "H": st.H[:, 0], "G": mech.G, "D": mech.D, "phi2": phi2,
            "sense": int(g["sense"]), "turn": turn}


def fig_mechanism(mech, program, phi1: float, backlash: float = 0.0, what: str = "") -> tuple[str, Figure]:
    """The cam, its groove and the follower at cam angle ``phi1`` (rad); ``what`` says why this
    angle (e.g. 'the measured first impact'). Lengths in mm on the axes."""
    p = pose(mech, program, phi1, backlash)
    mm = 1e3
    fig = Figure(figsize=(8.0, 6.4))
    ax = fig.add_axes([0.09, 0.08, 0.86, 0.84])
    disc = 0.5 * mech.cam_diameter
    reach = max(disc, float(np.max(np.hypot(*p["outer"]))) + 2 * mech.R)
    ax.add_patch(Circle((0, 0), reach * mm, facecolor="0.88", edgecolor="0.3", lw=0.8, zorder=1))
    # the groove: the band between the flanks, cut out of the disc
    ring = np.concatenate([p["outer"].T, p["inner"].T[::-1]]) * mm
    ax.add_patch(Polygon(ring, closed=True, facecolor="white", edgecolor="none", zorder=2))
    ax.plot(*(np.append(p["inner"], p["inner"][:, :1], axis=1) * mm), color="k", lw=0.9, zorder=3)
    ax.plot(*(np.append(p["outer"], p["outer"][:, :1], axis=1) * mm), color="k", lw=0.9, zorder=3)
    ax.plot(*(np.append(p["pitch"], p["pitch"][:, :1], axis=1) * mm), color="0.45", lw=0.6, ls="-.", zorder=3,
            label="pitch curve (roller-centre path)")
    # a radial mark on the cam: where phi1 = 0 (the start of the rise) has turned to
    start = p["pitch"][:, 0] * mm
    ax.plot([0, start[0]], [0, start[1]], color="0.55", lw=0.6, ls=":", zorder=3)
    ax.annotate("φ1 = 0", start, fontsize=7, color="0.35", xytext=(3, 3), textcoords="offset points")
    ax.plot(0, 0, "k+", ms=10, zorder=6)
    ax.annotate("A (cam axis)", (0, 0), fontsize=8, xytext=(6, -12), textcoords="offset points")
    arc = FancyArrowPatch((0.35 * disc * mm, 0), (0, 0.35 * disc * mm * p["sense"]),
                          connectionstyle=f"arc3,rad={0.4 * p['sense']}", arrowstyle="->", mutation_scale=12,
                          color="0.2", lw=0.9, zorder=6)
    ax.add_patch(arc)
    D, C, E, H, G = (np.asarray(p[k]) * mm for k in ("D", "C", "E", "H", "G"))
    orange, blue = "#E69F00", "#0072B2"        # Okabe-Ito
    ax.plot([D[0], max((C, E), key=lambda q: np.hypot(*(q - D)))[0]],
            [D[1], max((C, E), key=lambda q: np.hypot(*(q - D)))[1]], color=blue, lw=3.0, solid_capstyle="round",
            zorder=7, label="follower (element 2)")
    ax.add_patch(Circle(C, mech.R * mm, facecolor="white", edgecolor=blue, lw=1.6, zorder=8))
    ax.plot(*C, "o", color=blue, ms=3, zorder=9)
    ax.plot([E[0], H[0]], [E[1], H[1]], color=orange, lw=2.2, zorder=6, label="rod (element 4)")
    ax.plot(*G, "s", color=orange, ms=9, mfc="white", mew=1.6, zorder=7)
    ax.plot(*D, "^", color="k", ms=9, zorder=9)
    ax.plot(*E, "s", color="#D55E00", ms=6, zorder=9, label="E: accelerometer")
    for name, q, off in (("D", D, (6, -12)), ("C", C, (8, 6)), ("E", E, (8, 4)), ("G", G, (8, -12))):
        ax.annotate(name, q, fontsize=9, fontweight="bold", xytext=off, textcoords="offset points", zorder=10)
    pts = np.column_stack([np.array([[0, 0]]).T * mm, D[:, None], C[:, None], E[:, None], H[:, None], G[:, None]])
    lo = np.minimum(pts.min(axis=1), -reach * mm) - 10
    hi = np.maximum(pts.max(axis=1), reach * mm) + 10
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="box")     # the limits kept, the box fitted to them
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.grid(True, alpha=0.25)
    ax.legend(fontsize=7, loc="lower right")
    why = f" ({what})" if what else ""
    ax.set_title(f"Cam, groove (backlash j = {backlash * mm:g} mm) and follower at φ1 = {math.degrees(phi1):.1f}°{why}\n"
                 f"follower angle φ2 = {math.degrees(p['phi2']):.1f}°; the cam turns as the arrow shows", fontsize=9)
    return f"The mechanism at φ1 = {math.degrees(phi1):.1f}°{why}", fig
