"""``labtool acquire``: record the stand (simulated or NI-DAQmx) into a v1 recording (HDF5),
through ``labtool.acquire`` (labtool/api/acquisition.py)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import List, Optional

import typer

from labtool.acquisition.metadata import OPTION
from labtool.common.errors import InputError
from labtool.common.invocation import command_line
from labtool.options import op_option


def register(app: typer.Typer) -> None:
    app.command("acquire")(acquire)


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
    import labtool
    from labtool.output import console, terminal_confirm

    if not (math.isfinite(status_every) and status_every >= 0):
        raise InputError(f"--status-every must be >= 0 s, got {status_every:g}")
    stand = dict(cam_speed_rpm=rpm, duration_s=duration, rate_hz=rate, seed=seed, law=law, Fu_N=fu,
                 backlash_mm=backlash_mm, jt_factor=jt_factor, ripple=ripple, ka_m_s2_per_v=ka, mode=mode,
                 cal_freq_hz=cal_freq, cal_accel_m_s2=cal_accel, cal_channel=cal_channel, truth_model=truth)
    metadata = dict(test_id=test_id, operator=operator, sensor_model=sensor_model, sensor_serial=sensor_serial,
                    conditioner_gain=conditioner_gain, notes=notes)
    shown_by = {}

    def monitor(dev, ka_ch, dur):
        shown_by["display"] = _Display(console(stderr=True), dev, dur, ka_ch, status_every)
        return shown_by["display"]

    res = labtool.acquire(output, device=device, stand=stand, scene=scene, realtime=realtime,
                          truth_options=dict(restitution=restitution, contact_damping=contact_damping),
                          faults=fault or [], device_file=device_file, ni=ni or [], iepe_excitation=iepe_excitation,
                          metadata=metadata, motor_setting=motor_setting, force=force, yes=yes,
                          confirm=terminal_confirm(), monitor=monitor, warn=_warn,
                          command=command_line("labtool acquire"), check=False)
    rt = (res.n_samples / res.rate_hz) / res.wall_s if res.wall_s > 0 else float("inf")
    typer.echo(f"wrote {output}: {res.n_samples} samples x {res.n_channels} channels at {res.rate_hz:g} Hz "
               f"({res.n_samples / res.rate_hz:.3f} s, {rt:.1f}x real time), {res.overruns} overruns, {res.gaps} gaps, "
               f"complete={str(res.complete).lower()}")
    if res.unstated:
        _warn(f"operating point not stated: {', '.join(res.unstated)} ({', '.join(OPTION[m] for m in res.unstated)}); "
              "a report will assume the paper's experiment for them and say so")
    if shown_by["display"].headroom_warning:
        _warn(shown_by["display"].headroom_warning)
    if res.clipped:
        _warn(f"clipping on {', '.join(res.clipped)} (ADC range exceeded); see the 'clip' events")
    res.check()


def _warn(text: str) -> None:
    typer.echo(f"labtool: warning: {text}", err=True)


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
