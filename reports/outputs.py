"""A report's files, written as one set: the HTML page, the PDF, the JSON summary and the curves
(CSV and NetCDF beside the page) all, or none (a full disk, Ctrl-C), each atomically
(labtool.common.files.OutputSet)."""
from __future__ import annotations

from pathlib import Path

from labtool.common.files import OutputSet

CURVE_FORMATS = ("csv", "netcdf")      # beside every report; .mat through 'labtool export'
BESIDE = "beside"                       # write_report's default: the curves beside the page


def curves_beside(html: Path | None, pdf: Path | None = None, formats=CURVE_FORMATS) -> dict:
    """format -> ``<stem>_curves.<ext>`` beside the page (else the PDF); {} without either."""
    from labtool.reports.curves import curve_paths

    base = html if html is not None else pdf
    if base is None:
        return {}
    return curve_paths(str(Path(base).with_suffix("")), formats)


def write_report(report, html: Path | None = None, pdf: Path | None = None, json_path: Path | None = None,
                 progress=None, curves: dict | str | None = BESIDE) -> str | None:
    """Write the report's HTML (``html``), PDF (``pdf``), JSON summary (``json_path``; "-" = not
    written, returned) and curves (``curves``: format -> path, labtool.reports.curves; default
    CSV and NetCDF beside the page, ``curves_beside``; None or {} = none); the figures are drawn
    once for the page and the PDF. Returns the JSON text when asked for."""
    from labtool.reports.figures import all_figures, render
    from labtool.reports.html import render_html
    from labtool.reports.summary import to_json

    say = progress or (lambda msg: None)
    if curves == BESIDE:
        curves = curves_beside(html, pdf)
    text = to_json(report) if json_path is not None else None
    if html is None and pdf is None and not curves and (json_path is None or str(json_path) == "-"):
        return text
    figs = None
    if html is not None or pdf is not None:
        say("drawing the figures")
        figs = render(all_figures(report))
    with OutputSet() as out:
        if html is not None:
            out.write_text(html, render_html(report, figs), "-o")
        if pdf is not None:
            from labtool.reports.pdf import write_pdf
            say("writing the PDF")
            out.write(pdf, lambda tmp: write_pdf(report, tmp, figs), "--pdf")
        if json_path is not None and str(json_path) != "-":
            out.write_text(json_path, text + "\n", "--json")
        if curves:
            from labtool.reports.curves import report_curves, write_curves
            say("writing the curves")
            write_curves(report_curves(report), curves, out)
    return text
