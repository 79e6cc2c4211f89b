"""The report as one JSON object, for a lab's automation (``labtool report --json``).

Keys (stable): ``format`` ("labtool.report.summary"), ``format_version`` (2), ``measured`` (file,
cam speeds, Ka, whole revolutions used and in the file, and ``events``: the measured impacts and
jumps with ``impacts_per_rev``, ``jumps_per_rev``, ``first_impact_deg``, ``impact_angles_deg``, the
detectability ``threshold_rad_s`` and the detector), ``operating_point`` (what the models
simulated, edge units), ``conditioning``, ``simulations`` (per model and omega1 mode: level used,
periodic or not, revolutions, note, wall time, indicators, and for a model identified by
``labtool fit`` (``report --fit``, labelled "<model> (fitted)") its own ``operating_point``), ``comparisons`` (per model, mode and
signal: ``overall`` metrics on the cycle average, with ``band_overlap`` and ``scatter_ratio``, and
``per_revolution``), ``headline``, ``closest`` (the simulation with the best mean ISO rating of
omega2 and epsilon2), ``robustness`` (``rows``: preset, revolutions, closest, every model's grades;
``robust``, the verdict's), ``verdict`` (labtool.reports.verdict.judge: ``closest``, ``ranking``,
``margin``, ``resolution`` and its ``scatter`` and ``spread``, ``cannot_tell_apart``, ``pairs``,
``robust``, ``discrimination`` (labtool.reports.discrimination) and ``sentence``, the words every
output shows), ``events`` (per simulation: the predicted ``impacts_per_rev`` (all contacts of the
model's record), ``detectable_impacts_per_rev`` (those the chain shows, same threshold and
resolution as the measurement), ``jumps_per_rev``, ``first_impact_deg``, ``impact_angles_deg``
(of the visible ones), and the model's own indicators), ``thresholds`` (rows with ``passed``),
``passed`` (true when every threshold holds, also when there are none), ``notes``.
Non-finite numbers become null so that the output is strict JSON.
"""
from __future__ import annotations

import json
import math

import numpy as np

from labtool.common import recording_attrs
from labtool.reports.events import KEYS as EVENT_KEYS
from labtool.reports.pipeline import Report, closest, headline, robust_verdict

FORMAT_VERSION = 2


