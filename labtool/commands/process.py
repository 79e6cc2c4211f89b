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
    channels: Optional[str] = typer.Option(None, help="name the file's channels, e.g. 'aE_t=aE180t,aE_n=aE180n,tacho=Dev1/ai2' "
                                           "('aE_t=aE_n,aE_n=aE_t' swaps two)"),
    invert: Optional[str] = typer.Option(None, help="channels whose sensor reads the other way round (mounted turned "
                                         "over): 'aE_t', 'aE_n' or 'aE_t,aE_n'; their sign is inverted "
                                         "(a swap or inversion the data show is corrected and said anyway)"),
    units: Optional[str] = typer.Option(None, help="the unit of channels whose file states none usable, e.g. "
                                        "'aE_t=V,aE_n=V' (V, mV, m/s^2, g; a unit the file states is replaced)"),
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
    from labtool.api.processing import process as run
    from labtool.common.errors import InputError
    from labtool.models.mechanism import Mechanism

    check_output_path(output, force)
    if sample_rate is not None and not (0 < sample_rate < float("inf")):
        raise InputError(f"--sample-rate must be a positive number, got {sample_rate}")
    progress, bar = _progress(recording)
    with bar:
        measured = run(recording, output, calibration=calibration or (), channels=_channel_map(channels) if channels else None,
                       law=law, cam_speed_rpm=rpm, lowpass_hz=lowpass_hz, ac_tau_s=ac_tau,
                       mechanism=Mechanism.from_toml(mechanism) if mechanism is not None else None,
                       chunk_samples=chunk_samples, progress=progress,
                       warn=lambda msg: typer.echo(f"labtool: warning: {msg}", err=True),
                       sample_rate_hz=sample_rate, group=group, delimiter=_delimiter(delimiter),
                       decimal=_decimal(decimal), time_unit_s=_time_unit(time_unit), units=_unit_map(units),
                       invert=_inverted(invert), dataset=False)
    summary = measured
    # an unknown value is left out of the file's attributes (no revolution to check omega2 on)
    check = summary.get("omega2_normal_check_rel_rms")
    check = f"{100 * check:.1f} % rms of peak" if check is not None else "not computed (no finite omega2 while the follower moves)"
    typer.echo(f"wrote {output}: cam {summary['cam_speed_rpm_measured']:.2f} rpm (phi1 by {summary['phi1_method']}), "
               f"{summary['n_revolutions_averaged']} revolutions averaged, low-pass {summary['lowpass_hz']:.0f} Hz, "
               f"{summary['n_spikes']} spikes, {summary['n_clipped_samples']} clipped samples, "
               f"|omega2| vs sqrt(aE_n/DE): {check}")
    typer.echo(_ka_line(summary))
    typer.echo(_channels_line(summary))
    speeds = _speed_line(summary)
    if speeds:
        typer.echo(speeds)


def _progress(recording):
    """(progress callback, context) of a bar on a terminal; (None, a null context) when piped."""
    import contextlib
    if not sys.stderr.isatty():
        return None, contextlib.nullcontext()
    from rich.progress import Progress
    bar = Progress(transient=True)
    task = bar.add_task(f"processing {recording.name}", total=None)
    return (lambda done, total: bar.update(task, completed=done, total=total)), bar


def _ka_line(attrs) -> str:
    """'Ka: aE_t 864.39 +- 0.07 m/s^2/V (source), aE_n ...' from the measured file's attributes."""
    from labtool.common.names import shown

    parts = []
    for ch in ("aE_t", "aE_n"):
        ka = attrs.get(f"ka_{ch}_m_s2_per_v")
        if ka is None:
            continue
        u = attrs.get(f"ka_{ch}_uncertainty_m_s2_per_v")
        unc = f" +- {float(u):.4g}" if u is not None and u == u else " (uncertainty unknown)"
        parts.append(f"{ch} {float(ka):.6g}{unc} m/s^2/V ({shown(str(attrs.get(f'ka_source_{ch}', '?')))})")
    return "Ka: " + ", ".join(parts)


def _channels_line(attrs) -> str:
    """'channels: as labelled' / 'channels: corrected: aE_n inverted (...)', from the attributes."""
    verdict = str(attrs.get("channel_check", "?"))
    inverted = str(attrs.get("channels_inverted", "")).split()
    said = f" (processed with {' and '.join(inverted)} inverted)" if inverted else ""
    if verdict == "as labelled":
        return f"channels: aE_t and aE_n read as labelled{said}"
    return f"channels: {verdict}{said}: {attrs.get('channel_check_finding', '')}"


def _speed_line(attrs) -> str | None:
    """The per-revolution speed range when it is wider than speed.DRIFT_SAID of the mean, else None."""
    from labtool.processing.speed import DRIFT_SAID

    lo, hi, mean = (attrs.get(k) for k in ("cam_speed_rpm_min", "cam_speed_rpm_max", "cam_speed_rpm_measured"))
    if lo is None or hi is None or not mean or (hi - lo) <= DRIFT_SAID * mean:
        return None
    return (f"cam speed: {lo:.2f} to {hi:.2f} rpm per revolution (drift {100 * float(attrs.get('cam_speed_drift', 0)):+.1f} "
            "% over the recording): the cycle statistics span these speeds")


def _inverted(text) -> tuple | None:
    """--invert 'aE_t,aE_n' -> ("aE_t", "aE_n"); None when not given; InputError on anything else."""
    from labtool.common.errors import InputError

    if text is None:
        return None
    names = [c.strip() for c in text.split(",")]
    bad = [c for c in names if c not in ("aE_t", "aE_n")]
    if bad:
        raise InputError(f"--invert: {bad[0]!r} is not aE_t or aE_n (give 'aE_t', 'aE_n' or 'aE_t,aE_n')")
    return tuple(names)


def _unit_map(text) -> dict | None:
    """--units 'aE_t=V,ai1=g' -> {"aE_t": "V", "ai1": "g"}; None when not given; InputError on anything else."""
    from labtool.common.errors import InputError

    if text is None:
        return None
    pairs = {}
    for part in text.split(","):
        name, sep, unit = part.partition("=")
        if not sep or not name.strip() or not unit.strip():
            raise InputError(f"--units: '{part}' is not CHANNEL=UNIT (e.g. aE_t=V)")
        pairs[name.strip()] = unit.strip()
    return pairs


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
