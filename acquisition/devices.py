"""The devices an acquisition runs on, built from settings: the simulated stand at an operating
point, or an NI-DAQmx board from a device file and/or physical channels.

``labtool.acquire`` (the ``acquire`` command) and a campaign's acquire step both build their
device here, so a recording of the simulated stand at a point is the same whichever made it.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping, Sequence

from labtool.acquisition import signal_chain as sc
from labtool.common.errors import InputError

# advice of the error for a model truth that cannot cover the duration (the command's options)
MODEL_TRUTH_ADVICE = ("give energy loss (--restitution < 1, --contact-damping > 0) or a --duration of at most "
                      "{turns} turns")


@dataclasses.dataclass
class DeviceSetup:
    """A device ready to run, and what the recording says of it.

    Attributes
    ----------
    device : labtool.acquisition.device.Device
        The device (configured at the run's start by ``labtool.acquisition.session.run``).
    ka_m_s2_per_v : list of float
        Ka of each channel [m/s^2/V]; NaN where none (the tacho, an uncalibrated channel).
    attrs : dict
        Root attributes of the recording: where Ka comes from, the pacing, the nominal cam speed [rpm].
    """

    device: Any
    ka_m_s2_per_v: list
    attrs: dict


def sim_device(point: Mapping[str, Any], *, truth_model: str = "twin", mode: str = "run", ripple: float | None = None,
               cal_accel: float = 9.81, cal_freq: float = 79.6, cal_channel: str = "aE_t",
               truth_options: Mapping[str, Any] | None = None, ka_m_s2_per_v: float = sc.DEFAULT_KA, seed: int = 0,
               duration_s: float | None = None, realtime: bool = True, faults: Sequence[str] = (),
               advice: str = MODEL_TRUTH_ADVICE) -> DeviceSetup:
    """The simulated stand (``labtool.acquisition.sim_stand.SimStand``) at an operating point.

    Parameters
    ----------
    point : mapping
        The operating point's stated fields in SI (``labtool.common.operating_point.STATED``: ``law``,
        ``cam_speed`` [rad/s], ``Fu`` [N], ``backlash`` [m], ``jt_factor`` [-]).
    truth_model : {"twin", "kinematic", "rigid", "elastic"}
        What moves the follower (``labtool.acquisition.signal_chain.TRUTH_MODELS``).
    mode : {"run", "calibration"}
        The cam drives the follower, or a shaker drives the sensor (the cam stands still).
    ripple : float, optional
        The drive's speed ripple, relative [-]; default 0.005, and 0 for a model truth (its cam
        runs at constant speed).
    cal_accel : float
        Calibration mode: the shaker's amplitude [m/s^2 peak].
    cal_freq : float
        Calibration mode: the shaker's frequency [Hz].
    cal_channel : str
        Calibration mode: the channel on the shaker.
    truth_options : mapping, optional
        Further ``StandScene`` fields of the truth (``restitution`` [-], ``contact_damping`` [s/m], ...).
    ka_m_s2_per_v : float
        The simulated chain's Ka [m/s^2/V], both acceleration channels.
    seed : int
        Noise seed [-].
    duration_s : float, optional
        Seconds the stand generates [s] (None: until stopped).
    realtime : bool
        Pace the stand in real time, or run as fast as possible.
    faults : sequence of str
        Injected faults ``kind@seconds`` (``labtool.acquisition.sim_stand.parse_fault``).
    advice : str
        What to do when a model truth cannot cover ``duration_s`` (``{turns}``: the most it covers).

    Returns
    -------
    DeviceSetup
    """
    from labtool.acquisition.sim_stand import SimStand, parse_fault

    if ripple is None:
        ripple = 0.0 if truth_model in sc.MODEL_TRUTHS else 0.005     # a model truth's cam runs at constant speed
    scene = sc.StandScene(truth_model=truth_model, mode=mode, **point, ripple=float(ripple), cal_accel=float(cal_accel),
                          cal_freq=float(cal_freq), cal_channel=str(cal_channel), **dict(truth_options or {}))
    dur = math.inf if duration_s is None else float(duration_s)
    if truth_model in sc.MODEL_TRUTHS and scene.mode == "run":
        scene = model_truth_for(scene, dur, advice)
    k = float(ka_m_s2_per_v)
    params = sc.ChainParams(ka_m_s2_per_v=(k, k), resonance_hz=scene.twin.mode_hz, resonance_zeta=scene.twin.mode_zeta)
    dev = SimStand(scene, params, seed=int(seed), duration_s=None if math.isinf(dur) else dur, realtime=realtime,
                   faults=[parse_fault(f) for f in faults])
    attrs = {"ka_source": "simulated chain (true value)", "ka_m_s2_per_v": k, "pacing": "realtime" if realtime else "fast"}
    if scene.mode == "run":
        attrs["cam_speed_rpm"] = float(scene.cam_speed_rpm)
    return DeviceSetup(dev, [k, k, float("nan")], attrs)


def model_truth_for(scene: sc.StandScene, dur: float, advice: str = MODEL_TRUTH_ADVICE) -> sc.StandScene:
    """The rigid/elastic truth scene that covers ``dur`` s: its periodic steady state, or (not
    periodic) a run over the whole duration up to MAX_MODEL_REVOLUTIONS turns; InputError else."""
    if sc.model_truth_span(scene) >= dur:
        return scene
    needed = int(math.ceil((dur + 0.2) * scene.cam_speed_rpm / 60.0)) + 1 if math.isfinite(dur) else math.inf
    if scene.truth_revolutions == 0 and needed <= sc.MAX_MODEL_REVOLUTIONS:
        longer = dataclasses.replace(scene, truth_revolutions=needed)
        if sc.model_truth_span(longer) >= dur:
            return longer
    raise InputError(f"the {scene.truth_model} truth does not reach a periodic steady state in {scene.model_revolutions} "
                     f"cam turns (restitution {scene.restitution:g}, contact damping {scene.contact_damping:g} s/m), "
                     f"so it cannot be repeated over {dur:g} s: " + advice.format(turns=sc.MAX_MODEL_REVOLUTIONS))


def nidaqmx_device(channels: str | None, device_file=None, overrides: Sequence[str] = (), iepe_excitation: bool = False,
                   source: str = "command line"):
    """An NI-DAQmx board, its configuration checked and nothing touched yet.

    Parameters
    ----------
    channels : str, optional
        Physical channels (``Dev1/ai0:2``), or None for the device file's.
    device_file : path, optional
        TOML device file (channels by role, range [V], terminal, coupling, IEPE [A], sensitivity
        [mV/g] or TEDS, clock, trigger; ``labtool.acquisition.nidaqmx_config``).
    overrides : sequence of str
        Settings ``CHANNEL.KEY=VALUE`` over the device file.
    iepe_excitation : bool
        The board powers the IEPE sensors with 4 mA.
    source : str
        Where the configuration comes from, as messages name it.

    Returns
    -------
    (device, config, ka_nominal)
        The device (behind a software trigger when the configuration asks for one), its
        ``nidaqmx_config`` configuration and each channel's nominal Ka [m/s^2/V] (NaN: none).
    """
    from labtool.acquisition import nidaqmx_config as nc
    from labtool.acquisition.nidaqmx_driver import NIDAQmxDevice, expand_channels
    from labtool.acquisition.trigger import SoftwareTrigger

    doc = nc.load_device_file(device_file) if device_file is not None else None
    cfg = nc.build(expand_channels(channels) if channels else None, doc, overrides=list(overrides), source=source,
                   iepe_excitation_a=0.004 if iepe_excitation else None)
    dev = NIDAQmxDevice(cfg)
    ka_nominal = list(dev.ka_nominal)
    if cfg.trigger.software:
        dev = SoftwareTrigger(dev, cfg.names.index(nc.trigger_channel(cfg).name), cfg.trigger.level_v,
                              cfg.trigger.edge, cfg.trigger.pretrigger_samples)
    return dev, cfg, ka_nominal
