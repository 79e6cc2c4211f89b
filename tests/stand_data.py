"""Recordings for processing tests, from the one sensor chain (acquisition's simulated stand).

``stand_volts`` runs labtool.acquisition.sim_stand.SimStand with the kinematic truth (acquisition/signal_chain.py: gravity,
resonance, noise, Ka, AC coupling, anti-alias, ADC) without the recorder; ``write_v1`` writes
recording format v1 (docs/architecture.md) with plain h5py, so a test can damage or vary any part of it;
``truth`` is the chain's own noise-free truth at the samples' times. Benchmarks use it too.
"""
from __future__ import annotations

import contextlib
import math

import h5py
import numpy as np

from labtool.acquisition import signal_chain as sc
from labtool.acquisition.sim_stand import SimStand
from labtool.common.units import RPM


@contextlib.contextmanager
def drifting_speed(drift: float, duration_s: float):
    """The kinematic truth's cam turning at a speed that drifts linearly by ``drift`` (relative, e.g.
    0.05) from the first sample to the last, centred on the nominal speed: omega1 = Omega (1 + drift
    (t / duration_s - 1/2)), phi1 = 0 at t = 0 (a tacho pulse), no ripple. A drive warming up or a
    load change, which the simulated stand does not make: ``signal_chain.cam_angle`` is replaced
    while the block runs, so the chain (gravity, noise, filters, tacho) and ``truth`` both follow it."""
    original = sc.cam_angle

    def cam_angle(scene, t):
        t = np.asarray(t, dtype=float)
        W = scene.omega1_nominal
        phi1 = W * (t + drift * (t * t / (2.0 * duration_s) - 0.5 * t))
        omega1 = W * (1.0 + drift * (t / duration_s - 0.5))
        return phi1, omega1, np.full_like(t, W * drift / duration_s)

    sc.cam_angle = cam_angle
    try:
        yield
    finally:
        sc.cam_angle = original


def stand_volts(duration_s: float, rpm: float = 180.0, fs: float = 10000.0, seed: int = 1,
                scene: dict | None = None, params: dict | None = None):
    """(volts (n, 3) float32 of aE_t, aE_n, tacho; scene; chain params; the rate really used, Hz)."""
    # the kinematic truth (the cam as input, a speed ripple): smooth and known in closed form, what the
    # processing accuracy tests compare with; the stand's default twin truth is for the model checks
    st = sc.StandScene(cam_speed=rpm * RPM, **{"truth_model": "kinematic", **(scene or {})})
    # the paper's chain (480C02 at gain x10, Ka = 86.43 m/s^2/V), which the kinematic truth never clips
    pa = sc.ChainParams(**{"ka_m_s2_per_v": (sc.PAPER_KA, sc.PAPER_KA), **(params or {})})
    dev = SimStand(st, pa, seed=seed, duration_s=duration_s, realtime=False)
    rate = dev.configure(fs)
    dev.start()
    blocks = []
    while (blk := dev.read_block()) is not None:
        blocks.append(blk.data)
    dev.stop()
    return np.concatenate(blocks), st, pa, rate


def truth(scene, n: int, fs: float) -> dict:
    """The chain's truth (phi1, omega2, epsilon2, aE_t, aE_n, ...) at samples 0..n-1, plus ``moving``."""
    tr = sc.truth(scene, np.arange(n) / fs)
    tr["moving"] = scene.program.direction(tr["phi1"]) != 0
    tr["program"] = scene.program
    return tr


