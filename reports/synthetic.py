"""A synthetic stand-in for ``measured.nc``, built from the kinematics (no acquisition, no processing).

Used by the report's tests, and by ``labtool demo`` only while the acquisition or processing step is
not available (the demo says so, and the dataset's ``source`` attribute says ``synthetic``). It has
the layout ``labtool process`` writes: signals over ``time`` (aE_t, aE_n, epsilon2, omega2, phi1,
revolution), amplitude spectra over ``frequency``, cycle averages over ``phi1_grid``.
"""
from __future__ import annotations

import math

import numpy as np
import xarray as xr


def synthetic_measured(rpm: float = 180.0, revolutions: float = 4.3, fs: float = 10_000.0, law: str = "sine",
                       noise: float = 0.02, gain: float = 1.0, lag_deg: float = 0.0, seed: int = 0,
                       start_deg: float = 250.0, mechanism=None) -> xr.Dataset:
    """Kinematic omega2/epsilon2 at ``rpm`` (cam as input) seen through an imperfect "measurement":
    scaled by ``gain``, delayed by ``lag_deg`` of cam angle, plus white noise of ``noise`` times the
    signal's peak. The recording starts at cam angle ``start_deg`` so that its first and last
    revolutions are partial, as on the stand."""
    from labtool.models.mechanism.kinematics import analyze
    from labtool.models.mechanism import Mechanism, sensor_point
    from labtool.models.mechanism.motion_laws import CamProgram

    mech = mechanism or Mechanism.default()
    program = CamProgram.for_mechanism(mech, law=law)
    omega1 = rpm * math.pi / 30.0
    grid = np.linspace(0.0, 2.0 * math.pi, 7201)
    kin = analyze(mech, program, rpm, phi1=grid)
    n = int(round(revolutions * 2.0 * math.pi / omega1 * fs))
    t = np.arange(n) / fs
    theta = math.radians(start_deg) + omega1 * t
    phi1 = np.mod(theta, 2.0 * math.pi)
    src = np.mod(theta - math.radians(lag_deg), 2.0 * math.pi)
    rng = np.random.default_rng(seed)
    w2 = gain * np.interp(src, grid, kin["omega2"].values)
    e2 = gain * np.interp(src, grid, kin["epsilon2"].values)
    w2 = w2 + noise * np.abs(w2).max() * rng.standard_normal(n)
    e2 = e2 + noise * np.abs(e2).max() * rng.standard_normal(n)

    def var(dims, data, units, long_name):
        return (dims, np.asarray(data), {"units": units, "long_name": long_name})

    aE_t, aE_n = sensor_point.acceleration_at_E(mech.DE, w2, e2)
    freq = np.fft.rfftfreq(n, 1.0 / fs)
    amp = lambda y: 2.0 * np.abs(np.fft.rfft(y - y.mean())) / n   # noqa: E731 (single-sided amplitude)
    pg = np.linspace(0.0, 2.0 * math.pi, 361)[:-1]
    ds = xr.Dataset(
        {
            "aE_t": var("time", aE_t, "m/s^2", "tangential acceleration of E"),
            "aE_n": var("time", aE_n, "m/s^2", "normal acceleration of E, towards D"),
            "epsilon2": var("time", e2, "rad/s^2", "follower angular acceleration"),
            "omega2": var("time", w2, "rad/s", "follower angular velocity"),
            "phi1": var("time", phi1, "rad", "cam angle from the start of the rise"),
            "revolution": var("time", np.floor(theta / (2.0 * math.pi)).astype("int32"), "1", "cam revolution index"),
            "aE_t_amplitude": var("frequency", amp(aE_t), "m/s^2", "amplitude spectrum of aE_t"),
            "aE_n_amplitude": var("frequency", amp(aE_n), "m/s^2", "amplitude spectrum of aE_n"),
            "omega2_mean": var("phi1_grid", gain * np.interp(pg, grid, kin["omega2"].values), "rad/s", "cycle average of omega2"),
            "epsilon2_mean": var("phi1_grid", gain * np.interp(pg, grid, kin["epsilon2"].values), "rad/s^2", "cycle average of epsilon2"),
        },
        coords={
            "time": ("time", t, {"units": "s", "long_name": "time from the start of the recording"}),
            "frequency": ("frequency", freq, {"units": "Hz", "long_name": "frequency"}),
            "phi1_grid": ("phi1_grid", pg, {"units": "rad", "long_name": "cam angle grid of the cycle averages"}),
        },
        attrs={
            "title": "synthetic measurement (kinematics + noise), not a recording",
            "source": "synthetic",
            "cam_speed_rpm": float(rpm),
            "law": law,
            "ka_m_s2_per_v": 86.43,
            "ka_source": "paper default (synthetic data)",
            "sample_rate_hz": float(fs),
            "processing_history": f"labtool.reports.synthetic.synthetic_measured(rpm={rpm}, noise={noise}, gain={gain}, "
                                  f"lag_deg={lag_deg}, seed={seed})",
        },
    )
    return ds
