"""The points of a campaign as one table: what the cross-point page, JSON and CSV show.

A point comes from a campaign folder (its ``summary.json`` and ``cycles.nc``, written by the
compare step) or from a ``measured.nc`` file of any origin (compared here, with the plan's or the
default models). Either way it becomes a ``PointRecord``: the report summary (labtool.reports.summary's
keys) and the overlay data (labtool.campaign.steps.cycles_dataset).

``table(records)`` is tidy: one row per point and simulation (model x omega1 mode), the point's
operating point and measured values repeated on each row, so a spreadsheet can pivot it.
"""
from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr

from labtool.common.errors import FileFormatError, InputError
from labtool.common.names import shown

SIGNALS = ("omega2", "epsilon2")
ROW_METRICS = ("iso_rating", "iso_grade", "sg_comprehensive", "nrmse")


@dataclasses.dataclass
class PointRecord:
    name: str
    source: str                 # the point's folder or the measured file
    summary: dict               # labtool.reports.summary.build_summary(...)
    cycles: xr.Dataset          # labtool.campaign.steps.cycles_dataset(...)
    page: str | None = None     # the per-point report, relative to the campaign page
    fit: dict | None = None     # the point's labtool fit result (fit.json in its folder), if fitted

    @property
    def op(self) -> dict:
        return self.summary.get("operating_point", {})

    @property
    def rpm(self) -> float:
        """The point's speed (rpm): the one the recording states (the plan's), else the simulated one
        (the report runs its models at the measured mean speed, a few 1e-14 off a plan's 180)."""
        op = self.op
        stated = op.get("cam_speed_rpm_stated")
        return float(stated if stated else op.get("cam_speed_rpm", math.nan))

    def group(self) -> tuple:
        """The operating point without the speed: points of one group form a curve against rpm."""
        op = self.op
        return (str(op.get("law", "")), _num(op.get("Fu_N")), _num(op.get("backlash_mm")), _num(op.get("jt_factor")))

    def group_label(self) -> str:
        law, fu, j, jt = self.group()
        return f"Fu {fu:g} N, j {j:g} mm, Jt x{jt:g}, {law}"


