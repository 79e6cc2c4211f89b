"""``labtool.acquire``: record the stand (simulated or NI-DAQmx) into a v1 recording (HDF5)."""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any, Mapping, Sequence

from labtool.acquisition.metadata import OPTION, missing_operating_point, operating_point_attrs, run_metadata_attrs
from labtool.common.errors import InputError
from labtool.common.files import check_output_path
from labtool.common.names import shown
from labtool.common.operating_point import FIELD, schema_field
from labtool.common.schema import Integer, Number, String, Table, load_toml
from labtool.processing.calibration_file import KA_MAX, KA_MIN

# keys of a scene file's [stand] table (and of labtool.acquire's ``stand``) -> the command's option
SCENE_KEYS = {
    "mode": "mode", "law": "law", "cam_speed_rpm": "rpm", "Fu_N": "fu", "backlash_mm": "backlash_mm",
    "jt_factor": "jt_factor", "ripple": "ripple", "cal_accel_m_s2": "cal_accel", "cal_freq_hz": "cal_freq",
    "cal_channel": "cal_channel", "seed": "seed", "duration_s": "duration", "rate_hz": "rate",
    "ka_m_s2_per_v": "ka", "truth_model": "truth",
}
# option -> operating-point field (labtool.common.operating_point: its default, unit and bounds)
POINT_OPTIONS = {"law": "law", "rpm": "cam_speed", "fu": "Fu", "backlash_mm": "backlash", "jt_factor": "jt_factor"}
DEFAULTS = {**{opt: FIELD[name].default_edge for opt, name in POINT_OPTIONS.items()},
            "mode": "run", "ripple": 0.005, "cal_accel": 9.81, "cal_freq": 79.6, "cal_channel": "aE_t", "seed": 0,
            "duration": 10.0, "rate": 10000.0, "ka": 864.3, "truth": "twin"}

# the [stand] table of a scene file (labtool.common.schema): types, plausible bounds, unknown keys named
STAND_SCHEMA = Table({
    "mode": String(choices=("run", "calibration"), required=False),
    **{FIELD[name].attr: schema_field(name) for name in POINT_OPTIONS.values()},
    "ripple": Number(ge=0, lt=1, required=False),
    "cal_accel_m_s2": Number(gt=0, le=1e6, unit="m/s^2", required=False),
    "cal_freq_hz": Number(gt=0, le=1e6, unit="Hz", required=False),
    "cal_channel": String(max_len=64, required=False),
    "seed": Integer(ge=0, required=False),
    "duration_s": Number(gt=0, allow_inf=True, unit="s", required=False),
    "rate_hz": Number(gt=0, le=1e8, unit="Hz", required=False),
    "ka_m_s2_per_v": Number(gt=KA_MIN, lt=KA_MAX, unit="m/s^2/V", required=False),   # as a calibration file
    "truth_model": String(max_len=64, required=False),      # checked by StandScene (TRUTH_MODELS)
})
assert set(STAND_SCHEMA.fields) == set(SCENE_KEYS)
# [truth] is checked key by key by labtool.acquisition.signal_chain.truth_settings
SCENE_SCHEMA = Table({"stand": STAND_SCHEMA, "truth": Table({}, extra=True, required=False)})
MAX_SAMPLES = 1e15    # per channel: 3000 years at 10 kHz, and an exact integer in a float


