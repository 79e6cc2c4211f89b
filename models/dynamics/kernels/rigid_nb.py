"""The rigid-element model's equations (paper eqs 1-11), compiled: written once, run by the shared
Dormand-Prince driver (labtool.models.dynamics.kernels.dopri5.run) and by the scipy reference loop
(labtool.models.dynamics.reference.run) alike. The model, its assumptions and sign conventions are in
labtool.models.dynamics.rigid's docstring.

contact (mode 0; state phi1 rad, omega1 rad/s): the roller rides the inner (+1) or outer (-1)
    flank; eps1 from eq. (1) with the reduced inertia of eq. (2); events: the end of the cam angle,
    and (with backlash) the flank's normal force lam = MR13D / A2 (N) changing sign.
free (mode 1; state phi1, omega1, q rad, omega2 rad/s): eqs (4)-(7); events: the end of the cam
    angle, the gap g = A2 q closing on the inner flank (g = 0) or the outer one (g = j); on the
    flank just left the function is divided by (t - t0), which removes its trivial root at the start
    without an offset (an offset would feed energy into accumulating impacts).
impact: Newton's k on the normal velocity of the roller centre (eqs 8-11, labtool.models.dynamics.impact). The settle
    rule: a rebound whose flight would rise less above the flank than the contact deformation
    under the flank's force (Palmgren, the scene's contact law) is below what a model of rigid
    elements resolves: the impact is made plastic and the follower stays on the flank, provided
    the flank presses on it (persistent contact). It ends grazing chatter and the accumulation of
    impacts (k < 1) alike, at every solver preset.

Phase array: [mode, flank, flank just left, t0 of the phase (s), gap rate at t0 (m/s), 0].
"""
from __future__ import annotations

from collections import namedtuple

import numpy as np

from labtool.models.dynamics import events as ev_layout
from labtool.models.dynamics.contact import penetration_under
from labtool.models.dynamics.impact import impact, kinetic_energy
from labtool.models.dynamics.jit import jit, kernel
from labtool.models.dynamics.kernels import dopri5 as dp

INNER, OUTER, FREE = 1, -1, 0
CONTACT_MODE, FREE_MODE = 0, 1
ANGLE_TIE = 1e-12      # rad: an event this close to the end of the simulated angle is the end
# the model's own event columns (after the shared ones of labtool.models.dynamics.events)
(COL_OMEGA1_BEFORE, COL_OMEGA1_AFTER, COL_OMEGA2_BEFORE, COL_OMEGA2_AFTER, COL_ENERGY_BEFORE,
 COL_ENERGY_AFTER, COL_V_BEFORE, COL_V_AFTER, COL_PHI2) = range(ev_layout.N_SHARED, ev_layout.N_SHARED + 9)

RigidModel = namedtuple("RigidModel", [
    "cam",              # cam-angle table (rad), 8 columns (labtool.models.dynamics.rigid_tables.Table.packed)
    "fol",              # follower-angle table (rad), 4 columns per unit inertia factor
    "phi20",            # rad, follower angle at psi = 0 (phiD + psi0)
    "jt",               # inertia factor of elements 2-5
    "Jcam",             # kg m^2, J' (cam + motor reduced to the cam)
    "inv_Jcam",         # 1/(kg m^2): 1/J', 0 with the cam as input
    "const",            # bool: omega1 constant (cam as input)
    "m0", "m1",         # motor moment on the cam: M1 = m0 - m1 omega1 (N m, N m s/rad)
    "Fu",               # N, load magnitude
    "j",                # m, backlash
    "k",                # Newton's restitution coefficient
    "phi1_end",         # rad, the simulated cam angle
    "kc",               # N / m^(10/9), the contact law of the settle rule
])


@kernel(internal=True)
def _cell(tab, x):
    """Row of the cell [x_i, x_{i+1}) of a packed table that holds x, clipped. The nodes are
    uniform, or uniform piece by piece with nearly the same spacing (rigid_tables): a direct guess
    from the mean spacing, then a walk of a cell or two (the same row a binary search finds; 3-4x
    cheaper for the tables' 2000-4000 rows)."""
    n = tab.shape[0]
    x0, x1 = tab[0, 0], tab[n - 1, 0]
    if x < x0:
        return 0
    if x >= x1:
        return n - 2
    i = min(max(int((x - x0) / (x1 - x0) * (n - 1)), 0), n - 2)
    while i > 0 and x < tab[i, 0]:
        i -= 1
    while i < n - 2 and x >= tab[i + 1, 0]:
        i += 1
    return i


