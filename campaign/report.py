"""The cross-point verdict: one page, one JSON, one CSV for a whole campaign.

``collect(inputs)`` takes campaign folders (their finished points), point folders, and measured.nc
files (compared here), and returns the ``CampaignReport``; ``write_outputs`` renders it:

- HTML: self-contained (figures as base64 PNG), autoescaped jinja2 in the per-point report's
  style (labtool.reports.html's environment and stylesheet);
- JSON: ``format = "labtool.campaign.summary"``, version 1: the campaign and test metadata, every
  point (operating point, measured values, closest model, thresholds, notes, its report's summary
  file), where the closest model changes, and the table's rows (numbers, not strings; NaN -> null);
- CSV: the table (labtool.campaign.collect.table), written by pandas (RFC 4180 quoting, '.' decimals).

Nothing in the JSON or CSV depends on the wall clock, so a resumed campaign gives the same files
as an uninterrupted one.
"""
from __future__ import annotations

import base64
import dataclasses
import datetime as dt
import json
import math
import re
from pathlib import Path

import numpy as np
import pandas as pd

from labtool.common.errors import InputError
from labtool.common.names import shown
from labtool.campaign import collect
from labtool.campaign.figures import all_figures

FORMAT = "labtool.campaign.summary"
FORMAT_VERSION = 1
TEMPLATES = Path(__file__).with_name("templates")


@dataclasses.dataclass
class CampaignReport:
    name: str
    description: str
    test: dict
    records: list                  # collect.PointRecord, sorted by group and speed
    table: pd.DataFrame
    changes: list                  # collect.closest_changes
    notes: list
    missing: list                  # points of the plan without a comparison yet
    identification: dict | None = None   # the points' fits across the campaign (labtool.identification.joint)

    @property
    def passed(self) -> bool | None:
        """All points' thresholds held (None when no point had thresholds)."""
        rows = [r for r in self.records if r.summary.get("thresholds", {}).get("rows")]
        return None if not rows else all(r.summary.get("passed") for r in rows)


def _campaign_points(folder: Path, page_base: Path):
    """(records, missing names, plan metadata) of a campaign folder, in the plan's order."""
    from labtool.campaign.plan import load_plan
    from labtool.campaign.runner import POINTS_DIR

    plan_file = folder / "plan.toml"
    meta = {}
    names = None
    if plan_file.is_file():
        plan = load_plan(plan_file, check_files=False)
        names = [p.name for p in plan.points]
        meta = {"name": plan.doc.campaign.name, "description": plan.doc.campaign.description,
                "test": plan.doc.test.as_dict()}
    if names is None:
        names = sorted(p.name for p in (folder / POINTS_DIR).iterdir() if p.is_dir())
    records, missing = [], []
    for n in names:
        pf = folder / POINTS_DIR / n
        if (pf / "summary.json").is_file() and (pf / "cycles.nc").is_file():
            records.append(collect.load_point_folder(pf, n, page_base))
        else:
            missing.append(n)
    return records, missing, meta


def collect_inputs(inputs, compare=None, overrides: dict | None = None, page_base: Path | None = None,
                   say=None) -> CampaignReport:
    """A CampaignReport from campaign folders, point folders and measured.nc files."""
    from labtool.campaign.plan import check_compare

    compare = compare or check_compare({}, "options")
    records, missing, meta, notes = [], [], {}, []
    for item in inputs:
        p = Path(item)
        if p.is_dir() and (p / "points").is_dir():
            recs, miss, m = _campaign_points(p, page_base or p)
            records += recs
            missing += miss
            meta = meta or m
        elif p.is_dir() and (p / "summary.json").is_file():
            records.append(collect.load_point_folder(p, None, page_base))
        elif p.is_file():
            if say:
                say(f"comparing {shown(p)} with {', '.join(compare.models)}")
            records.append(collect.load_measured_file(p, compare, overrides or {}, say=say))
            revs = f"{compare.revolutions:g}" if compare.revolutions else "the report's default"
            notes.append(f"{shown(p)} was compared here ({', '.join(compare.models)}; accuracy {compare.accuracy}, "
                         f"{revs} simulated revolutions), with the operating point its file states")
        elif p.is_dir():
            raise InputError(f"{shown(p)} is neither a campaign folder (no points/) nor a point folder (no summary.json)")
        else:
            raise InputError(f"{shown(p)} does not exist")
    names = [r.name for r in records]
    dup = sorted({n for n in names if names.count(n) > 1})
    for r in records:   # two inputs with the same name (two measured.nc): tell them apart by source
        if r.name in dup:
            r.name = f"{r.name} ({Path(r.source).parent.name or r.source})"
    if not records:
        raise InputError("no point has a comparison yet" + (f" (unfinished: {', '.join(missing)})" if missing else "")
                         + "; run 'labtool campaign run' first, or give measured.nc files")
    recs = collect.sort_records(records)
    if missing:
        notes.append(f"{len(missing)} point(s) of the plan have no comparison yet and are not shown: {', '.join(missing)}")
    test = meta.get("test") or {"test_id": "", "operator": "", "notes": ""}
    return CampaignReport(meta.get("name", "campaign"), meta.get("description", ""), test, recs,
                          collect.table(recs), collect.closest_changes(recs), notes, missing)


