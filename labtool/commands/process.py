"""``labtool process``: a recording (labtool HDF5 v1, TDMS or CSV) -> measured.nc (omega2, epsilon2, ...)."""
from __future__ import annotations

import sys
from pathlib import Path
from typing import List, Optional

import typer

from labtool.common.files import check_output_path


def register(app: typer.Typer) -> None:
    app.command("process")(process)


def process(
    recording: Path = typer.Argument(..., help="recording to process: labtool HDF5 (v1), LabVIEW TDMS or CSV"),
    output: Path = typer.Option(..., "-o", "--output", help="NetCDF file to write (measured.nc)"),
    calibration: Optional[List[Path]] = typer.Option(None, help="calibration TOML from 'labtool calibrate' (Ka per channel); "
                                                     "repeatable: the files' channels are merged, a channel in two is refused"),
    sample_rate: Optional[float] = typer.Option(None, help="sample rate [Hz] for TDMS/CSV files that state none"),
    law: Optional[str] = typer.Option(None, help="motion law of the cam (default: the recording's, else sine)"),
    rpm: Optional[float] = typer.Option(None, help="nominal cam speed [rpm] (default: the recording's; the speed used is measured)"),
    lowpass_hz: Optional[float] = typer.Option(None, help="low-pass corner [Hz] (default: 100 x cam frequency)"),
    ac_tau: Optional[float] = typer.Option(None, help="AC-coupling time constant of the sensor chain [s], undone if given"),
    channels: Optional[str] = typer.Option(None, help="name the file's channels, e.g. 'aE_t=aE180t,aE_n=aE180n,tacho=Dev1/ai2'"),
    group: Optional[str] = typer.Option(None, help="TDMS group holding the samples (default: the only group with samples)"),
    delimiter: Optional[str] = typer.Option(None, help="text tables: column delimiter, 'comma', 'semicolon' or 'tab' (default: detected)"),
    decimal: Optional[str] = typer.Option(None, help="text tables: decimal mark, '.' or ',' (default: detected)"),
    time_unit: Optional[str] = typer.Option(None, help="text tables: unit of the time column, s, ms or us (default: from its header)"),
    mechanism: Optional[Path] = typer.Option(None, help="mechanism TOML file (default: the paper's STB-216)"),
    chunk_samples: int = typer.Option(1 << 17, help="samples per processing chunk (memory bound; 2^17 keeps a 1-hour run under 300 MB)"),
    force: bool = typer.Option(False, help="overwrite an existing output file"),
) -> None:
    """Recorded accelerations at E -> follower epsilon2 and omega2, cam angle, spectra, cycle
    averages and spikes, with every step in the processing history (docs/processing.md)."""
    from labtool.common.errors import InputError
    from labtool.processing.calibration_file import read_calibrations
    from labtool.processing.pipeline import ProcessOptions, process_recording
    from labtool.processing.readers import open_recording

    check_output_path(output, force)
    if output.resolve() == recording.resolve():
        raise InputError("the output file must not be the recording itself")
    if chunk_samples < 1024:
        raise InputError("--chunk-samples must be at least 1024")
    for name, v in (("--rpm", rpm), ("--lowpass-hz", lowpass_hz), ("--sample-rate", sample_rate), ("--ac-tau", ac_tau)):
        if v is not None and not (v > 0 and v < float("inf")):
            raise InputError(f"{name} must be a positive number, got {v}")
    from labtool.models.mechanism import Mechanism

    mapping = _channel_map(channels) if channels else {}
    mech = Mechanism.from_toml(mechanism) if mechanism is not None else None
    cal = read_calibrations(calibration) if calibration else None
    rec = open_recording(recording, sample_rate_hz=sample_rate, group=group, delimiter=_delimiter(delimiter),
                         decimal=_decimal(decimal), time_unit_s=_time_unit(time_unit), channels=mapping)
    try:
        rec.rename_channels(mapping)
    except Exception:
        rec.close()
        raise

    def warn(msg: str) -> None:
        typer.echo(f"labtool: warning: {msg}", err=True)

    sources = "; ".join(str(c) for c in calibration or [])
    opts = ProcessOptions(calibration=cal, calibration_source=sources, law=law, cam_speed_rpm=rpm,
                          lowpass_hz=lowpass_hz, ac_tau_s=ac_tau, chunk_samples=chunk_samples,
                          mechanism=mech)
    try:
        if sys.stderr.isatty():
            from rich.progress import Progress
            with Progress(transient=True) as bar:
                task = bar.add_task(f"processing {recording.name}", total=2 * rec.n_samples)
                summary = process_recording(rec, output, opts, progress=lambda k: bar.advance(task, k), warn=warn)
        else:
            summary = process_recording(rec, output, opts, warn=warn)
    finally:
        rec.close()
    check = summary["normal_check_rel_rms"]
    typer.echo(f"wrote {output}: cam {summary['cam_speed_rpm']:.2f} rpm (phi1 by {summary['phi1_method']}), "
               f"{summary['revolutions_averaged']} revolutions averaged, low-pass {summary['lowpass_hz']:.0f} Hz, "
               f"{summary['spikes']} spikes, {summary['clipped']} clipped samples, "
               f"|omega2| vs sqrt(aE_n/DE): {100 * check:.1f} % rms of peak")
    typer.echo(_ka_line(summary.get("history", [])))


