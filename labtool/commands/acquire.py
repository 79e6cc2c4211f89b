"""``labtool acquire``: record the stand (simulated or NI-DAQmx) into a v1 recording (HDF5)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import List, Optional

import typer

from labtool.acquisition.metadata import OPTION, missing_operating_point, operating_point_attrs, run_metadata_attrs
from labtool.common.errors import InputError
from labtool.common.files import check_output_path
from labtool.common.invocation import command_line
from labtool.common.names import shown
from labtool.common.operating_point import FIELD, schema_field
from labtool.common.schema import Integer, Number, String, Table, load_toml
from labtool.options import op_option
from labtool.processing.calibration_file import KA_MAX, KA_MIN

# keys a scene file's [stand] table may hold -> option name
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


def register(app: typer.Typer) -> None:
    app.command("acquire")(acquire)


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


def acquire(
    output: Path = typer.Option(..., "-o", "--output", help="recording to write (HDF5, format v1)"),
    device: Optional[str] = typer.Option(None, help="sim | nidaqmx:<physical channels> (e.g. nidaqmx:Dev1/ai0:2), "
                                         "or nidaqmx with --device-file (default: sim)"),
    rpm: Optional[float] = op_option("cam_speed", "sim: the stand's; nidaqmx: stored as stated"),
    duration: Optional[float] = typer.Option(None, help="seconds to record; inf = until Ctrl-C (default 10)"),
    rate: Optional[float] = typer.Option(None, help="sample rate (Hz) (default 10000)"),
    realtime: bool = typer.Option(True, "--realtime/--fast", help="pace the simulated stand in real time, or run as fast as possible"),
    seed: Optional[int] = typer.Option(None, help="noise seed of the simulated stand (default 0)"),
    law: Optional[str] = op_option("law", "sim: the stand's; nidaqmx: stored as stated"),
    fu: Optional[float] = op_option("Fu", "sim: the stand's; nidaqmx: stored as stated"),
    backlash_mm: Optional[float] = op_option("backlash", "sim: the stand's; nidaqmx: stored as stated"),
    jt_factor: Optional[float] = op_option("jt_factor", "sim: the stand's; nidaqmx: stored as stated"),
    ripple: Optional[float] = typer.Option(None, help="motor speed ripple on omega1, relative (sim) (default 0.005)"),
    ka: Optional[float] = typer.Option(None, help="Ka (m/s^2/V): the simulated chain's, or the calibration to store for nidaqmx "
                                       "(default 864.3 sim = the 480C02 at gain x1; 86.43 = gain x10, the impacts clip; none nidaqmx)"),
    mode: Optional[str] = typer.Option(None, help="sim: run (cam drives the follower) | calibration (shaker sine) (default run)"),
    cal_freq: Optional[float] = typer.Option(None, help="calibration mode: shaker frequency (Hz) (default 79.6)"),
    cal_accel: Optional[float] = typer.Option(None, help="calibration mode: shaker amplitude (m/s^2 peak) (default 9.81)"),
    cal_channel: Optional[str] = typer.Option(None, help="calibration mode: channel on the shaker (default aE_t)"),
    truth: Optional[str] = typer.Option(None, help="sim: what moves the follower: twin (the stand's model richer than "
                                        "both models, default; docs/twin.md), kinematic (cam as input), or the rigid / "
                                        "elastic model's own equations (their periodic steady state)"),
    restitution: Optional[float] = op_option("restitution", "sim: the rigid truth's impacts"),
    contact_damping: Optional[float] = op_option("contact_damping", "sim: the twin's and the elastic truth's contact"),
    scene: Optional[Path] = typer.Option(None, help="TOML scene file with a (stand) table; options given here override it"),
    fault: Optional[List[str]] = typer.Option(None, help="sim fault injection kind@seconds (overrun, drop, disconnect, clip); repeatable"),
    iepe_excitation: bool = typer.Option(False, help="nidaqmx: the DAQ powers the IEPE sensors with 4 mA (no 480C02)"),
    device_file: Optional[Path] = typer.Option(None, help="nidaqmx: TOML device file (channels by role, range [V], "
                                               "terminal, coupling, IEPE [A], sensitivity [mV/g] or TEDS, clock, "
                                               "trigger); see docs/acquisition.md"),
    ni: Optional[List[str]] = typer.Option(None, "--ni", help="nidaqmx setting CHANNEL.KEY=VALUE, trigger.KEY=VALUE or "
                                           "device.KEY=VALUE, over the device file (e.g. --ni aE_t.range_v=5 "
                                           "--ni trigger.type=digital); repeatable"),
    test_id: Optional[str] = typer.Option(None, help="test ID stored in the recording"),
    operator: Optional[str] = typer.Option(None, help="operator's name stored in the recording"),
    sensor_model: Optional[str] = typer.Option(None, help="accelerometer model (e.g. PCB 352A76)"),
    sensor_serial: Optional[str] = typer.Option(None, help="accelerometer serial number(s)"),
    conditioner_gain: Optional[float] = typer.Option(None, help="signal conditioner gain [-] (480C02: 1, 10 or 100)"),
    motor_setting: Optional[str] = typer.Option(None, help="motor / variator setting as stated by the operator"),
    notes: Optional[str] = typer.Option(None, help="free-text notes stored in the recording"),
    status_every: float = typer.Option(5.0, help="not on a terminal: one status line every this many seconds "
                                       "[s] (0 = none)"),
    force: bool = typer.Option(False, help="overwrite an existing output file (never one being recorded)"),
    yes: bool = typer.Option(False, "--yes", "-y", help="record more than 10 min [s of the stand] or 100 MB without "
                             "asking (off a terminal such a recording is refused without it)"),
) -> None:
    """Record aE_t, aE_n (volts) and the tacho from the stand into recording format v1 (docs/architecture.md)."""
    from labtool.acquisition.device import parse_device

    given = {k: v for k, v in dict(rpm=rpm, duration=duration, rate=rate, seed=seed, law=law, fu=fu,
                                     backlash_mm=backlash_mm, jt_factor=jt_factor, ripple=ripple, ka=ka, mode=mode,
                                     cal_freq=cal_freq, cal_accel=cal_accel, cal_channel=cal_channel,
                                     truth=truth).items()
             if v is not None}
    opts = dict(DEFAULTS)
    opts["_truth"] = {}
    if scene is not None:
        opts.update(load_scene(scene))
    opts.update(given)
    for name, value in (("restitution", restitution), ("contact_damping", contact_damping)):
        if value is not None:
            opts["_truth"] = {**opts["_truth"], name: float(value)}
    if "ripple" in given or (scene is not None and "ripple" in load_scene(scene)):
        opts["_ripple_given"] = True
    if device is None:
        device = "nidaqmx" if device_file is not None else "sim"
    kind, arg = ("nidaqmx", "") if device.strip() == "nidaqmx" and device_file is not None else parse_device(device)
    if kind == "nidaqmx" and "ka" not in given and (scene is None or "ka" not in load_scene(scene)):
        opts["ka"] = None
    dur = float(opts["duration"])
    if not (dur > 0):
        raise InputError(f"--duration must be > 0 s (or inf), got {dur:g}")
    if math.isinf(dur) and not (realtime or kind == "nidaqmx"):
        raise InputError("--duration inf needs --realtime (a --fast run would never end)")
    if not (math.isfinite(float(opts["rate"])) and float(opts["rate"]) > 0):
        raise InputError(f"--rate must be a positive number of Hz, got {opts['rate']}")
    _check_sample_count(dur, float(opts["rate"]))
    _check_sampled(dur, float(opts["rate"]), kind == "sim" and str(opts["mode"]) == "calibration",
                   float(opts["cal_freq"]))
    if opts["ka"] is not None:   # --ka 1e308 was stored, and processing used it
        if not (math.isfinite(float(opts["ka"])) and KA_MIN < float(opts["ka"]) < KA_MAX):
            raise InputError(f"--ka must lie between {KA_MIN:g} and {KA_MAX:g} m/s^2/V (as in a calibration file), "
                             f"got {float(opts['ka']):g}")
    if output.is_dir():
        raise InputError(f"{output} is a folder; give a file name for the recording")
    replacing = _check_output(output, force)
    if not (math.isfinite(status_every) and status_every >= 0):
        raise InputError(f"--status-every must be >= 0 s, got {status_every:g}")
    meta_given = dict(test_id=test_id, operator=operator, sensor_model=sensor_model, sensor_serial=sensor_serial,
                      conditioner_gain=conditioner_gain, notes=notes)

    dev, ka_ch, attrs = _device(kind, arg, opts, given, realtime, fault or [], dur, device_file, ni or [],
                                iepe_excitation, meta_given, motor_setting)
    attrs["command"] = command_line("labtool acquire")
    _check_size(dur, float(opts["rate"]), len(dev.channel_names), realtime or kind == "nidaqmx", yes)
    if replacing:
        typer.echo(f"labtool: warning: recording over {shown(output)}, {replacing}", err=True)
    _run(dev, output, float(opts["rate"]), None if math.isinf(dur) else dur, attrs, ka_ch, force or bool(replacing),
         status_every)


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


def _device(kind, arg, opts, given, realtime, faults, dur, device_file, ni, iepe_excitation, meta_given,
            motor_setting):
    """The device, its per-channel Ka and the recording's attributes (operating point, metadata)."""
    if kind == "sim":
        if device_file is not None or ni:
            raise InputError("--device-file and --ni configure NI-DAQmx devices; use them with --device nidaqmx")
        dev, ka_ch, attrs = _sim_device(opts, realtime, faults, dur)
        attrs.update(run_metadata_attrs(meta_given))
        if motor_setting is not None:
            attrs.update(operating_point_attrs({"motor_setting": motor_setting}, "stated by the operator (--motor-setting)"))
        return dev, ka_ch, attrs
    if faults:
        raise InputError("--fault works with --device sim only")
    if not realtime:
        raise InputError("--fast works with --device sim only: a DAQ board runs at its own pace")
    return _nidaqmx_device(arg, device_file, ni, iepe_excitation, opts, given, meta_given, motor_setting)


