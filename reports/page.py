"""What the report's page says, once, for its two renderers: the HTML (labtool.reports.html) and the
PDF (labtool.reports.pdf) show the same title block, verdict, tables, numbered figures and
provenance, in the same order.

``build_page(report, rendered)`` returns a ``Page`` of plain text: no markup (the HTML template
escapes every string, the PDF prints it), numbers already formatted, units in the headings.
"""
from __future__ import annotations

import dataclasses
import json
import math
import re

import numpy as np

from labtool.reports.pipeline import Report, closest, headline, point_rows

NOT_STATED = "not stated"
SIG = {"omega2": "ω2", "epsilon2": "ε2"}
METRIC_COLUMNS = ("iso_rating", "iso_corridor", "iso_phase", "iso_magnitude", "iso_slope", "sg_magnitude", "sg_phase",
                  "sg_comprehensive", "nrmse", "peak_max_error", "peak_min_error", "peak_max_shift_deg",
                  "peak_min_shift_deg", "lag_deg", "band_overlap", "scatter_ratio")
# operating-point rows the title block leaves out: the report compares both modes at one preset,
# said in the 'models compared' row
NOT_IN_TITLE = ("omega1 mode", "accuracy")


@dataclasses.dataclass
class Table:
    """A typeset table: ``columns`` (headings), ``rows`` of cells; a cell is text or (text, css
    class) (the HTML colours grades; the PDF prints the text); ``align`` per column, 'L' or 'R'."""

    id: str
    columns: list
    rows: list
    align: str = ""
    caption: str = ""
    widths: tuple = ()          # relative column widths for the PDF (default equal)

    def text(self, cell) -> str:
        return cell[0] if isinstance(cell, tuple) else str(cell)

    def css(self, cell) -> str:
        return cell[1] if isinstance(cell, tuple) else ""

    def aligned(self, i: int) -> str:
        return self.align[i] if i < len(self.align) else "L"


@dataclasses.dataclass
class Figure:
    number: int
    caption: str
    rendered: object            # labtool.reports.figures.Rendered


@dataclasses.dataclass
class Page:
    title: str
    subtitle: str
    measured_file: str
    title_block: Table
    verdict: str
    verdict_kind: str           # robust | apart | tied | none
    thresholds: str             # one sentence: passed, failed, none given
    thresholds_passed: bool | None
    notes: list
    tables: list                # Table: headline, events, robustness (the body, in order)
    figures: list               # Figure, numbered
    appendix: list              # Table: operating point with sources, simulations, metrics, file attributes
    history: Table | None       # the processing history, step by step


_PROSE_SYMBOLS = ((re.compile(r"\bomega2\b"), "ω2"), (re.compile(r"\bepsilon2\b"), "ε2"),
                  (re.compile(r"\bomega1\b"), "ω1"), (re.compile(r"\bw1 = "), "ω1 = "))


def typeset(text: str) -> str:
    """A console sentence as the page prints it: omega2, epsilon2, omega1 and "w1 =" as ω2, ε2, ω1
    (the console and the JSON keep the ASCII names a script greps for)."""
    for pattern, symbol in _PROSE_SYMBOLS:
        text = pattern.sub(symbol, text)
    return text


def _fmt(v, spec=".3f") -> str:
    if v is None:
        return "—"
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, float, np.integer, np.floating)):
        return format(float(v), spec) if math.isfinite(float(v)) else "—"
    return str(v)


def _attr(a: dict, key: str) -> str:
    v = a.get(key)
    if v is None or (isinstance(v, str) and not v.strip()):
        return NOT_STATED
    if isinstance(v, bytes):
        v = v.decode("utf-8", "replace")
    if isinstance(v, (float, np.floating)):
        return f"{float(v):g}"
    return str(v)


