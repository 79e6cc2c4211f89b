"""``labtool calibrate``: Ka (m/s^2/V) of one or several channels from recordings of a reference sine."""
from __future__ import annotations

from pathlib import Path
from typing import List

import typer

from labtool.common.files import check_output_path
from labtool.common.names import utf8_text


def register(app: typer.Typer) -> None:
    app.command("calibrate")(calibrate)


def calibrate(
    recordings: List[Path] = typer.Argument(..., help="reference recordings (HDF5 v1, TDMS or CSV): the exciter on the channel(s)"),
    channel: List[str] = typer.Option(["aE_t"], help="channel on the exciter, from every recording given, or NAME=RECORDING "
                                      "for one of them (repeatable; a channel in several recordings is merged)"),
    reference_accel: float = typer.Option(9.81, help="reference acceleration [m/s^2] (B&K 4291: 9.81)"),
    reference_freq: float = typer.Option(79.6, help="reference frequency [Hz], refined by the fit"),
    convention: str = typer.Option("peak", help="peak | rms: what --reference-accel means"),
    reference_uncertainty: float = typer.Option(0.0, help="relative standard uncertainty of the exciter [-] (e.g. 0.01)"),
    output: Path = typer.Option(..., "-o", "--output", help="calibration file to write (TOML)"),
    force: bool = typer.Option(False, help="overwrite an existing output file"),
) -> None:
    """Fit a sine at the reference frequency (least squares, frequency refined) in each channel and
    write Ka with its uncertainty, all channels in one file. A clipped, distorted or non-volt
    reference is refused, naming the channel."""
    from labtool.processing.calibration import ReferenceSpec, calibrate_pairs, pair_channels
    from labtool.processing.calibration_file import calibration_document, write_calibration
    from labtool.processing.readers import open_recording

    reference = ReferenceSpec(reference_accel, reference_freq, convention, reference_uncertainty)
    check_output_path(output, force)
    pairs = pair_channels(recordings, channel)
    results = calibrate_pairs(pairs, reference, open_recording)
    sources = list(dict.fromkeys(utf8_text(p) for _, p in pairs))   # a non-UTF-8 byte is written as \xff
    doc = calibration_document({r.channel: r.entry() for r in results}, reference.as_dict(), "; ".join(sources))
    write_calibration(output, doc)
    _print_table(results, reference, sources)
    for r in results:
        if r.birge_ratio > 3:
            typer.echo(f"labtool: warning: the {len(r.fits)} calibrations of {r.channel} scatter {r.birge_ratio:.1f} times "
                       "more than their uncertainties; the uncertainty is inflated by that factor", err=True)
    typer.echo(f"wrote {output}")


def _print_table(results, reference, sources) -> None:
    from rich.markup import escape
    from rich.table import Table

    from labtool.common.names import shown
    from labtool.output import console
    from labtool.processing.calibration_file import PAPER_KA_M_S2_PER_V as PAPER_KA

    what = shown(Path(sources[0]).name) if len(sources) == 1 else f"{len(sources)} reference recordings"
    table = Table(title=escape(f"Calibration from {what}: {reference.accel_m_s2:g} m/s^2 {reference.convention} "
                               f"at {reference.freq_hz:g} Hz"))
    for col in ("channel", "Ka [m/s^2/V]", "u(Ka) [m/s^2/V]", "vs paper 86.43", "fitted f [Hz]", "amplitude [V peak]",
                "residual rms [V]", "harmonics", "recordings"):
        table.add_column(escape(col), justify="right")     # "[m/s^2/V]" is not rich markup
    for r in results:
        f = r.fits[0].fit
        many = len(r.fits) > 1
        table.add_row(escape(shown(r.channel)), f"{r.ka_m_s2_per_v:.4f}", f"{r.uncertainty_m_s2_per_v:.4f}",
                      f"{100 * (r.ka_m_s2_per_v / PAPER_KA - 1):+.2f} %", "—" if many else f"{f.freq_hz:.4f}",
                      "—" if many else f"{f.amplitude:.5f}", "—" if many else f"{f.residual_rms:.2e}",
                      f"{100 * max(c.fit.harmonic_distortion for c in r.fits):.2f} %",
                      str(len(r.fits)) + (f" (Birge {r.birge_ratio:.2f})" if many else ""))
    console().print(table)