@dataclasses.dataclass
class Acquisition:
    """How a recording run ended, as :func:`labtool.acquire` returns it.

    Attributes
    ----------
    path : pathlib.Path
        The recording written (format v1, docs/architecture.md).
    n_samples : int
        Samples per channel in the file [-].
    n_channels : int
        Channels recorded [-].
    rate_hz : float
        The rate the device really ran at [Hz].
    wall_s : float
        Wall time of the run [s].
    overruns, gaps : int
        Device buffer overruns and gaps in the samples [-].
    clipped : tuple of str
        The channels whose ADC range was exceeded.
    stop_reason : str
        Why the run ended: ``done``, ``interrupted``, ``disconnected``, ``disk_full``, ``write_error``.
    message : str
        The same in a sentence ("duration reached", "stopped by the user (SIGTERM)", ...).
    complete : bool
        The recording holds what was asked (the file's ``complete`` attribute).
    signum : int or None
        The stop signal received (SIGINT, SIGTERM, SIGHUP), if any.
    duration_s : float or None
        The duration asked [s] (None: until stopped).
    unstated : list of str
        Operating-point values a report needs that the recording does not state (NI-DAQmx runs).
    """

    path: Path
    n_samples: int
    n_channels: int
    rate_hz: float
    wall_s: float
    overruns: int
    gaps: int
    clipped: tuple
    stop_reason: str
    message: str
    complete: bool
    signum: int | None
    duration_s: float | None
    unstated: list

    def check(self) -> None:
        """Raise what a run that did not end well means: InputError for a disconnected device, a
        full disk or a write error (the samples written are kept), KeyboardInterrupt (or
        ``Interrupted``) for a stop signal, each saying what the file holds."""
        secs = self.n_samples / self.rate_hz
        if self.stop_reason in ("disconnected", "disk_full", "write_error"):
            raise InputError(f"{self.message}; {self.n_samples} samples ({secs:.3f} s) kept in {self.path}, "
                             f"complete={str(self.complete).lower()}")
        if self.signum is not None:        # exit 128 + signal (labtool.cli)
            from labtool.common.errors import interruption

            if self.complete:
                note = f"{shown(self.path)} is closed and complete ({self.n_samples} samples, {secs:.3f} s)"
            else:
                of = f" of {self.duration_s:g}" if self.duration_s is not None else ""
                note = (f"{shown(self.path)} keeps its {self.n_samples} samples ({secs:.3f}{of} s), closed and "
                        "marked incomplete; the same command records it again")
            raise interruption(self.signum, note)


