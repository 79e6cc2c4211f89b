"""Normalized cam motion laws and the cam's motion program (rise, dwell, return, dwell).

A normalized law maps u in [0, 1] (fraction of the segment's cam angle) to the fraction of
the stroke s(u) in [0, 1], with its derivatives s'(u), s''(u), s'''(u) (dimensionless:
the peak coefficients Cv, Ca, Cj of the cam literature). Every law satisfies
s(0) = 0, s(1) = 1, s'(0) = s'(1) = 0.

``sine``  = sine acceleration (cycloidal), the paper's main law;
``cosine`` = cosine acceleration (simple harmonic), the paper's second law.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Callable

import numpy as np

from labtool.common.errors import InputError
from labtool.common.names import shown

TWO_PI = 2.0 * math.pi


@dataclasses.dataclass(frozen=True)
class Law:
    """A normalized rise law: ``derivs(u) -> (s, s', s'', s''')`` for u in [0, 1]."""

    name: str
    description: str
    derivs: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]

    def __call__(self, u):
        u = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
        return self.derivs(u)


def _cycloidal(u):
    w = TWO_PI * u
    sin_w, cos_w = np.sin(w), np.cos(w)
    return u - sin_w / TWO_PI, 1.0 - cos_w, TWO_PI * sin_w, TWO_PI**2 * cos_w


def _harmonic(u):
    w = math.pi * u
    return (
        0.5 * (1.0 - np.cos(w)),
        0.5 * math.pi * np.sin(w),
        0.5 * math.pi**2 * np.cos(w),
        -0.5 * math.pi**3 * np.sin(w),
    )


def _polynomial(coeffs: dict[int, float]):
    """s(u) = sum c_k u^k, with exact derivatives."""
    def f(u):
        out = [np.zeros_like(u) for _ in range(4)]
        for k, c in coeffs.items():
            for order in range(4):
                if k - order < 0:
                    continue
                fac = math.perm(k, order)
                out[order] = out[order] + c * fac * u ** (k - order)
        return tuple(out)
    return f


@dataclasses.dataclass(frozen=True)
class _TrigPiece:
    """Acceleration on [u0, u1]: c0 + c1*sin(k*(u-u0)) + c2*cos(k*(u-u0))."""
    u0: float
    u1: float
    k: float
    c0: float
    c1: float
    c2: float


def _piecewise_trig(pieces: list[_TrigPiece]):
    """A law defined by a piecewise trigonometric acceleration, integrated in closed form.

    The amplitude is scaled so that s(1) = 1; velocity and displacement are continuous.
    """
    # integrate once with unit amplitude to get the start values of each piece
    starts = []
    v, s = 0.0, 0.0
    for p in pieces:
        starts.append((v, s))
        v, s = _trig_integrals(p, p.u1, v, s)[1:3]
    scale = 1.0 / s

    def f(u):
        res = [np.zeros_like(u) for _ in range(4)]
        for p, (v0, s0) in zip(pieces, starts):
            mask = (u >= p.u0) & (u <= p.u1)
            if not np.any(mask):
                continue
            a, vv, ss, j = _trig_integrals(p, u[mask], v0, s0)
            for out, val in zip(res, (ss, vv, a, j)):
                out[mask] = scale * val
        return tuple(res)
    return f


def _trig_integrals(p: _TrigPiece, u, v0, s0):
    """(a, v, s, jerk) on a piece, with v(u0) = v0 and s(u0) = s0."""
    t = np.asarray(u, dtype=float) - p.u0
    k = p.k
    sin, cos = np.sin(k * t), np.cos(k * t)
    a = p.c0 + p.c1 * sin + p.c2 * cos
    jerk = k * (p.c1 * cos - p.c2 * sin)
    v = v0 + p.c0 * t + p.c1 * (1.0 - cos) / k + p.c2 * sin / k
    s = s0 + v0 * t + 0.5 * p.c0 * t**2 + p.c1 * (t - sin / k) / k + p.c2 * (1.0 - cos) / k**2
    return a, v, s, jerk


_F = 4.0 * math.pi  # sine ramps over 1/8 of the segment
_MOD_TRAP = _piecewise_trig([
    _TrigPiece(0.0, 0.125, _F, 0.0, 1.0, 0.0),
    _TrigPiece(0.125, 0.375, _F, 1.0, 0.0, 0.0),
    _TrigPiece(0.375, 0.625, _F, 0.0, 0.0, 1.0),
    _TrigPiece(0.625, 0.875, _F, -1.0, 0.0, 0.0),
    _TrigPiece(0.875, 1.0, _F, 0.0, 0.0, -1.0),
])
_MOD_SINE = _piecewise_trig([
    _TrigPiece(0.0, 0.125, _F, 0.0, 1.0, 0.0),
    _TrigPiece(0.125, 0.875, _F / 3.0, 0.0, 0.0, 1.0),
    _TrigPiece(0.875, 1.0, _F, 0.0, 0.0, -1.0),
])

LAWS: dict[str, Law] = {
    law.name: law
    for law in [
        Law("sine", "sine acceleration (cycloidal): Cv=2, Ca=2*pi, Cj=4*pi^2", _cycloidal),
        Law("cosine", "cosine acceleration (simple harmonic): Cv=pi/2, Ca=pi^2/2", _harmonic),
        Law("poly345", "3-4-5 polynomial: Cv=1.875, Ca=5.774, Cj=60", _polynomial({3: 10, 4: -15, 5: 6})),
        Law("poly4567", "4-5-6-7 polynomial: Cv=2.1875, Ca=7.513, Cj=52.5",
            _polynomial({4: 35, 5: -84, 6: 70, 7: -20})),
        Law("modtrap", "modified trapezoid: Cv=2, Ca=4.888, Cj=61.43", _MOD_TRAP),
        Law("modsine", "modified sine: Cv=1.760, Ca=5.528, Cj=69.47", _MOD_SINE),
    ]
}
ALIASES = {"cycloidal": "sine", "harmonic": "cosine", "345": "poly345", "4567": "poly4567"}


def get_law(name: str) -> Law:
    """Look a law up by name (or alias); InputError naming the known laws otherwise."""
    key = ALIASES.get(name.lower(), name.lower())
    try:
        return LAWS[key]
    except KeyError:
        raise InputError(f"unknown motion law '{name}'; known laws: {', '.join(LAWS)}") from None


@dataclasses.dataclass(frozen=True)
class Segment:
    """One part of the cam program: ``kind`` in rise|dwell|return, over ``beta`` rad of cam angle."""
    kind: str
    beta: float
    law: Law | None = None


@dataclasses.dataclass(frozen=True)
class CamProgram:
    """The follower stroke psi (rad, rise positive) as a function of the cam angle phi1 (rad).

    phi1 = 0 at the start of the rise (docs/architecture.md); the program repeats every 2*pi.
    """

    stroke: float
    segments: tuple[Segment, ...]

    def __hash__(self) -> int:
        # the dataclass hash, made once: a program keys the per-process tables (labtool.models.mechanism.memo)
        # and hashing its segments and laws field by field cost ~5 us a lookup
        h = self.__dict__.get("_hash")
        if h is None:
            h = hash((self.stroke, self.segments))
            object.__setattr__(self, "_hash", h)
        return h

    def __getstate__(self) -> dict:
        # a string's hash differs between processes: another process makes its own
        state = dict(self.__dict__)
        state.pop("_hash", None)
        state.pop("_edge_table", None)
        return state

    @classmethod
    def rise_dwell_return_dwell(cls, law: str | Law = "sine", stroke: float = math.radians(15.0),
                                rise: float = math.radians(58.0), upper_dwell: float | None = None,
                                ret: float | None = None, lower_dwell: float | None = None,
                                return_law: str | Law | None = None) -> "CamProgram":
        """Rise, dwell, return, dwell; by default a symmetric return and equal dwells."""
        law = get_law(law) if isinstance(law, str) else law
        rlaw = law if return_law is None else (get_law(return_law) if isinstance(return_law, str) else return_law)
        ret = rise if ret is None else ret
        rest = TWO_PI - rise - ret
        upper_dwell = rest / 2 if upper_dwell is None else upper_dwell
        lower_dwell = TWO_PI - rise - ret - upper_dwell if lower_dwell is None else lower_dwell
        for label, value in [("rise", rise), ("return", ret)]:
            if not (0 < value < TWO_PI):
                raise InputError(f"cam program: {label} angle must lie in (0, 360) degrees")
        if upper_dwell < 0 or lower_dwell < 0:
            raise InputError("cam program: dwell angles must not be negative")
        total = rise + upper_dwell + ret + lower_dwell
        if not math.isclose(total, TWO_PI, rel_tol=0, abs_tol=1e-9):
            raise InputError(
                f"cam program: rise + dwells + return = {math.degrees(total):.6g} deg, must be 360 deg"
            )
        if not (stroke > 0 and math.isfinite(stroke)):
            raise InputError("cam program: the stroke psi_a must be positive")
        return cls(stroke, (
            Segment("rise", rise, law), Segment("dwell", upper_dwell),
            Segment("return", ret, rlaw), Segment("dwell", lower_dwell),
        ))

    @classmethod
    def for_mechanism(cls, mech, law: str | None = None, **overrides) -> "CamProgram":
        """The program of a Mechanism's [program] table (paper: sine law, rise 58 deg)."""
        prog = dict(mech.program)
        d = math.radians
        kw = dict(
            law=law or prog.get("law", "sine"),
            stroke=mech.psi_a,
            rise=d(prog.get("rise_deg", 58.0)),
            upper_dwell=d(prog["upper_dwell_deg"]) if "upper_dwell_deg" in prog else None,
            ret=d(prog["return_deg"]) if "return_deg" in prog else None,
            lower_dwell=d(prog["lower_dwell_deg"]) if "lower_dwell_deg" in prog else None,
        )
        kw.update({k: v for k, v in overrides.items() if v is not None})
        _check_program_sum(mech, kw, [k for k, v in overrides.items() if v is not None])
        return cls.rise_dwell_return_dwell(**kw)

    @property
    def rise_angle(self) -> float:
        return self.segments[0].beta

    def _edges(self) -> tuple:
        """The segments' first angles and end (rad, from 0: the sums __call__ makes) and their
        directions (+1 rise, -1 return, 0 dwell), made once a program."""
        got = self.__dict__.get("_edge_table")
        if got is None:
            got = (np.cumsum([0.0] + [s.beta for s in self.segments]),
                   np.array([{"rise": 1.0, "return": -1.0}.get(s.kind, 0.0) for s in self.segments]))
            object.__setattr__(self, "_edge_table", got)
        return got

    def segment_index(self, phi1) -> np.ndarray:
        """Index of the segment each cam angle falls in (0 = rise)."""
        phi = np.mod(np.asarray(phi1, dtype=float), TWO_PI)
        edges = self._edges()[0]
        # phi >= 0 = edges[0]: only the upper end needs the clip (an angle at or past the last edge, NaN)
        return np.minimum(np.searchsorted(edges, phi, side="right") - 1, len(self.segments) - 1)

    def direction(self, phi1) -> np.ndarray:
        """+1 during a rise, -1 during a return, 0 in a dwell (the follower's nominal direction)."""
        return self._edges()[1][self.segment_index(phi1)]

    def __call__(self, phi1):
        """(psi, dpsi/dphi1, d2psi/dphi1^2, d3psi/dphi1^3) in rad, rad/rad, ... at cam angles phi1."""
        phi = np.mod(np.asarray(phi1, dtype=float), TWO_PI)
        out = [np.zeros_like(phi) for _ in range(4)]
        # the angles' range decides most segments without a mask (a run over one rise: one
        # segment, no masked copies); NaN angles fail every comparison and take the masks
        lo, hi = (phi.min(), phi.max()) if phi.size else (math.inf, -math.inf)
        start = 0.0
        level = 0.0
        for seg in self.segments:
            end = start + seg.beta
            closed = not end < TWO_PI                     # the last segment takes the angles up to 2 pi
            # the angles of this segment: all of them, none (nothing to evaluate), or some
            if lo >= start and (closed or hi < end):
                sel = Ellipsis
            elif hi < start or (not closed and lo >= end):
                sel = None
            else:
                mask = (phi >= start) & (phi < end) if not closed else (phi >= start)
                sel = Ellipsis if mask.all() else mask if mask.any() else None
            if seg.kind == "dwell":
                if sel is not None:
                    out[0][sel] = level
            else:
                if sel is not None:
                    u = (phi[sel] - start) / seg.beta
                    s, v, a, j = seg.law(u)
                    sign = 1.0 if seg.kind == "rise" else -1.0
                    base = 0.0 if seg.kind == "rise" else 1.0
                    out[0][sel] = self.stroke * (base + sign * s)
                    out[1][sel] = sign * self.stroke * v / seg.beta
                    out[2][sel] = sign * self.stroke * a / seg.beta**2
                    out[3][sel] = sign * self.stroke * j / seg.beta**3
                level = 1.0 * self.stroke if seg.kind == "rise" else 0.0
            start = end
        return tuple(out)


