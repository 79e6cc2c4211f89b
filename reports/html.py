"""The self-contained HTML report: jinja2 with autoescaping, figures as base64 PNG.

Every string that comes from a file or a user (file names, variable names, attributes, processing
history, notes) reaches the page through jinja2's autoescape, so markup in a channel name shows
as text. The page loads nothing from the network.
"""
from __future__ import annotations

import base64
import datetime as dt
import math
from pathlib import Path

import jinja2
import numpy as np

from labtool.reports.figures import all_figures, render
from labtool.reports.align import PERIODIC_TOL
from labtool.reports.pipeline import Report
from labtool.reports.summary import build_summary

TEMPLATES = Path(__file__).with_name("templates")
PER_REV_COLUMNS = ("iso_rating", "iso_corridor", "iso_phase", "iso_magnitude", "iso_slope", "sg_comprehensive", "nrmse",
                   "lag_deg")


def _fmt(value, spec: str = ".3g") -> str:
    """Numbers formatted, None/NaN as an em dash, anything else as text (escaped by the template)."""
    if value is None:
        return "—"
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, float, np.integer, np.floating)):
        v = float(value)
        if not math.isfinite(v):
            return "—"
        return format(v, spec)
    return str(value)


def environment() -> jinja2.Environment:
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(TEMPLATES)),
        autoescape=True,                      # every template, whatever its extension
        undefined=jinja2.StrictUndefined,
        trim_blocks=True, lstrip_blocks=True,
    )
    env.globals["fmt"] = _fmt
    from labtool.reports.page import typeset
    env.filters["typeset"] = typeset        # ω2, ε2, ω1 in the page's prose (labtool.reports.page.typeset)
    return env


def render_html(report: Report, rendered=None, dpi: int = 100) -> str:
    """The report page as a string, from the page's content (labtool.reports.page, the same the PDF
    typesets). ``rendered``: figures.Rendered list (drawn once, shared with the PDF); default all
    of the report's figures drawn at ``dpi``."""
    from labtool.reports.page import build_page

    rendered = render(all_figures(report), dpi) if rendered is None else rendered
    page = build_page(report, rendered)
    figs = [{"number": f.number, "caption": f.caption, "png_b64": base64.b64encode(f.rendered.png).decode("ascii"),
             "width": int(f.rendered.rgba.shape[1]), "height": int(f.rendered.rgba.shape[0])} for f in page.figures]
    summary = build_summary(report)
    ds = report.measured
    variables = [{"name": str(n), "dims": ", ".join(map(str, ds[n].dims)), "units": str(ds[n].attrs.get("units", "")),
                  "long_name": str(ds[n].attrs.get("long_name", ""))} for n in ds.variables]
    context = {
        "generated": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"), "page": page,
        "comparisons": report.comparisons, "per_rev_columns": PER_REV_COLUMNS, "periodic_tol": PERIODIC_TOL,
        "mev": summary["measured"]["events"], "figures": figs, "variables": variables,
    }
    return environment().get_template("report.html.j2").render(**context)
