"""The stand's twin: a model of the STB-216 stand richer than the rigid and the elastic model.

It is the simulated stand's default truth (labtool.acquisition.signal_chain, ``--truth twin``), the
physics the two models are measured against; docs/twin.md gives the parameters and why. Three
bodies and their couplings, in SI:

* cam + motor (phi1, omega1; inertia J' = labtool.models.mechanism.motor.cam_inertia): driven by the
  asynchronous motor's linear characteristic (labtool.models.mechanism.motor: slip under load, omega1
  variable) through a variator set so that the cam's no-load speed is the nominal n1, with a
  once-per-turn ripple of the drive's no-load speed, M1 = s (W0 (1 + r sin phi1) - omega1). The
  contact force acts back on the cam (moment -N G1), and so does the cam's own gravity.
  ``drive = "input"`` imposes omega1 = Omega (1 + r sin(Omega t)) instead (the cam as input).
* follower side (phi2 = phi2_pitch(phi1) + q, omega2): J''red(phi2) x Jt of the paper's links 2-5
  (labtool.models.mechanism.linkage through the rigid model's tables), gravity on all of them, the load Fu
  (as the models apply it), pivot friction Mf = -(T_f + r_f |N|) tanh(omega2 / w_f) (a constant
  torque plus mu r_pin times the contact force, regularised below w_f).
* the follower's first bending mode (u, du): a modal mass m_b at E on a spring k_b and damper c_b
  along E's tangent, m_b = share x J''red / DE^2 taken out of the rigid inertia, so that
  sqrt(k_b / m_b) = 2 pi mode_hz is the mode with the follower's root held. The accelerometer at
  E reads the modal mass: aE_t = DE omega2' + u'' = -(k_b u + c_b du) / m_b (the mode is a degree
  of freedom here, so the measuring chain must not add it again as a filter).
* the groove: both flanks elastic (Palmgren, Kc = labtool.models.dynamics.contact.contact_stiffness) with
  Hunt-Crossley damping (labtool.models.dynamics.contact.hunt_crossley_force), the backlash j crossed
  physically: g = A2(phi1) q is the normal distance of the roller centre from the pitch curve
  (interior flank at g = 0, exterior at g = j; the rigid model's geometry), and N along the normal
  acts on the follower with the moment N A2 and on the cam with -N G1, G1 = A2 psi' - A2' q. The
  forces derive exactly from the contact potential, so with damping and friction off and the
  motor off the total energy is constant (tests/test_twin.py).

With the mode, the friction, the drive and the cam inertia switched off it is the elastic model's
system without its linearisation in the deviation (tests/test_twin.py shows the convergence).

The integration is compiled (labtool.models.dynamics.kernels.twin_nb, Dormand-Prince 5(4) with events at the
contact boundaries) and streams: ``TwinRun.sample(t)`` continues the same trajectory for every new
block of times, so a 1-hour recording is produced block by block with carried state. The run
starts ``warmup_revolutions`` turns before t = 0 (phi1 = 0 at the start of a rise, t = 0), so a
recording begins on a stand that has been running.

Events follow the one event record (labtool.models.dynamics.events): a contact phase ending is a ``separation``, one
beginning a ``contact``; ``event_domega2`` is the change of the follower's speed relative to the
flank (q' = omega2 - psi' omega1) and ``event_percussion`` the integral of the contact force, over
the contact or its first ``persistence_s`` if it lasts longer (then it is ``persistent``, and so
is the separation that ends it; its domega2 is 0, a rebound's separation has NaN). With j = 0 a
change of flank is a separation only (no flight ends). These follow labtool.models.dynamics.events; the
persistence is the twin's own: its rebounds last 1-3 times the elastic model's bounce time (the
damping and the bending mode lengthen them), so "longer than two bounce times" would call its
rebounds lift-offs (docs/twin.md).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import xarray as xr

from labtool.common.operating_point import OperatingPoint
from labtool.common.errors import InputError, SolverError
from labtool.models.dynamics.contact import contact_stiffness, static_penetration
from labtool.models.dynamics.scene import Scene
from labtool.models.mechanism import sensor_point
from labtool.models.mechanism.motor import cam_inertia, motor_moment_on_cam, motor_slope_on_cam

TWO_PI = 2.0 * math.pi
DRIVES = ("motor", "input")
# solver presets, as the elastic model's: relative tolerance, absolute tolerance (x the run's own
# scales: static deflection under the largest kinetostatic force, and its rate at the contact's
# frequency) and the step limit as a fraction of the shortest period (contact or bending mode)
PRESETS = {
    "fast": dict(rtol=1e-6, atol=1e-5, steps_per_period=4.0),
    "standard": dict(rtol=1e-8, atol=1e-7, steps_per_period=8.0),
    "reference": dict(rtol=1e-10, atol=1e-9, steps_per_period=16.0),
}
EVENT_BUFFER = 4096
ZENO_SEGMENTS, ZENO_DT = 200, 1e-9
NUDGE = 1e-13


@dataclasses.dataclass(frozen=True)
class TwinPhysics:
    """What the twin adds to a models Scene (operating point, contact law and its damping). SI.

    drive            "motor" (characteristic with slip, omega1 variable) or "input" (omega1 imposed)
    ripple           relative ripple of the drive's speed, once per cam turn (-)
    mode_hz          first bending mode of the follower with its root held (Hz)
    mode_zeta        its damping ratio (-)
    mode_mass_share  its modal mass at E as a share of J''red / DE^2 (0 = no mode)
    friction_torque  constant part of the pivot friction (N m)
    friction_radius  load part: mu x pin radius, times |contact force| (m)
    friction_speed   omega2 below which the friction is regularised (tanh) (rad/s)
    persistence_s    a contact lasting this long is persistent (s); its impact figures are taken over it
    warmup_revolutions  cam turns simulated before t = 0
    """

    drive: str = "motor"
    ripple: float = 0.005
    mode_hz: float = 1200.0
    mode_zeta: float = 0.04
    mode_mass_share: float = 0.25
    friction_torque: float = 0.02
    friction_radius: float = 5e-5
    friction_speed: float = 1e-3
    persistence_s: float = 2e-3
    warmup_revolutions: int = 3

    def __post_init__(self):
        checks = [
            (self.drive in DRIVES, f"twin drive must be one of {', '.join(DRIVES)}, got '{self.drive}'"),
            (math.isfinite(self.ripple) and 0 <= self.ripple < 0.5, f"speed ripple must lie in [0, 0.5), got {self.ripple}"),
            (math.isfinite(self.mode_hz) and self.mode_hz > 0, f"bending mode frequency must be > 0 Hz, got {self.mode_hz}"),
            (math.isfinite(self.mode_zeta) and 0 <= self.mode_zeta < 1, f"bending mode damping ratio must lie in [0, 1), got {self.mode_zeta}"),
            (math.isfinite(self.mode_mass_share) and 0 <= self.mode_mass_share < 0.9,
             f"bending mode mass share must lie in [0, 0.9), got {self.mode_mass_share}"),
            (math.isfinite(self.friction_torque) and self.friction_torque >= 0, f"friction torque must be >= 0 N m, got {self.friction_torque}"),
            (math.isfinite(self.friction_radius) and self.friction_radius >= 0, f"friction radius must be >= 0 m, got {self.friction_radius}"),
            (math.isfinite(self.friction_speed) and self.friction_speed > 0, f"friction speed must be > 0 rad/s, got {self.friction_speed}"),
            (math.isfinite(self.persistence_s) and self.persistence_s > 0, f"persistence time must be > 0 s, got {self.persistence_s}"),
            (isinstance(self.warmup_revolutions, int) and 0 <= self.warmup_revolutions <= 100,
             f"warm-up revolutions must be an integer in [0, 100], got {self.warmup_revolutions}"),
        ]
        for ok, message in checks:
            if not ok:
                raise InputError(message)

    def replace(self, **changes) -> "TwinPhysics":
        return dataclasses.replace(self, **changes)

    # recording attributes (truth_*) and back; units in the names
    ATTRS = {"drive": "truth_drive", "ripple": "truth_omega1_ripple", "mode_hz": "truth_mode_hz",
             "mode_zeta": "truth_mode_zeta", "mode_mass_share": "truth_mode_mass_share",
             "friction_torque": "truth_friction_torque_Nm", "friction_radius": "truth_friction_radius_m",
             "friction_speed": "truth_friction_speed_rad_s", "persistence_s": "truth_persistence_s",
             "warmup_revolutions": "truth_warmup_revolutions"}

    def attrs(self) -> dict:
        return {key: getattr(self, name) for name, key in self.ATTRS.items()}

    @classmethod
    def from_attrs(cls, attrs: dict) -> "TwinPhysics":
        """The physics stored by ``attrs()`` (missing keys take the defaults)."""
        kw = {}
        for name, key in cls.ATTRS.items():
            if key in attrs:
                v = attrs[key]
                kw[name] = v.decode() if isinstance(v, bytes) else (str(v) if name == "drive" else
                                                                      int(v) if name == "warmup_revolutions" else float(v))
        return cls(**kw)


# ------------------------------------------------------------------------------------------ the plant
@dataclasses.dataclass(frozen=True)
class TwinPlant:
    """Tables, parameter vector and tolerances of one run (built by ``build_plant``)."""

    cam: tuple            # (nodes, inv_h, coef) of the rigid model's cam table over one turn
    follower: tuple       # (nodes, inv_h, coef) of its follower table
    p: np.ndarray         # twin_nb parameter vector
    atol: np.ndarray      # absolute tolerances (phi1, omega1, q, omega2, u, du)
    rtol: np.ndarray
    info: dict            # derived figures (SI) for the dataset's attributes


def _tables(mech, program):
    from labtool.models.dynamics.rigid_tables import cam_table, follower_table
    from labtool.models.mechanism.cam_profile import cached_sense
    from labtool.models.mechanism.memo import cached

    sense = cached_sense(mech, program)
    lo, hi = -0.05, TWO_PI + 0.05
    cam = cached(("twin_cam_table", mech.cache_key, program, sense, lo, hi), lambda: cam_table(mech, program, sense, lo, hi))
    lo2, hi2 = mech.phiD + mech.psi0 - 0.05, mech.phiD + mech.psi0 + program.stroke + 0.05
    fol = cached(("twin_follower_table", mech.cache_key, lo2, hi2), lambda: follower_table(mech, lo2, hi2))
    from labtool.models.dynamics.kernels import twin_nb as nb

    return nb.compact_cam(cam), nb.compact_follower(fol), sense


def _scales(scene: Scene, kc: float, J_side):
    """Force, deflection and frequency scales of the scene: the largest kinetostatic normal force
    over a turn, its static deflection, the contact's angular frequency, the arm A2 range."""
    from labtool.models.dynamics.elastic import contact_period
    from labtool.models.mechanism.cam_tables import grid_terms

    mech, program = scene.mechanism, scene.program
    terms = grid_terms(mech, program, TWO_PI, 2001)
    op = terms.at_speed(scene.omega1_nominal, scene.Fu, scene.jt_factor)
    arm = mech.l * np.cos(terms.alpha)
    f_scale = max(float(np.max(np.abs(op["MR13D"] / arm))), 1.0)
    m_min = float(np.min(J_side * terms.J0 / arm**2))
    period = contact_period(kc, m_min, f_scale)
    eps2_max = float(np.max(np.abs(op["epsilon2"])))
    return f_scale, float(static_penetration(f_scale, kc)), TWO_PI / period, float(arm.min()), float(arm.max()), eps2_max