def write_v1(path, volts: np.ndarray, names=("aE_t", "aE_n", "tacho"), fs: float = 10000.0, ka=None, events=(),
             complete: bool = True, cam_speed_rpm: float | None = 180.0, dtype="float32",
             start_time_utc: str = "2026-11-22T04:00:00Z", attrs: dict | None = None, libver=("v110", "latest")):
    """Write recording format v1 (docs/architecture.md) (events: (index, kind, detail) tuples), with the file
    format bounds the recorder uses (v110: SWMR-capable, superblock version 3)."""
    volts = np.asarray(volts)
    with h5py.File(path, "w", libver=libver) as f:
        f.attrs["format"] = "labtool.recording"
        f.attrs["format_version"] = 1
        f.attrs["sample_rate_hz"] = float(fs)
        f.attrs["start_time_utc"] = start_time_utc
        f.attrs["complete"] = bool(complete)
        if cam_speed_rpm is not None:
            f.attrs["cam_speed_rpm"] = float(cam_speed_rpm)
        for k, v in (attrs or {}).items():
            f.attrs[k] = v
        d = f.create_dataset("signals", data=volts.astype(dtype), chunks=(min(len(volts), 8192), volts.shape[1]),
                             maxshape=(None, volts.shape[1]))
        d.attrs["channel_names"] = np.array(list(names), dtype=h5py.string_dtype())
        d.attrs["ka_m_s2_per_v"] = np.array([np.nan] * len(names) if ka is None else ka, dtype=float)
        ev_dt = np.dtype([("index", "<i8"), ("kind", h5py.string_dtype()), ("detail", h5py.string_dtype())])
        ev = np.array([(int(i), k, d_) for i, k, d_ in events], dtype=ev_dt)
        f.create_dataset("events", data=ev, maxshape=(None,), chunks=(64,))


def stand_recording(path, duration_s: float = 3.0, rpm: float = 180.0, seed: int = 1, events=(), tacho: bool = True,
                    scene: dict | None = None, params: dict | None = None, extra_m_s2=None, speed_drift: float = 0.0,
                    **kw) -> dict:
    """Record ``duration_s`` of the simulated stand into ``path`` (format v1); returns the truth.

    ``extra_m_s2(t) -> (n, 2)`` adds accelerations (m/s^2) after the chain, divided by the chain's Ka
    (impact bursts at known times). ``tacho=False`` leaves the tacho channel out. ``speed_drift``:
    the cam speed drifts by this fraction over the recording (drifting_speed; the ripple is then 0).
    """
    if speed_drift:
        with drifting_speed(speed_drift, duration_s):
            return stand_recording(path, duration_s, rpm, seed, events, tacho, {**(scene or {}), "ripple": 0.0},
                                   params, extra_m_s2, **kw)
    volts, st, pa, fs = stand_volts(duration_s, rpm, seed=seed, scene=scene, params=params)
    volts = volts.astype(np.float64)
    if extra_m_s2 is not None:
        volts[:, :2] += extra_m_s2(np.arange(len(volts)) / fs) / np.asarray(pa.ka_m_s2_per_v)[None, :]
    names = ["aE_t", "aE_n", "tacho"]
    if not tacho:
        volts, names = volts[:, :2], names[:2]
    n = len(volts)
    # as the recorder stores the simulated stand's Ka (the chain's true value)
    kw.setdefault("ka", [*pa.ka_m_s2_per_v, math.nan][:len(names)])
    write_v1(path, volts, names, fs, events=[(0, "start", ""), *events, (n, "stop", "")],
             cam_speed_rpm=kw.pop("cam_speed_rpm", rpm), **kw)
    tr = truth(st, n, fs)
    tr.update(scene=st, params=pa, fs=fs)
    return tr


def impact_bursts(times_s, amplitude_m_s2: float = 60.0, freq_hz: float = 2000.0, decay_s: float = 0.0006):
    """extra_m_s2 for stand_recording: a decaying ``freq_hz`` burst at each time (closed form)."""
    def extra(t):
        out = np.zeros((len(t), 2))
        for ts in times_s:
            dt = t - ts
            on = (dt >= 0) & (dt < 0.004)
            b = amplitude_m_s2 * np.exp(-dt[on] / decay_s) * np.sin(2 * math.pi * freq_hz * dt[on])
            out[on, 0] += b
            out[on, 1] += 0.5 * b
        return out
    return extra


def without_statements(full, nc, words=("backlash", "restitution")) -> None:
    """``full`` (a processed file) written to ``nc`` without the attributes naming any of ``words``:
    what a fit gets from a stand whose worn groove's j (and energy loss) nobody states."""
    import xarray as xr

    from labtool.common.files import write_netcdf

    with xr.open_dataset(full, engine="h5netcdf") as ds:
        ds = ds.load()
    for k in [k for k in ds.attrs if any(w in k for w in words)]:
        del ds.attrs[k]
    write_netcdf(ds, nc)
