"""Palmgren line contact between the follower roller and a groove flank (paper eq. 15), in SI.

Palmgren's roller/raceway line contact gives the approach delta (mm) under a load Q (N) over a
contact length lw (mm): delta = 3.84e-5 Q^0.9 / lw^0.8, i.e. Q = 8.07e4 lw^(8/9) delta^(10/9).
The paper's eq. (15) rounds the constant to 8.05e4:

    F [N] = Kc_mm * x[mm]^(10/9),      Kc_mm = 8.05e4 * lw[mm]^(8/9)   (N / mm^(10/9))

Converted once to SI (x in m): F = Kc * x^(10/9) with Kc = Kc_mm * (1e3)^(10/9) (N / m^(10/9)).
Every function here is small and pure (scalars or numpy arrays in, the same out) so that a later
numba kernel can reuse it unchanged. A penetration is never raised to 10/9 when negative: the
force functions clip it at zero first.
"""
from __future__ import annotations

import math

import numpy as np

from common.errors import InputError

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


def contact_force(penetration, kc: float):
    """Elastic contact force (N, >= 0) for a penetration (m); zero where the penetration <= 0."""
    p = np.maximum(penetration, 0.0)
    return kc * p ** N_EXP


def contact_potential(penetration, kc: float):
    """Elastic energy (J) stored at a penetration (m): integral of Kc p^(10/9) = 9/19 Kc p^(19/9)."""
    p = np.maximum(penetration, 0.0)
    return (9.0 / 19.0) * kc * p ** (N_EXP + 1.0)


def static_penetration(force, kc: float):
    """Penetration (m) that carries a compressive force (N >= 0): (F / Kc)^(9/10); 0 for F <= 0."""
    f = np.maximum(force, 0.0)
    return (f / kc) ** (1.0 / N_EXP)


def hunt_crossley_force(penetration, rate, kc: float, damping: float):
    """Contact force (N, >= 0) with Hunt-Crossley damping: Kc p^n (1 + damping * dp/dt).

    ``damping`` in s/m (0 = purely elastic, as in the paper); ``rate`` = dp/dt (m/s, > 0 while the
    penetration grows). Clipped at zero so the contact never pulls.
    """
    return np.maximum(contact_force(penetration, kc) * (1.0 + damping * rate), 0.0)