def _nidaqmx_device(arg, device_file, ni, iepe_excitation, opts, given, meta_given, motor_setting):
    """The NI device (configuration checked, nothing touched yet), per-channel Ka and the attributes:
    the operating point as the operator stated it (each value with its source), the run metadata
    (device file's [metadata], then the options), and where each channel's Ka comes from."""
    from labtool.acquisition import nidaqmx_config as nc
    from labtool.acquisition.nidaqmx_driver import NIDAQmxDevice, expand_channels
    from labtool.acquisition.trigger import SoftwareTrigger

    doc = nc.load_device_file(device_file) if device_file is not None else None
    cfg = nc.build(expand_channels(arg) if arg else None, doc, overrides=ni,
                   source=f"device file {device_file}" if device_file is not None else "command line",
                   iepe_excitation_a=0.004 if iepe_excitation else None)
    meta = {k: v for k, v in cfg.metadata.items()}
    meta.update({k: v for k, v in meta_given.items() if v is not None})
    attrs = run_metadata_attrs(meta)
    stated = {"law": "law", "cam_speed_rpm": "rpm", "Fu_N": "fu", "backlash_mm": "backlash_mm", "jt_factor": "jt_factor"}
    op = {name: opts[key] for name, key in stated.items() if key in given}
    if motor_setting is not None:
        op["motor_setting"] = motor_setting
    attrs.update(operating_point_attrs(op, {n: f"stated by the operator ({OPTION[n]})" for n in op}))
    dev = NIDAQmxDevice(cfg)
    ka_ch, sources = [], []
    for ch, nominal in zip(cfg.channels, dev.ka_nominal):
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
    if cfg.trigger.software:
        dev = SoftwareTrigger(dev, cfg.names.index(nc.trigger_channel(cfg).name), cfg.trigger.level_v,
                              cfg.trigger.edge, cfg.trigger.pretrigger_samples)
    return dev, ka_ch, attrs