def acquire(output, *, device: str | None = None, stand: Mapping[str, Any] | None = None, scene=None,
            realtime: bool = True, truth_options: Mapping[str, float] | None = None, faults: Sequence[str] = (),
            device_file=None, ni: Sequence[str] = (), iepe_excitation: bool = False,
            metadata: Mapping[str, Any] | None = None, motor_setting: str | None = None, force: bool = False,
            yes: bool = False, confirm=None, monitor=None, warn=None, command: str | None = None,
            check: bool = True) -> Acquisition:
    """Record aE_t, aE_n (volts) and the tacho from the stand into a recording (format v1).

    Parameters
    ----------
    output : path
        The recording to write (HDF5, format v1; docs/architecture.md).
    device : str, optional
        ``sim`` (the simulated stand), ``nidaqmx:<physical channels>`` (``nidaqmx:Dev1/ai0:2``), or
        ``nidaqmx`` with ``device_file`` (default: ``sim``, ``nidaqmx`` when a device file is given).
    stand : mapping, optional
        Settings with the keys of a scene file's ``[stand]`` table (docs/acquisition.md), each
        unit in its name: ``cam_speed_rpm`` [rpm], ``Fu_N`` [N], ``backlash_mm`` [mm],
        ``jt_factor`` [-], ``law``, ``duration_s`` [s] (``inf``: until stopped; default 10),
        ``rate_hz`` [Hz] (default 10000), ``seed``, ``ripple`` [-], ``ka_m_s2_per_v`` [m/s^2/V],
        ``mode`` (``run`` or ``calibration``), ``cal_freq_hz`` [Hz], ``cal_accel_m_s2`` [m/s^2
        peak], ``cal_channel``, ``truth_model``. Over ``scene``'s. The simulated stand runs at
        them; an NI-DAQmx recording stores the operating point as stated.
    scene : path, optional
        A TOML scene file with a ``[stand]`` table (and an optional ``[truth]`` table).
    realtime : bool
        Pace the simulated stand in real time, or run it as fast as possible.
    truth_options : mapping, optional
        The simulated truth's ``restitution`` [-] and ``contact_damping`` [s/m], over the scene's.
    faults : sequence of str
        Simulated faults ``kind@seconds`` (overrun, drop, disconnect, clip).
    device_file : path, optional
        NI-DAQmx: the TOML device file (docs/acquisition.md).
    ni : sequence of str
        NI-DAQmx settings ``CHANNEL.KEY=VALUE``, ``trigger.KEY=VALUE`` or ``device.KEY=VALUE``.
    iepe_excitation : bool
        NI-DAQmx: the board powers the IEPE sensors with 4 mA.
    metadata : mapping, optional
        Run metadata stored in the recording: ``test_id``, ``operator``, ``sensor_model``,
        ``sensor_serial``, ``conditioner_gain`` [-], ``notes``.
    motor_setting : str, optional
        The motor or variator setting as the operator states it.
    force : bool
        Overwrite an existing file (never one another process is recording).
    yes : bool
        Record more than 10 min [s of the stand] or 100 MB without asking.
    confirm : callable, optional
        ``confirm(question) -> bool`` asks before such a recording (without it, and without ``yes``,
        it is refused).
    monitor : callable, optional
        ``monitor(device, ka_m_s2_per_v, duration_s)`` -> an object with ``on_block(block)``,
        ``progress(recorder, elapsed_s)`` and ``stop()``: a live display of the run.
    warn : callable, optional
        ``warn(text)`` for each warning before the run (an unfinished recording recorded over).
    command : str, optional
        The command line stored as the recording's ``command``.
    check : bool
        Raise as :meth:`Acquisition.check` when the run did not end well (the file is kept).

    Returns
    -------
    Acquisition
        The recording's path, its samples, rate, overruns, stop reason and completeness.
    """
    from labtool.acquisition import devices
    from labtool.acquisition import session
    from labtool.acquisition.device import parse_device

    unknown = sorted(set(stand or {}) - set(SCENE_KEYS))
    if unknown:
        raise InputError(f"unknown stand setting(s) {', '.join(unknown)}; known: {', '.join(SCENE_KEYS)}")
    given = {SCENE_KEYS[k]: v for k, v in (stand or {}).items() if v is not None}
    from_scene = load_scene(Path(scene)) if scene is not None else {}
    opts = {**DEFAULTS, "_truth": {}, **from_scene, **given}
    opts["_truth"] = {**opts["_truth"], **{k: float(v) for k, v in (truth_options or {}).items() if v is not None}}
    if device is None:
        device = "nidaqmx" if device_file is not None else "sim"
    kind, arg = ("nidaqmx", "") if device.strip() == "nidaqmx" and device_file is not None else parse_device(device)
    if kind == "nidaqmx" and "ka" not in given and "ka" not in from_scene:
        opts["ka"] = None
    dur, rate = float(opts["duration"]), float(opts["rate"])
    _check_run(dur, rate, opts, kind, realtime)
    output = Path(output)
    if output.is_dir():
        raise InputError(f"{output} is a folder; give a file name for the recording")
    replacing = _check_output(output, force)
    meta = {k: v for k, v in (metadata or {}).items()}
    if kind == "sim":
        if device_file is not None or ni:
            raise InputError("--device-file and --ni configure NI-DAQmx devices; use them with --device nidaqmx")
        point = {name: FIELD[name].check_edge(opts[opt]) for opt, name in POINT_OPTIONS.items()}
        ripple = opts["ripple"] if "ripple" in given or "ripple" in from_scene else None
        setup = devices.sim_device(point, truth_model=str(opts["truth"]), mode=str(opts["mode"]), ripple=ripple,
                                   cal_accel=float(opts["cal_accel"]), cal_freq=float(opts["cal_freq"]),
                                   cal_channel=str(opts["cal_channel"]), truth_options=opts["_truth"],
                                   ka_m_s2_per_v=float(opts["ka"]), seed=int(opts["seed"]), duration_s=dur,
                                   realtime=realtime, faults=faults)
        setup.attrs.update(run_metadata_attrs(meta))
        if motor_setting is not None:
            setup.attrs.update(operating_point_attrs({"motor_setting": motor_setting},
                                                     "stated by the operator (--motor-setting)"))
    else:
        if faults:
            raise InputError("--fault works with --device sim only")
        if not realtime:
            raise InputError("--fast works with --device sim only: a DAQ board runs at its own pace")
        setup = _nidaqmx_setup(arg, device_file, ni, iepe_excitation, opts, given, meta, motor_setting)
    dev, attrs = setup.device, setup.attrs
    if command is not None:
        attrs["command"] = command
    _check_size(dur, rate, len(dev.channel_names), realtime or kind == "nidaqmx", yes, confirm)
    if replacing and warn is not None:
        warn(f"recording over {shown(output)}, {replacing}")
    duration = None if math.isinf(dur) else dur
    display = monitor(dev, setup.ka_m_s2_per_v, duration) if monitor is not None else None
    try:  # session.run turns Ctrl-C and SIGTERM into a clean stop between blocks
        res = session.run(dev, output, rate, duration, attrs=attrs, ka_m_s2_per_v=setup.ka_m_s2_per_v,
                          progress=display.progress if display else None,
                          on_block=display.on_block if display else None, replace=force or bool(replacing))
        if display is not None:
            display.progress(None, res.wall_s, final=True)
    finally:
        if display is not None:
            display.stop()
    # the simulated stand states its whole operating point; a real stand only what the operator said
    unstated = [] if dev.metadata.get("device") == "sim" else missing_operating_point(attrs)
    out = Acquisition(output, res.n_samples, len(dev.channel_names), res.rate_hz, res.wall_s, res.overruns, res.gaps,
                      tuple(res.clipped), res.outcome, res.message, res.complete, res.signum, duration, unstated)
    if check:
        out.check()
    return out