def build_plant(scene: Scene, physics: TwinPhysics) -> TwinPlant:
    """Tables and parameters of the twin for a scene (rigid-model tables shared per process)."""
    from labtool.models.dynamics.kernels import twin_nb as nb

    mech, program = scene.mechanism, scene.program
    cam, fol, sense = _tables(mech, program)
    W = scene.omega1_nominal
    it = mech.omega_sync_motor / W             # the variator: no-load cam speed = n1 (docs/twin.md)
    slope = motor_slope_on_cam(mech, it)
    W0 = float(motor_moment_on_cam(mech, 0.0, it)) / slope
    Jcam = cam_inertia(mech, it)
    kc = contact_stiffness(scene.contact_length, scene.kc_factor)
    J0_start = _follower_at(fol, mech.phiD + mech.psi0)[0]
    mb = physics.mode_mass_share * scene.jt_factor * J0_start / mech.DE**2
    wb = TWO_PI * physics.mode_hz
    kb, cb = mb * wb**2, 2.0 * physics.mode_zeta * mb * wb
    f_scale, x_scale, w_c, a2_min, a2_max, eps2_max = _scales(scene, kc, scene.jt_factor * (1.0 - physics.mode_mass_share))
    preset = PRESETS[scene.accuracy]
    w_max = max(w_c, wb if mb > 0 else 0.0)
    max_step = TWO_PI / w_max / preset["steps_per_period"]
    p = np.zeros(nb.NP)
    values = {nb.P_PHI20: mech.phiD + mech.psi0, nb.P_JT: scene.jt_factor, nb.P_JCAM: Jcam,
              nb.P_INPUT: 1.0 if physics.drive == "input" else 0.0, nb.P_W0: W if physics.drive == "input" else W0,
              nb.P_SLOPE: slope, nb.P_RIPPLE: physics.ripple, nb.P_FU: scene.Fu, nb.P_GAP: scene.backlash,
              nb.P_KC: kc, nb.P_DAMP: scene.contact_damping, nb.P_MB: mb, nb.P_KB: kb, nb.P_CB: cb, nb.P_DE: mech.DE,
              nb.P_TF: physics.friction_torque, nb.P_RF: physics.friction_radius,
              nb.P_WF: physics.friction_speed if (physics.friction_torque > 0 or physics.friction_radius > 0) else 0.0,
              nb.P_WINDOW: physics.persistence_s, nb.P_NUDGE: NUDGE, nb.P_MAXSTEP: max_step,
              nb.P_ZENO_N: ZENO_SEGMENTS, nb.P_ZENO_DT: ZENO_DT, nb.P_MAXSTEPS: 0.0}
    for k, v in values.items():
        p[k] = v
    a = preset["atol"]
    q_tol = a * x_scale / a2_max
    u_scale = max(mech.DE * eps2_max / wb**2, x_scale)
    atol = np.array([q_tol, q_tol * w_c, q_tol, q_tol * w_c, a * u_scale, a * u_scale * wb])
    rtol = np.array([0.0, 0.0, preset["rtol"], preset["rtol"], preset["rtol"], preset["rtol"]])
    info = dict(transmission_ratio=it, J_cam_kgm2=Jcam, motor_slope_Nms=slope, no_load_speed_rad_s=W0,
                Kc_SI=kc, modal_mass_kg=mb, modal_stiffness_N_m=kb, modal_damping_Ns_m=cb,
                force_scale_N=f_scale, deflection_scale_m=x_scale, contact_frequency_hz=w_c / TWO_PI,
                max_step_s=max_step, cam_sense=int(sense))
    if mb > 0 and scene.jt_factor * J0_start - mb * mech.DE**2 <= 0:
        raise InputError("the bending mode's modal mass exceeds the follower's inertia: lower mode_mass_share")
    return TwinPlant(cam, fol, p, atol, rtol, info)


