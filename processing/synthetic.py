"""Synthetic recordings with a known truth, for tests, docs and benchmarks (not the simulated stand).

The truth is the kinematics of the paper's mechanism (models.mechanism.kinematics.follower_motion: omega2 =
psi' omega1, epsilon2 = psi'' omega1^2 + psi' epsilon1; aE_t = epsilon2 DE, aE_n = omega2^2 DE) at a
cam speed that may vary slowly. The chain applied to it, in order: gravity as the sensor reads it
(tangential + g cos phi2, normal - g sin phi2), a lightly damped mount resonance, the AC coupling of
the ICP sensor (first-order high-pass), white noise, an offset, division by Ka (volts), and
quantization of an ADC of ``adc_bits`` over +-``adc_range_v`` with clipping at the range.
A tacho channel gives a 1 ms, 5 V pulse at every phi1 = 0.
"""
from __future__ import annotations

import dataclasses
import math

import h5py
import numpy as np
from scipy import signal


@dataclasses.dataclass
class SynthSpec:
    rpm: float = 180.0
    fs: float = 10000.0
    duration_s: float = 4.0
    rpm_drift: float = 0.0            # rpm change per second (slow speed variation)
    phase0_rad: float = 1.0            # cam angle at t = 0
    law: str = "sine"
    ka: float = 86.43                  # m/s^2/V
    noise_rms_m_s2: float = 1.0
    offset_v: float = 0.02
    ac_tau_s: float = 1.0              # ICP discharge time constant (s); 0 = DC coupled
    resonance_hz: float = 1800.0       # mount resonance (Hz); 0 = none
    resonance_q: float = 15.0
    adc_bits: int = 16
    adc_range_v: float = 10.0
    gravity: bool = True
    tacho: bool = True
    seed: int = 1
    spikes_at_s: tuple = ()            # times of impact-like bursts
    spike_amplitude_m_s2: float = 60.0


def truth(spec: SynthSpec, n: int | None = None, start: int = 0):
    """Per-sample truth for samples [start, start + n): dict of time, phi1 (unwrapped), omega1,
    epsilon1, omega2, epsilon2, aE_t, aE_n, phi2 (SI)."""
    from models.mechanism.kinematics import follower_motion
    from models.mechanism import Mechanism
    from models.mechanism.motion_laws import CamProgram

    mech = Mechanism.default()
    program = CamProgram.for_mechanism(mech, law=spec.law)
    n = int(round(spec.duration_s * spec.fs)) if n is None else n
    t = (start + np.arange(n)) / spec.fs
    w0 = spec.rpm * 2 * math.pi / 60.0
    e1 = spec.rpm_drift * 2 * math.pi / 60.0  # rad/s^2
    omega1 = w0 + e1 * t
    phi1 = spec.phase0_rad + w0 * t + 0.5 * e1 * t**2
    psi, dpsi, ddpsi, _ = program(phi1)
    omega2 = dpsi * omega1
    epsilon2 = ddpsi * omega1**2 + dpsi * e1
    phi2 = mech.phiD + mech.psi0 + psi
    return {"time": t, "phi1": phi1, "omega1": omega1, "omega2": omega2, "epsilon2": epsilon2,
            "aE_t": epsilon2 * mech.DE, "aE_n": omega2**2 * mech.DE, "phi2": phi2,
            "moving": program.direction(phi1) != 0, "mech": mech, "program": program}