def load_scene(path: Path) -> dict:
    """Option values from a scene file's [stand] table (keys in SCENE_KEYS), and under "_truth"
    the StandScene arguments of its optional [truth] table (labtool.acquisition.signal_chain.TRUTH_TABLE_KEYS);
    InputError if bad (labtool.common.schema: types, bounds, unknown keys named)."""
    doc = SCENE_SCHEMA.check(load_toml(path, "scene file"), where=f"scene file {path}")
    out = {SCENE_KEYS[k]: v for k, v in doc["stand"].items()}
    table = doc.get("truth")
    if table is not None:
        from labtool.acquisition.signal_chain import truth_settings
        settings = truth_settings(table, f"scene file {path}")
        if "truth_model" in settings:
            out["truth"] = settings.pop("truth_model")
        out["_truth"] = settings
    return out


def _check_run(dur: float, rate: float, opts: dict, kind: str, realtime: bool) -> None:
    """InputError for a duration [s], rate [Hz] or Ka [m/s^2/V] the recording could not hold."""
    if not (dur > 0):
        raise InputError(f"--duration must be > 0 s (or inf), got {dur:g}")
    if math.isinf(dur) and not (realtime or kind == "nidaqmx"):
        raise InputError("--duration inf needs --realtime (a --fast run would never end)")
    if not (math.isfinite(rate) and rate > 0):
        raise InputError(f"--rate must be a positive number of Hz, got {opts['rate']}")
    _check_sample_count(dur, rate)
    _check_sampled(dur, rate, kind == "sim" and str(opts["mode"]) == "calibration", float(opts["cal_freq"]))
    if opts["ka"] is not None:   # --ka 1e308 was stored, and processing used it
        if not (math.isfinite(float(opts["ka"])) and KA_MIN < float(opts["ka"]) < KA_MAX):
            raise InputError(f"--ka must lie between {KA_MIN:g} and {KA_MAX:g} m/s^2/V (as in a calibration file), "
                             f"got {float(opts['ka']):g}")


def _check_output(output: Path, force: bool) -> str | None:
    """Refuse an output another process is recording (--force does not help there), or an existing
    file without --force unless a rerun may record over it: an unfinished recording (an interrupted
    or killed run of this command; labtool.acquisition.recorder.unfinished). Returns what is
    recorded over without --force (None: nothing)."""
    from labtool.acquisition.recorder import unfinished
    from labtool.acquisition.writer_lock import RecordingBusy, busy_message, is_being_written

    if is_being_written(output):
        raise RecordingBusy(busy_message(output))
    replacing = None if force else unfinished(output)
    check_output_path(output, force or replacing is not None)
    return replacing


