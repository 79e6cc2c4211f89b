"""``labtool calibrate``: Ka (m/s^2/V) per channel from a recording of a reference sine excitation."""
from __future__ import annotations

from pathlib import Path
from typing import List

import typer

from common.files import check_output_path, write_text
from common.errors import InputError
from common.names import shown

PAPER_KA = 86.43


def register(app: typer.Typer) -> None:
    app.command("calibrate")(calibrate)


def calibrate(
    recording: Path = typer.Argument(..., help="recording (HDF5 v1) of the reference excitation"),
    channel: List[str] = typer.Option(["aE_t"], help="channel on the exciter (repeatable)"),
    reference_accel: float = typer.Option(9.81, help="reference acceleration (m/s^2) (B&K 4291: 9.81)"),
    reference_freq: float = typer.Option(79.6, help="reference frequency (Hz), refined by the fit"),
    convention: str = typer.Option("peak", help="peak | rms: what --reference-accel means"),
    reference_uncertainty: float = typer.Option(0.0, help="relative standard uncertainty of the exciter (e.g. 0.01)"),
    output: Path = typer.Option(..., "-o", "--output", help="calibration file to write (TOML)"),
    force: bool = typer.Option(False, help="overwrite an existing output file"),
) -> None:
    """Fit a sine at the reference frequency (least squares, frequency refined) and write Ka with its uncertainty."""
    from rich.markup import escape
    from rich.table import Table

    from labtool.output import console

    from acquisition.calibration import calibrate_recording, calibration_toml

    if convention not in ("peak", "rms"):
        raise InputError(f"--convention must be peak or rms, got '{convention}'")
    check_output_path(output, force)
    cals = calibrate_recording(recording, channel, reference_accel, reference_freq, convention, reference_uncertainty)
    text = calibration_toml(cals, shown(recording), reference_accel, reference_freq, convention, reference_uncertainty)
    write_text(output, text)      # atomic, with the user's umask (a calibration is meant to be shared)

    table = Table(title=f"Calibration from {escape(shown(recording.name))}: {reference_accel:g} m/s^2 {convention} at {reference_freq:g} Hz")
    for col in ("channel", "Ka [m/s^2/V]", "u(Ka) [m/s^2/V]", "vs paper 86.43", "fitted f [Hz]", "amplitude [V peak]", "residual rms [V]"):
        table.add_column(escape(col), justify="right")     # "[m/s^2/V]" is not rich markup
    for c in cals:
        table.add_row(c.channel, f"{c.ka_m_s2_per_v:.4f}", f"{c.ka_std_m_s2_per_v:.4f}",
                      f"{100 * (c.ka_m_s2_per_v / PAPER_KA - 1):+.2f} %", f"{c.fit.freq_hz:.4f}",
                      f"{c.fit.amplitude:.5f}", f"{c.fit.residual_rms:.2e}")
    console().print(table)
    typer.echo(f"wrote {output}")
