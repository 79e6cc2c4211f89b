"""``labtool acquire``: record the stand (simulated or NI-DAQmx) into a v1 recording (HDF5)."""
from __future__ import annotations

import math
import sys
import tomllib
from pathlib import Path
from typing import List, Optional

import typer

from common.files import check_output_path
from common.errors import InputError

# keys a scene file's [stand] table may hold -> option name
SCENE_KEYS = {
    "mode": "mode", "law": "law", "cam_speed_rpm": "rpm", "Fu_N": "fu", "backlash_mm": "backlash_mm",
    "jt_factor": "jt_factor", "ripple": "ripple", "cal_accel_m_s2": "cal_accel", "cal_freq_hz": "cal_freq",
    "cal_channel": "cal_channel", "seed": "seed", "duration_s": "duration", "rate_hz": "rate",
    "ka_m_s2_per_v": "ka", "truth_model": "truth",
}
DEFAULTS = {"mode": "run", "law": "sine", "rpm": 180.0, "fu": 0.0, "backlash_mm": 0.128, "jt_factor": 1.0,
            "ripple": 0.005, "cal_accel": 9.81, "cal_freq": 79.6, "cal_channel": "aE_t", "seed": 0,
            "duration": 10.0, "rate": 10000.0, "ka": 864.3,
            "truth": "twin"}


def register(app: typer.Typer) -> None:
    app.command("acquire")(acquire)


def load_scene(path: Path) -> dict:
    """Option values from a scene file's [stand] table (keys in SCENE_KEYS), and under "_truth"
    the StandScene arguments of its optional [truth] table (acquisition.signal_chain.TRUTH_TABLE_KEYS);
    InputError if bad."""
    try:
        doc = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"scene file {path} does not exist") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"scene file {path} is not valid TOML: {exc}") from None
    stand = doc.get("stand")
    if not isinstance(stand, dict):
        raise InputError(f"scene file {path} has no [stand] table")
    unknown = set(stand) - set(SCENE_KEYS)
    if unknown:
        raise InputError(f"scene file {path}: unknown keys {', '.join(sorted(unknown))}; known: {', '.join(SCENE_KEYS)}")
    out = {SCENE_KEYS[k]: v for k, v in stand.items()}
    table = doc.get("truth")
    if table is not None:
        from acquisition.signal_chain import truth_settings
        if not isinstance(table, dict):
            raise InputError(f"scene file {path}: [truth] must be a table")
        settings = truth_settings(table, f"scene file {path}")
        if "truth_model" in settings:
            out["truth"] = settings.pop("truth_model")
        out["_truth"] = settings
    return out


def acquire(
    output: Path = typer.Option(..., "-o", "--output", help="recording to write (HDF5, format v1)"),
    device: str = typer.Option("sim", help="sim | nidaqmx:<physical channels> (e.g. nidaqmx:Dev1/ai0:2)"),
    rpm: Optional[float] = typer.Option(None, help="cam speed n1 (rpm) (sim) (default 180)"),
    duration: Optional[float] = typer.Option(None, help="seconds to record; inf = until Ctrl-C (default 10)"),
    rate: Optional[float] = typer.Option(None, help="sample rate (Hz) (default 10000)"),
    realtime: bool = typer.Option(True, "--realtime/--fast", help="pace the simulated stand in real time, or run as fast as possible"),
    seed: Optional[int] = typer.Option(None, help="noise seed of the simulated stand (default 0)"),
    law: Optional[str] = typer.Option(None, help="motion law of the simulated cam (default sine)"),
    fu: Optional[float] = typer.Option(None, "--fu", help="load Fu (N) (sim, stored) (default 0)"),
    backlash_mm: Optional[float] = typer.Option(None, help="groove backlash j (mm) (sim, stored) (default 0.128)"),
    jt_factor: Optional[float] = typer.Option(None, help="inertia factor Jt (sim, stored) (default 1)"),
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
    restitution: Optional[float] = typer.Option(None, help="sim, rigid truth: Newton's restitution k of the impacts (default 0.2)"),
    contact_damping: Optional[float] = typer.Option(None, help="sim, twin and elastic truths: Hunt-Crossley contact damping (s/m) (default 40)"),
    scene: Optional[Path] = typer.Option(None, help="TOML scene file with a (stand) table; options given here override it"),
    fault: Optional[List[str]] = typer.Option(None, help="sim fault injection kind@seconds (overrun, drop, disconnect, clip); repeatable"),
    iepe_excitation: bool = typer.Option(False, help="nidaqmx: the DAQ powers the IEPE sensor (no 480C02)"),
    force: bool = typer.Option(False, help="overwrite an existing output file"),
) -> None:
    """Record aE_t, aE_n (volts) and the tacho from the stand into DESIGN.md's recording format v1."""
    from acquisition.device import parse_device

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
    kind, arg = parse_device(device)
    if kind == "nidaqmx" and "ka" not in given and (scene is None or "ka" not in load_scene(scene)):
        opts["ka"] = None
    dur = float(opts["duration"])
    if not (dur > 0):
        raise InputError(f"--duration must be > 0 s (or inf), got {dur:g}")
    if math.isinf(dur) and not (realtime or kind == "nidaqmx"):
        raise InputError("--duration inf needs --realtime (a --fast run would never end)")
    if not (math.isfinite(float(opts["rate"])) and float(opts["rate"]) > 0):
        raise InputError(f"--rate must be a positive number of Hz, got {opts['rate']}")
    if output.is_dir():
        raise InputError(f"{output} is a folder; give a file name for the recording")
    check_output_path(output, force)

    if kind == "sim":
        dev, ka_ch, attrs = _sim_device(opts, realtime, fault or [], dur)
    else:
        if fault:
            raise InputError("--fault works with --device sim only")
        if not realtime:
            raise InputError("--fast works with --device sim only: a DAQ board runs at its own pace")
        from acquisition.nidaqmx_driver import NIDAQmxDevice
        dev = NIDAQmxDevice(arg, iepe_excitation=iepe_excitation)
        k = float("nan") if opts["ka"] is None else float(opts["ka"])
        ka_ch = [k if n in ("aE_t", "aE_n") else float("nan") for n in dev.channel_names]
        attrs = {"ka_source": "none" if opts["ka"] is None else "--ka option"}
        if rpm is not None:
            attrs["cam_speed_rpm"] = float(rpm)
    attrs["command"] = "labtool acquire " + " ".join(sys.argv[2:]) if sys.argv[1:2] == ["acquire"] else "labtool acquire"
    _run(dev, output, float(opts["rate"]), None if math.isinf(dur) else dur, attrs, ka_ch)