def plain_json(obj):
    """Plain JSON types (also for labtool fit); NaN/Inf -> None."""
    if isinstance(obj, dict):
        return {str(k): plain_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain_json(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return plain_json(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if obj is None or isinstance(obj, str):
        return obj
    return str(obj)


def measured_info(report: Report) -> dict:
    ds = report.measured
    a = ds.attrs
    ka = a.get("ka_m_s2_per_v", a.get("ka"))
    ka_source = a.get("ka_source", a.get("calibration"))
    if ka is None:   # labtool process: one Ka per channel
        per = {k[3:-len("_m_s2_per_v")]: a[k] for k in a
               if k.startswith("ka_") and k.endswith("_m_s2_per_v") and "uncertainty" not in k}
        if per:
            vals = set(map(str, per.values()))
            def g(v):
                try:
                    return f"{float(v):.5g}"
                except (TypeError, ValueError):
                    return str(v)
            ka = next(iter(per.values())) if len(vals) == 1 else ", ".join(f"{c}: {g(v)}" for c, v in per.items())
            srcs = {str(a[k]) for k in a if k.startswith("ka_source_")}
            ka_source = "; ".join(sorted(srcs)) or None
    history = a.get("processing_history", a.get("history"))
    try:    # labtool process stores the history as a JSON list of steps
        history = json.dumps(json.loads(history), indent=1) if isinstance(history, str) else history
    except ValueError:
        pass
    return {
        "file": report.measured_path,
        "source": a.get("source", "recording"),
        "cam_speed_rpm_nominal": report.scene.get("cam_speed_rpm_stated"),
        "cam_speed_rpm_measured": report.cycles.cam_speed_rpm,
        "ka_m_s2_per_v": ka,
        "ka_source": ka_source,
        "whole_revolutions": len(report.cycles.revolutions),
        "revolutions_in_file": report.cycles.in_file if report.cycles.in_file is not None else len(report.cycles.revolutions),
        "partial_revolutions_left_out": report.cycles.partial,
        "processing_history": history,
        "events": measured_events(report),
        # the run as its recording states it (common/recording_attrs.py): test ID, operator, sensor, ...
        "run": {k: _plain_attr(a[k]) for k in recording_attrs.RUN_METADATA + ("motor_setting", "headroom_summary")
                if k in a},
    }


def _plain_attr(v):
    v = v.item() if hasattr(v, "item") and getattr(v, "size", 1) == 1 else v
    return v.decode() if isinstance(v, bytes) else v


def measured_events(report: Report) -> dict | None:
    m = report.measured_events
    if m is None:
        return None
    keys = EVENT_KEYS + ("threshold_rad_s", "threshold_m_s", "revolutions", "normal_check_median", "normal_check_n",
                         "detector", "impacts_each_rev", "jumps_each_rev")
    return {k: m.get(k) for k in keys}


def event_rows(report: Report) -> list[dict]:
    keys = ("label", "requested_model", "model", "omega1") + EVENT_KEYS + (
        "detectable_impacts_per_rev", "flights_per_rev", "jumps_indicator", "impacts_indicator", "sign_change",
        "MR13D_max_Nm", "MR13D_min_Nm")
    return [{k: e.get(k) for k in keys} for e in report.events]


def build_summary(report: Report) -> dict:
    sims = [{
        "requested_model": r.requested, "model": r.model, "omega1": r.omega1, "label": r.label,
        "note": r.note, "wall_s": r.wall_s, "revolutions": r.revolutions, "accuracy": r.accuracy,
        "periodic": bool(r.cycle.periodic), "revolution_change": r.cycle.change,
        "revolutions_averaged": int(r.cycle.n_used),
        "operating_point": r.op,     # an identified model's own (labtool fit); None: the report's
        "indicators": {k: v for k, v in r.indicators.items() if not isinstance(v, (np.ndarray, list))},
    } for r in report.sims]
    comps = []
    for c in report.comparisons:
        comps.append({k: c[k] for k in ("requested_model", "model", "omega1", "signal", "label", "covered_fraction",
                                         "periodic", "model_revolutions_averaged", "overall", "per_revolution")})
    out = {
        "format": "labtool.report.summary",
        "format_version": FORMAT_VERSION,
        "measured": measured_info(report),
        "operating_point": report.scene,
        "conditioning": {"grid_points_per_revolution": report.conditioning.n_grid,
                         "harmonics": report.conditioning.n_harmonics,
                         "processing_lowpass_on_simulations": None if report.time_filter is None else {
                             "fs_hz": report.time_filter.fs, "cutoff_hz": report.time_filter.cutoff_hz,
                             "order": report.time_filter.order},
                         "description": report.conditioning.describe() + (
                             "" if report.time_filter is None else "; before that, " + report.time_filter.describe())},
        "simulations": sims,
        "comparisons": comps,
        "headline": headline(report),
        "closest": None if closest(report) is None else closest(report)["label"],
        "robustness": {"rows": report.robustness, **(robust_verdict(report.robustness) or {"robust": None}),
                       # robust = the verdict's: the closest everywhere AND ahead by more than the measurement resolves
                       "robust": None if report.verdict is None else report.verdict["robust"]},
        "verdict": report.verdict,
        "events": event_rows(report),
        "thresholds": {"file": report.thresholds_source, "rows": report.threshold_rows},
        "passed": report.passed,
        "notes": report.notes,
        "wall_s": report.wall_s,
    }
    return plain_json(out)


def to_json(report: Report) -> str:
    return json.dumps(build_summary(report), indent=1, allow_nan=False)