def title_block(report: Report) -> Table:
    """Test ID, operator, date, stand, sensor and its serial, the measured file, then the
    operating point with the source of each value, and what was compared."""
    from labtool.models.mechanism import Mechanism

    a = report.measured.attrs
    cyc = report.cycles
    sensor = _attr(a, "sensor_model")
    serial = _attr(a, "sensor_serial")
    cond = _attr(a, "conditioner_model")
    gain = a.get("conditioner_gain")
    if cond != NOT_STATED and gain is not None:
        cond += f", gain x{float(gain):g}"
    rows = [("Test ID", _attr(a, "test_id")), ("Operator", _attr(a, "operator")),
            ("Date (recording start)", _attr(a, "start_time_utc")),
            ("Stand", f"{Mechanism.default().name}; recording {_attr(a, 'source_file')} ({_attr(a, 'source_format')})"),
            ("Sensor, serial", f"{sensor}, serial {serial}"), ("Conditioner", cond),
            ("Measured file", f"{report.measured_path} ({a.get('source', 'recording')}): {len(cyc.revolutions)} whole "
                              f"revolutions at {cyc.cam_speed_rpm:.2f} rpm")]
    if a.get("notes"):
        rows.append(("Notes", _attr(a, "notes")))
    for what, value, source in point_rows(report.scene):
        if what in NOT_IN_TITLE:
            continue
        rows.append((what[0].upper() + what[1:], f"{value}" + (f" ({source})" if source else "")))
    modes = sorted({r.omega1 for r in report.sims})
    models = ", ".join(dict.fromkeys(r.requested for r in report.sims))
    preset = ", ".join(sorted({r.accuracy for r in report.sims})) or "—"
    rows.append(("Models compared", f"{models}; ω1 {' and '.join(modes)}; solver preset {preset}"))
    return Table("title-block", ["", ""], rows, "LL", widths=(1, 3))


def _grade(value, grade) -> tuple:
    return (f"{_fmt(value)} {grade}", f"grade-{grade}")


def headline_table(report: Report) -> Table:
    rows = []
    for h in headline(report):
        rows.append([typeset(h["label"]), h["motion"], _grade(h["omega2_iso_rating"], h["omega2_iso_grade"]),
                     _fmt(h["omega2_sg_comprehensive"]), _fmt(h["omega2_nrmse"]),
                     _grade(h["epsilon2_iso_rating"], h["epsilon2_iso_grade"]), _fmt(h["epsilon2_sg_comprehensive"]),
                     _fmt(h["epsilon2_nrmse"]), f"{_fmt(100 * h['epsilon2_band_overlap'], '.0f')} %"])
    return Table("headline", ["model, ω1", "model's motion", "ω2 ISO R", "ω2 S&G C", "ω2 NRMSE", "ε2 ISO R",
                              "ε2 S&G C", "ε2 NRMSE", "ε2 in ±2σ band"], rows, "LLRRRRRRR",
                 "Agreement of each model with the measured ω2 and ε2: ISO/TS 18571 rating R (1 = identical; excellent "
                 "> 0.94, good > 0.8, fair > 0.58), Sprague & Geers comprehensive error C and NRMSE (0 = identical), "
                 "the simulation's cycle against the measured cycle average on one cam-angle grid.",
                 widths=(2.2, 2.0, 1.2, 1, 1, 1.2, 1, 1, 1))


def events_table(report: Report) -> Table:
    m = report.measured_events
    rows = []

    def angles(v):
        return ", ".join(f"{a:.1f}" for a in v) if v else "—"
    if m is not None:
        rows.append([f"measured ({m.get('revolutions', '—')} rev)", _fmt(m.get("impacts_per_rev"), ".2f"), "—",
                     _fmt(m.get("jumps_per_rev"), ".2f"), _fmt(m.get("first_impact_deg"), ".1f"),
                     angles(m.get("impact_angles_deg"))])
    for e in report.events:
        rows.append([typeset(e["label"]), _fmt(e["detectable_impacts_per_rev"], ".2f"), _fmt(e["impacts_per_rev"], ".2f"),
                     _fmt(e["jumps_per_rev"], ".2f"), _fmt(e["first_impact_deg"], ".1f"), angles(e["impact_angles_deg"])])
    thr = "" if m is None or m.get("threshold_rad_s") is None else (
        f" Visible: a velocity step |Δω2| ≥ {m['threshold_rad_s']:.3g} rad/s, this recording's detectability; the "
        "models' events counted with the same threshold and resolution.")
    return Table("events", ["source", "visible impacts / rev", "all impacts / rev", "jumps / rev",
                            "first impact φ1 [deg]", "impact angles φ1 [deg]"], rows, "LRRRRL",
                 "Jumps and impacts, measured against predicted." + thr, widths=(2.2, 1.1, 1.1, 1, 1.1, 2.5))


