"""The report as a PDF worth handing on, typeset with fpdf2 from the page's content
(labtool.reports.page, the same the HTML shows): a title block (test ID, operator, date, stand,
sensor, the operating point with the source of each value), the verdict in one paragraph, the
tables, the figures with numbered captions, page numbers, and the provenance in an appendix.

Text is set in DejaVu Sans, the TrueType font matplotlib ships (so Greek letters and units print
and nothing beyond labtool's own dependencies is needed), embedded as a subset. A figure is placed
from its PNG (drawn once for the page and the PDF), scaled to the text width.
"""
from __future__ import annotations

import io
from pathlib import Path

from labtool.reports.page import Page, Table, build_page

FONT = "DejaVu"
MARGIN_MM = 15.0
VERDICT_FILL = {"robust": (227, 244, 227), "apart": (227, 244, 227), "tied": (255, 244, 214), "none": (238, 238, 255)}


def _fonts(pdf) -> None:
    from matplotlib import get_data_path

    ttf = Path(get_data_path()) / "fonts" / "ttf"
    pdf.add_font(FONT, "", str(ttf / "DejaVuSans.ttf"))
    pdf.add_font(FONT, "B", str(ttf / "DejaVuSans-Bold.ttf"))
    pdf.add_font(FONT, "I", str(ttf / "DejaVuSans-Oblique.ttf"))


def _document(page: Page):
    from fpdf import FPDF

    class Document(FPDF):
        def header(self):
            if self.page_no() == 1:
                return
            self.set_font(FONT, "", 7)
            self.set_text_color(110)
            text = f"labtool report · test {page.title_block.rows[0][1]} · {page.measured_file}"
            while self.get_string_width(text) > self.epw and len(text) > 20:
                text = "…" + text[len(text) // 8:]     # a long path: its end, which names the file
            self.cell(0, 5, text, align="L")
            self.ln(7)
            self.set_text_color(0)

        def footer(self):
            self.set_y(-12)
            self.set_font(FONT, "", 7)
            self.set_text_color(110)
            self.cell(0, 6, f"page {self.page_no()} of {{nb}}", align="C")
            self.set_text_color(0)

    pdf = Document(orientation="P", unit="mm", format="A4")
    pdf.set_margins(MARGIN_MM, MARGIN_MM, MARGIN_MM)
    pdf.set_auto_page_break(True, margin=16)
    pdf.alias_nb_pages()
    _fonts(pdf)
    pdf.set_title(f"{page.title}: {page.subtitle}")
    pdf.set_author(page.title_block.rows[1][1])
    pdf.set_creator("labtool report")
    return pdf


def _heading(pdf, text: str, size: float = 12) -> None:
    if pdf.will_page_break(20):
        pdf.add_page()
    pdf.ln(2)
    pdf.set_font(FONT, "B", size)
    pdf.multi_cell(0, size * 0.5, text, new_x="LMARGIN", new_y="NEXT")
    pdf.ln(1)


def _para(pdf, text: str, size: float = 9, style: str = "", fill=None) -> None:
    pdf.set_font(FONT, style, size)
    if fill is not None:
        pdf.set_fill_color(*fill)
    pdf.multi_cell(0, size * 0.48, text, new_x="LMARGIN", new_y="NEXT", fill=fill is not None,
                   padding=1.5 if fill else 0, align="L")
    pdf.set_fill_color(255)
    pdf.ln(1)


def _table(pdf, t: Table, size: float = 7.5, headings: bool = True) -> None:
    from fpdf.fonts import FontFace

    if not t.rows:
        return
    pdf.set_font(FONT, "", size)
    widths = t.widths or (1,) * len(t.columns)
    if pdf.will_page_break(25):
        pdf.add_page()
    with pdf.table(col_widths=widths, text_align=tuple(t.aligned(i) for i in range(len(t.columns))),
                   first_row_as_headings=headings, line_height=size * 0.5, padding=0.8,
                   headings_style=FontFace(emphasis="B", fill_color=(242, 242, 242)), width=pdf.epw,
                   cell_fill_mode="NONE") as table:
        if headings:
            row = table.row()
            for c in t.columns:
                row.cell(str(c))
        for cells in t.rows:
            row = table.row()
            for cell in cells:
                row.cell(t.text(cell))
    if t.caption:
        pdf.set_font(FONT, "I", 7)
        pdf.multi_cell(0, 3.4, t.caption, new_x="LMARGIN", new_y="NEXT")
    pdf.ln(3)


def _figure(pdf, fig) -> None:
    r = fig.rendered
    w_in, h_in = r.size_inches
    width = min(pdf.epw, w_in * 25.4)
    height = width * h_in / w_in
    if height + 12 > pdf.h - pdf.t_margin - 16 - 8:       # taller than a page: fit the page's height
        height = pdf.h - pdf.t_margin - 16 - 20
        width = height * w_in / h_in
    if pdf.will_page_break(height + 10):
        pdf.add_page()
    x = pdf.l_margin + (pdf.epw - width) / 2
    pdf.image(io.BytesIO(r.png), x=x, y=pdf.get_y(), w=width, h=height)
    pdf.set_y(pdf.get_y() + height + 1)
    pdf.set_font(FONT, "", 8)
    pdf.multi_cell(0, 3.8, f"Figure {fig.number}. {fig.caption}", new_x="LMARGIN", new_y="NEXT", align="C")
    pdf.ln(4)


def render_pdf(page: Page, path: Path) -> None:
    """Typeset ``page`` (labtool.reports.page) into the PDF file ``path``."""
    pdf = _document(page)
    pdf.add_page()
    pdf.set_font(FONT, "B", 16)
    pdf.cell(0, 9, page.title, new_x="LMARGIN", new_y="NEXT")
    _para(pdf, page.subtitle, 8.5)
    _table(pdf, page.title_block, 8, headings=False)
    _heading(pdf, "Verdict")
    _para(pdf, page.verdict, 9.5, fill=VERDICT_FILL.get(page.verdict_kind))
    _para(pdf, page.thresholds, 9, "B" if page.thresholds_passed is False else "")
    for n in page.notes:
        _para(pdf, f"Note: {n}", 8)
    for t in page.tables:
        _table(pdf, t)
    _heading(pdf, "Figures")
    for fig in page.figures:
        _figure(pdf, fig)
    pdf.add_page()
    _heading(pdf, "Appendix: provenance")
    for t in page.appendix:
        _table(pdf, t, 7)
    if page.history is not None:
        _table(pdf, page.history, 6.5)
    pdf.output(str(path))


def write_pdf(report, path: Path, rendered=None) -> None:
    """Write the report's PDF to ``path`` (the caller makes it atomic). ``rendered``: the figures
    drawn once for the page (figures.render); default drawn now."""
    from labtool.reports.figures import all_figures, render

    rendered = render(all_figures(report)) if rendered is None else rendered
    render_pdf(build_page(report, rendered), path)