@kernel(internal=True)
def _cubic(tab, i, col, t):
    k = 2 + 4 * col
    return tab[i, k] + t * (tab[i, k + 1] + t * (tab[i, k + 2] + t * tab[i, k + 3]))


@kernel
def cam_row(m, phi1):
    """(psi, psi', psi'', A2, A2', A2'', Mc, direction) at the cam angle phi1 (rad)."""
    c = m.cam
    i = _cell(c, phi1)
    t = (phi1 - c[i, 0]) * c[i, 1]
    return (_cubic(c, i, 0, t), _cubic(c, i, 1, t), _cubic(c, i, 2, t), _cubic(c, i, 3, t),
            _cubic(c, i, 4, t), _cubic(c, i, 5, t), _cubic(c, i, 6, t), _cubic(c, i, 7, t))


@kernel
def follower_row(m, phi2):
    """(J'', dJ''/dphi2 per unit inertia factor, M_gravity, load arm per N) at phi2 (rad)."""
    c = m.fol
    i = _cell(c, phi2)
    t = (phi2 - c[i, 0]) * c[i, 1]
    return _cubic(c, i, 0, t), _cubic(c, i, 1, t), _cubic(c, i, 2, t), _cubic(c, i, 3, t)


@kernel(internal=True)
def flank_offset(m, flank, A2, dA2, ddA2):
    """Angular offset of the flank in contact from the pitch curve and its two phi1 derivatives."""
    if flank == OUTER and m.j > 0.0:
        return m.j / A2, -m.j * dA2 / (A2 * A2), m.j * (2.0 * dA2 * dA2 / A2 ** 3 - ddA2 / (A2 * A2))
    return 0.0, 0.0, 0.0


@kernel
def contact_terms(m, phi1, omega1, flank):
    """1-DOF motion on ``flank``: (eps1 rad/s^2, phi2 rad, omega2 rad/s, eps2 rad/s^2, MR13D N m,
    lam N (> 0 along the normal away from A), q rad, A2 m, psi')."""
    psi, d1, d2, A2, dA2, ddA2, Mc, dirn = cam_row(m, phi1)
    qc, dqc, ddqc = flank_offset(m, flank, A2, dA2, ddA2)
    phi2 = m.phi20 + psi + qc
    f1, f2 = d1 + dqc, d2 + ddqc
    J0, dJ0, Mg, arm = follower_row(m, phi2)
    J, dJ, ML = J0 * m.jt, dJ0 * m.jt, m.Fu * dirn * arm
    if m.const:
        eps1 = 0.0
    else:
        Jred = m.Jcam + J * f1 * f1                                   # eq. (2)
        dJred = dJ * f1 ** 3 + 2.0 * J * f1 * f2
        eps1 = (m.m0 - m.m1 * omega1 + Mc + (Mg + ML) * f1 - 0.5 * dJred * omega1 * omega1) / Jred   # eq. (1)
    omega2 = f1 * omega1
    eps2 = f2 * omega1 * omega1 + f1 * eps1
    MR = J * eps2 + 0.5 * dJ * omega2 * omega2 - Mg - ML
    return eps1, phi2, omega2, eps2, MR, MR / A2, qc, A2, d1


@kernel
def free_terms(m, phi1, omega1, q, omega2):
    """2-DOF motion in the gap: (eps1, dq/dt, eps2, gap g m, phi2, A2, psi', A2')."""
    psi, d1, d2, A2, dA2, ddA2, Mc, dirn = cam_row(m, phi1)
    phi2 = m.phi20 + psi + q
    J0, dJ0, Mg, arm = follower_row(m, phi2)
    eps1 = 0.0 if m.const else (m.m0 - m.m1 * omega1 + Mc) * m.inv_Jcam                    # eq. (4)
    eps2 = (Mg + m.Fu * dirn * arm - 0.5 * m.jt * dJ0 * omega2 * omega2) / (m.jt * J0)      # eq. (6)
    return eps1, omega2 - d1 * omega1, eps2, A2 * q, phi2, A2, d1, dA2