def _check_program_sum(mech, kw: dict, given: list[str]) -> None:
    """A program whose four angles are all stated (the mechanism's [program], or a value given over
    it) must add up to 360 deg: the line names each angle, where it comes from, and what would fit."""
    parts = (("rise", "rise_deg"), ("upper_dwell", "upper_dwell_deg"), ("ret", "return_deg"),
             ("lower_dwell", "lower_dwell_deg"))
    if any(kw.get(k) is None for k, _ in parts):
        return
    total = sum(kw[k] for k, _ in parts)
    if math.isclose(total, TWO_PI, rel_tol=0, abs_tol=1e-9):
        return
    terms = " + ".join(f"{name} {math.degrees(kw[k]):.6g}" + (" (given)" if k in given else "") for k, name in parts)
    mine = [(k, name) for k, name in parts if k in given]
    where = f"[program] of the mechanism {shown(mech.source)}"
    if not mine:
        fix = f"change the {where} so that they add up to 360"
    else:
        k, name = mine[0]
        need = TWO_PI - (total - kw[k])
        fix = (f"give a {name[:-4].replace('_', ' ')} of {math.degrees(need):.6g} deg, or " if 0 < need < TWO_PI
               else "give ") + "a mechanism file whose [program] angles add up to 360 with yours"
        fix = f"the others are the {where}; {fix}"
    raise InputError(f"cam program: {terms} = {math.degrees(total):.6g} deg, must be 360 deg; {fix}")