def _ka_line(history) -> str:
    """'Ka: aE_t 864.39 +- 0.07 m/s^2/V (source), aE_n ...' from the apply_ka step of the history."""
    from labtool.common.names import shown

    step = next((h for h in history if isinstance(h, dict) and h.get("step") == "apply_ka"), {})
    chans = step.get("channels") or step.get("parameters", {}).get("channels") or {}
    parts = []
    for ch in ("aE_t", "aE_n"):
        c = chans.get(ch)
        if not c:
            continue
        u = c.get("uncertainty_m_s2_per_v")
        unc = f" +- {u:.4g}" if isinstance(u, (int, float)) and u == u else " (uncertainty unknown)"
        parts.append(f"{ch} {c['ka_m_s2_per_v']:.6g}{unc} m/s^2/V ({shown(str(c.get('source', '?')))})")
    return "Ka: " + ", ".join(parts)


def _channel_map(text: str) -> dict[str, str]:
    """'aE_t=ai0,aE_n=ai1' -> {"aE_t": "ai0", "aE_n": "ai1"}; InputError on anything else."""
    from labtool.common.errors import InputError

    out = {}
    for part in text.split(","):
        new, sep, old = part.partition("=")
        if not sep or not new.strip() or not old.strip():
            raise InputError(f"--channels: '{part}' is not NAME=SOURCE (e.g. aE_t=aE180t)")
        if new.strip() not in ("aE_t", "aE_n", "tacho"):
            raise InputError(f"--channels: '{new.strip()}' is not one of aE_t, aE_n, tacho")
        out[new.strip()] = old.strip()
    return out


def _delimiter(text):
    from labtool.common.errors import InputError
    if text is None:
        return None
    d = {"comma": ",", ",": ",", "semicolon": ";", ";": ";", "tab": "\t", "\\t": "\t", "\t": "\t"}.get(text.lower())
    if d is None:
        raise InputError(f"--delimiter must be comma, semicolon or tab, got {text!r}")
    return d


def _decimal(text):
    from labtool.common.errors import InputError
    if text is None:
        return None
    if text not in (".", ","):
        raise InputError(f"--decimal must be '.' or ',', got {text!r}")
    return text


def _time_unit(text):
    from labtool.common.errors import InputError
    from labtool.processing.readers.units import time_unit
    if text is None:
        return None
    f = time_unit(text)
    if f is None:
        raise InputError(f"--time-unit must be s, ms or us, got {text!r}")
    return f