def _nidaqmx_setup(arg, device_file, ni, iepe_excitation, opts, given, meta_given, motor_setting):
    """The NI device (configuration checked, nothing touched yet), per-channel Ka and the attributes:
    the operating point as the operator stated it (each value with its source), the run metadata
    (device file's [metadata], then the options), and where each channel's Ka comes from."""
    from labtool.acquisition.devices import DeviceSetup, nidaqmx_device

    dev, cfg, nominal_ka = nidaqmx_device(arg, device_file, ni, iepe_excitation,
                                          f"device file {device_file}" if device_file is not None else "command line")
    meta = {k: v for k, v in cfg.metadata.items()}
    meta.update({k: v for k, v in meta_given.items() if v is not None})
    attrs = run_metadata_attrs(meta)
    stated = {FIELD[name].attr: opt for opt, name in POINT_OPTIONS.items()}    # file attribute: option key
    op = {name: opts[key] for name, key in stated.items() if key in given}
    if motor_setting is not None:
        op["motor_setting"] = motor_setting
    attrs.update(operating_point_attrs(op, {n: f"stated by the operator ({OPTION[n]})" for n in op}))
    ka_ch, sources = [], []
    for ch, nominal in zip(cfg.channels, nominal_ka):
        if ch.kind != "accel":
            ka_ch.append(float("nan"))
            sources.append("none (not an accelerometer)")
        elif opts["ka"] is not None:
            ka_ch.append(float(opts["ka"]))
            sources.append("--ka option")
        elif math.isfinite(nominal):
            ka_ch.append(nominal)
            sources.append(f"nominal: {ch.sensitivity_mv_per_g:g} mV/g x gain {ch.conditioner_gain:g} (calibrate to measure it)")
        else:
            ka_ch.append(float("nan"))
            sources.append("none (calibrate, or give --ka or the sensitivity)")
    attrs["ka_source"] = "; ".join(f"{n}: {s}" for n, s in zip(cfg.names, sources))
    return DeviceSetup(dev, ka_ch, attrs)


def _check_sample_count(duration_s: float, rate_hz: float) -> None:
    """InputError when a finite --duration (s) at --rate (Hz) asks for more than MAX_SAMPLES
    samples: --duration 1e308 overflowed the device's sample count (OverflowError, exit 70)."""
    if math.isfinite(duration_s) and duration_s * rate_hz > MAX_SAMPLES:
        raise InputError(f"--duration {duration_s:g} s at {rate_hz:g} Hz is more samples than the {MAX_SAMPLES:g} "
                         f"a recording can hold; give at most {MAX_SAMPLES / rate_hz:g} s, "
                         "or --duration inf --realtime to record until Ctrl-C")


def _check_size(duration_s: float, rate_hz: float, n_channels: int, paced: bool, yes: bool, confirm) -> None:
    """Ask before a recording of more than 10 min of the stand (paced: real time) or 100 MB
    (float32 samples), through ``confirm``; refuse it without one unless ``yes``
    (labtool.common.budget.check_work): a --duration of 2000 meant as ms is 240 MB at 10 kHz."""
    if not math.isfinite(duration_s):            # until Ctrl-C: the user stops it
        return
    from labtool.common import budget

    samples = duration_s * rate_hz
    budget.check_work(f"--duration {duration_s:g} s at {rate_hz:g} Hz", duration_s if paced else 0.0,
                      samples * n_channels * 4, f"{samples:.4g} samples x {n_channels} channels x 4 bytes"
                      + (", in real time" if paced else ""), confirm, yes,
                      "give a shorter --duration (in seconds)")


def _check_sampled(duration_s: float, rate_hz: float, shaker: bool, cal_freq_hz: float) -> None:
    """InputError when the recording could not hold what it asks: --duration under one sample
    (1e-9 s wrote a recording of 0 samples marked complete, exit 0), or the calibration shaker's
    sine at or past half --rate (6000 Hz at 10 kHz recorded its 4000 Hz alias, exit 0)."""
    if math.isfinite(duration_s) and duration_s * rate_hz < 1.0:
        raise InputError(f"--duration {duration_s:g} s at {rate_hz:g} Hz is less than one sample; "
                         f"give at least {1.0 / rate_hz:g} s")
    if shaker and not cal_freq_hz < 0.5 * rate_hz:
        raise InputError(f"--cal-freq {cal_freq_hz:g} Hz is not below half the sample rate ({0.5 * rate_hz:g} Hz): "
                         "the recording would hold its alias; lower --cal-freq or raise --rate")