def _sim_device(opts, realtime, faults, dur):
    from labtool.acquisition import signal_chain as sc
    from labtool.acquisition.sim_stand import SimStand, parse_fault

    model = str(opts["truth"])
    if model in sc.MODEL_TRUTHS and opts.get("_ripple_given") is None:
        opts["ripple"] = 0.0  # the model's cam runs at constant speed
    point = {name: FIELD[name].check_edge(opts[opt]) for opt, name in POINT_OPTIONS.items()}
    scene = sc.StandScene(truth_model=model, mode=str(opts["mode"]), **point, ripple=float(opts["ripple"]),
                          cal_accel=float(opts["cal_accel"]), cal_freq=float(opts["cal_freq"]),
                          cal_channel=str(opts["cal_channel"]), **opts["_truth"])
    if model in sc.MODEL_TRUTHS and scene.mode == "run":
        scene = _model_truth_for(scene, dur)
    k = float(opts["ka"])
    params = sc.ChainParams(ka_m_s2_per_v=(k, k), resonance_hz=scene.twin.mode_hz, resonance_zeta=scene.twin.mode_zeta)
    dev = SimStand(scene, params, seed=int(opts["seed"]), duration_s=None if math.isinf(dur) else dur,
                   realtime=realtime, faults=[parse_fault(f) for f in faults])
    attrs = {"ka_source": "simulated chain (true value)", "ka_m_s2_per_v": k,
             "pacing": "realtime" if realtime else "fast"}
    if scene.mode == "run":
        attrs["cam_speed_rpm"] = float(scene.cam_speed_rpm)
    return dev, [k, k, float("nan")], attrs


