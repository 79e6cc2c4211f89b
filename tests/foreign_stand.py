"""A stand that is not labtool's: recordings from physics written here, not from labtool's models.

labtool's models and its twin share their contact law (Palmgren with Hunt-Crossley damping, or
Newton's restitution), their linearised gap geometry and their sensor chain. A fit judged only on
recordings they make is judged on its own assumptions. This generator writes the follower's motion
from the physics again, with the choices a real stand could make differently, and records it
through a sensor chain of its own in recording format v1 (docs/architecture.md), with plain h5py:

* **the flank contact**: Hertz's point-contact law F = K delta^1.5 with Flores et al.'s
  dissipation (Flores, Machado, Silva, Martins, Multibody Syst. Dyn. 25 (2011) 357-375):
  F = K delta^1.5 (1 + 8 (1 - e) / (5 e) delta' / v0), v0 the approach speed at the contact's
  onset, so that an isolated impact rebounds at about e, whatever its speed (0.26, 0.47, 0.79 for
  e = 0.3, 0.5, 0.8; tests/test_foreign_stand.py); the force is
  never adhesive and its damping is capped (a lubricated contact's finite damping; it also keeps
  the explicit integration stable);
* **the gap**: the exact normal distance of the roller centre from the pitch curve (found by
  Newton's method on the pitch curve in the cam frame, second order in the follower's deviation),
  where labtool linearises it; the groove's width varies once a turn around its mean j
  (``width_variation``, a machined groove is not exactly an offset curve);
* **the follower**: the rigid lever of the paper's links 2-5 (the mechanism's own inertia,
  gravity and load arm, labtool.models.mechanism.linkage: geometry, not dynamics) plus its long
  arm's bending as a second degree of freedom (a modal mass at E on a spring, ``mode_hz``), pivot
  friction (Coulomb, regularised, and viscous), the load Fu at N opposing N's actual velocity (labtool's
  models take its direction from the cam program);
* **the drive**: the cam turns at the nominal speed with a ripple twice a turn (``ripple``);
* **the sensor chain**: specific force at E (gravity included), the accelerometer's mounted
  resonance (``sensor_resonance_hz``), the conditioner's AC coupling, a Butterworth anti-alias
  filter at ``antialias_hz`` applied at the 200 kHz integration rate, decimation to 10 kHz, white
  noise, and a 16-bit ADC over +-10 V (quantised); a 5 V tacho pulse through the same filter.

The integration is a fixed-step Runge-Kutta (4th order, 5 us: 150 steps over the fastest contact
period here) compiled with numba; a 4 s recording takes a few seconds. ``record`` writes one and
returns its truth (the mean width j and e, and what the run measured: the effective restitution
of its landings, contacts per turn).
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
from numba import njit
from scipy import signal
from scipy.interpolate import CubicSpline

TWO_PI = 2.0 * math.pi
G = 9.81
FS = 10_000.0                # recorded sample rate, Hz
OVERSAMPLE = 20              # integration steps per recorded sample (200 kHz)
KA = 864.3                   # m/s^2 per V: the chain's true gain, stated in the file


@dataclasses.dataclass(frozen=True)
class ForeignStand:
    """One run of the foreign stand (SI unless the name says otherwise).

    rpm              nominal cam speed (rpm)
    Fu               load at N (N), opposing N's actual velocity
    backlash         the groove's mean width j over a turn (m): the truth a fit should find
    restitution      e of Flores' contact law: the truth of an impact's restitution
    width_variation  relative once-a-turn variation of the groove's width (-)
    width_phase      its phase (rad of cam angle)
    contact_k        Hertz stiffness K (N m^-1.5)
    damping_cap      the contact's largest damping (N s/m)
    v_min            the smallest approach speed the dissipation is scaled with (m/s)
    mode_hz, mode_zeta, mode_share  the long arm's bending: frequency with the root held (Hz),
                     damping ratio (-), modal mass at E as a share of J''red / DE^2 (-)
    friction_torque, friction_speed, friction_viscous  pivot friction: Coulomb torque (N m)
                     regularised below friction_speed (rad/s), viscous (N m s/rad)
    load_speed       speed of N below which the load is regularised (m/s)
    ripple           the cam speed's relative ripple, twice a turn (-)
    sensor_resonance_hz, sensor_q   the accelerometer's mounted resonance and its quality factor
    highpass_hz      the conditioner's AC coupling (first order)
    antialias_hz, antialias_order   the DAQ's Butterworth anti-alias filter
    noise_m_s2       white noise at the ADC input (m/s^2 rms at the recorded rate)
    adc_bits, adc_range_v  the converter
    duration_s       recorded duration (s)
    warmup_turns     cam turns run before the recording starts
    seed             noise and the recording's starting cam angle
    """

    rpm: float = 180.0
    Fu: float = 0.0
    backlash: float = 0.128e-3
    restitution: float = 0.5
    width_variation: float = 0.02
    width_phase: float = 0.0
    contact_k: float = 1.0e11
    damping_cap: float = 2.0e5
    v_min: float = 1.0e-3
    mode_hz: float = 900.0
    mode_zeta: float = 0.03
    mode_share: float = 0.2
    friction_torque: float = 0.01
    friction_speed: float = 2e-3
    friction_viscous: float = 2e-3
    load_speed: float = 1e-3
    ripple: float = 0.003
    sensor_resonance_hz: float = 6500.0
    sensor_q: float = 25.0
    highpass_hz: float = 0.3
    antialias_hz: float = 4000.0
    antialias_order: int = 4
    noise_m_s2: float = 0.3
    adc_bits: int = 16
    adc_range_v: float = 10.0
    duration_s: float = 4.0
    warmup_turns: int = 2
    seed: int = 0

    def attrs(self) -> dict:
        return {f"foreign_{f.name}": getattr(self, f.name) for f in dataclasses.fields(self)}


# --------------------------------------------------------------------------- tables of the geometry

N_PHI1 = 1 << 16             # cam-angle table points over a turn
N_PHI2 = 4096                # follower-angle table points


def _mechanism():
    from labtool.models.mechanism import Mechanism
    from labtool.models.mechanism.motion_laws import CamProgram

    mech = Mechanism.default()
    return mech, CamProgram.for_mechanism(mech)


def _rot(x, y, a):
    c, s = np.cos(a), np.sin(a)
    return c * x - s * y, s * x + c * y


def gap_tables(mech, program) -> dict:
    """The pitch angle and the exact gap over the cam angle: phi2_pitch, its rate psi', and the
    coefficients of g = a1 q + a2 q^2 (q = phi2 - phi2_pitch, m) with their cam-angle rates.

    g is the signed normal distance of the roller centre C from the pitch curve, in the cam's frame
    (positive away from the cam's axis A): the point of the pitch curve nearest to C is found by
    Newton's method on a periodic spline of the curve; g at q = +-h, +-2h gives a1, a2 by least
    squares."""
    from labtool.models.mechanism.cam_profile import cached_sense

    sense = cached_sense(mech, program)
    phi = np.linspace(0.0, TWO_PI, N_PHI1, endpoint=False)
    psi, dpsi, _, _ = program(phi)
    phi2p = mech.phiD + mech.psi0 + psi
    # the pitch curve in the cam frame, periodic
    cx, cy = mech.xD + mech.l * np.cos(phi2p), mech.yD + mech.l * np.sin(phi2p)
    px, py = _rot(cx, cy, -sense * phi)
    ext = np.append(phi, TWO_PI)
    spl = CubicSpline(ext, np.column_stack([np.append(px, px[0]), np.append(py, py[0])]), bc_type="periodic")
    d1, d2 = spl.derivative(1), spl.derivative(2)
    P1 = d1(phi)
    nx, ny = P1[:, 1], -P1[:, 0]
    flip = np.sign(nx * px + ny * py)
    h = 2e-3
    qs = np.array([-2 * h, -h, h, 2 * h])
    gs = []
    for q in qs:
        qx, qy = _rot(mech.xD + mech.l * np.cos(phi2p + q), mech.yD + mech.l * np.sin(phi2p + q), -sense * phi)
        s = phi.copy()
        for _ in range(8):
            P, Pd, Pdd = spl(s), d1(s), d2(s)
            rx, ry = P[:, 0] - qx, P[:, 1] - qy
            f = rx * Pd[:, 0] + ry * Pd[:, 1]
            fd = Pd[:, 0] ** 2 + Pd[:, 1] ** 2 + rx * Pdd[:, 0] + ry * Pdd[:, 1]
            s = s - f / fd
        P, Pd = spl(s), d1(s)
        n_x, n_y = Pd[:, 1], -Pd[:, 0]
        norm = np.hypot(n_x, n_y)
        gs.append(flip * ((qx - P[:, 0]) * n_x + (qy - P[:, 1]) * n_y) / norm)
    A = np.column_stack([qs, qs ** 2])
    coef, *_ = np.linalg.lstsq(A, np.array(gs), rcond=None)
    a1, a2 = coef
    dphi = TWO_PI / N_PHI1
    da1 = (np.roll(a1, -1) - np.roll(a1, 1)) / (2 * dphi)
    da2 = (np.roll(a2, -1) - np.roll(a2, 1)) / (2 * dphi)
    return dict(phi2p=phi2p, dpsi=dpsi, a1=a1, a2=a2, da1=da1, da2=da2, sense=sense)


def follower_tables(mech, jt_factor: float = 1.0) -> dict:
    """J''red, its derivative, gravity's moment and the load's arm (dN_x/dphi2) over the follower
    angle: the linkage's geometry and masses."""
    from labtool.models.mechanism.linkage import linkage_state, reduced_follower

    lo = mech.phiD + mech.psi0 - 0.1
    hi = mech.phiD + mech.psi0 + math.radians(15.0) + 0.1
    th = np.linspace(lo, hi, N_PHI2)
    unit = linkage_state(mech, th, 1.0, 0.0)
    red = reduced_follower(mech, th, None, jt_factor, unit)
    return dict(lo=lo, step=(hi - lo) / (N_PHI2 - 1), J=red.J, dJ=red.dJ, Mg=red.M_gravity,
                arm=unit.vN[0])


# --------------------------------------------------------------------------- the integration

@njit(cache=True)
def _lin(tab, x0, dx, x):
    """Linear interpolation of a uniform table (clamped at its ends)."""
    f = (x - x0) / dx
    i = int(math.floor(f))
    n = tab.shape[0]
    if i < 0:
        return tab[0]
    if i >= n - 1:
        return tab[n - 1]
    w = f - i
    return tab[i] * (1.0 - w) + tab[i + 1] * w


@njit(cache=True)
def _per(tab, x):
    """Linear interpolation of a table over one turn [0, 2 pi), periodic."""
    n = tab.shape[0]
    f = (x % (2.0 * math.pi)) / (2.0 * math.pi) * n
    i = int(math.floor(f))
    w = f - i
    i0 = i % n
    i1 = (i + 1) % n
    return tab[i0] * (1.0 - w) + tab[i1] * w


@njit(cache=True)
def _flank_force(delta, rate, v0, K, e, cap):
    """Flores' dissipative Hertz force (N, >= 0) at penetration delta (m), penetration rate
    ``rate`` (m/s), approach speed v0 (m/s)."""
    if delta <= 0.0:
        return 0.0
    elastic = K * delta * math.sqrt(delta)
    c = elastic * 8.0 * (1.0 - e) / (5.0 * e * v0)
    if c > cap:
        c = cap
    f = elastic + c * rate
    return f if f > 0.0 else 0.0


@njit(cache=True)
def _rhs(y, par, mem, phi2p, dpsi, a1t, a2t, da1t, da2t, J, dJ, Mg, arm, out):
    """d/dt of y = (phi1, theta, omega, u, du); out[5:8] = the flank forces and the sensor's
    tangential acceleration. par: Omega, ripple, j, wvar, wphase, K, e, cap, mb, kb, cb, Tf, wf,
    cv, Fu, vload, th0, dth, DE; mem: v0 of the interior and exterior flank."""
    Om, rip, j, wv, wph, K, e, cap = par[0], par[1], par[2], par[3], par[4], par[5], par[6], par[7]
    mb, kb, cb, Tf, wf, cv, Fu, vl, th0, dth, DE = (par[8], par[9], par[10], par[11], par[12], par[13],
                                                    par[14], par[15], par[16], par[17], par[18])
    phi1, th, om, u, du = y[0], y[1], y[2], y[3], y[4]
    w1 = Om * (1.0 + rip * math.sin(2.0 * phi1))
    p2 = _per(phi2p, phi1)
    dp = _per(dpsi, phi1)
    a1, a2 = _per(a1t, phi1), _per(a2t, phi1)
    da1, da2 = _per(da1t, phi1), _per(da2t, phi1)
    q = th - p2
    dgdq = a1 + 2.0 * a2 * q
    g = a1 * q + a2 * q * q
    gdot = dgdq * (om - dp * w1) + (da1 * q + da2 * q * q) * w1
    width = j * (1.0 + wv * math.cos(phi1 - wph))
    dwidth = -j * wv * math.sin(phi1 - wph) * w1
    # interior flank: penetration -g; exterior: g - width (the force on the follower along +g / -g)
    f_in = _flank_force(-g, -gdot, mem[0], K, e, cap)
    f_out = _flank_force(g - width, gdot - dwidth, mem[1], K, e, cap)
    N = f_in - f_out
    Jr = _lin(J, th0, dth, th) - mb * DE * DE
    dJr = _lin(dJ, th0, dth, th)
    # the load at N along x opposes N's actual velocity (vN_x = arm x omega2): it only takes energy
    a = _lin(arm, th0, dth, th)
    load = -Fu * math.tanh(a * om / vl) * a
    fric = -Tf * math.tanh(om / wf) - cv * om
    spring = kb * u + cb * du      # the force of the arm's bending on the modal mass at E, along E's tangent
    eps = (_lin(Mg, th0, dth, th) + load + fric + N * dgdq + DE * spring - 0.5 * dJr * om * om) / Jr
    out[0] = w1
    out[1] = om
    out[2] = eps
    out[5] = f_in
    out[6] = f_out
    if mb > 0.0:
        out[3] = du
        out[4] = -spring / mb - DE * eps
        out[7] = -spring / mb      # DE eps + u'': the modal mass's acceleration along the tangent
    else:                          # no bending: the sensor rides the rigid lever
        out[3] = 0.0
        out[4] = 0.0
        out[7] = DE * eps
    out[8] = g
    out[9] = gdot
    out[10] = width
    out[11] = dwidth


@njit(cache=True)
def _integrate(y0, dt, n, skip, par, phi2p, dpsi, a1t, a2t, da1t, da2t, J, dJ, Mg, arm, rec, events):
    """Fixed-step RK4 over n steps; from step ``skip`` on, rec[k] = (phi1, theta, omega, a_t, u,
    du) at each step. events[m] = (step, flank (+1 interior, -1 exterior), +1 onset / -1 end, rate):
    every contact's onset and end with its penetration rate. Returns the number of events."""
    y = y0.copy()
    mem = np.full(2, par[20])
    k1 = np.zeros(12)
    k2 = np.zeros(12)
    k3 = np.zeros(12)
    k4 = np.zeros(12)
    yt = np.zeros(5)
    inside = np.zeros(2, np.bool_)
    approach = np.zeros(2)          # each flank's penetration rate at the last step outside it
    ne = 0
    for step in range(n):
        _rhs(y, par, mem, phi2p, dpsi, a1t, a2t, da1t, da2t, J, dJ, Mg, arm, k1)
        # the contacts' state at the step's start: an onset fixes its approach speed v0
        g, gdot, width, dwidth = k1[8], k1[9], k1[10], k1[11]
        for side in range(2):
            pen = -g if side == 0 else g - width
            rate = -gdot if side == 0 else gdot - dwidth
            now = pen > 0.0
            if now and not inside[side]:
                # the approach speed: the rate just before the onset (within the step the flank
                # has already braked the follower by a / f_step, 6 % for stiff flanks)
                mem[side] = max(approach[side], par[20])
                if ne < events.shape[0]:
                    events[ne, 0] = step
                    events[ne, 1] = 1.0 if side == 0 else -1.0
                    events[ne, 2] = 1.0
                    events[ne, 3] = approach[side]
                    ne += 1
            elif inside[side] and not now:
                if ne < events.shape[0]:
                    events[ne, 0] = step
                    events[ne, 1] = 1.0 if side == 0 else -1.0
                    events[ne, 2] = -1.0
                    events[ne, 3] = rate
                    ne += 1
            inside[side] = now
            if not now:
                approach[side] = rate
        if step >= skip:
            r = step - skip
            rec[r, 0] = y[0]
            rec[r, 1] = y[1]
            rec[r, 2] = y[2]
            rec[r, 3] = k1[7]
            rec[r, 4] = y[3]
            rec[r, 5] = y[4]
        for i in range(5):
            yt[i] = y[i] + 0.5 * dt * k1[i]
        _rhs(yt, par, mem, phi2p, dpsi, a1t, a2t, da1t, da2t, J, dJ, Mg, arm, k2)
        for i in range(5):
            yt[i] = y[i] + 0.5 * dt * k2[i]
        _rhs(yt, par, mem, phi2p, dpsi, a1t, a2t, da1t, da2t, J, dJ, Mg, arm, k3)
        for i in range(5):
            yt[i] = y[i] + dt * k3[i]
        _rhs(yt, par, mem, phi2p, dpsi, a1t, a2t, da1t, da2t, J, dJ, Mg, arm, k4)
        for i in range(5):
            y[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
    return ne


_TABLES: dict = {}


def _tables():
    if "gap" not in _TABLES:
        mech, program = _mechanism()
        _TABLES.update(mech=mech, program=program, gap=gap_tables(mech, program), fol=follower_tables(mech))
    return _TABLES


def parameters(stand: ForeignStand) -> tuple[np.ndarray, float]:
    """The integration's parameter vector (``_rhs``) and the modal mass at E (kg)."""
    tb = _tables()
    mech, fol = tb["mech"], tb["fol"]
    j_red = float(np.interp(mech.phiD + mech.psi0, fol["lo"] + fol["step"] * np.arange(N_PHI2), fol["J"]))
    mb = stand.mode_share * j_red / mech.DE ** 2
    kb = mb * (TWO_PI * stand.mode_hz) ** 2
    cb = 2.0 * stand.mode_zeta * math.sqrt(kb * mb)
    par = np.array([stand.rpm * TWO_PI / 60.0, stand.ripple, stand.backlash, stand.width_variation, stand.width_phase,
                    stand.contact_k, stand.restitution, stand.damping_cap, mb, kb, cb, stand.friction_torque,
                    stand.friction_speed, stand.friction_viscous, stand.Fu, stand.load_speed, fol["lo"], fol["step"],
                    mech.DE, 0.0, stand.v_min])
    return par, mb


def integrate(par: np.ndarray, y0, n: int, skip: int = 0, dt: float = 1.0 / (FS * OVERSAMPLE)):
    """``n`` steps from state y0 = (phi1, theta, omega2, u, du): the records from step ``skip`` on
    (phi1, theta, omega2, a_t, u, du) and the events (step, flank, onset/end, rate)."""
    tb = _tables()
    gap, fol = tb["gap"], tb["fol"]
    rec = np.empty((n - skip, 6))
    events = np.zeros((200_000, 4))
    ne = _integrate(np.asarray(y0, float), dt, n, skip, par, gap["phi2p"], gap["dpsi"], gap["a1"], gap["a2"],
                    gap["da1"], gap["da2"], fol["J"], fol["dJ"], fol["Mg"], fol["arm"], rec, events)
    return rec, events[:ne]


def motion(stand: ForeignStand) -> dict:
    """The follower's motion at the integration rate over the recording, with its events.

    Returns t (s, 0 at the recording's first sample), phi1 (rad, unwrapped), theta (rad),
    omega2 (rad/s), a_t (m/s^2, the sensor's tangential acceleration, no gravity), the events
    (time s, flank, onset/end, penetration rate m/s) and the run's effective restitution."""
    gap = _tables()["gap"]
    rng = np.random.default_rng(stand.seed)
    Om = stand.rpm * TWO_PI / 60.0
    dt = 1.0 / (FS * OVERSAMPLE)
    start_angle = rng.uniform(0.0, TWO_PI)           # a recording starts anywhere in a turn
    t_warm = (stand.warmup_turns * TWO_PI + start_angle) / Om
    n_rec = int(round(stand.duration_s * FS)) * OVERSAMPLE
    skip = int(round(t_warm / dt))
    par, mb = parameters(stand)
    # start at rest on the interior flank at the start of a rise, the cam's ripple phase included
    th0 = float(gap["phi2p"][0])
    y0 = np.array([-stand.warmup_turns * TWO_PI, th0, 0.0, 0.0, 0.0])
    rec, ev = integrate(par, y0, skip + n_rec, skip, dt)
    ev = ev[ev[:, 0] >= skip]
    return dict(t=np.arange(n_rec) * dt, phi1=rec[:, 0], theta=rec[:, 1], omega2=rec[:, 2], a_t=rec[:, 3],
                events=np.column_stack([(ev[:, 0] - skip) * dt, ev[:, 1:]]),
                effective_restitution=effective_restitution(ev[:, 0] * dt, ev[:, 1], ev[:, 2] > 0, ev[:, 3]), mb=mb)


def effective_restitution(times, flanks, onsets, rates, persistence_s: float = 2e-3,
                          v_landing: float = 0.01) -> float:
    """The restitution of a run's landings: sum(v_out v_in) / sum(v_in^2) over the landings faster
    than ``v_landing`` (m/s), v_in the normal approach speed at a contact's onset, v_out the
    separation speed at its end, 0 when the contact lasts ``persistence_s`` or longer (the
    follower stayed on the flank). Weighted by the approach speed, so the main impacts decide, as
    they decide a rigid model's k. ``onsets``: True at a contact's onset, False at its end;
    ``rates``: the normal speed into the flank (> 0 approaching)."""
    num = den = 0.0
    open_ = {}
    for t, flank, onset, rate in zip(times, flanks, onsets, rates):
        if onset:
            open_[flank] = (t, rate)
        elif flank in open_:
            t0, v_in = open_.pop(flank)
            if v_in > v_landing:
                v_out = max(-rate, 0.0) if t - t0 < persistence_s else 0.0
                num += v_out * v_in
                den += v_in * v_in
    return num / den if den > 0 else math.nan


# --------------------------------------------------------------------------- the sensor chain

def _resonance_sos(f0: float, q: float, fs: float):
    """The mounted accelerometer: a base-excited second-order system, unit gain at DC."""
    w0 = TWO_PI * f0
    b, a = signal.bilinear([w0 ** 2], [1.0, w0 / q, w0 ** 2], fs)
    return signal.tf2sos(b, a)


def chain(stand: ForeignStand, m: dict) -> tuple[np.ndarray, dict]:
    """Volts (n, 3) of aE_t, aE_n, tacho at FS from the motion ``m`` at FS x OVERSAMPLE."""
    rng = np.random.default_rng(stand.seed + 7919)
    fs_os = FS * OVERSAMPLE
    mech = _tables()["mech"]
    th, om = m["theta"], m["omega2"]
    # specific force on the sensor's axes (tangential along increasing psi, normal towards D)
    a_t = m["a_t"] + G * np.cos(th)
    a_n = mech.DE * om ** 2 - G * np.sin(th)
    acc = np.column_stack([a_t, a_n])
    res = _resonance_sos(stand.sensor_resonance_hz, stand.sensor_q, fs_os)
    acc = signal.sosfilt(res, acc, axis=0)
    hp = signal.butter(1, stand.highpass_hz, "highpass", fs=fs_os, output="sos")
    # the coupling has settled during the warm-up: its input's mean is gone, its transient with it
    acc = signal.sosfilt(hp, acc - acc.mean(axis=0), axis=0)
    volts = acc / KA
    tacho = np.where(np.mod(m["phi1"], TWO_PI) < (stand.rpm * TWO_PI / 60.0) * 1e-3, 5.0, 0.0)
    x = np.column_stack([volts, tacho])
    aa = signal.butter(stand.antialias_order, stand.antialias_hz, fs=fs_os, output="sos")
    x = signal.sosfilt(aa, x, axis=0)[::OVERSAMPLE]
    x[:, :2] += rng.normal(0.0, stand.noise_m_s2 / KA, size=(len(x), 2))
    lsb = 2 * stand.adc_range_v / 2 ** stand.adc_bits
    x = np.clip(np.round(x / lsb) * lsb, -stand.adc_range_v, stand.adc_range_v - lsb)
    return x, {"lsb_v": lsb}


def record(path, stand: ForeignStand, state_backlash: bool = False) -> dict:
    """Write ``stand``'s recording (format v1) to ``path``; return its truth and what the run did.

    The recording states the cam speed, law, load and inertia factor as a stand's operator would,
    not the backlash (unless ``state_backlash``): a worn groove's width is what nobody knows."""
    import h5py

    m = motion(stand)
    volts, info = chain(stand, m)
    n = len(volts)
    with h5py.File(path, "w", libver=("v110", "latest")) as f:
        f.attrs["format"] = "labtool.recording"
        f.attrs["format_version"] = 1
        f.attrs["sample_rate_hz"] = FS
        f.attrs["start_time_utc"] = "2026-12-07T12:00:00Z"
        f.attrs["complete"] = True
        f.attrs["cam_speed_rpm"] = float(stand.rpm)
        f.attrs["law"] = "sine"
        f.attrs["Fu_N"] = float(stand.Fu)
        f.attrs["jt_factor"] = 1.0
        for k in ("cam_speed_rpm", "law", "Fu_N", "jt_factor"):
            f.attrs[k + "_source"] = "foreign stand (tests/foreign_stand.py)"
        if state_backlash:
            f.attrs["backlash_mm"] = stand.backlash * 1e3
            f.attrs["backlash_mm_source"] = "foreign stand (tests/foreign_stand.py)"
        f.attrs["adc_range_v"] = stand.adc_range_v
        f.attrs["adc_bits"] = stand.adc_bits
        f.attrs["device"] = "foreign stand (tests/foreign_stand.py)"
        for k, v in stand.attrs().items():
            f.attrs[k] = v
        f.attrs["foreign_effective_restitution"] = m["effective_restitution"]
        d = f.create_dataset("signals", data=volts.astype("float32"), chunks=(8192, 3), maxshape=(None, 3))
        d.attrs["channel_names"] = np.array(["aE_t", "aE_n", "tacho"], dtype=h5py.string_dtype())
        d.attrs["ka_m_s2_per_v"] = np.array([KA, KA, np.nan])
        ev_dt = np.dtype([("index", "<i8"), ("kind", h5py.string_dtype()), ("detail", h5py.string_dtype())])
        ev = np.array([(0, "start", "foreign stand"), (n, "stop", "duration reached")], dtype=ev_dt)
        f.create_dataset("events", data=ev, maxshape=(None,), chunks=(64,))
    ev = m["events"]
    turns = (m["phi1"][-1] - m["phi1"][0]) / TWO_PI
    landings = int(np.sum((ev[:, 2] > 0) & (ev[:, 3] > 0.01)))
    return {"backlash_mm": stand.backlash * 1e3, "restitution": stand.restitution,
            "effective_restitution": m["effective_restitution"], "landings_per_turn": landings / turns,
            "peak_v": float(np.abs(volts[:, 0]).max()), "lsb_v": info["lsb_v"]}
