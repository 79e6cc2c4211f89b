"""Instantaneous cam-follower impact with Newton's restitution, eqs (8)-(11) of the paper.

Two bodies on fixed pivots: the cam with the motor (inertia J' reduced to the cam, angular velocity
omega1 about A) and the follower with links 3-5 (inertia J'' reduced to the follower, omega2 about D).
The contact's relative normal velocity is linear in the two speeds,

    v_n = G2 * omega2 - G1 * omega1            (m/s, positive = gap opening towards the outer flank)

with G2 the moment arm of the contact normal about D (the paper's A2 = l cos(alpha) = Db2/2) and
G1 that about A (the paper's A1 = Db1/2, signed by the cam's sense of rotation). An impulse P (N s)
along the unit normal n acts with +P on the follower and -P on the cam:

    J'' (omega2+ - omega2-) = +P G2         (eq. 9, moment of the percussion about D)
    J'  (omega1+ - omega1-) = -P G1         (eq. 8, moment about A)
    v_n+ = -k v_n-                          (eq. 9, Newton's hypothesis)

so P = -(1 + k) v_n- / (G2^2 / J'' + G1^2 / J'). This is eq. (10) in another arrangement
(``paper_eq10`` below, checked against it in the tests). With k = 1 the kinetic energy
1/2 J' omega1^2 + 1/2 J'' omega2^2 is unchanged:  dT = P (v_n+ + v_n-) / 2 = 0.
A cam driven at constant speed (omega1 'const') has J' = infinity: pass ``inv_Jcam = 0``.
"""
from __future__ import annotations

from labtool.models.dynamics.jit import jit


@jit
def impact(omega1, omega2, G1, G2, inv_Jcam, J_follower, k):
    """Velocities after an impact and its percussion.

    omega1, omega2 in rad/s before the impact; G1, G2 in m (moment arms of the contact normal
    about A and D, signed as above); inv_Jcam = 1/J' in 1/(kg m^2) (0: cam as input);
    J_follower = J'' in kg m^2; k in [0, 1].
    Returns (omega1+, omega2+, P [N s, signed: > 0 pushes the follower towards the outer flank],
    v_n- [m/s], v_n+ [m/s]). Compiled: the rigid model's loops call it (labtool.models.dynamics.kernels.rigid_nb).
    """
    v_before = G2 * omega2 - G1 * omega1
    P = -(1.0 + k) * v_before / (G2 * G2 / J_follower + G1 * G1 * inv_Jcam)
    omega1_after = omega1 - P * G1 * inv_Jcam
    omega2_after = omega2 + P * G2 / J_follower
    return omega1_after, omega2_after, P, v_before, -k * v_before


def paper_eq10(omega10: float, omega20: float, A1: float, A2: float, J_cam: float,
               J_follower: float, k: float) -> tuple[float, float, float]:
    """The paper's eq. (10) as printed: (omega1, omega2, P_int1) after the impact.

    Kept as an independent formula for the tests; ``impact`` is what the model uses.
    """
    omega2 = ((J_cam * omega10 * A1 * A2 * (1.0 + k) + omega20 * (J_follower * A1**2 - J_cam * A2**2 * k))
              / (J_cam * A2**2 + J_follower * A1**2))
    omega1 = (omega2 * A2 + omega20 * A2 * k - omega10 * A1 * k) / A1
    P = (J_follower * omega2 - J_follower * omega20) / (-A2)
    return omega1, omega2, P


@jit
def kinetic_energy(omega1, omega2, J_cam, J_follower):
    """1/2 J' omega1^2 + 1/2 J'' omega2^2 in J."""
    return 0.5 * J_cam * omega1 * omega1 + 0.5 * J_follower * omega2 * omega2