# --------------------------------------------------------------------------- outputs


def _clean(obj):
    """Plain JSON types (numpy scalars and arrays converted), NaN/inf -> None."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    return obj if obj is None or isinstance(obj, (str, int, bool)) else str(obj)


def summary(rep: CampaignReport, files: dict | None = None) -> dict:
    points = []
    for r in rep.records:
        s = r.summary
        points.append({"name": r.name, "source": r.source, "page": r.page, "operating_point": r.op,
                       "measured": {k: s.get("measured", {}).get(k) for k in (
                           "cam_speed_rpm_nominal", "cam_speed_rpm_measured", "ka_m_s2_per_v", "ka_source",
                           "whole_revolutions", "partial_revolutions_left_out")},
                       "closest": s.get("closest"), "closest_model": collect.closest_family(r),
                       "cannot_tell_from": collect.undecided_with(r),
                       "verdict": (s.get("verdict") or {}).get("sentence"),
                       "passed": s.get("passed"), "thresholds": s.get("thresholds"), "notes": s.get("notes", [])})
    table = rep.table.astype(object).where(rep.table.notna(), None).to_dict(orient="records")
    return _clean({"format": FORMAT, "format_version": FORMAT_VERSION, "campaign": {"name": rep.name,
                   "description": rep.description}, "test": rep.test, "points": points,
                   "closest_changes": rep.changes, "passed": rep.passed, "notes": rep.notes,
                   "missing_points": rep.missing, "files": files or {}, "table": table,
                   "identification": rep.identification})


def to_json(rep: CampaignReport, files: dict | None = None) -> str:
    return json.dumps(summary(rep, files), indent=1, allow_nan=False)


def to_csv(rep: CampaignReport) -> str:
    return rep.table.to_csv(index=False, lineterminator="\n")


def _stylesheet() -> str:
    """The per-point report's stylesheet (reports/templates/report.html.j2), so both pages look alike."""
    from labtool.reports.html import TEMPLATES as REPORT_TEMPLATES

    text = (REPORT_TEMPLATES / "report.html.j2").read_text(encoding="utf-8")
    m = re.search(r"<style>(.*?)</style>", text, re.S)
    return m.group(1) if m else ""


def render_html(rep: CampaignReport, files: dict | None = None, dpi: int = 90) -> str:
    import jinja2

    from labtool.reports.figures import render
    from labtool.reports.html import environment

    env = environment()
    env.loader = jinja2.ChoiceLoader([jinja2.FileSystemLoader(str(TEMPLATES)), env.loader])
    figs = []
    for r in render(all_figures(rep.records, rep.table), dpi=dpi):      # each figure drawn once (Agg)
        h, w = r.rgba.shape[:2]
        figs.append({"title": r.title, "png_b64": base64.b64encode(r.png).decode("ascii"), "width": w, "height": h})
    s = summary(rep, files)
    grades = {}
    for row in s["table"]:
        grades.setdefault(row["point"], []).append(row)
    models = ", ".join(dict.fromkeys(str(row.get("label")) for row in s["table"])) or "—"
    context = {"generated": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"), "s": s, "models": models,
               "css": _stylesheet(), "figures": figs, "rows_by_point": grades, "files": files or {},
               "finite": lambda v: isinstance(v, (int, float)) and math.isfinite(v)}
    return env.get_template("campaign.html.j2").render(**context)


def write_outputs(rep: CampaignReport, html: Path | None, json_path: Path | None, csv_path: Path | None) -> None:
    """Write the page, the JSON and the CSV that are asked for, each atomically."""
    from labtool.common.files import atomic_write

    base = (html or json_path or csv_path).parent
    files = {k: (str(p.relative_to(base)) if p.parent == base else str(p)) for k, p in
             (("html", html), ("json", json_path), ("csv", csv_path)) if p is not None}
    texts = []
    if csv_path is not None:
        texts.append((csv_path, to_csv(rep)))
    if json_path is not None:
        texts.append((json_path, to_json(rep, files) + "\n"))
    if html is not None:
        texts.append((html, render_html(rep, files)))
    for path, text in texts:
        try:
            atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))
        except OSError as exc:
            raise InputError(f"cannot write {shown(path)}: {exc.strerror or exc}; the points are kept "
                             "('labtool campaign report' writes the page again)") from None