def _follower_at(fol, phi2: float) -> np.ndarray:
    """(J0, dJ0, M_gravity, M_load per N) of the follower table at phi2 (rad)."""
    from labtool.models.dynamics.kernels import twin_nb as nb

    out = np.zeros(4)
    nb.follower_eval(*fol, phi2, out)
    return out


# ------------------------------------------------------------------------------------ the run
COLUMNS = ("phi1", "omega1", "phi2", "omega2", "vE", "u_bend", "contact_force", "gap", "epsilon2", "aE_t", "contact_phase")


class TwinRun:
    """One trajectory of the twin, sampled block by block (bounded memory).

    ``sample(t)`` returns the state at global times t (s, non-decreasing, not before the last
    request; t = 0 is phi1 = 0 at the start of a rise after the warm-up). ``take_events()`` returns
    the event record's arrays closed since the last call (``keep_events=False``: discarded).
    """

    def __init__(self, scene: Scene, physics: TwinPhysics | None = None, keep_events: bool = True,
                 start: dict | None = None):
        from labtool.models.dynamics import validity
        from labtool.models.dynamics.kernels import twin_nb as nb

        validity.check_scene(scene)   # a groove no cam realises (an undercut, a backlash past R): refused, as the models do
        self.scene, self.physics = scene, physics or TwinPhysics()
        self.plant = build_plant(scene, self.physics)
        self.keep_events = keep_events
        self._nb = nb
        self._S = np.zeros(nb.NS)
        self._Y, self._K0, self._Y0, self._Q = np.zeros(nb.NY), np.zeros(nb.NY), np.zeros(nb.NY), np.zeros((nb.NY, 4))
        self._ev = np.zeros((EVENT_BUFFER, nb.NE))
        self._work = nb.new_workspace()
        self._chunks: list[np.ndarray] = []
        self._last_t = -math.inf
        self._start(start)

    # -- set-up
    def _start(self, start: dict | None):
        """The state at the start of the warm-up: phi1 = 0, the follower at rest on the flank that
        carries it. ``start`` (tests) overrides any of phi1, omega1, q, omega2, u, du (SI) and
        phase (0 interior, 1 flight, 2 exterior), and then the warm-up is skipped."""
        nb, S, P = self._nb, self._S, self.plant
        phase, q = self._rest_state()
        y = dict(phi1=0.0, omega1=P.p[nb.P_W0], q=q, omega2=0.0, u=0.0, du=0.0, phase=phase)
        y.update(start or {})
        S[nb.S_PHASE] = int(y["phase"])
        S[nb.S_REV] = 0.0 if start else -float(self.physics.warmup_revolutions)
        S[nb.S_CIDX] = -1.0
        S[nb.S_CT0] = -math.inf
        S[nb.S_PHT0] = -math.inf
        self._Y[:] = (y["phi1"], y["omega1"], y["q"], y["omega2"], y["u"], y["du"], 0.0)
        if start or self.physics.warmup_revolutions == 0:
            self.t_zero = 0.0
            return
        self._budget(self.physics.warmup_revolutions * TWO_PI / self.scene.omega1_nominal)
        status = nb.BUFFER_FULL
        while status == nb.BUFFER_FULL:
            status = nb.run_until_rev(*self._args(), 0.0)
            self._drain(keep=False)
        self._check(status)
        self.t_zero = float(S[nb.S_WRAPT])

    def _rest_state(self):
        """At phi1 = 0 (end of the lower dwell) at rest on the flank that carries gravity and load."""
        from labtool.models.dynamics.kernels import twin_nb as nb

        P, mech = self.plant, self.scene.mechanism
        cam, fol = np.zeros(6), np.zeros(4)
        nb.cam_eval(*P.cam, 0.0, cam)
        nb.follower_eval(*P.follower, P.p[nb.P_PHI20] + cam[0], fol)
        A2 = cam[2]
        N = -(fol[2]) / A2           # the flank's force balances gravity (the dwell: no load)
        kc, j = P.p[nb.P_KC], P.p[nb.P_GAP]
        if N >= 0:
            return nb.INTERIOR, -float(static_penetration(N, kc)) / A2
        return nb.EXTERIOR, (j + float(static_penetration(-N, kc))) / A2

    def _args(self):
        P = self.plant
        K, Qs, wk = self._work
        return (*P.cam, *P.follower, P.p, P.atol, P.rtol, self._S, self._Y, self._K0, self._Y0, self._Q, self._ev, K, Qs, wk)

    def _budget(self, span_s: float):
        """Step cap for the next call: far above any real need (4e6 steps per simulated second)."""
        nb = self._nb
        self.plant.p[nb.P_MAXSTEPS] = self._S[nb.S_NSTEP] + max(1e5, 4e6 * span_s)

    def _check(self, status):
        from labtool.models.dynamics.kernels import dopri5 as dp

        nb = self._nb
        if status == nb.OK:
            return
        t = self._S[nb.S_T] - getattr(self, "t_zero", 0.0)
        if status == nb.STALLED:
            raise SolverError(f"twin: the cam stalled at t = {t:.6g} s (the motor cannot drive the load)")
        if status == dp.NO_PROGRESS:
            raise SolverError(f"twin: {ZENO_SEGMENTS} contact switches within {ZENO_SEGMENTS * ZENO_DT:.1g} s at "
                              f"t = {t:.6g} s (endless chatter); add contact damping")
        raise SolverError(f"twin: {dp.STATUS_TEXT.get(status, f'status {status}')} at t = {t:.6g} s")

    def _drain(self, keep: bool | None = None):
        """Move closed events (all but a contact still open) out of the kernel's buffer."""
        nb, S = self._nb, self._S
        n = int(S[nb.S_NEV])
        pending = int(S[nb.S_CIDX])
        closed = n if pending < 0 else pending
        if closed and (self.keep_events if keep is None else keep):
            self._chunks.append(self._ev[:closed].copy())
        if pending >= 0:
            self._ev[0] = self._ev[pending]
            S[nb.S_CIDX] = 0.0
            S[nb.S_NEV] = 1.0
        else:
            S[nb.S_NEV] = 0.0

    # -- public
    def sample(self, t, accelerations: bool = False) -> dict:
        """The state at global times t (s): dict of arrays (COLUMNS; epsilon2, aE_t and
        contact_force only with ``accelerations``, else NaN). vE = DE omega2 + du is the speed of the
        sensor at E along its tangential axis (m/s); its interval differences are what a sampled
        accelerometer integrates."""
        nb = self._nb
        t = np.ascontiguousarray(t, dtype=float)
        if t.size == 0:
            return {c: np.zeros(0) for c in COLUMNS}
        if t[0] < self._last_t - 1e-12 or np.any(np.diff(t) < 0):
            raise ValueError("twin samples must be requested in time order, after the previous ones")
        tk = t + self.t_zero
        out = np.empty((t.size, nb.NO))
        self._budget(float(t[-1] - max(self._last_t, 0.0)))
        done = 0
        while done < t.size:
            status, n = nb.advance(*self._args(), tk[done:], out[done:], accelerations)
            done += n
            if status == nb.BUFFER_FULL:
                self._drain()
                continue
            self._check(status)
        self._drain()
        self._last_t = float(t[-1])
        return {c: out[:, i] for i, c in enumerate(COLUMNS)}

    def take_events(self, final: bool = False) -> dict:
        """Closed events since the last call (global times >= 0) as arrays of the event record.

        ``final``: the run ends here: a contact still open is included too, persistent (it lasted
        to the end), its figures over what has elapsed of it (or its persistence window)."""
        nb = self._nb
        self._drain()
        if final and self._S[nb.S_CIDX] >= 0:
            row = self._ev[int(self._S[nb.S_CIDX])].copy()
            # the impulse and the change of q' of the open contact from its start to the state now
            row[nb.E_P] = abs(self._Y[6])
            row[nb.E_DW2] = self._open_qdot() - self._S[nb.S_CQD0]
            row[nb.E_PERS] = 1.0
            self._chunks.append(row[None, :])
            self._S[nb.S_CIDX] = -1.0
            self._S[nb.S_NEV] = 0.0
        rows = np.concatenate(self._chunks) if self._chunks else np.zeros((0, nb.NE))
        self._chunks = []
        rows[:, nb.E_T] -= self.t_zero           # kernel time -> recording time
        rows = rows[rows[:, nb.E_T] >= 0.0]
        return event_arrays(rows)

    def _open_qdot(self) -> float:
        """q' = omega2 - psi'(phi1) omega1 of the current state (rad/s)."""
        cam = np.zeros(6)
        self._nb.cam_eval(*self.plant.cam, float(self._Y[0]), cam)
        return float(self._Y[3] - cam[1] * self._Y[1])

    @property
    def position(self) -> float:
        """The last time sampled (s; -inf before the first request): requests may not go back."""
        return self._last_t

    @property
    def stats(self) -> dict:
        nb = self._nb
        return {"n_steps": int(self._S[nb.S_NSTEP]), "nfev": int(self._S[nb.S_NFEV])}


