"""A report's files, written as one set: the HTML page, the PDF and the JSON summary all, or none
(a full disk, Ctrl-C), each atomically (labtool.common.files.OutputSet)."""
from __future__ import annotations

from pathlib import Path

from labtool.common.files import OutputSet


def write_report(report, html: Path | None = None, pdf: Path | None = None, json_path: Path | None = None,
                 progress=None) -> str | None:
    """Write the report's HTML (``html``), PDF (``pdf``) and JSON summary (``json_path``; "-" = not
    written, returned); the figures are drawn once for the page and the PDF. Returns the JSON text
    when asked for."""
    from labtool.reports.figures import all_figures, render
    from labtool.reports.html import render_html
    from labtool.reports.summary import to_json

    say = progress or (lambda msg: None)
    text = to_json(report) if json_path is not None else None
    if html is None and pdf is None:
        return text
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
    return text