def _num(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def load_point_folder(folder: Path, name: str | None = None, page_base: Path | None = None) -> PointRecord:
    """A finished point of a campaign folder; InputError when its compare step has not run."""
    folder = Path(folder)
    s, c = folder / "summary.json", folder / "cycles.nc"
    if not (s.is_file() and c.is_file()):
        raise InputError(f"point {shown(folder.name)} has no comparison yet ({shown(s.name)}, {shown(c.name)}); "
                         "finish it with 'labtool campaign run'")
    try:
        summary = json.loads(s.read_text(encoding="utf-8"))
        cycles = xr.open_dataset(c, engine="h5netcdf").load()
    except (OSError, ValueError) as exc:
        raise FileFormatError(f"point {shown(folder.name)}: unreadable {shown(str(exc))}") from None
    _check_summary(summary, folder)
    _check_cycles(cycles, folder)
    page = str(_relative(folder / "report.html", page_base)) if (folder / "report.html").is_file() else None
    return PointRecord(name or folder.name, str(_relative(folder, page_base)), summary, cycles, page,
                       _point_fit(folder))


FIT_FILE = "fit.json"


def _point_fit(folder: Path) -> dict | None:
    """The point's fit (``labtool fit points/NAME/measured.nc ... -o points/NAME/fit.json``), or None;
    a file there that is not a fit result is refused, naming it."""
    f = folder / FIT_FILE
    if not f.is_file():
        return None
    try:
        doc = json.loads(f.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise FileFormatError(f"point {shown(folder.name)}: {FIT_FILE} is unreadable ({shown(str(exc))}); "
                              f"fit the point again with 'labtool fit ... -o {shown(str(f))} --force'") from None
    if not (isinstance(doc, dict) and doc.get("format") == "labtool.fit" and isinstance(doc.get("parameters"), dict)
            and isinstance(doc.get("measured"), dict)):
        raise FileFormatError(f"point {shown(folder.name)}: {FIT_FILE} is not a labtool fit result; fit the point "
                              f"again with 'labtool fit ... -o {shown(str(f))} --force' or move the file away")
    return doc


def _check_summary(summary, folder: Path) -> None:
    """FileFormatError unless ``summary`` has the shape labtool.reports.summary writes: a hand-edited
    summary.json holding [] or {} was an internal error (AttributeError, jinja's UndefinedError)."""
    op = summary.get("operating_point") if isinstance(summary, dict) else None
    lists = ("headline", "simulations", "events")
    ok = (isinstance(summary, dict) and summary.get("format") == "labtool.report.summary"
          and isinstance(op, dict) and math.isfinite(_num(op.get("cam_speed_rpm")))
          and isinstance(summary.get("measured"), dict)
          and all(isinstance(summary.get(k, []), list) and all(isinstance(x, dict) for x in summary.get(k, []))
                  for k in lists))
    if not ok:
        raise FileFormatError(f"point {shown(folder.name)}: summary.json is not a labtool report summary (format "
                              "labtool.report.summary, with its operating_point, measured and headline); delete it and "
                              "run 'labtool campaign run' again to remake the point's comparison")


def _check_cycles(cycles: xr.Dataset, folder: Path) -> None:
    """FileFormatError unless ``cycles`` holds what labtool.campaign.steps.cycles_dataset writes and the
    page draws: another NetCDF file there was an internal error (KeyError: No variable named 'phi1')."""
    need = {f"measured_{s}_{k}": ("phi1",) for s in SIGNALS for k in ("mean", "std")}
    if "sim" in cycles.dims:
        need.update({f"sim_{k}": ("sim",) for k in ("label", "requested", "omega1")})
        need.update({f"sim_{s}": ("sim", "phi1") for s in SIGNALS})
    bad = ([] if "phi1" in cycles.coords else ["phi1"]) + [
        k for k, dims in need.items() if k not in cycles.variables or cycles[k].dims != dims]
    if bad:
        raise FileFormatError(f"point {shown(folder.name)}: cycles.nc is not a campaign point's cycle overlays "
                              f"(missing or misshapen: {', '.join(bad)}); delete it and run 'labtool campaign run' "
                              "again to remake the point's comparison")


def _relative(path: Path, base: Path | None) -> Path:
    """``path`` relative to ``base`` when inside it (a campaign folder moves as a whole)."""
    if base is None:
        return path
    try:
        return Path(path).resolve().relative_to(Path(base).resolve())
    except ValueError:
        return path


def load_measured_file(path: Path, compare, overrides: dict, say=None) -> PointRecord:
    """Compare a measured.nc (from an earlier run or another tool) now; nothing is written."""
    from labtool.campaign.steps import build, cycles_dataset
    from labtool.reports.summary import build_summary

    rep = build(Path(path), compare, None, overrides, say=say)
    return PointRecord(Path(path).stem, str(path), build_summary(rep), cycles_dataset(rep), None)


def sort_records(records: list[PointRecord]) -> list[PointRecord]:
    """By operating-point group, then speed (the page's curves run along rpm)."""
    return sorted(records, key=lambda r: (r.group(), r.rpm, r.name))


def table(records: list[PointRecord]) -> pd.DataFrame:
    """Tidy table: one row per point x simulation (module docstring)."""
    rows = []
    for r in records:
        s, op, m = r.summary, r.op, r.summary.get("measured", {})
        events = {e.get("label"): e for e in s.get("events", [])}
        sims = {x.get("label"): x for x in s.get("simulations", [])}
        for h in s.get("headline", []):
            ev = events.get(h.get("label"), {})
            row = {
                "point": r.name, "rpm": r.rpm, "rpm_measured": m.get("cam_speed_rpm_measured"),
                "law": op.get("law"), "Fu_N": op.get("Fu_N"), "backlash_mm": op.get("backlash_mm"),
                "jt_factor": op.get("jt_factor"), "whole_revolutions": m.get("whole_revolutions"),
                "model": h.get("requested_model"), "level_used": h.get("model"), "omega1": h.get("omega1"),
                "label": h.get("label"),
            }
            for sig in SIGNALS:
                for k in ROW_METRICS:
                    row[f"{sig}_{k}"] = h.get(f"{sig}_{k}")
            row["mean_iso_rating"] = _mean(h.get("omega2_iso_rating"), h.get("epsilon2_iso_rating"))
            row["closest"] = h.get("label") == s.get("closest")
            row.update(event_columns(ev, m.get("events")))
            row["sim_note"] = (sims.get(h.get("label")) or {}).get("note") or ""
            row["thresholds_passed"] = s.get("passed")
            row["ka_m_s2_per_v"] = m.get("ka_m_s2_per_v")
            row["source"] = r.source
            rows.append(row)
    return pd.DataFrame(rows)


EVENT_COLUMNS = ("impacts_measured_per_rev", "impacts_predicted_per_rev", "impacts_detectable_per_rev",
                 "jumps_measured_per_rev", "jumps_predicted_per_rev", "first_impact_deg_measured",
                 "first_impact_deg_predicted")


def event_columns(ev: dict, measured: dict | None) -> dict:
    """Measured and predicted events of one simulation row, from a report summary: format 2
    (measured.events, and per simulation impacts_per_rev, detectable_impacts_per_rev, ...) or 1
    (impacts_measured_per_rev, ... per simulation)."""
    if "impacts_per_rev" in ev or measured is not None:
        m = measured or {}
        return {"impacts_measured_per_rev": m.get("impacts_per_rev"), "impacts_predicted_per_rev": ev.get("impacts_per_rev"),
                "impacts_detectable_per_rev": ev.get("detectable_impacts_per_rev"),
                "jumps_measured_per_rev": m.get("jumps_per_rev"), "jumps_predicted_per_rev": ev.get("jumps_per_rev"),
                "first_impact_deg_measured": m.get("first_impact_deg"),
                "first_impact_deg_predicted": ev.get("first_impact_deg")}
    out = {k: ev.get(k) for k in EVENT_COLUMNS}
    out["impacts_detectable_per_rev"] = ev.get("impacts_predicted_per_rev")
    return out


def _mean(a, b):
    vals = [v for v in (a, b) if isinstance(v, (int, float)) and math.isfinite(v)]
    return float(np.mean(vals)) if len(vals) == 2 else None


def undecided_with(r: PointRecord) -> list[str]:
    """The models of another family that the point's measurement cannot tell from its closest
    (the report's verdict, labtool.reports.verdict): [] where the verdict separates the families."""
    v = r.summary.get("verdict") or {}
    best, fam = v.get("closest"), closest_family(r)
    out = []
    for group in v.get("cannot_tell_apart") or []:
        if best in group:
            out += [lab for lab in group if lab != best and family_of(r, lab) not in (None, fam)]
    return list(dict.fromkeys(out))


def closest_changes(records: list[PointRecord]) -> list[dict]:
    """Where the closest model (the model family: rigid, elastic, ...) changes between neighbouring
    speeds of one operating-point group: [{group, from_rpm, to_rpm, from, to}]. A point whose
    measurement cannot tell its closest from a model of another family (``undecided_with``) is no
    side of a change."""
    out = []
    by_group: dict[tuple, list[PointRecord]] = {}
    for r in sort_records(records):
        by_group.setdefault(r.group(), []).append(r)
    for group, recs in by_group.items():
        prev = None
        for r in recs:
            fam = closest_family(r) if not undecided_with(r) else None
            if prev is not None and fam is not None and closest_family(prev) not in (None, fam):
                out.append({"group": r.group_label(), "from_rpm": prev.rpm, "to_rpm": r.rpm,
                            "from": closest_family(prev), "to": fam,
                            "from_label": prev.summary.get("closest"), "to_label": r.summary.get("closest")})
            prev = r if fam is not None else prev
    return out


def closest_family(r: PointRecord) -> str | None:
    return family_of(r, r.summary.get("closest"))


def family_of(r: PointRecord, label: str | None) -> str | None:
    """The model family (rigid, elastic, ...) of the point's model ``label``, None if not compared."""
    for h in r.summary.get("headline", []):
        if h.get("label") == label:
            return h.get("requested_model")
    return None