def _model_truth_for(scene, dur):
    """The rigid/elastic truth scene that covers ``dur`` s: its periodic steady state, or (not
    periodic) a run over the whole duration up to MAX_MODEL_REVOLUTIONS turns; InputError else."""
    import dataclasses

    from labtool.acquisition import signal_chain as sc

    if sc.model_truth_span(scene) >= dur:
        return scene
    needed = int(math.ceil((dur + 0.2) * scene.cam_speed_rpm / 60.0)) + 1 if math.isfinite(dur) else math.inf
    if scene.truth_revolutions == 0 and needed <= sc.MAX_MODEL_REVOLUTIONS:
        longer = dataclasses.replace(scene, truth_revolutions=needed)
        if sc.model_truth_span(longer) >= dur:
            return longer
    raise InputError(f"the {scene.truth_model} truth does not reach a periodic steady state in {scene.model_revolutions} "
                     f"cam turns (restitution {scene.restitution:g}, contact damping {scene.contact_damping:g} s/m), "
                     f"so it cannot be repeated over {dur:g} s: give energy loss (--restitution < 1, --contact-damping > 0) "
                     f"or a --duration of at most {sc.MAX_MODEL_REVOLUTIONS} turns")


MAX_SAMPLES = 1e15    # per channel: 3000 years at 10 kHz, and an exact integer in a float


def _check_sample_count(duration_s: float, rate_hz: float) -> None:
    """InputError when a finite --duration (s) at --rate (Hz) asks for more than MAX_SAMPLES
    samples: --duration 1e308 overflowed the device's sample count (OverflowError, exit 70)."""
    if math.isfinite(duration_s) and duration_s * rate_hz > MAX_SAMPLES:
        raise InputError(f"--duration {duration_s:g} s at {rate_hz:g} Hz is more samples than the {MAX_SAMPLES:g} "
                         f"a recording can hold; give at most {MAX_SAMPLES / rate_hz:g} s, "
                         "or --duration inf --realtime to record until Ctrl-C")


