"""The measuring chain of the stand as pure functions: truth -> sensor -> conditioner -> ADC.

What the simulated stand records is the follower's true motion seen through everything a real
chain adds and the models do not. The truth (``truth_model``) is by default the stand's **twin**
(labtool.models.dynamics.twin: elastic contact with energy loss on both flanks, the backlash crossed, the
follower's first bending mode as a degree of freedom, pivot friction, motor slip and drive ripple,
gravity; docs/twin.md), or ``kinematic`` (the cam as input with a speed ripple), or one model's
own equations (``rigid``, ``elastic``: its periodic steady state, for self-consistency checks).
The chain:

1. gravity: a piezoelectric accelerometer measures specific force, so a sensor riding on the
   follower at E also reads the component of -g along its axis; the axes turn with the follower
   (tangential t = (-sin phi2, cos phi2), normal n = -(cos phi2, sin phi2) towards D);
2. a structural resonance of the follower (base-excited 1-DOF, f_r, zeta_r) excited by the motion
   and by broadband mechanical noise (roller rolling in the groove). With the twin truth the mode
   is in the truth itself, so the chain applies it to the mechanical noise only (never twice);
3. sensor noise (white, m/s^2 rms at the oversampled rate, i.e. before the anti-alias filter);
4. sensitivity x conditioner gain = 1/Ka (V per m/s^2): the PCB 352A76's 1/(86.43 x 10) V per
   m/s^2 and the 480C02 at gain x1 by default, Ka = 864.3 m/s^2/V, so that the twin's impacts fit
   the ADC range (the paper's x10 chain, Ka = 86.43, clips them: docs/twin.md);
5. the 480C02's AC coupling, a first-order high-pass (0.1 Hz default);
6. the DAQ's anti-alias low-pass (Butterworth, order 8, 0.40 x the sample rate) at an
   oversampled rate, then decimation to the sample rate;
7. ADC range (+-10 V default), clipping at the rails and quantization (16 bits default).

Every function here is pure (state in, state out), so a run is deterministic for a seed and the
same code serves blocks of any size. Sign conventions: aE_t positive along increasing psi,
aE_n positive towards D (docs/architecture.md); time t in s from the run's first sample; phi1 = 0 at the
start of the rise at t = 0.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import signal

from labtool.common.errors import InputError
from labtool.common.operating_point import STATED, OperatingPoint
from labtool.common.units import RPM
from labtool.models.dynamics import periodicity
from labtool.models.dynamics.twin import TwinPhysics
from labtool.models.mechanism.kinematics import check_load_and_inertia, follower_motion
from labtool.models.mechanism import Mechanism, sensor_point
from labtool.models.mechanism.motion_laws import CamProgram

TWO_PI = 2.0 * math.pi
PAPER_KA = 86.43  # m/s^2 per V, paper sec. 2.4: the 480C02 at gain x10
SENSOR_SENSITIVITY = 1.0 / (PAPER_KA * 10.0)  # V per m/s^2 of the PCB 352A76 (11.3 mV/g)
DEFAULT_KA = 1.0 / SENSOR_SENSITIVITY  # 864.3 m/s^2 per V: the 480C02 at gain x1
ACCEL_CHANNELS = ("aE_t", "aE_n")
CHANNELS = ("aE_t", "aE_n", "tacho")
TRUTH_MODELS = ("twin", "kinematic", "rigid", "elastic")
MODEL_TRUTHS = ("rigid", "elastic")
MODEL_TRUTH_REVOLUTIONS = 8      # turns a model truth simulates by default (the last one repeats)
MAX_MODEL_REVOLUTIONS = 200


@dataclasses.dataclass(frozen=True)
class StandScene(OperatingPoint):
    """What the simulated stand does: an operating point (OperatingPoint's fields, SI; its model
    options are the truth's energy loss and contact) and the stand's own settings.

    mode            "run": the cam drives the follower; "calibration": the sensor sits on a
                    shaker (B&K 4291) giving cal_accel (m/s^2 peak) at cal_freq (Hz) along
                    channel cal_channel, the cam stands still.
    law, cam_speed, Fu, backlash, jt_factor: the operating point (the paper's factors); they do
                    not change the kinematic truth (then they are only stored).
    restitution     Newton's k of the rigid truth's impacts
    contact_damping, contact_length, kc_factor: the twin's and the elastic truth's contact
    accuracy        solver preset of the twin and the model truths (default fast: the chain's
                    noise is far above its error, docs/twin.md)
    omega1_mode, elastic_gap: the truths turn the cam at constant speed (plus ``ripple``) across
                    the physical gap; only const and physical are taken
    ripple          relative amplitude of the drive's speed ripple, once per cam turn (kinematic:
                    omega1 = Omega (1 + ripple sin(Omega t)); twin: on the motor's no-load speed)
    truth_model     twin | kinematic | rigid | elastic (module doc)
    truth_revolutions  rigid/elastic truth: cam turns simulated (0 = MODEL_TRUTH_REVOLUTIONS); the
                    last one repeats when the model has reached its periodic steady state
    twin            the twin's other physics (labtool.models.dynamics.twin.TwinPhysics; its ripple is
                    this scene's ``ripple``)
    """

    accuracy: str = "fast"
    mode: str = "run"
    ripple: float = 0.005
    cal_accel: float = 9.81
    cal_freq: float = 79.6
    cal_channel: str = "aE_t"
    truth_model: str = "twin"
    truth_revolutions: int = 0
    twin: TwinPhysics = dataclasses.field(default_factory=TwinPhysics)
    mechanism: Mechanism = dataclasses.field(default_factory=Mechanism.default, repr=False)

    def __post_init__(self):
        super().__post_init__()
        model_truth = self.truth_model in MODEL_TRUTHS
        checks = [
            (self.truth_model in TRUTH_MODELS, f"truth model must be one of {', '.join(TRUTH_MODELS)}, got '{self.truth_model}'"),
            (isinstance(self.truth_revolutions, int) and 0 <= self.truth_revolutions <= MAX_MODEL_REVOLUTIONS,
             f"truth revolutions must be an integer in [0, {MAX_MODEL_REVOLUTIONS}], got {self.truth_revolutions}"),
            (not model_truth or self.ripple == 0.0,
             f"the {self.truth_model} truth turns the cam at constant speed: set the speed ripple to 0"),
            (self.omega1_mode == "const" and self.elastic_gap == "physical",
             "the simulated stand turns its cam at constant speed (plus its ripple) across the physical gap: "
             "omega1 mode 'const' and elastic gap 'physical' only"),
            (self.mode in ("run", "calibration"), f"stand mode must be 'run' or 'calibration', got '{self.mode}'"),
            (math.isfinite(self.ripple) and 0 <= self.ripple < 0.5, f"speed ripple must lie in [0, 0.5), got {self.ripple}"),
            (math.isfinite(self.cal_accel) and self.cal_accel > 0, f"calibration acceleration must be > 0 m/s^2, got {self.cal_accel}"),
            (math.isfinite(self.cal_freq) and self.cal_freq > 0, f"calibration frequency must be > 0 Hz, got {self.cal_freq}"),
            (self.cal_channel in ACCEL_CHANNELS, f"calibration channel must be one of {', '.join(ACCEL_CHANNELS)}, got '{self.cal_channel}'"),
        ]
        for ok, msg in checks:
            if not ok:
                raise InputError(msg)
        check_load_and_inertia(self.Fu, self.jt_factor)
        self.mechanism.check_cam_speed(self.cam_speed_rpm)     # the one cam speed range of every command
        if self.twin.ripple != self.ripple:   # one ripple: the scene's
            object.__setattr__(self, "twin", self.twin.replace(ripple=self.ripple))
        self.program  # unknown law -> InputError now, not mid-run

    @property
    def program(self) -> CamProgram:
        return CamProgram.for_mechanism(self.mechanism, law=self.law)

    @property
    def model_revolutions(self) -> int:
        """Cam turns a rigid/elastic truth simulates."""
        return self.truth_revolutions or MODEL_TRUTH_REVOLUTIONS

    def model_scene(self, revolutions: float | None = None):
        """The models' Scene of this operating point and truth parameters (omega1 constant, the
        whole cycle, the physical gap)."""
        from labtool.models.dynamics.scene import Scene
        return Scene.at(self, revolutions=float(revolutions if revolutions is not None else self.model_revolutions),
                        rise_only=False, mechanism=self.mechanism)

    def truth_description(self) -> str:
        if self.truth_model == "kinematic":
            return "kinematic (labtool.models.mechanism.kinematics.follower_motion)"
        if self.truth_model == "twin":
            return f"twin (labtool.models.dynamics.twin, accuracy {self.accuracy}, docs/twin.md)"
        return (f"{self.truth_model} (labtool.models.dynamics.simulate, omega1 const, accuracy {self.accuracy}, "
                f"{self.model_revolutions} revolutions, the last repeated once periodic)")

    def attrs(self, names=None) -> dict:
        """Scene parameters as recording attributes: the stated operating point (edge units, as
        OperatingPoint.attrs), the truth's parameters (``truth_*``, SI unless named) and the
        stand's. ``names``: OperatingPoint.attrs of those fields only."""
        if names is not None:
            return super().attrs(names)
        twin = self.twin.attrs()
        twin["truth_warmup_revolutions"] = int(twin["truth_warmup_revolutions"])
        return {
            "stand_mode": self.mode, **super().attrs(STATED),
            "truth_model": self.truth_description(),
            "truth_revolutions": int(self.truth_revolutions),
            "truth_omega1_ripple": float(self.ripple),
            "truth_omega1_ripple_form": (
                "omega1 = Omega*(1 + ripple*sin(Omega*t)), phi1 = Omega*t + ripple*(1 - cos(Omega*t))"
                if self.truth_model == "kinematic" or self.twin.drive == "input" else
                "motor moment M1 = slope*(Omega*(1 + ripple*sin(phi1)) - omega1) (docs/twin.md)"),
            "truth_restitution": float(self.restitution),
            "truth_contact_damping_s_per_m": float(self.contact_damping),
            "truth_contact_length_m": float(self.contact_length),
            "truth_kc_factor": float(self.kc_factor),
            "truth_accuracy": self.accuracy,
            **twin,
            "chain_resonance_applies_to": "mechanical noise only (the twin truth carries the bending mode)"
            if self.truth_model == "twin" else "motion and mechanical noise",
            "cal_accel_m_s2_peak": float(self.cal_accel), "cal_freq_hz": float(self.cal_freq),
            "cal_channel": self.cal_channel, "mechanism": self.mechanism.name,
            "DE_m": float(self.mechanism.DE),
        }


@dataclasses.dataclass(frozen=True)
class ChainParams:
    """The sensor / conditioner / DAQ chain (SI).

    ka_m_s2_per_v   Ka per accelerometer channel (aE_t, aE_n), m/s^2 per V (volts = a / Ka); the
                    480C02's gain follows: Ka = 1 / (sensor sensitivity x gain)
    highpass_hz     AC coupling corner of the conditioner (first order), Hz
    resonance_hz, resonance_zeta  follower structural mode seen at E (base-excited 1-DOF)
    mech_noise_m_s2 broadband mechanical excitation of that mode, m/s^2 rms at the oversampled rate
    noise_m_s2      sensor + electronics noise, m/s^2 rms at the oversampled rate
    antialias_frac  anti-alias corner as a fraction of the sample rate; order antialias_order
    oversample      internal oversampling factor before the anti-alias filter and decimation
    adc_range_v     ADC input range +-V; adc_bits resolution
    tacho_v, tacho_width_s  tacho pulse height (V) and width (s)
    """

    ka_m_s2_per_v: tuple[float, float] = (DEFAULT_KA, DEFAULT_KA)
    highpass_hz: float = 0.1
    resonance_hz: float = 1200.0
    resonance_zeta: float = 0.04
    mech_noise_m_s2: float = 0.3
    noise_m_s2: float = 0.05
    antialias_frac: float = 0.40
    antialias_order: int = 8
    oversample: int = 2
    adc_range_v: float = 10.0
    adc_bits: int = 16
    tacho_v: float = 5.0
    tacho_width_s: float = 1e-3

    def __post_init__(self):
        ka = self.ka_m_s2_per_v
        if len(ka) != 2 or not all(math.isfinite(k) and k > 0 for k in ka):
            raise InputError(f"Ka must be two positive numbers (m/s^2/V), got {ka}")
        if not (self.adc_range_v > 0 and 8 <= self.adc_bits <= 32):
            raise InputError("ADC range must be > 0 V and resolution 8..32 bits")
        if self.oversample < 1 or int(self.oversample) != self.oversample:
            raise InputError("oversampling factor must be a positive integer")

    @property
    def conditioner_gain(self) -> float:
        """480C02 gain on aE_t that gives this Ka with the 352A76's sensitivity (1 at Ka 864.3, 10 at 86.43)."""
        return 1.0 / (SENSOR_SENSITIVITY * self.ka_m_s2_per_v[0])

    @property
    def lsb_v(self) -> float:
        return 2.0 * self.adc_range_v / 2**self.adc_bits

    def attrs(self) -> dict:
        return {
            "chain_ka_m_s2_per_v": np.asarray(self.ka_m_s2_per_v, float),
            "sensor": "PCB 352A76 (simulated)", "conditioner": "PCB 480C02 (simulated)",
            "conditioner_gain": float(self.conditioner_gain),
            "sensor_sensitivity_v_per_m_s2": np.full(2, SENSOR_SENSITIVITY),
            "chain_range_m_s2": np.asarray([self.adc_range_v * k for k in self.ka_m_s2_per_v]),
            "highpass_hz": float(self.highpass_hz), "resonance_hz": float(self.resonance_hz),
            "resonance_zeta": float(self.resonance_zeta), "mech_noise_m_s2": float(self.mech_noise_m_s2),
            "noise_m_s2": float(self.noise_m_s2), "antialias": f"Butterworth order {self.antialias_order} at {self.antialias_frac:g} x rate",
            "oversample": int(self.oversample), "adc_range_v": float(self.adc_range_v), "adc_bits": int(self.adc_bits),
            "tacho_v": float(self.tacho_v), "tacho_width_s": float(self.tacho_width_s),
        }


# --------------------------------------------------------------------------- truth

def cam_angle(scene: StandScene, t):
    """phi1 (rad, unwrapped), omega1 (rad/s), epsilon1 (rad/s^2) at times t (s), with the ripple.

    omega1 = Omega (1 + r sin(Omega t)) integrates to phi1 = Omega t + r (1 - cos(Omega t)), so
    phi1 = 2 pi k exactly at t = k T (T = 2 pi / Omega): the tacho pulses are evenly spaced.
    """
    t = np.asarray(t, dtype=float)
    W, r = scene.omega1_nominal, scene.ripple
    phi1 = W * t + r * (1.0 - np.cos(W * t))
    omega1 = W * (1.0 + r * np.sin(W * t))
    epsilon1 = r * W**2 * np.cos(W * t)
    return phi1, omega1, epsilon1


def _at_E(mech: Mechanism, omega2, epsilon2) -> dict:
    """{aE_t, aE_n} (m/s^2) of an ideal sensor at E (labtool.models.mechanism.sensor_point)."""
    aE_t, aE_n = sensor_point.acceleration_at_E(mech.DE, omega2, epsilon2)
    return {"aE_t": aE_t, "aE_n": aE_n}


def truth(scene: StandScene, t, seed: int | None = None, interval: float | None = None) -> dict:
    """The noise-free truth at times t (s): what an ideal sensor at E would see, no gravity.

    Returns arrays phi1 (rad, unwrapped), omega1 (rad/s), epsilon1 (rad/s^2), phi2 (rad), psi (rad),
    omega2 (rad/s), epsilon2 (rad/s^2), aE_t, aE_n = omega2^2 DE (m/s^2). aE_t is epsilon2 DE, or
    for the twin the acceleration of the sensor on the bending follower; with ``interval`` (s) it
    is the mean over [t - interval/2, t + interval/2] (clipped at t = 0), what a sampled sensor
    integrates: impacts keep their whole velocity step. ``seed`` only sets the noise of a run, never
    the truth; it is accepted so callers can pass a run's settings. In calibration mode the
    follower stands still and aE along the calibrated axis is cal_accel sin(2 pi cal_freq t).
    """
    t = np.asarray(t, dtype=float)
    mech = scene.mechanism
    if scene.mode == "calibration":
        z = np.zeros_like(t)
        shaker = scene.cal_accel * np.sin(TWO_PI * scene.cal_freq * t)
        phi2 = np.full_like(t, mech.phiD + mech.psi0)
        return {"phi1": z, "omega1": z, "epsilon1": z, "phi2": phi2, "psi": z, "omega2": z, "epsilon2": z,
                "aE_t": shaker if scene.cal_channel == "aE_t" else z,
                "aE_n": shaker if scene.cal_channel == "aE_n" else z}
    if scene.truth_model == "twin":
        return twin_truth(scene, t, interval)
    if scene.truth_model in MODEL_TRUTHS:
        return _model_truth(scene, t, interval)
    phi1, omega1, epsilon1 = cam_angle(scene, t)
    phi2, omega2, epsilon2, psi = follower_motion(scene.program, mech, phi1, omega1, epsilon1)
    return {"phi1": phi1, "omega1": omega1, "epsilon1": epsilon1, "phi2": phi2, "psi": psi,
            "omega2": omega2, "epsilon2": epsilon2, **_at_E(mech, omega2, epsilon2)}


# ---- the twin (labtool.models.dynamics.twin), streamed

def new_twin_run(scene: StandScene, keep_events: bool = False):
    """A fresh twin trajectory for the scene (its warm-up done; t = 0 at the start of a rise)."""
    from labtool.models.dynamics.twin import TwinRun
    return TwinRun(scene.model_scene(), scene.twin, keep_events=keep_events)


_TWIN_RUNS: dict = {}


def _cached_twin_run(scene: StandScene, t0: float):
    """The process's twin run of this scene if it has not passed t0 yet, else a new one (one kept)."""
    key = (repr(scene), repr(scene.mechanism))
    run = _TWIN_RUNS.get(key)
    if run is None or run.position > t0 + 1e-9:
        _TWIN_RUNS.clear()
        run = _TWIN_RUNS[key] = new_twin_run(scene)
    return run


def twin_truth(scene: StandScene, t, interval: float | None = None, run=None) -> dict:
    """The twin's truth at times t (s; any order). ``run``: a stream to continue (the stand's own,
    carried from block to block: its requests must move forward in time); default the process's
    cached run of the scene, restarted when t goes back. With ``interval`` aE_t and epsilon2 are
    interval means (from the sensor's speed vE and omega2 at the interval's edges), else point
    values (epsilon2 of the follower's rigid part, aE_t of the sensor on the bending follower)."""
    t = np.asarray(t, dtype=float)
    order = np.argsort(t, kind="stable")
    ts = t[order]
    n = ts.size
    mech = scene.mechanism
    if interval is None:
        query = ts
    elif n >= 2 and np.allclose(np.diff(ts), interval, rtol=1e-9, atol=0.0):
        edges = np.concatenate([ts - 0.5 * interval, ts[-1:] + 0.5 * interval])   # shared edges
        lo, hi = np.maximum(edges[:-1], 0.0), edges[1:]
        query = np.concatenate([ts, np.maximum(edges, 0.0)])
    else:
        lo, hi = np.maximum(ts - 0.5 * interval, 0.0), ts + 0.5 * interval
        query = np.concatenate([ts, lo, hi])
    qo = np.argsort(query, kind="stable")
    if run is None:
        run = _cached_twin_run(scene, float(query.min()) if query.size else 0.0)
    s = run.sample(np.maximum(query[qo], run.position), accelerations=interval is None)
    got = {k: np.empty(query.size) for k in ("phi1", "omega1", "phi2", "omega2", "vE", "epsilon2", "aE_t")}
    for k in got:
        got[k][qo] = s[k]
    c = {k: v[:n] for k, v in got.items()}
    if interval is None:
        aE_t, eps2 = c["aE_t"], c["epsilon2"]
    else:
        rest = {k: v[n:] for k, v in got.items()}
        if rest["vE"].size == n + 1:
            d_v, d_w = np.diff(rest["vE"]), np.diff(rest["omega2"])
        else:
            d_v, d_w = rest["vE"][n:] - rest["vE"][:n], rest["omega2"][n:] - rest["omega2"][:n]
        width = np.maximum(hi - lo, 1e-300)
        aE_t, eps2 = d_v / width, d_w / width
    res = {}
    for k, v in (("phi1", c["phi1"]), ("omega1", c["omega1"]), ("phi2", c["phi2"]), ("omega2", c["omega2"]),
                 ("aE_t", aE_t), ("epsilon2", eps2)):
        res[k] = np.empty_like(t)
        res[k][order] = v
    res["epsilon1"] = np.full_like(t, np.nan)   # not tabulated: the cam's speed varies with the load
    res["psi"] = res["phi2"] - mech.phiD - mech.psi0
    res["aE_n"] = sensor_point.acceleration_at_E(mech.DE, res["omega2"], 0.0)[1]
    return res


# ---- the model truths (rigid, elastic): the periodic steady state

_MODEL_TABLES: dict = {}


def model_table(scene: StandScene) -> dict:
    """The dynamic model's run behind a rigid/elastic truth (labtool.models.dynamics.simulate, omega1
    constant, ``model_revolutions`` turns): time (s), phi1, omega1, phi2, omega2, epsilon2, the
    event record (labtool.models.dynamics.events names, times in s of the run), ``period`` (s), and ``periodic``: the
    last two turns have the same events and omega2 away from them (labtool.models.dynamics.periodicity's
    REPEAT_TOL and EVENT_ANGLE_TOL). Cached per scene: the model runs once per process and
    scene. Points at repeated times (impacts of the rigid model) keep the later state.
    """
    key = (repr(scene), repr(scene.mechanism))
    if key not in _MODEL_TABLES:
        from labtool.models.dynamics.simulate import simulate
        R = scene.model_revolutions
        ds = simulate(scene.model_scene(R), scene.truth_model).dataset
        t = np.asarray(ds["time"].values, float)
        keep = np.append(np.diff(t) > 0, True)
        tab = {name: np.asarray(ds[name].values, float)[keep]
               for name in ("time", "phi1", "omega1", "phi2", "omega2", "epsilon2")}
        tab["events"] = model_events(ds)
        tab["period"] = TWO_PI / scene.omega1_nominal
        tab["revolutions"] = R
        tab["periodic"] = R >= 2 and _is_periodic(tab)
        _MODEL_TABLES.clear()  # one model run in memory at a time
        _MODEL_TABLES[key] = tab
    return _MODEL_TABLES[key]


def _is_periodic(tab: dict) -> bool:
    T, R = tab["period"], tab["revolutions"]
    te, ph = tab["events"]["event_time"], tab["events"]["event_phi1"]
    last, prev = (te >= (R - 1) * T), (te >= (R - 2) * T) & (te < (R - 1) * T)
    if not periodicity.events_repeat(ph[last] - TWO_PI, ph[prev]):
        return False
    tt = np.linspace((R - 1) * T, R * T, 4001)[:-1]
    a = np.interp(tt, tab["time"], tab["omega2"])
    b = np.interp(tt - T, tab["time"], tab["omega2"])
    away = np.ones(tt.size, bool)
    for x in np.concatenate([te[last], te[prev] + T]):
        away &= np.abs(tt - x) > 1e-3
    scale = max(np.abs(tab["omega2"]).max(), 1e-12)
    return periodicity.revolution_change(a, b, "max", keep=away, scale=scale) <= periodicity.REPEAT_TOL


def model_events(ds) -> dict:
    """A model dataset's contact events as the event record's arrays (labtool.models.dynamics.events, times
    in s of the run)."""
    from labtool.models.dynamics import events

    ev = events.read(ds)
    return {name: np.asarray(ev[name].values) for name in events.VARIABLES}


def model_truth_span(scene: StandScene) -> float:
    """Seconds of recording a rigid/elastic truth can serve: unlimited once periodic, else its run
    (less a margin for the sensor's interval)."""
    tab = model_table(scene)
    return math.inf if tab["periodic"] else float(tab["time"][-1]) - 1e-3


def _model_time(scene: StandScene, t):
    """Times of the model's run that stand for recording times t: the last (steady) turn
    repeated when the run is periodic, the run itself otherwise (InputError beyond it)."""
    tab = model_table(scene)
    t = np.asarray(t, dtype=float)
    if tab["periodic"]:
        T = tab["period"]
        return (tab["revolutions"] - 1) * T + np.mod(t, T), tab
    if t.size and (t.min() < tab["time"][0] - 1e-12 or t.max() > tab["time"][-1] + 1e-9):
        raise InputError(f"the {scene.truth_model} truth is not periodic after {tab['revolutions']} turns and covers "
                         f"0 to {tab['time'][-1]:.3f} s only: give energy loss (restitution < 1, contact damping > 0), "
                         "more truth revolutions, or a shorter duration")
    return t, tab


def _model_truth(scene: StandScene, t, interval: float | None = None) -> dict:
    tm, tab = _model_time(scene, t)
    mech = scene.mechanism
    out = {k: np.interp(tm, tab["time"], tab[k]) for k in ("omega1", "phi2", "omega2", "epsilon2")}
    out["phi1"] = scene.omega1_nominal * np.asarray(t, dtype=float)
    out["epsilon1"] = np.zeros_like(out["omega1"])
    out["psi"] = out["phi2"] - mech.phiD - mech.psi0
    eps2 = out["epsilon2"] if interval is None else boxcar_epsilon2(scene, t, interval)
    out.update(_at_E(mech, out["omega2"], eps2))
    return out


def boxcar_epsilon2(scene: StandScene, t, dt: float):
    """Mean epsilon2 over [t - dt/2, t + dt/2] (rad/s^2) = the change of the truth's omega2 over the
    interval / dt.

    What a sampled sensor integrates over one (oversampled) interval: it keeps the whole velocity
    step of an impact (the rigid model's omega2 jumps) and never misses a contact spike narrower
    than dt, unlike sampling epsilon2 at points. Intervals are clipped at t = 0 (and, for a run that
    is not periodic, at its end). Summed, the means give back the truth's omega2 exactly.
    """
    t = np.asarray(t, dtype=float)
    lo_t = np.maximum(t - 0.5 * dt, 0.0)
    hi_t = t + 0.5 * dt
    tab = model_table(scene)
    if not tab["periodic"]:
        hi_t = np.minimum(hi_t, tab["time"][-1])
    w_lo = np.interp(_model_time(scene, lo_t)[0], tab["time"], tab["omega2"])
    w_hi = np.interp(_model_time(scene, hi_t)[0], tab["time"], tab["omega2"])
    return (w_hi - w_lo) / np.maximum(hi_t - lo_t, 1e-300)


def truth_events(scene: StandScene, duration: float) -> dict:
    """The truth's event record (labtool.models.dynamics.events arrays) over [0, duration] s of a recording: the twin
    integrated again from its attributes, or a model truth's events (its steady turn repeated).
    The kinematic truth has none."""
    from labtool.models.dynamics import events

    if scene.mode != "run" or scene.truth_model == "kinematic":
        n = np.zeros(0)
        return events.columns(events.record(n, n, n.astype(int), n.astype(int), n, n, n, n.astype(bool)))
    if scene.truth_model == "twin":
        run = new_twin_run(scene, keep_events=True)
        step = 0.05
        for k in range(int(math.ceil(duration / step))):
            run.sample(np.array([min((k + 1) * step, duration)]))
        ev = run.take_events(final=True)
        keep = ev["event_time"] <= duration
        return {k: v[keep] for k, v in ev.items()}
    tab = model_table(scene)
    ev = tab["events"]
    if not tab["periodic"]:
        keep = ev["event_time"] <= duration
        return {k: v[keep] for k, v in ev.items()}
    T, R = tab["period"], tab["revolutions"]
    last = ev["event_time"] >= (R - 1) * T
    base = {k: v[last] for k, v in ev.items()}
    n_rev = int(math.ceil(duration / T)) + 1
    out = {k: np.concatenate([v] * n_rev) if len(v) else v for k, v in base.items()}
    shift = np.repeat(np.arange(n_rev), last.sum())
    out["event_time"] = out["event_time"] - (R - 1) * T + shift * T
    out["event_phi1"] = out["event_phi1"] - (R - 1) * TWO_PI + shift * TWO_PI
    keep = out["event_time"] <= duration
    return {k: v[keep] for k, v in out.items()}


# keys of a scene file's [truth] table -> (StandScene field or "twin.<TwinPhysics field>", scale to SI)
TRUTH_TABLE_KEYS = {
    "model": ("truth_model", None), "revolutions": ("truth_revolutions", None), "accuracy": ("accuracy", None),
    "restitution": ("restitution", 1.0), "contact_damping_s_per_m": ("contact_damping", 1.0),
    "contact_length_mm": ("contact_length", 1e-3), "kc_factor": ("kc_factor", 1.0),
    "drive": ("twin.drive", None), "mode_hz": ("twin.mode_hz", 1.0), "mode_zeta": ("twin.mode_zeta", 1.0),
    "mode_mass_share": ("twin.mode_mass_share", 1.0), "friction_torque_Nm": ("twin.friction_torque", 1.0),
    "friction_radius_mm": ("twin.friction_radius", 1e-3), "friction_speed_rad_s": ("twin.friction_speed", 1.0),
    "persistence_ms": ("twin.persistence_s", 1e-3), "warmup_revolutions": ("twin.warmup_revolutions", None),
}


def truth_settings(table: dict, source: str = "scene file") -> dict:
    """StandScene keyword arguments from a scene file's [truth] table (edge units: mm, ms; the
    twin's fields gathered into ``twin``). InputError on unknown keys or wrong types."""
    unknown = set(table) - set(TRUTH_TABLE_KEYS)
    if unknown:
        raise InputError(f"{source}: unknown [truth] keys {', '.join(sorted(unknown))}; known: {', '.join(TRUTH_TABLE_KEYS)}")
    out, twin = {}, {}
    for key, value in table.items():
        field, scale = TRUTH_TABLE_KEYS[key]
        if scale is None:
            if field in ("truth_revolutions", "twin.warmup_revolutions"):
                if isinstance(value, bool) or not isinstance(value, int):
                    raise InputError(f"{source}: [truth] {key} must be an integer, got {value!r}")
            elif not isinstance(value, str):
                raise InputError(f"{source}: [truth] {key} must be a string, got {value!r}")
        else:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise InputError(f"{source}: [truth] {key} must be a number, got {value!r}")
            value = float(value) * scale
        if field.startswith("twin."):
            twin[field[5:]] = value
        else:
            out[field] = value
    if twin:
        out["twin"] = TwinPhysics(**twin)
    return out


def scene_from_attrs(attrs: dict, mechanism: Mechanism | None = None) -> StandScene:
    """The StandScene a simulated recording was made with, from its root attributes.

    ``truth(scene_from_attrs(recording_format.load(p)["attrs"]), t)`` is the noise-free truth behind
    recording p (t = row / sample_rate_hz when there are no gaps), exactly: every truth parameter
    is an attribute. InputError if the recording does not come from the simulated stand. The
    mechanism is the default one unless given. Recordings made before the twin (no truth_model
    attribute) had the kinematic truth.
    """
    def text(v):
        return v.decode() if isinstance(v, bytes) else str(v)

    def num(key, default):
        return float(attrs[key]) if key in attrs else default

    if text(attrs.get("device", "")) != "sim" or "stand_mode" not in attrs:
        raise InputError("this recording does not come from the simulated stand: it has no known truth")
    d = StandScene.__dataclass_fields__
    return StandScene(
        mode=text(attrs["stand_mode"]), law=text(attrs["law"]), cam_speed=(num("cam_speed_rpm", 180.0)) * RPM,
        Fu=float(attrs["Fu_N"]), backlash=float(attrs["backlash_mm"]) * 1e-3,
        jt_factor=float(attrs["jt_factor"]), ripple=float(attrs["truth_omega1_ripple"]),
        cal_accel=float(attrs["cal_accel_m_s2_peak"]), cal_freq=float(attrs["cal_freq_hz"]),
        cal_channel=text(attrs["cal_channel"]), mechanism=mechanism or Mechanism.default(),
        truth_model=text(attrs.get("truth_model", "kinematic")).split()[0],
        truth_revolutions=int(attrs.get("truth_revolutions", 0)),
        restitution=num("truth_restitution", d["restitution"].default),
        contact_damping=num("truth_contact_damping_s_per_m", d["contact_damping"].default),
        contact_length=num("truth_contact_length_m", d["contact_length"].default),
        kc_factor=num("truth_kc_factor", d["kc_factor"].default),
        accuracy=text(attrs.get("truth_accuracy", d["accuracy"].default)),
        twin=TwinPhysics.from_attrs(attrs))


def sensed_acceleration(scene: StandScene, tr: dict) -> np.ndarray:
    """Specific force along the sensor axes (n, 2) in m/s^2: truth minus gravity, on the moving axes.

    On the follower the axes turn with phi2: f_t = aE_t + g cos(phi2), f_n = aE_n - g sin(phi2)
    (g along -y; labtool.models.mechanism.sensor_point.sensor_reading). On the shaker the calibrated axis is vertical: gravity is constant, and the AC
    coupling removes it like any constant.
    """
    g = scene.mechanism.g
    if scene.mode == "calibration":
        return np.column_stack([tr["aE_t"], tr["aE_n"]]) + np.array([g, 0.0]) * (scene.cal_channel == "aE_t") \
            + np.array([0.0, g]) * (scene.cal_channel == "aE_n")
    return np.column_stack(sensor_point.sensor_reading(tr["aE_t"], tr["aE_n"], tr["phi2"], g))


TACHO_ANGLE_TOL = 1e-9   # rad: a phi1 this far below 2 pi k (rounding of an integrated angle) is at it


def tacho(scene: StandScene, phi1, params: ChainParams) -> np.ndarray:
    """Tacho volts: tacho_v from each phi1 = 2 pi k (k >= 0) for tacho_width_s, else 0."""
    if scene.mode == "calibration":
        return np.zeros_like(np.asarray(phi1, float))
    width = scene.omega1_nominal * params.tacho_width_s  # rad
    return np.where(np.mod(np.asarray(phi1) + TACHO_ANGLE_TOL, TWO_PI) < width + TACHO_ANGLE_TOL, params.tacho_v, 0.0)


# --------------------------------------------------------------------------- filters

def _resonance_sos(params: ChainParams, fs: float):
    """Base-excited 1-DOF transmissibility (2 zeta w s + w^2) / (s^2 + 2 zeta w s + w^2), bilinear."""
    w = TWO_PI * params.resonance_hz
    z = params.resonance_zeta
    b, a = signal.bilinear([2 * z * w, w * w], [1.0, 2 * z * w, w * w], fs=fs)
    return signal.tf2sos(b, a)


@dataclasses.dataclass
class ChainState:
    """Filter states carried from block to block (one sos state per channel and filter)."""

    fs_os: float
    sos_res: np.ndarray
    sos_hp: np.ndarray
    sos_aa: np.ndarray
    zi_res: np.ndarray | None = None
    zi_hp: np.ndarray | None = None
    zi_aa: np.ndarray | None = None
    hp_level: np.ndarray | None = None  # mean input (V) of the AC coupling over one cam turn
    truth_run: object | None = None     # the twin's trajectory, continued block after block


def new_chain_state(params: ChainParams, rate_hz: float) -> ChainState:
    """Filters designed at the oversampled rate; states are set on the first block (steady state)."""
    fs = rate_hz * params.oversample
    nyq = 0.5 * fs
    if params.resonance_hz >= 0.95 * nyq:
        raise InputError(f"resonance {params.resonance_hz:g} Hz is above the simulated band at {rate_hz:g} Hz")
    return ChainState(
        fs_os=fs,
        sos_res=_resonance_sos(params, fs),
        sos_hp=signal.butter(1, params.highpass_hz, "highpass", fs=fs, output="sos"),
        sos_aa=signal.butter(params.antialias_order, params.antialias_frac * rate_hz, "lowpass", fs=fs, output="sos"),
    )


def _run(sos, x, zi, level=None):
    """sosfilt along axis 0; zi None -> start in the steady state of a constant input ``level``
    (default x[0]): the stand was already running before the first sample."""
    if zi is None:
        zi0 = signal.sosfilt_zi(sos)  # (n_sections, 2), steady state for a unit step
        level = x[0] if level is None else np.asarray(level, float)
        zi = zi0[:, :, None] * level[None, None, :]
    return signal.sosfilt(sos, x, axis=0, zi=zi)


def chain_block(scene: StandScene, params: ChainParams, state: ChainState, t_os, rng,
                resonant: bool = True, extra_m_s2=None):
    """Volts before the ADC at the oversampled times t_os (s), shape (n_os, 3), and the new state.

    The sensor integrates over each oversampled interval (dynamic truths): impacts keep their full
    velocity step. With the twin truth the bending mode is the truth's own degree of freedom, so
    the chain's resonance shapes the broadband mechanical noise only (never the motion a second
    time). ``extra_m_s2`` (n_os, 2) is added to the sensed acceleration (fault injection: impacts).
    """
    run = scene.mode == "run"
    dt = float(t_os[1] - t_os[0]) if t_os.size > 1 else None
    if run and scene.truth_model == "twin":
        if state.truth_run is None:
            state.truth_run = new_twin_run(scene)
        tr = twin_truth(scene, t_os, interval=dt, run=state.truth_run)
    else:
        tr = truth(scene, t_os, interval=dt if run and scene.truth_model in MODEL_TRUTHS else None)
    acc = sensed_acceleration(scene, tr)
    if extra_m_s2 is not None:
        acc = acc + extra_m_s2
    n = acc.shape[0]
    if resonant and run:
        noise = params.mech_noise_m_s2 * rng.standard_normal((n, 2))
        if scene.truth_model == "twin":
            shaped, state.zi_res = _run(state.sos_res, noise, state.zi_res, level=np.zeros(2))
            acc = acc + shaped
        else:
            acc, state.zi_res = _run(state.sos_res, acc + noise, state.zi_res)
    acc = acc + params.noise_m_s2 * rng.standard_normal((n, 2))
    volts = acc / np.asarray(params.ka_m_s2_per_v)[None, :]
    volts, state.zi_hp = _run(state.sos_hp, volts, state.zi_hp, state.hp_level)
    tach = tacho(scene, tr["phi1"], params)
    allv = np.column_stack([volts, tach])
    allv, state.zi_aa = _run(state.sos_aa, allv, state.zi_aa)
    return allv, state


def dc_level(scene: StandScene, params: ChainParams, n: int = 4096) -> np.ndarray:
    """Mean volts (2,) at the AC coupling's input over one cam turn (gravity + motion): the DC the
    coupling has settled on in a stand that has been running, used as its initial state."""
    period = 1.0 / scene.cal_freq if scene.mode == "calibration" else TWO_PI / scene.omega1_nominal
    t = np.arange(n) * (period / n)
    acc = sensed_acceleration(scene, truth(scene, t))
    return acc.mean(axis=0) / np.asarray(params.ka_m_s2_per_v)


def decimate(x_os: np.ndarray, oversample: int) -> np.ndarray:
    """Keep every ``oversample``-th sample (the anti-alias filter already ran at the high rate)."""
    return x_os[::oversample]


def adc(volts: np.ndarray, params: ChainParams):
    """Quantize to the ADC's LSB and clip at its rails. Returns (codes as volts float32, clipped mask).

    Range: [-range, range - lsb] as a two's-complement converter; a sample is "clipped" when the
    input lay beyond the rails.
    """
    lsb = params.lsb_v
    lo, hi = -params.adc_range_v, params.adc_range_v - lsb
    clipped = (volts < lo) | (volts > hi)
    q = np.clip(np.round(volts / lsb) * lsb, lo, hi)
    return q.astype(np.float32), clipped


def chain_frequency_response(params: ChainParams, rate_hz: float, f, resonant: bool = True):
    """Complex response (V per m/s^2, times Ka gives 1 at mid band) of the accel chain at f (Hz).

    Product of resonance (if ``resonant``), 1/Ka (channel aE_t), AC coupling and anti-alias, at the
    oversampled rate. Lets processing or tests undo or account for the chain.
    """
    st = new_chain_state(params, rate_hz)
    f = np.asarray(f, dtype=float)
    h = np.ones_like(f, dtype=complex)
    parts = [st.sos_hp, st.sos_aa] + ([st.sos_res] if resonant else [])
    for sos in parts:
        _, hh = signal.sosfreqz(sos, worN=f, fs=st.fs_os)
        h = h * hh
    return h / params.ka_m_s2_per_v[0]