def event_arrays(rows) -> dict:
    """The kernel's event rows as the one event record's arrays (labtool.models.dynamics.events, SI)."""
    from labtool.models.dynamics import events
    from labtool.models.dynamics.kernels import twin_nb as nb

    rows = np.asarray(rows, dtype=float).reshape(-1, nb.NE)
    return events.columns(events.record(
        rows[:, nb.E_T], rows[:, nb.E_PHI1], rows[:, nb.E_KIND].astype(int), rows[:, nb.E_SIDE].astype(int),
        rows[:, nb.E_VREL], rows[:, nb.E_DW2], rows[:, nb.E_P], rows[:, nb.E_PERS] > 0.5))


def event_dataset(event_columns: dict) -> xr.Dataset:
    """The event record (labtool.models.dynamics.events) as a Dataset over dimension ``event``."""
    from labtool.models.dynamics import events

    c = event_columns
    return xr.Dataset(events.record(c["event_time"], c["event_phi1"], c["event_kind"], c["event_side"],
                                    c["event_v_rel"], c["event_domega2"], c["event_percussion"], c["event_persistent"]))


def simulate(scene: Scene, physics: TwinPhysics | None = None, duration: float | None = None,
             output_step: float = 5e-5) -> xr.Dataset:
    """The twin over ``duration`` s (default: scene.revolutions cam turns) sampled every
    ``output_step`` s: time series and the event record (dimension ``event``), parameters in attrs."""
    physics = physics or TwinPhysics()
    if duration is None:
        duration = scene.revolutions * TWO_PI / scene.omega1_nominal
    if not (math.isfinite(duration) and duration > 0):
        raise InputError(f"twin duration must be > 0 s, got {duration}")
    run = TwinRun(scene, physics)
    t = np.arange(int(math.floor(duration / output_step)) + 1) * output_step
    s = run.sample(t, accelerations=True)
    meta = {
        "phi1": ("rad", "cam angle (unwrapped, 0 at the start of the first rise)"), "omega1": ("rad/s", "cam angular velocity"),
        "phi2": ("rad", "follower angle of DC from the x axis"), "omega2": ("rad/s", "follower angular velocity"),
        "epsilon2": ("rad/s^2", "follower angular acceleration (rigid part)"),
        "aE_t": ("m/s^2", "tangential acceleration at E of the sensor (modal mass): DE epsilon2 + u''"),
        "vE": ("m/s", "tangential speed of the sensor at E"), "u_bend": ("m", "bending-mode displacement at E"),
        "contact_force": ("N", "groove-on-roller normal force, > 0 = the interior flank pushes"),
        "gap": ("m", "normal distance of the roller centre from the interior flank's contact position"),
        "contact_phase": ("1", "0 interior flank, 1 flight in the gap, 2 exterior flank"),
    }
    data = {k: ("time", s[k], {"units": u, "long_name": ln}) for k, (u, ln) in meta.items()}
    aE_n = sensor_point.acceleration_at_E(scene.mechanism.DE, s["omega2"], 0.0)[1]
    data["aE_n"] = ("time", aE_n, {"units": "m/s^2", "long_name": "normal acceleration of E, towards D"})
    ds = xr.Dataset(data, coords={"time": ("time", t, {"units": "s", "long_name": "time from the start of the first rise"})})
    ds = ds.merge(event_dataset(run.take_events(final=True)))
    ds.attrs.update(title="labtool stand twin (docs/twin.md)", **OperatingPoint.attrs(scene),
                    **{k: v for k, v in physics.attrs().items()},
                    **{f"twin_{k}": v for k, v in run.plant.info.items()}, **run.stats)
    return ds