def sensor_volts(spec: SynthSpec, tr: dict, rng: np.random.Generator) -> np.ndarray:
    """(n, 2) volts of aE_t and aE_n through the chain described in the module docstring."""
    g = tr["mech"].g if spec.gravity else 0.0
    acc = np.column_stack([tr["aE_t"] + g * np.cos(tr["phi2"]), tr["aE_n"] - g * np.sin(tr["phi2"])])
    fs = spec.fs
    for ts in spec.spikes_at_s:  # decaying 2 kHz burst: an impact
        k0 = int(ts * fs)
        m = np.arange(int(0.004 * fs))
        burst = spec.spike_amplitude_m_s2 * np.exp(-m / (0.0006 * fs)) * np.sin(2 * math.pi * 2000.0 * m / fs)
        sl = slice(k0, min(k0 + len(m), len(acc)))
        acc[sl, 0] += burst[: sl.stop - sl.start]
        acc[sl, 1] += 0.5 * burst[: sl.stop - sl.start]
    if spec.resonance_hz:
        w = 2 * math.pi * spec.resonance_hz
        b, a = signal.bilinear([w * w], [1.0, w / spec.resonance_q, w * w], fs)
        zi = signal.lfilter_zi(b, a)
        acc = np.column_stack([signal.lfilter(b, a, acc[:, j], zi=zi * acc[0, j])[0] for j in range(2)])
    if spec.ac_tau_s:
        b, a = signal.bilinear([spec.ac_tau_s, 0.0], [spec.ac_tau_s, 1.0], fs)
        acc = signal.lfilter(b, a, acc, axis=0)
    acc = acc + rng.normal(0.0, spec.noise_rms_m_s2, acc.shape)
    volts = acc / spec.ka + spec.offset_v
    lsb = 2 * spec.adc_range_v / 2**spec.adc_bits
    volts = np.clip(np.round(volts / lsb) * lsb, -spec.adc_range_v, spec.adc_range_v - lsb)
    return volts


def tacho_volts(tr: dict, fs: float) -> np.ndarray:
    """5 V for 1 ms after every phi1 = 0 (mod 2 pi) crossing, else 0 V."""
    rev = np.floor(tr["phi1"] / (2 * math.pi))
    start = np.flatnonzero(np.diff(rev) > 0) + 1
    out = np.zeros(len(rev))
    width = max(1, int(0.001 * fs))
    for s in start:
        out[s:s + width] = 5.0
    return out


def make_signals(spec: SynthSpec):
    """(volts (n, nch), channel names, truth)."""
    rng = np.random.default_rng(spec.seed)
    tr = truth(spec)
    cols = [sensor_volts(spec, tr, rng)]
    names = ["aE_t", "aE_n"]
    if spec.tacho:
        cols.append(tacho_volts(tr, spec.fs)[:, None])
        names.append("tacho")
    return np.hstack(cols), names, tr


def write_v1(path, volts: np.ndarray, names, fs: float, ka=None, events=(), complete: bool = True,
             cam_speed_rpm: float | None = None, dtype="float32", start_time_utc="2026-11-22T04:00:00Z"):
    """Write a recording exactly as DESIGN.md's format v1 (no dependency on acquisition/)."""
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "labtool.recording"
        f.attrs["format_version"] = 1
        f.attrs["sample_rate_hz"] = float(fs)
        f.attrs["start_time_utc"] = start_time_utc
        f.attrs["complete"] = bool(complete)
        if cam_speed_rpm is not None:
            f.attrs["cam_speed_rpm"] = float(cam_speed_rpm)
        d = f.create_dataset("signals", data=np.asarray(volts, dtype=dtype), chunks=(min(len(volts), 8192), volts.shape[1]),
                             maxshape=(None, volts.shape[1]))
        d.attrs["channel_names"] = np.array(list(names), dtype=h5py.string_dtype())
        d.attrs["ka_m_s2_per_v"] = np.array([np.nan] * len(names) if ka is None else ka, dtype=float)
        ev_dt = np.dtype([("index", "<i8"), ("kind", h5py.string_dtype()), ("detail", h5py.string_dtype())])
        ev = np.array([(int(i), k, d_) for i, k, d_ in events], dtype=ev_dt)
        f.create_dataset("events", data=ev, maxshape=(None,), chunks=(64,))


def write_synthetic(path, spec: SynthSpec, **kw):
    """Build and write a synthetic v1 recording; returns the truth dict."""
    volts, names, tr = make_signals(spec)
    events = [(0, "start", "")] + list(kw.pop("events", [])) + [(len(volts), "stop", "")]
    write_v1(path, volts, names, spec.fs, events=events, cam_speed_rpm=kw.pop("cam_speed_rpm", spec.rpm), **kw)
    return tr
