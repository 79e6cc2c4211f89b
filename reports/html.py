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
from labtool.reports.pipeline import Report, closest, headline, point_rows, robust_verdict
from labtool.reports.summary import build_summary

TEMPLATES = Path(__file__).with_name("templates")
METRIC_COLUMNS = ("iso_rating", "iso_corridor", "iso_phase", "iso_magnitude", "iso_slope", "sg_magnitude", "sg_phase",
                  "sg_comprehensive", "nrmse", "peak_max_error", "peak_min_error", "peak_max_shift_deg",
                  "peak_min_shift_deg", "lag_deg", "band_overlap", "scatter_ratio")
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
    return env


def _attr_text(v, limit: int = 400) -> str:
    s = np.array2string(v, threshold=8) if isinstance(v, np.ndarray) else str(v)
    return s if len(s) <= limit else s[:limit] + " …"


def render_html(report: Report, rendered=None, dpi: int = 100) -> str:
    """The report page as a string. ``rendered``: figures.Rendered list (drawn once, shared with
    the PDF); default all of the report's figures drawn at ``dpi``."""
    rendered = render(all_figures(report), dpi) if rendered is None else rendered
    figs = [{"title": r.title, "png_b64": base64.b64encode(r.png).decode("ascii"), "width": int(r.rgba.shape[1]),
             "height": int(r.rgba.shape[0])} for r in rendered]
    summary = build_summary(report)
    ds = report.measured
    variables = [{"name": str(n), "dims": ", ".join(map(str, ds[n].dims)), "units": str(ds[n].attrs.get("units", "")),
                  "long_name": str(ds[n].attrs.get("long_name", ""))} for n in ds.variables]
    attributes = [(str(k), _attr_text(v)) for k, v in ds.attrs.items() if k != "processing_history"]
    rows = report.threshold_rows
    context = {
        "generated": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "measured": summary["measured"], "op": report.scene, "op_rows": point_rows(report.scene), "notes": report.notes,
        "headline": headline(report), "closest": closest(report), "comparisons": report.comparisons,
        "metric_columns": METRIC_COLUMNS, "per_rev_columns": PER_REV_COLUMNS, "periodic_tol": PERIODIC_TOL,
        "metrics_by_signal": [(s, [c for c in report.comparisons if c["signal"] == s]) for s in ("omega2", "epsilon2")],
        "robustness": {"rows": report.robustness, "robust": (robust_verdict(report.robustness) or {}).get("robust"),
                       "labels": [m["label"] for m in report.robustness[0]["models"]] if report.robustness else []},
        "events": report.events, "mev": summary["measured"]["events"], "simulations": summary["simulations"], "conditioning": summary["conditioning"],
        "thresholds": {"file": report.thresholds_source, "rows": rows}, "passed": report.passed,
        "failed": [r for r in rows if not r["passed"]], "figures": figs,
        "variables": variables, "attributes": attributes,
    }
    return environment().get_template("report.html.j2").render(**context)
