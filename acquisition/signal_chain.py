"""The measuring chain of the stand as pure functions: truth -> sensor -> conditioner -> ADC.

What the simulated stand records is the follower's true motion (models.mechanism.kinematics, cam as input,
plus a motor speed ripple) seen through everything a real chain adds and the models do not:

1. gravity: a piezoelectric accelerometer measures specific force, so a sensor riding on the
   follower at E also reads the component of -g along its axis; the axes turn with the follower
   (tangential t = (-sin phi2, cos phi2), normal n = -(cos phi2, sin phi2) towards D);
2. a structural resonance of the follower (base-excited 1-DOF, f_r, zeta_r) excited by the motion
   and by broadband mechanical noise (roller rolling in the groove);
3. sensor noise (white, m/s^2 rms at the oversampled rate, i.e. before the anti-alias filter);
4. sensitivity x conditioner gain = 1/Ka (V per m/s^2), Ka = 86.43 m/s^2/V by default (paper);
5. the 480C02's AC coupling, a first-order high-pass (0.1 Hz default);
6. the DAQ's anti-alias low-pass (Butterworth, order 8, 0.40 x the sample rate) at an
   oversampled rate, then decimation to the sample rate;
7. ADC range (+-10 V default), clipping at the rails and quantization (16 bits default).

Every function here is pure (state in, state out), so a run is deterministic for a seed and the
same code serves blocks of any size. Sign conventions: aE_t positive along increasing psi,
aE_n positive towards D (DESIGN.md); time t in s from the run's first sample; phi1 = 0 at the
start of the rise at t = 0.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import signal

from common.errors import InputError
from models.mechanism.kinematics import follower_motion
from models.mechanism import Mechanism
from models.mechanism.motion_laws import CamProgram

TWO_PI = 2.0 * math.pi
PAPER_KA = 86.43  # m/s^2 per V, paper sec. 2.4
ACCEL_CHANNELS = ("aE_t", "aE_n")
CHANNELS = ("aE_t", "aE_n", "tacho")
TRUTH_MODELS = ("kinematic", "rigid", "elastic")
MAX_MODEL_REVOLUTIONS = 200


@dataclasses.dataclass(frozen=True)
class StandScene:
    """What the simulated stand does (SI except cam_speed_rpm, as in models.dynamics.scene.Scene).

    mode            "run": the cam drives the follower; "calibration": the sensor sits on a
                    shaker (B&K 4291) giving cal_accel (m/s^2 peak) at cal_freq (Hz) along
                    channel cal_channel, the cam stands still.
    law, cam_speed_rpm, Fu (N), backlash (m), jt_factor: the operating point (paper's factors);
                    Fu, backlash and jt_factor do not change the kinematic truth, they are stored.
    ripple          relative amplitude of the motor speed ripple on omega1, once per cam turn:
                    omega1(t) = Omega (1 + ripple sin(Omega t))
    """

    mode: str = "run"
    law: str = "sine"
    cam_speed_rpm: float = 180.0
    Fu: float = 0.0
    backlash: float = 0.128e-3
    jt_factor: float = 1.0
    ripple: float = 0.005
    cal_accel: float = 9.81
    cal_freq: float = 79.6
    cal_channel: str = "aE_t"
    truth_model: str = "kinematic"
    truth_revolutions: int = 0
    mechanism: Mechanism = dataclasses.field(default_factory=Mechanism.default, repr=False)

    def __post_init__(self):
        model_truth = self.truth_model != "kinematic"
        checks = [
            (self.truth_model in TRUTH_MODELS, f"truth model must be one of {', '.join(TRUTH_MODELS)}, got '{self.truth_model}'"),
            (not model_truth or 1 <= self.truth_revolutions <= MAX_MODEL_REVOLUTIONS,
             f"the {self.truth_model} truth needs 1 to {MAX_MODEL_REVOLUTIONS} cam revolutions (a finite, shorter --duration)"),
            (not model_truth or self.ripple == 0.0, "the motor speed ripple applies to the kinematic truth only (set it to 0)"),
            (self.mode in ("run", "calibration"), f"stand mode must be 'run' or 'calibration', got '{self.mode}'"),
            (math.isfinite(self.Fu) and self.Fu >= 0, f"load Fu must be >= 0 N, got {self.Fu}"),
            (math.isfinite(self.backlash) and self.backlash >= 0, f"backlash must be >= 0 mm, got {self.backlash * 1e3:g}"),
            (math.isfinite(self.jt_factor) and self.jt_factor > 0, f"inertia factor Jt must be > 0, got {self.jt_factor}"),
            (math.isfinite(self.ripple) and 0 <= self.ripple < 0.5, f"speed ripple must lie in [0, 0.5), got {self.ripple}"),
            (math.isfinite(self.cal_accel) and self.cal_accel > 0, f"calibration acceleration must be > 0 m/s^2, got {self.cal_accel}"),
            (math.isfinite(self.cal_freq) and self.cal_freq > 0, f"calibration frequency must be > 0 Hz, got {self.cal_freq}"),
            (self.cal_channel in ACCEL_CHANNELS, f"calibration channel must be one of {', '.join(ACCEL_CHANNELS)}, got '{self.cal_channel}'"),
        ]
        for ok, msg in checks:
            if not ok:
                raise InputError(msg)
        self.mechanism.check_cam_speed(self.cam_speed_rpm)     # the one cam speed range of every command
        self.program  # unknown law -> InputError now, not mid-run

    @property
    def omega1_nominal(self) -> float:
        """Nominal cam speed Omega (rad/s)."""
        return self.cam_speed_rpm * TWO_PI / 60.0

    @property
    def program(self) -> CamProgram:
        return CamProgram.for_mechanism(self.mechanism, law=self.law)

    def attrs(self) -> dict:
        """Scene parameters as recording attributes (SI, plus rpm and mm where named so)."""
        return {
            "stand_mode": self.mode, "law": self.law, "cam_speed_rpm": float(self.cam_speed_rpm),
            "Fu_N": float(self.Fu), "backlash_mm": float(self.backlash * 1e3),
            "jt_factor": float(self.jt_factor),
            "truth_model": "kinematic (models.mechanism.kinematics.follower_motion)" if self.truth_model == "kinematic" else
            f"{self.truth_model} (models.dynamics.simulate, omega1 const, accuracy fast, {self.truth_revolutions} revolutions)",
            "truth_revolutions": int(self.truth_revolutions),
            "truth_omega1_ripple": float(self.ripple),
            "truth_omega1_ripple_form": "omega1 = Omega*(1 + ripple*sin(Omega*t)), phi1 = Omega*t + ripple*(1 - cos(Omega*t))",
            "cal_accel_m_s2_peak": float(self.cal_accel), "cal_freq_hz": float(self.cal_freq),
            "cal_channel": self.cal_channel, "mechanism": self.mechanism.name,
            "DE_m": float(self.mechanism.DE),
        }


@dataclasses.dataclass(frozen=True)
class ChainParams:
    """The sensor / conditioner / DAQ chain (SI).

    ka_m_s2_per_v   Ka per accelerometer channel (aE_t, aE_n), m/s^2 per V (volts = a / Ka)
    conditioner_gain 480C02 gain (x1, x10 or x100); sensor sensitivity = 1/(Ka gain) V per m/s^2
    highpass_hz     AC coupling corner of the conditioner (first order), Hz
    resonance_hz, resonance_zeta  follower structural mode seen at E (base-excited 1-DOF)
    mech_noise_m_s2 broadband mechanical excitation of that mode, m/s^2 rms at the oversampled rate
    noise_m_s2      sensor + electronics noise, m/s^2 rms at the oversampled rate
    antialias_frac  anti-alias corner as a fraction of the sample rate; order antialias_order
    oversample      internal oversampling factor before the anti-alias filter and decimation
    adc_range_v     ADC input range +-V; adc_bits resolution
    tacho_v, tacho_width_s  tacho pulse height (V) and width (s)
    """

    ka_m_s2_per_v: tuple[float, float] = (PAPER_KA, PAPER_KA)
    conditioner_gain: float = 10.0
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
    def lsb_v(self) -> float:
        return 2.0 * self.adc_range_v / 2**self.adc_bits

    def attrs(self) -> dict:
        return {
            "chain_ka_m_s2_per_v": np.asarray(self.ka_m_s2_per_v, float),
            "sensor": "PCB 352A76 (simulated)", "conditioner": "PCB 480C02 (simulated)",
            "conditioner_gain": float(self.conditioner_gain),
            "sensor_sensitivity_v_per_m_s2": np.asarray([1.0 / (k * self.conditioner_gain) for k in self.ka_m_s2_per_v]),
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


def truth(scene: StandScene, t, seed: int | None = None) -> dict:
    """The noise-free truth at times t (s): what an ideal sensor at E would see, no gravity.

    Returns arrays phi1 (rad, unwrapped), omega1 (rad/s), epsilon1 (rad/s^2), phi2 (rad), psi (rad),
    omega2 (rad/s), epsilon2 (rad/s^2), aE_t = epsilon2 DE, aE_n = omega2^2 DE (m/s^2). ``seed`` only
    sets the noise of a run, never the truth; it is accepted so callers can pass a run's settings.
    In calibration mode the follower stands still and aE along the calibrated axis is the shaker's
    sine cal_accel sin(2 pi cal_freq t).
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
    if scene.truth_model != "kinematic":
        return _model_truth(scene, t)
    phi1, omega1, epsilon1 = cam_angle(scene, t)
    phi2, omega2, epsilon2, psi = follower_motion(scene.program, mech, phi1, omega1, epsilon1)
    return {"phi1": phi1, "omega1": omega1, "epsilon1": epsilon1, "phi2": phi2, "psi": psi,
            "omega2": omega2, "epsilon2": epsilon2,
            "aE_t": epsilon2 * mech.DE, "aE_n": omega2**2 * mech.DE}


_MODEL_TABLES: dict = {}


def model_table(scene: StandScene) -> dict:
    """The dynamic model's run behind a rigid/elastic truth: time (s) and phi1, omega1, phi2, omega2,
    epsilon2 over ``truth_revolutions`` cam turns at constant cam speed (models.dynamics.simulate, accuracy
    fast). Cached per scene: the model runs once per run, not per block. Points at repeated times
    (impacts of the rigid model) keep the later state, so omega2 steps across them.
    """
    key = (scene.truth_model, scene.law, scene.cam_speed_rpm, scene.Fu, scene.backlash, scene.jt_factor,
           scene.truth_revolutions, repr(scene.mechanism))
    if key not in _MODEL_TABLES:
        from models.dynamics.scene import Scene
        from models.dynamics.simulate import simulate
        ms = Scene(law=scene.law, cam_speed_rpm=scene.cam_speed_rpm, Fu=scene.Fu, backlash=scene.backlash,
                   jt_factor=scene.jt_factor, omega1_mode="const", revolutions=float(scene.truth_revolutions),
                   rise_only=False, accuracy="fast", mechanism=scene.mechanism)
        ds = simulate(ms, scene.truth_model).dataset
        t = np.asarray(ds["time"].values, float)
        keep = np.append(np.diff(t) > 0, True)
        _MODEL_TABLES.clear()  # one model run in memory at a time
        _MODEL_TABLES[key] = {name: np.asarray(ds[name].values, float)[keep]
                              for name in ("time", "phi1", "omega1", "phi2", "omega2", "epsilon2")}
    return _MODEL_TABLES[key]


def _model_truth(scene: StandScene, t) -> dict:
    tab = model_table(scene)
    if t.size and (t.min() < tab["time"][0] - 1e-12 or t.max() > tab["time"][-1] + 1e-9):
        raise InputError(f"the {scene.truth_model} truth covers 0 to {tab['time'][-1]:.3f} s only")
    mech = scene.mechanism
    out = {k: np.interp(t, tab["time"], tab[k]) for k in ("phi1", "omega1", "phi2", "omega2", "epsilon2")}
    out["epsilon1"] = np.zeros_like(t)
    out["psi"] = out["phi2"] - mech.phiD - mech.psi0
    out["aE_t"] = out["epsilon2"] * mech.DE
    out["aE_n"] = out["omega2"] ** 2 * mech.DE
    return out


def boxcar_epsilon2(scene: StandScene, t, dt: float):
    """Mean epsilon2 over [t - dt/2, t + dt/2] (rad/s^2) = the change of omega2 over the interval / dt.

    What a sampled sensor integrates over one (oversampled) interval: it keeps the whole velocity
    step of an impact (the rigid model's omega2 jumps) and never misses a contact spike narrower
    than dt, unlike sampling epsilon2 at points.
    """
    tab = model_table(scene)
    lo = np.clip(t - 0.5 * dt, tab["time"][0], tab["time"][-1])
    hi = np.clip(t + 0.5 * dt, tab["time"][0], tab["time"][-1])
    return (np.interp(hi, tab["time"], tab["omega2"]) - np.interp(lo, tab["time"], tab["omega2"])) / dt


def scene_from_attrs(attrs: dict, mechanism: Mechanism | None = None) -> StandScene:
    """The StandScene a simulated recording was made with, from its root attributes.

    ``truth(scene_from_attrs(read_recording(p)["attrs"]), t)`` is the noise-free truth behind
    recording p (t = row / sample_rate_hz when there are no gaps). InputError if the recording does
    not come from the simulated stand. The mechanism is the default one unless given.
    """
    def text(v):
        return v.decode() if isinstance(v, bytes) else str(v)
    if text(attrs.get("device", "")) != "sim" or "stand_mode" not in attrs:
        raise InputError("this recording does not come from the simulated stand: it has no known truth")
    return StandScene(
        mode=text(attrs["stand_mode"]), law=text(attrs["law"]), cam_speed_rpm=float(attrs["cam_speed_rpm"])
        if "cam_speed_rpm" in attrs else 180.0, Fu=float(attrs["Fu_N"]), backlash=float(attrs["backlash_mm"]) * 1e-3,
        jt_factor=float(attrs["jt_factor"]), ripple=float(attrs["truth_omega1_ripple"]),
        cal_accel=float(attrs["cal_accel_m_s2_peak"]), cal_freq=float(attrs["cal_freq_hz"]),
        cal_channel=text(attrs["cal_channel"]), mechanism=mechanism or Mechanism.default(),
        truth_model=text(attrs.get("truth_model", "kinematic")).split()[0],
        truth_revolutions=int(attrs.get("truth_revolutions", 0)))


def sensed_acceleration(scene: StandScene, tr: dict) -> np.ndarray:
    """Specific force along the sensor axes (n, 2) in m/s^2: truth minus gravity, on the moving axes.

    On the follower the axes turn with phi2: f_t = aE_t + g cos(phi2), f_n = aE_n - g sin(phi2)
    (g along -y). On the shaker the calibrated axis is vertical: gravity is constant, and the AC
    coupling removes it like any constant.
    """
    g = scene.mechanism.g
    if scene.mode == "calibration":
        return np.column_stack([tr["aE_t"], tr["aE_n"]]) + np.array([g, 0.0]) * (scene.cal_channel == "aE_t") \
            + np.array([0.0, g]) * (scene.cal_channel == "aE_n")
    return np.column_stack([tr["aE_t"] + g * np.cos(tr["phi2"]), tr["aE_n"] - g * np.sin(tr["phi2"])])


def tacho(scene: StandScene, phi1, params: ChainParams) -> np.ndarray:
    """Tacho volts: tacho_v from each phi1 = 2 pi k (k >= 0) for tacho_width_s, else 0."""
    if scene.mode == "calibration":
        return np.zeros_like(np.asarray(phi1, float))
    width = scene.omega1_nominal * params.tacho_width_s  # rad
    return np.where(np.mod(phi1, TWO_PI) < width, params.tacho_v, 0.0)


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

    ``extra_m_s2`` (n_os, 2) is added to the sensed acceleration (fault injection: impacts).
    """
    tr = truth(scene, t_os)
    if scene.truth_model != "kinematic" and scene.mode == "run" and t_os.size > 1:
        # the sensor integrates over each interval: impacts keep their full velocity step
        tr["aE_t"] = boxcar_epsilon2(scene, t_os, t_os[1] - t_os[0]) * scene.mechanism.DE
    acc = sensed_acceleration(scene, tr)
    if extra_m_s2 is not None:
        acc = acc + extra_m_s2
    n = acc.shape[0]
    if resonant and scene.mode == "run":
        acc = acc + params.mech_noise_m_s2 * rng.standard_normal((n, 2))
        acc, state.zi_res = _run(state.sos_res, acc, state.zi_res)
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