def robustness_table(report: Report) -> Table | None:
    if not report.robustness:
        return None
    labels = [m["label"] for m in report.robustness[0]["models"]]
    rows = []
    for r in report.robustness:
        got = {m["label"]: m for m in r.get("models", [])}
        cells = [r["accuracy"], _fmt(r["revolutions"], "g"), typeset(r["closest"] or f"failed: {r.get('error', '')}")]
        for lab in labels:
            m = got.get(lab)
            cells.append("—" if m is None else
                         (f"{_fmt(m['omega2_iso_rating'], '.3f')} / {_fmt(m['epsilon2_iso_rating'], '.3f')}",
                          f"grade-{m['epsilon2_iso_grade']}"))
        rows.append(cells)
    return Table("robustness", ["preset", "revolutions", "closest"] + [f"{typeset(lab)}: ω2 / ε2 R" for lab in labels], rows,
                 "LRL" + "R" * len(labels), "The verdict at both solver presets and at half the simulated length (the "
                 "first half of the same simulation): each model's ISO ratings.", widths=(1, 1, 2) + (1.6,) * len(labels))


def metrics_table(report: Report, signal: str) -> Table:
    comps = [c for c in report.comparisons if c["signal"] == signal]
    rows = [[m] + [_fmt(c["overall"].get(m), ".3g") for c in comps] for m in METRIC_COLUMNS]
    return Table("metrics" if signal == "omega2" else f"metrics-{signal}", [SIG[signal]] + [typeset(c["label"]) for c in comps], rows, "L" + "R" * len(comps),
                 f"All overall metrics of {SIG[signal]} (docs/reports.md defines each).", widths=(2,) + (1.4,) * len(comps))


def thresholds_table(report: Report) -> Table | None:
    if not report.threshold_rows:
        return None
    rows = []
    for r in report.threshold_rows:
        who = r["requested_model"] + (f" (ran {r['model']})" if r["model"] != r["requested_model"] else "")
        rows.append([f"{who}, {r['omega1']}", r["limit"], r["scope"], _fmt(r["value"], ".4g"),
                     ("pass", "") if r["passed"] else ("FAIL", "grade-poor")])
    return Table("thresholds", ["model, ω1", "check", "scope", "value", "result"], rows, "LLLRL",
                 f"Threshold checks ({report.thresholds_source}).", widths=(1.6, 2.4, 1.2, 1, 0.8))


def simulations_table(report: Report) -> Table:
    rows = [[typeset(r.label), r.model, r.accuracy, _fmt(r.revolutions, "g"), _fmt(r.wall_s, ".2f"), r.note] for r in report.sims]
    return Table("simulations", ["model, ω1", "level", "preset", "revolutions", "wall time [s]", "note"], rows,
                 "LLLRRL", "The simulations.", widths=(1.8, 1, 1, 1, 1, 4))


