"""Palmgren line contact between the follower roller and a groove flank (paper eq. 15), in SI.

Palmgren's roller/raceway line contact gives the approach delta (mm) under a load Q (N) over a
contact length lw (mm): delta = 3.84e-5 Q^0.9 / lw^0.8, i.e. Q = 8.07e4 lw^(8/9) delta^(10/9).
The paper's eq. (15) rounds the constant to 8.05e4:

    F [N] = Kc_mm * x[mm]^(10/9),      Kc_mm = 8.05e4 * lw[mm]^(8/9)   (N / mm^(10/9))

Converted once to SI (x in m): F = Kc * x^(10/9) with Kc = Kc_mm * (1e3)^(10/9) (N / m^(10/9)).
With Hunt-Crossley damping c (s/m) on the penetration rate: F = Kc p^(10/9) (1 + c dp/dt), clipped
at zero so that the contact never pulls.

The law is written once, ``normal_force`` (compiled, scalar): the elastic model's loops call it,
and the array functions below (``contact_force``, ``hunt_crossley_force``) run it over numpy
arrays. A penetration is never raised to 10/9 when negative: the force is zero there.
``contact_potential`` (its integral) and ``static_penetration`` (its inverse) are closed forms of
the same law.
"""
from __future__ import annotations

import math

import numpy as np

from labtool.common.errors import InputError
from labtool.models.dynamics.jit import jit, kernel

N_EXP = 10.0 / 9.0                     # Palmgren exponent n of eq. (12)-(15)
PALMGREN_MM = 8.05e4                   # N / mm^(10/9) per mm^(8/9) of contact length (eq. 15)
MM_TO_SI = 1e3 ** N_EXP                # (mm/m)^(10/9): Kc_mm -> Kc in N / m^(10/9)


def contact_stiffness(contact_length: float, kc_factor: float = 1.0) -> float:
    """Kc in N / m^(10/9) for a roller-flank contact length ``contact_length`` (m), eq. (15).

    ``kc_factor`` (> 0) multiplies the Palmgren value (stiffness studies).
    """
    if not (math.isfinite(contact_length) and contact_length > 0):
        raise InputError(f"contact length lw must be > 0 mm, got {contact_length * 1e3:g} mm")
    if not (math.isfinite(kc_factor) and kc_factor > 0):
        raise InputError(f"contact stiffness factor must be > 0, got {kc_factor}")
    lw_mm = contact_length * 1e3
    return kc_factor * PALMGREN_MM * lw_mm ** (8.0 / 9.0) * MM_TO_SI


@kernel
def normal_force(penetration, rate, kc, damping):
    """Contact force (N, >= 0) at a penetration (m) growing at ``rate`` (m/s): Kc p^(10/9) times
    (1 + damping * rate) with Hunt-Crossley damping (s/m, 0 = purely elastic), clipped at 0."""
    if penetration <= 0.0:
        return 0.0
    # p^n as p exp((n - 1) ln p): libm's pow was ~30 % of the elastic loop (26-29 ns a call,
    # 6930 calls in Table 1 run 1); exp and log cost ~20 % less and agree with pow to a few ulps
    # (tests/test_elastic.py holds them to 1e-14 over 1e-15..1e-2 m)
    f = kc * penetration * math.exp((N_EXP - 1.0) * math.log(penetration))
    if damping > 0.0:
        f = max(f * (1.0 + damping * rate), 0.0)
    return f


@jit
def _force_many(penetration, rate, kc, damping, out):
    for i in range(out.size):
        out[i] = normal_force(penetration[i], rate[i], kc, damping)


def hunt_crossley_force(penetration, rate, kc: float, damping: float):
    """``normal_force`` over arrays (N): penetration (m) and its rate (m/s), broadcast together."""
    p, r = np.broadcast_arrays(np.asarray(penetration, dtype=float), np.asarray(rate, dtype=float))
    out = np.empty(p.shape)
    _force_many(np.ascontiguousarray(p).reshape(-1), np.ascontiguousarray(r).reshape(-1), float(kc),
                float(damping), out.reshape(-1))
    return out if out.ndim else float(out)


def contact_force(penetration, kc: float):
    """Elastic contact force (N, >= 0) for a penetration (m); zero where the penetration <= 0."""
    return hunt_crossley_force(penetration, 0.0, kc, 0.0)


def contact_potential(penetration, kc: float):
    """Elastic energy (J) stored at a penetration (m): integral of Kc p^(10/9) = 9/19 Kc p^(19/9)."""
    p = np.maximum(penetration, 0.0)
    return (9.0 / 19.0) * kc * p ** (N_EXP + 1.0)


@jit
def penetration_under(force, kc):
    """Penetration (m) that carries a compressive force (N >= 0): (F / Kc)^(9/10); 0 for F <= 0,
    NaN for NaN (not 0: the elastic model's scales divide by it, and a NaN scale says why)."""
    if force > 0.0:
        return (force / kc) ** (1.0 / N_EXP)
    return 0.0 if force <= 0.0 else force


@jit
def _penetration_many(force, kc, out):
    for i in range(out.size):
        out[i] = penetration_under(force[i], kc)


def static_penetration(force, kc: float):
    """``penetration_under`` over arrays (m)."""
    f = np.asarray(force, dtype=float)
    out = np.empty(f.shape)
    _penetration_many(np.ascontiguousarray(f).reshape(-1), float(kc), out.reshape(-1))
    return out if out.ndim else float(out)
