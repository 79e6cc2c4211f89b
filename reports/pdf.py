"""The report as a PDF (matplotlib PdfPages): a summary page, then every figure."""
from __future__ import annotations

import math
import textwrap
from pathlib import Path

from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.figure import Figure

from labtool.reports.figures import all_figures, render
from labtool.reports.pipeline import Report, headline, verdict_lines


def _dash(v, spec=".2f") -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, spec)


def _summary_lines(report: Report) -> list[str]:
    lines = [f"labtool report: {report.measured_path}",
             f"cam speed simulated {report.scene['cam_speed_rpm']:.2f} rpm ({report.scene['cam_speed_rpm_source']}), "
             f"law {report.scene['law']}, Fu {report.scene['Fu_N']:g} N, j {report.scene['backlash_mm']:g} mm, "
             f"{len(report.cycles.revolutions)} whole revolution(s) used", ""]
    if report.threshold_rows:
        nfail = sum(not r["passed"] for r in report.threshold_rows)
        lines.append(f"thresholds ({report.thresholds_source}): " + ("all passed" if not nfail else f"{nfail} FAILED"))
    lines += ["", f"{'model, w1':26s} {'motion':13s} {'w2 ISO R':>8s} {'w2 S&G C':>8s} {'e2 ISO R':>8s} {'e2 S&G C':>8s} {'e2 band':>7s}"]
    for h in headline(report):
        lines.append(f"{h['label'][:26]:26s} {('periodic' if h['periodic'] else 'NOT periodic'):13s} "
                     f"{h['omega2_iso_rating']:8.3f} {h['omega2_sg_comprehensive']:8.3f} {h['epsilon2_iso_rating']:8.3f} "
                     f"{h['epsilon2_sg_comprehensive']:8.3f} {100 * h['epsilon2_band_overlap']:6.0f}%")
    lines += verdict_lines(report)
    m = report.measured_events
    lines += ["", f"{'events':26s} {'visible/rev':>11s} {'all/rev':>8s} {'jumps/rev':>9s} {'first [deg]':>11s}  angles [deg]"]
    if m is not None:
        lines.append(f"{'measured':26s} {_dash(m['impacts_per_rev']):>11s} {'-':>8s} {_dash(m['jumps_per_rev']):>9s} "
                     f"{_dash(m['first_impact_deg'], '.1f'):>11s}  {', '.join(f'{a:.1f}' for a in m['impact_angles_deg'])[:60]}")
    for e in report.events:
        lines.append(f"{e['label'][:26]:26s} {_dash(e['detectable_impacts_per_rev']):>11s} {_dash(e['impacts_per_rev']):>8s} "
                     f"{_dash(e['jumps_per_rev']):>9s} {_dash(e['first_impact_deg'], '.1f'):>11s}  "
                     f"{', '.join(f'{a:.1f}' for a in (e['impact_angles_deg'] or []))[:60]}")
    if m is not None and m.get("threshold_rad_s") is not None:
        lines.append(f"visible: |d omega2| >= {m['threshold_rad_s']:.3g} rad/s (the recording's detectability)")
    desc = report.conditioning.describe()
    if report.time_filter is not None:
        desc = report.time_filter.describe() + "; then, on both sides, " + desc
    lines += ["", "conditioning: " + desc, ""] + [f"note: {n}" for n in report.notes]
    lines += ["", "ISO/TS 18571 grades: excellent > 0.94, good > 0.8, fair > 0.58, poor; S&G C and NRMSE: 0 = identical"]
    return lines


def _summary_page(report: Report) -> Figure:
    fig = Figure(figsize=(11.69, 8.27))
    ax = fig.add_axes([0.04, 0.04, 0.92, 0.92])
    ax.axis("off")
    wrapped = []
    for line in _summary_lines(report):       # A4 landscape at 8 pt monospace holds ~150 characters
        wrapped += textwrap.wrap(line, 150, subsequent_indent="    ") or [""]
    # file strings (path, law, notes) are shown literally: '$' would start matplotlib's mathtext
    ax.text(0.0, 1.0, "\n".join(wrapped).replace("$", r"\$"), va="top", ha="left", family="monospace", fontsize=8)
    return fig


def write_pdf(report: Report, path: Path, rendered=None) -> None:
    """Write the summary page and the figures to ``path`` (the caller makes it atomic).
    ``rendered``: figures.Rendered list (drawn once for the page; each becomes a page of its pixels
    at its size, not drawn again); default the report's figures drawn now."""
    rendered = render(all_figures(report)) if rendered is None else rendered
    with PdfPages(path) as pdf:
        pdf.savefig(_summary_page(report))
        for r in rendered:
            page = Figure(figsize=r.size_inches, dpi=r.dpi)
            page.figimage(r.rgba, resize=False)
            pdf.savefig(page, dpi=r.dpi)