@kernel
def rhs(model, ph, t, y, out):
    if int(ph[0]) == CONTACT_MODE:
        out[0] = y[1]
        out[1] = contact_terms(model, y[0], y[1], int(ph[1]))[0]
    else:
        eps1, dq, eps2 = free_terms(model, y[0], y[1], y[2], y[3])[:3]
        out[0] = y[1]
        out[1] = eps1
        out[2] = dq
        out[3] = eps2


@kernel
def event(model, ph, which, t, y):
    """which 0: the end of the cam angle. contact: 1 the flank's force. free: 1 the inner gap,
    2 the outer gap (divided by t - t0 on the flank just left)."""
    if which == 0:
        return y[0] - model.phi1_end
    if int(ph[0]) == CONTACT_MODE:
        flank = int(ph[1])
        return flank * contact_terms(model, y[0], y[1], flank)[5]
    g = free_terms(model, y[0], y[1], y[2], y[3])[3] - (0.0 if which == 1 else model.j)
    target = INNER if which == 1 else OUTER
    if target != int(ph[2]):
        return g
    return g / (t - ph[3]) if t > ph[3] else ph[4]


@kernel
def n_events(model, ph):
    if int(ph[0]) == CONTACT_MODE:
        return 2 if model.j > 0.0 else 1
    return 3


@kernel
def direction(model, ph, which):
    if which == 0:
        return 1.0
    if int(ph[0]) == CONTACT_MODE:
        return -1.0
    return -1.0 if which == 1 else 1.0


@kernel
def state_size(model, ph):
    return 2 if int(ph[0]) == CONTACT_MODE else 4


@kernel(internal=True)
def settles(m, phi1, omega1_held, flank, v_rebound, G1, A2, J2):
    """The settle rule (module doc): is a rebound at ``v_rebound`` (m/s) off ``flank`` below the
    contact's resolution, with the flank pressing on the follower held on it?"""
    lam = contact_terms(m, phi1, omega1_held, flank)[5]
    if flank * lam <= 0.0:
        return False                               # the flank does not hold it: it flies off
    inv_mass = A2 * A2 / J2 + G1 * G1 * m.inv_Jcam   # normal acceleration per N of the flank force
    # rebound apex v^2 / (2 a), a = |lam| inv_mass, against the deformation under |lam|
    return v_rebound * v_rebound < 2.0 * abs(lam) * inv_mass * penetration_under(abs(lam), m.kc)


@jit(internal=True)
def _row(ev, nev, t, phi1, kind, flank, v_rel, domega2, percussion, persistent):
    r = ev[nev]
    r[ev_layout.COL_TIME] = t
    r[ev_layout.COL_PHI1] = phi1
    r[ev_layout.COL_KIND] = kind
    r[ev_layout.COL_SIDE] = ev_layout.SIDE_INTERIOR if flank == INNER else ev_layout.SIDE_EXTERIOR
    r[ev_layout.COL_V_REL] = abs(v_rel)
    r[ev_layout.COL_DOMEGA2] = domega2
    r[ev_layout.COL_PERCUSSION] = percussion
    r[ev_layout.COL_PERSISTENT] = 1.0 if persistent else 0.0
    return r


@jit(internal=True)
def _lift_off(m, ph, t, y, ev, nev):
    """Contact loss: the flank's force changed sign; the follower flies from the flank's position."""
    flank = int(ph[1])
    phi1, omega1 = y[0], y[1]
    terms = contact_terms(m, phi1, omega1, flank)
    omega2, q = terms[2], terms[6]
    r = _row(ev, nev, t, phi1, ev_layout.KIND_SEPARATION, flank, 0.0, 0.0, np.nan, True)
    r[COL_OMEGA1_BEFORE], r[COL_OMEGA1_AFTER], r[COL_OMEGA2_BEFORE], r[COL_OMEGA2_AFTER] = omega1, omega1, omega2, omega2
    r[COL_V_BEFORE], r[COL_V_AFTER], r[COL_PHI2] = 0.0, 0.0, terms[1]
    y[2], y[3] = q, omega2
    ph[0], ph[1], ph[2], ph[3], ph[4] = FREE_MODE, FREE, flank, t, 0.0
    return nev + 1


