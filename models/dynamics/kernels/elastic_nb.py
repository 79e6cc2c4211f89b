"""The elastic-contact model's equations (paper eqs 12-19), compiled: written once, run by the
shared Dormand-Prince driver (labtool.models.dynamics.kernels.dopri5.run) and by the scipy reference loop
(labtool.models.dynamics.reference.run) alike. Read the physics and sign conventions in labtool.models.dynamics.elastic.

    M(t) x'' = F(x, x') - drive(t)        x (m) relative displacement along the normal (+ exterior)
    interior flank (phase 0): F = +N(-x, -x'), exterior (phase 2): F = -N(x - j, x'),
    flight (phase 1): F = 0; N the contact law (labtool.models.dynamics.contact.normal_force); drive and M
    linear in t on the tables' grid.

Events: the boundary of the phase's flank (x = 0 interior, x = j exterior); after one the state
restarts NUDGE inside the new phase, so a boundary event cannot re-fire from rounding. With j = 0
(the gap closed) the follower passes from one flank to the other at x = 0 directly. The phase
array is [phase, 0, 0, 0, 0, 0]; the state (x m, x' m/s).
"""
from __future__ import annotations

from collections import namedtuple

from labtool.models.dynamics import events as ev_layout
from labtool.models.dynamics.contact import normal_force, penetration_under
from labtool.models.dynamics.jit import jit, kernel
from labtool.models.dynamics.kernels import dopri5 as dp

INTERIOR, FLIGHT, EXTERIOR = 0, 1, 2
NUDGE = 1e-13          # m, how far inside the new phase a restart begins (<< any deformation)
COL_V = ev_layout.N_SHARED            # the model's own event column: signed x' at the event (m/s)

# the tables are one array (3, n) (rows TG, DRIVE, MASS): a struct member array costs a reference
# count update at every access, one array one update
TG, DRIVE, MASS = 0, 1, 2
ElasticModel = namedtuple("ElasticModel", [
    "tab",       # rows: s, time grid (increasing, nearly uniform); N, R31 on it (consistent reading,
                 # -R31 for the literal one); kg, reduced mass M on it
    "kc",        # N / m^(10/9)
    "gap",       # m, j between the flanks (0: closed)
    "damping",   # s/m, Hunt-Crossley
    "omega1",    # rad/s, the cam's constant speed (phi1 = omega1 t)
    "nudge",     # m, restart offset inside a new phase
    "rate",      # 1/s, (n - 1) / (tab[TG, -1] - tab[TG, 0]): interp_rows' first guess of an interval
])


@kernel
def grid_rate(tg):
    """ElasticModel.rate of the time grid tg (s): intervals per second (0 for a single instant)."""
    n = tg.size
    if n < 2 or not tg[n - 1] > tg[0]:
        return 0.0
    return (n - 1) / (tg[n - 1] - tg[0])


@kernel(inline="always")
def interp_rows(t, tab, row_a, row_b, rate):
    """np.interp(t, tab[TG], tab[row]) of two rows on the increasing, nearly uniform grid tab[TG]
    (one guess from ``rate``, ElasticModel.rate, then a short walk; the interval and its weight
    found once for both). The guess multiplies: a division there waited on the other one."""
    n = tab.shape[1]
    t0, t1 = tab[TG, 0], tab[TG, n - 1]
    if t <= t0:
        return tab[row_a, 0], tab[row_b, 0]
    if t >= t1:
        return tab[row_a, n - 1], tab[row_b, n - 1]
    i = int((t - t0) * rate)
    i = min(max(i, 0), n - 2)
    while i > 0 and t < tab[TG, i]:
        i -= 1
    while i < n - 2 and t >= tab[TG, i + 1]:
        i += 1
    w = (t - tab[TG, i]) / (tab[TG, i + 1] - tab[TG, i])
    return (tab[row_a, i] + w * (tab[row_a, i + 1] - tab[row_a, i]),
            tab[row_b, i] + w * (tab[row_b, i + 1] - tab[row_b, i]))


@kernel(internal=True)
def flank_force(phase, x, v, kc, gap, damping):
    """Groove-on-follower normal force along +x (N) in ``phase`` at the normal offset x (m) from the
    interior flank, moving at v (m/s): the contact law (labtool.models.dynamics.contact.normal_force) on the
    flank in contact, + from the interior one, - from the exterior one at x = gap. The twin
    (labtool.models.dynamics.kernels.twin_nb) applies the same."""
    if phase == INTERIOR:
        return normal_force(-x, -v, kc, damping)
    if phase == EXTERIOR:
        return -normal_force(x - gap, v, kc, damping)
    return 0.0


@kernel(internal=True)
def force(m, phase, x, v):
    """``flank_force`` with the model's contact law and gap."""
    return flank_force(phase, x, v, m.kc, m.gap, m.damping)