def provenance_table(report: Report) -> Table:
    """Where the numbers come from: the conditioning, the processing, the file's attributes."""
    from labtool.reports.summary import measured_info

    info = measured_info(report)
    desc = report.conditioning.describe()
    if report.time_filter is not None:
        desc = report.time_filter.describe() + "; then, on both sides, " + desc
    rows = [("conditioning of both sides", desc),
            ("Ka used by the processing", f"{_fmt(info['ka_m_s2_per_v'], 'g')} m/s²/V"
             + (f" ({info['ka_source']})" if info.get("ka_source") else "")),
            ("revolutions compared / left out", f"{info['whole_revolutions']} / {info['partial_revolutions_left_out']}"),
            ("cam speed measured / stated", f"{report.cycles.cam_speed_rpm:.3f} rpm / "
                                            f"{_fmt(report.scene.get('cam_speed_rpm_stated'), 'g')} rpm"),
            ("ω1 var: nominal n1 of the drive", f"{_fmt(report.scene.get('omega1_var_n1_rpm'), '.2f')} rpm (set so that "
                                                "its no-load speed is the simulated speed)")]
    for k, v in report.measured.attrs.items():
        if k == "processing_history":
            continue
        s = np.array2string(v, threshold=8) if isinstance(v, np.ndarray) else str(v)
        rows.append((f"file attribute {k}", s if len(s) <= 300 else s[:300] + " …"))
    return Table("provenance", ["what", "value"], rows, "LL", "Provenance: the comparison's conditioning and the "
                 "measured file's attributes.", widths=(1.3, 3))


def history_table(report: Report) -> Table | None:
    """The processing history (labtool process), one row per step with its parameters."""
    raw = report.measured.attrs.get("processing_history", report.measured.attrs.get("history"))
    if raw is None:
        return None
    try:
        steps = json.loads(raw) if isinstance(raw, str) else None
    except ValueError:
        steps = None
    if not isinstance(steps, list):
        return Table("history", ["step", "parameters"], [["history", str(raw)]], "LL", "Processing history.", (1, 4))
    rows = []
    for i, st in enumerate(steps, 1):
        if not isinstance(st, dict):
            rows.append([str(i), str(st)])
            continue
        params = st.get("parameters", {})
        text = "; ".join(f"{k} = {json.dumps(v) if not isinstance(v, str) else v}" for k, v in params.items()) \
            if isinstance(params, dict) else str(params)
        rows.append([f"{i}. {st.get('step', '')}", text])
    return Table("history", ["step", "parameters"], rows, "LL", "Processing history of the measured file "
                 "(labtool process), step by step.", widths=(1, 4))


def thresholds_sentence(report: Report) -> tuple[str, bool | None]:
    rows = report.threshold_rows
    if not rows:
        return "No thresholds given: the metrics are informative only.", None
    failed = [r for r in rows if not r["passed"]]
    if not failed:
        return f"All {len(rows)} threshold checks passed ({report.thresholds_source}).", True
    return f"{len(failed)} of {len(rows)} threshold checks FAILED ({report.thresholds_source}).", False


def verdict_kind(report: Report) -> str:
    v = report.verdict
    if v is None:
        return "none"
    best_group = any(v["closest"] in g for g in v["cannot_tell_apart"])
    return "tied" if best_group else ("robust" if v["robust"] else "apart")


def figure_captions(rendered) -> list:
    return [Figure(i, r.title, r) for i, r in enumerate(rendered, 1)]


def build_page(report: Report, rendered) -> Page:
    """The page's content (module doc) with the figures ``rendered`` (figures.render)."""
    best = closest(report)
    th, passed = thresholds_sentence(report)
    body = [headline_table(report), robustness_table(report), thresholds_table(report), events_table(report)]
    appendix = [title_block_sources(report), simulations_table(report), metrics_table(report, "omega2"),
                metrics_table(report, "epsilon2"), provenance_table(report)]
    sub = typeset(f"labtool report of {report.measured_path}: the measured ω2 and ε2 against "
                  f"{', '.join(dict.fromkeys(r.requested for r in report.sims))}"
                  + (f"; closest {best['label']}" if best else ""))
    return Page("Model vs measurement", sub, report.measured_path, title_block(report),
                typeset((report.verdict or {}).get("sentence") or "No model was compared."), verdict_kind(report), th,
                passed, [typeset(n) for n in report.notes], [t for t in body if t is not None], figure_captions(rendered),
                [t for t in appendix if t is not None], history_table(report))


def title_block_sources(report: Report) -> Table:
    """Every operating-point field with its value and source (the title block leaves some out)."""
    rows = [(what, value, source) for what, value, source in point_rows(report.scene)]
    return Table("operating-point", ["quantity", "value", "source"], rows, "LLL",
                 "The operating point the models simulated, and where each value came from.", widths=(1.3, 1, 3))