@jit(internal=True)
def _impact_on(m, ph, flank, t, y, ev, nev):
    """The gap closed on ``flank``: Newton's impact, or settling on the flank (module doc)."""
    phi1, omega1, q, omega2 = y[0], y[1], y[2], y[3]
    phi2, A2, d1, dA2 = free_terms(m, phi1, omega1, q, omega2)[4:8]
    q = 0.0 if flank == INNER else m.j / A2            # project onto the flank
    G1 = A2 * d1 - dA2 * q
    J2 = follower_row(m, phi2)[0] * m.jt
    approach = abs(A2 * omega2 - G1 * omega1)
    held = impact(omega1, omega2, G1, A2, m.inv_Jcam, J2, 0.0)[0]
    settle = settles(m, phi1, held, flank, m.k * approach, G1, A2, J2)
    w1, w2, Pimp, vb, va = impact(omega1, omega2, G1, A2, m.inv_Jcam, J2, 0.0 if settle else m.k)
    r = _row(ev, nev, t, phi1, ev_layout.KIND_CONTACT, flank, vb, w2 - omega2, abs(Pimp), settle)
    r[COL_OMEGA1_BEFORE], r[COL_OMEGA1_AFTER], r[COL_OMEGA2_BEFORE], r[COL_OMEGA2_AFTER] = omega1, w1, omega2, w2
    r[COL_ENERGY_BEFORE] = kinetic_energy(omega1, omega2, m.Jcam, J2)
    r[COL_ENERGY_AFTER] = kinetic_energy(w1, w2, m.Jcam, J2)
    r[COL_V_BEFORE], r[COL_V_AFTER], r[COL_PHI2] = vb, va, phi2
    nev += 1
    y[1] = w1
    if settle:
        ph[0], ph[1] = CONTACT_MODE, flank
        return nev
    r = _row(ev, nev, t, phi1, ev_layout.KIND_SEPARATION, flank, va, 0.0, np.nan, False)     # the rebound
    r[COL_OMEGA1_BEFORE], r[COL_OMEGA1_AFTER], r[COL_OMEGA2_BEFORE], r[COL_OMEGA2_AFTER] = w1, w1, w2, w2
    r[COL_V_BEFORE], r[COL_V_AFTER], r[COL_PHI2] = va, va, phi2
    y[2], y[3] = q, w2
    ph[0], ph[1], ph[2], ph[3], ph[4] = FREE_MODE, FREE, flank, t, va
    return nev + 1


@jit
def transition(model, ph, which, t, y, ev, nev):
    if which == 0 or y[0] >= model.phi1_end - ANGLE_TIE:
        # the end of the span; a force jump at the very end (the end of the rise, where the load is
        # removed) ends the run too: it is not a lift-off inside the span
        return dp.END, nev
    if int(ph[0]) == CONTACT_MODE:
        return dp.CONTINUE, _lift_off(model, ph, t, y, ev, nev)
    return dp.CONTINUE, _impact_on(model, ph, INNER if which == 1 else OUTER, t, y, ev, nev)


@jit
def start_flank(m, phi1, omega1):
    """The flank whose force is compressive at (phi1, omega1): the inner one unless it would pull."""
    lam = contact_terms(m, phi1, omega1, INNER)[5]
    return INNER if (lam >= 0.0 or m.j == 0.0) else OUTER


@jit
def derived(m, modes, flanks, Y, out):
    """Derived quantities at the states Y (>= n_state, k) in the modes and flanks (arrays, one a
    state), into out (9, k): phi1, omega1, epsilon1, phi2, omega2, epsilon2, MR13D, lam (R13n),
    gap g (m)."""
    for i in range(Y.shape[1]):
        if modes[i] == CONTACT_MODE:
            eps1, phi2, omega2, eps2, MR, lam, q, A2, _ = contact_terms(m, Y[0, i], Y[1, i], flanks[i])
            gap = A2 * q
        else:
            eps1, _, eps2, gap, phi2, _, _, _ = free_terms(m, Y[0, i], Y[1, i], Y[2, i], Y[3, i])
            omega2, MR, lam = Y[3, i], 0.0, 0.0
        out[0, i], out[1, i], out[2, i], out[3, i], out[4, i] = Y[0, i], Y[1, i], eps1, phi2, omega2
        out[5, i], out[6, i], out[7, i], out[8, i] = eps2, MR, lam, gap


@jit
def cam_rows(m, phi1, out):
    """``cam_row`` at the angles phi1 (array, rad) into out (8, len(phi1))."""
    for i in range(phi1.size):
        r = cam_row(m, phi1[i])
        for c in range(8):
            out[c, i] = r[c]


dp.register(RigidModel, rhs, event, n_events, direction, state_size, transition)