@kernel
def rhs(model, ph, t, y, out):
    d, mass = interp_rows(t, model.tab, DRIVE, MASS, model.rate)
    out[0] = y[1]
    out[1] = (force(model, int(ph[0]), y[0], y[1]) - d) / mass


@kernel(internal=True)
def _on_zero(phase, which):
    """Is event ``which`` of ``phase`` the boundary x = 0 (else x = j)?"""
    return phase == INTERIOR or (phase == FLIGHT and which == 0)


@kernel
def event(model, ph, which, t, y):
    return y[0] if _on_zero(int(ph[0]), which) else y[0] - model.gap


@kernel
def event_offset(model, ph, which):
    """Both events are x minus a constant (0 or j): state component 0 (dopri5.event_offset)."""
    return 0


@kernel
def n_events(model, ph):
    return 2 if int(ph[0]) == FLIGHT else 1


@kernel
def direction(model, ph, which):
    """Leaving the interior flank x rises through 0, leaving the exterior one falls through j;
    in flight a landing on the interior flank falls through 0, on the exterior rises through j."""
    phase = int(ph[0])
    if phase == INTERIOR:
        return 1.0
    if phase == EXTERIOR:
        return -1.0
    return -1.0 if which == 0 else 1.0


@kernel
def state_size(model, ph):
    return 2


@kernel(internal=True)
def next_phase(m, phase, which):
    if phase == INTERIOR:
        return FLIGHT if m.gap > 0.0 else EXTERIOR
    if phase == EXTERIOR:
        return FLIGHT if m.gap > 0.0 else INTERIOR
    return INTERIOR if which == 0 else EXTERIOR


@kernel(internal=True)
def restart_position(m, at_zero, new_phase):
    """x (m) just inside ``new_phase`` at the boundary x = 0 (at_zero) or x = j."""
    eps = m.nudge if m.gap == 0.0 else min(m.nudge, 0.25 * m.gap)
    boundary = 0.0 if at_zero else m.gap
    if new_phase == INTERIOR:
        inward = -1.0
    elif new_phase == EXTERIOR:
        inward = 1.0
    else:
        inward = 1.0 if at_zero else -1.0
    return boundary + inward * eps


@jit
def transition(model, ph, which, t, y, ev, nev):
    """A contact ends (a separation row) or a flight ends on a flank (a contact row); the impact
    columns of a landing (domega2, percussion, persistent) are completed from the run afterwards
    (labtool.models.dynamics.elastic). With j = 0 a change of flank is a separation only: no flight ends."""
    phase = int(ph[0])
    new = next_phase(model, phase, which)
    at_zero = _on_zero(phase, which)
    r = ev[nev]
    r[ev_layout.COL_TIME] = t
    r[ev_layout.COL_PHI1] = model.omega1 * t
    if phase == FLIGHT:
        r[ev_layout.COL_KIND] = ev_layout.KIND_CONTACT
        side = new
    else:
        r[ev_layout.COL_KIND] = ev_layout.KIND_SEPARATION
        side = phase
    r[ev_layout.COL_SIDE] = ev_layout.SIDE_INTERIOR if side == INTERIOR else ev_layout.SIDE_EXTERIOR
    r[ev_layout.COL_V_REL] = abs(y[1])
    r[ev_layout.COL_PERSISTENT] = 0.0
    r[COL_V] = y[1]
    y[0] = restart_position(model, at_zero, new)
    ph[0] = new
    return dp.CONTINUE, nev + 1


@jit
def start(m):
    """(phase, t0 s, x0 m, v0 m/s) of a run: static equilibrium under the drive at t = 0. With no
    drive at the start nothing moves until the drive departs from zero: the run begins at the last
    grid instant before it does, against the flank it will load (so that it does not begin with a
    zero-speed landing or jump)."""
    drive, tg = m.tab[DRIVE], m.tab[TG]
    d0 = drive[0]
    if d0 > 0.0:
        return INTERIOR, 0.0, -penetration_under(d0, m.kc), 0.0
    if d0 < 0.0:
        return EXTERIOR, 0.0, m.gap + penetration_under(-d0, m.kc), 0.0
    for i in range(1, drive.size):
        if drive[i] != 0.0:
            phase = INTERIOR if drive[i] > 0.0 else EXTERIOR
            return phase, tg[i - 1], restart_position(m, phase == INTERIOR, phase), 0.0
    return (FLIGHT if m.gap > 0.0 else INTERIOR), 0.0, 0.0, 0.0


@jit
def forces(m, phases, x, v, out):
    """``force`` over output samples (arrays)."""
    for i in range(out.size):
        out[i] = force(m, phases[i], x[i], v[i])


dp.register(ElasticModel, rhs, event, n_events, direction, state_size, transition, event_offset)
