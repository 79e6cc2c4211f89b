"""The report as a PDF (matplotlib PdfPages): a summary page, then every figure."""
from __future__ import annotations

from pathlib import Path

from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.figure import Figure

from reports.figures import all_figures
from reports.pipeline import Report, headline


def _summary_page(report: Report) -> Figure:
    fig = Figure(figsize=(11.69, 8.27))
    ax = fig.add_axes([0.04, 0.04, 0.92, 0.92])
    ax.axis("off")
    lines = [f"labtool report: {report.measured_path}",
             f"cam speed {report.scene['cam_speed_rpm']:g} rpm (measured {report.cycles.cam_speed_rpm:.2f} rpm), "
             f"law {report.scene['law']}, Fu {report.scene['Fu']:g} N, j {report.scene['backlash_mm']:g} mm, "
             f"{len(report.cycles.revolutions)} whole revolution(s)", ""]
    if report.threshold_rows:
        nfail = sum(not r["passed"] for r in report.threshold_rows)
        lines.append(f"thresholds ({report.thresholds_source}): " + ("all passed" if not nfail else f"{nfail} FAILED"))
    lines += ["", f"{'model, w1':34s} {'w2 ISO R':>9s} {'w2 S&G C':>9s} {'w2 NRMSE':>9s} {'e2 ISO R':>9s} {'e2 S&G C':>9s} {'e2 NRMSE':>9s}"]
    for h in headline(report):
        lines.append(f"{h['label'][:34]:34s} {h['omega2_iso_rating']:9.3f} {h['omega2_sg_comprehensive']:9.3f} "
                     f"{h['omega2_nrmse']:9.3f} {h['epsilon2_iso_rating']:9.3f} {h['epsilon2_sg_comprehensive']:9.3f} "
                     f"{h['epsilon2_nrmse']:9.3f}")
    lines += ["", f"{'model, w1':34s} {'jumps/rev pred.':>16s} {'meas.':>6s} {'impacts/rev pred.':>18s} {'meas.':>6s}"]
    dash = lambda v: "-" if v is None else f"{v:.2f}"   # noqa: E731
    for e in report.events:
        lines.append(f"{e['label'][:34]:34s} {dash(e['jumps_predicted_per_rev']):>16s} {dash(e['jumps_measured_per_rev']):>6s} "
                     f"{dash(e['impacts_predicted_per_rev']):>18s} {dash(e['impacts_measured_per_rev']):>6s}")
    desc = report.conditioning.describe()
    if report.time_filter is not None:
        desc = report.time_filter.describe() + "; then, on both sides, " + desc
    lines += ["", "conditioning: " + desc, ""] + [f"note: {n}" for n in report.notes]
    lines += ["", "ISO/TS 18571 grades: excellent > 0.94, good > 0.8, fair > 0.58, poor; S&G C and NRMSE: 0 = identical"]
    # file strings (path, law, notes) are shown literally: '$' would start matplotlib's mathtext
    ax.text(0.0, 1.0, "\n".join(lines).replace("$", r"\$"), va="top", ha="left", family="monospace", fontsize=8.5, wrap=True)
    return fig


def write_pdf(report: Report, path: Path, figures=None) -> None:
    """Write the summary page and the figures to ``path`` (the caller makes it atomic)."""
    figures = all_figures(report) if figures is None else figures
    with PdfPages(path) as pdf:
        pdf.savefig(_summary_page(report))
        for _, fig in figures:
            pdf.savefig(fig)