def _check_size(duration_s: float, rate_hz: float, n_channels: int, paced: bool, yes: bool) -> None:
    """Ask before a recording of more than 10 min of the stand (paced: real time) or 100 MB
    (float32 samples), on a terminal; refuse it elsewhere unless --yes (labtool.common.budget.check_work):
    a --duration of 2000 meant as ms is 240 MB at 10 kHz."""
    if not math.isfinite(duration_s):            # until Ctrl-C: the user stops it
        return
    from labtool.common import budget
    from labtool.output import terminal_confirm

    samples = duration_s * rate_hz
    budget.check_work(f"--duration {duration_s:g} s at {rate_hz:g} Hz", duration_s if paced else 0.0,
                      samples * n_channels * 4, f"{samples:.4g} samples x {n_channels} channels x 4 bytes"
                      + (", in real time" if paced else ""), terminal_confirm(), yes,
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


def _run(dev, output: Path, rate: float, duration, attrs, ka_ch, force: bool, status_every: float = 5.0):
    from labtool.output import console

    from labtool.acquisition import session

    con = console(stderr=True)
    display = _Display(con, dev, duration, ka_ch, status_every)
    try:  # session.run turns Ctrl-C and SIGTERM into a clean stop between blocks
        result = session.run(dev, output, rate, duration, attrs=attrs, ka_m_s2_per_v=ka_ch, progress=display.progress,
                             on_block=display.on_block, replace=force)
        display.progress(None, result.wall_s, final=True)
    finally:
        display.stop()
    rt = (result.n_samples / result.rate_hz) / result.wall_s if result.wall_s > 0 else float("inf")
    typer.echo(f"wrote {output}: {result.n_samples} samples x {len(dev.channel_names)} channels at "
               f"{result.rate_hz:g} Hz ({result.n_samples / result.rate_hz:.3f} s, {rt:.1f}x real time), "
               f"{result.overruns} overruns, {result.gaps} gaps, complete={str(result.complete).lower()}")
    # the simulated stand states its whole operating point; a real stand only what the operator said
    missing = [] if dev.metadata.get("device") == "sim" else missing_operating_point(attrs)
    if missing:
        typer.echo(f"labtool: warning: operating point not stated: {', '.join(missing)} "
                   f"({', '.join(OPTION[m] for m in missing)}); a report will assume the paper's experiment for "
                   "them and say so", err=True)
    if display.headroom_warning:
        typer.echo(f"labtool: warning: {display.headroom_warning}", err=True)
    if result.clipped:
        typer.echo(f"labtool: warning: clipping on {', '.join(result.clipped)} (ADC range exceeded); "
                   "see the 'clip' events", err=True)
    if result.outcome in ("disconnected", "disk_full", "write_error"):
        raise InputError(f"{result.message}; {result.n_samples} samples ({result.n_samples / result.rate_hz:.3f} s) "
                         f"kept in {output}, complete={str(result.complete).lower()}")
    if result.signum is not None:        # Ctrl-C, SIGTERM, SIGHUP: exit 128 + signal (labtool.cli)
        from labtool.common.errors import interruption

        secs = result.n_samples / result.rate_hz
        if result.complete:
            note = f"{shown(output)} is closed and complete ({result.n_samples} samples, {secs:.3f} s)"
        else:
            of = f" of {duration:g}" if duration is not None else ""
            note = (f"{shown(output)} keeps its {result.n_samples} samples ({secs:.3f}{of} s), closed and marked "
                    "incomplete; the same command records it again")
        raise interruption(result.signum, note)


class _Display:
    """The live monitor (labtool.acquisition.monitor figures, labtool.monitor_view layout): a rich Live panel
    on a terminal (4 updates/s), else one status line on stderr every ``status_every`` s of wall time."""

    def __init__(self, con, dev, duration, ka_ch, status_every: float):
        self.con, self.dev, self.duration, self.ka = con, dev, duration, ka_ch
        self.status_every = status_every
        self.monitor = None
        self.live = None
        self.last = 0.0
        self.rec = None
        self.headroom_warning = ""
        self.off = False

    def on_block(self, block) -> None:
        if self.off:
            return
        try:
            self._feed(block)
        except Exception as exc:  # the display must never stop a recording
            self._switch_off(exc)

    def _feed(self, block) -> None:
        if self.monitor is None:
            from labtool.acquisition.monitor import Monitor
            self.monitor = Monitor(self.dev.channel_names, self.dev.actual_rate_hz, self.ka, self.dev.input_range_v,
                                   self.duration)
            if self.con.is_terminal:
                from rich.live import Live
                self.live = Live(console=self.con, refresh_per_second=4, transient=False)
                self.live.start()
        self.monitor.update(block)

    def progress(self, rec, elapsed: float, final: bool = False) -> None:
        if rec is not None:
            self.rec = rec
        if self.off or self.monitor is None or self.rec is None:
            return
        try:
            self._show(elapsed, final)
        except Exception as exc:  # the display must never stop a recording
            self._switch_off(exc)

    def _switch_off(self, exc) -> None:
        self.stop()
        self.off = True
        typer.echo(f"labtool: warning: live monitor off ({type(exc).__name__}: {' '.join(str(exc).split())[:200]}); "
                   "the recording goes on", err=True)

    def _show(self, elapsed: float, final: bool) -> None:
        every = 0.25 if self.live is not None else self.status_every
        if not final and (every <= 0 or elapsed - self.last < every):
            return
        self.last = elapsed
        r = self.rec
        snap = self.monitor.snapshot(elapsed, r.overruns, r.gaps, r.samples_lost, r.clipped, self.dev.buffer_fill(),
                                     rows=r.n_samples)
        from labtool import monitor_view as view
        if self.live is not None:
            self.live.update(view.render(snap, self.dev.describe(), width=self.con.width))
        elif self.status_every > 0:
            self.con.print(view.status_line(snap), markup=False, highlight=False, soft_wrap=True)
        if final:
            low = [f"{c.name} {100 * c.fraction:.0f} % of +-{c.range_v:g} V" for c in snap.channels
                   if c.state == "warn" and c.name != "tacho"]
            if low:
                self.headroom_warning = (f"little headroom: peak {', '.join(low)} (> 80 %); a larger range or a "
                                         "lower conditioner gain would keep impacts from clipping")

    def stop(self) -> None:
        if self.live is not None:
            live, self.live = self.live, None
            live.stop()