def _sim_device(opts, realtime, faults, dur):
    from acquisition import signal_chain as sc
    from acquisition.sim_stand import SimStand, parse_fault

    model = str(opts["truth"])
    if model in sc.MODEL_TRUTHS and opts.get("_ripple_given") is None:
        opts["ripple"] = 0.0  # the model's cam runs at constant speed
    scene = sc.StandScene(truth_model=model, mode=str(opts["mode"]), law=str(opts["law"]), cam_speed_rpm=float(opts["rpm"]),
                          Fu=float(opts["fu"]), backlash=float(opts["backlash_mm"]) * 1e-3,
                          jt_factor=float(opts["jt_factor"]), ripple=float(opts["ripple"]),
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

    from acquisition import signal_chain as sc

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


def _run(dev, output: Path, rate: float, duration, attrs, ka_ch):
    from labtool.output import console

    from acquisition import session

    console = console(stderr=True)
    live = None
    progress = None
    if console.is_terminal:
        live, progress = _live_display(console, dev, duration)
    try:  # session.run turns Ctrl-C and SIGTERM into a clean stop between blocks
        if live is not None:
            live.start()
        result = session.run(dev, output, rate, duration, attrs=attrs, ka_m_s2_per_v=ka_ch, progress=progress)
        if live is not None:
            progress.finish(result.wall_s)
    finally:
        if live is not None:
            live.stop()
    rt = (result.n_samples / result.rate_hz) / result.wall_s if result.wall_s > 0 else float("inf")
    typer.echo(f"wrote {output}: {result.n_samples} samples x {len(dev.channel_names)} channels at "
               f"{result.rate_hz:g} Hz ({result.n_samples / result.rate_hz:.3f} s, {rt:.1f}x real time), "
               f"{result.overruns} overruns, {result.gaps} gaps, complete={str(result.complete).lower()}")
    if result.clipped:
        typer.echo(f"labtool: warning: clipping on {', '.join(result.clipped)} (ADC range exceeded); "
                   "see the 'clip' events", err=True)
    if result.outcome == "interrupted":
        typer.echo(f"labtool: {result.message}; the recording is closed and complete", err=True)
    if result.outcome in ("disconnected", "disk_full", "write_error"):
        raise InputError(f"{result.message}; {result.n_samples} samples kept in {output}")


def _live_display(console, dev, duration):
    """A rich Live panel (elapsed, samples, rate, overruns, peak per channel, clipping) and its updater."""
    from rich.live import Live
    from rich.table import Table

    state = {"last": -1.0}
    names = dev.channel_names

    def render(rec=None, elapsed=0.0):
        t = Table(title=dev.describe(), show_header=False, expand=False)
        t.add_column("what")
        t.add_column("value", justify="right")
        n = rec.n_samples if rec else 0
        rate = rec.rate_hz if rec else float("nan")
        t.add_row("elapsed", f"{elapsed:7.1f} s" + (f" / {duration:g} s of data" if duration else ""))
        t.add_row("samples", f"{n} ({n / rate if rec else 0:.1f} s of data)")
        t.add_row("rate", f"{rate:g} Hz device, {n / elapsed if elapsed > 0 else 0:,.0f} samples/s written")
        t.add_row("overruns / gaps", f"{rec.overruns if rec else 0} / {rec.gaps if rec else 0}")
        for i, name in enumerate(names):
            peak = rec.peak_v[i] if rec else 0.0
            t.add_row(f"peak {name}", f"{peak:6.3f} V" + ("  [bold red]CLIPPING[/]" if rec and name in rec.clipped else ""))
        return t

    live = Live(render(), console=console, refresh_per_second=4, transient=False)

    def progress(rec, elapsed, final=False):
        state["rec"] = rec
        if final or elapsed - state["last"] >= 0.25:
            state["last"] = elapsed
            live.update(render(rec, elapsed))

    def finish(wall_s):
        if state.get("rec") is not None:
            progress(state["rec"], wall_s, final=True)

    progress.finish = finish

    return live, progress
