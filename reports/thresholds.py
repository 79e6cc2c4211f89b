"""Pass/fail limits on the report's metrics, from a TOML file.

Format (docs/reports.md)::

    [omega2]                      # a signal: omega2 or epsilon2
    iso_rating = 0.58             # a bare number: a minimum for scores, a maximum for errors
    nrmse = { max = 0.10 }        # or an explicit side (min and/or max)

    [epsilon2]
    sg_comprehensive = 0.5

    [apply]                       # optional: where the limits apply (default: everything compared)
    models = ["elastic"]          # rigid, elastic, kinematic
    omega1 = ["const", "var"]
    scope = "overall"             # "overall" (the cycle average) or "each_revolution" (the worst one)

Signed metrics (S&G magnitude, peak and timing errors) are limited in absolute value.
Anything unknown (signal, metric, key, value) is an InputError naming the file and the entry.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from labtool.common.errors import InputError
from labtool.common.schema import ListOf, MapOf, Number, OneOf, String, Table, load_toml
from labtool.reports.metrics import METRICS

SIGNALS = ("omega2", "epsilon2")
MODELS = ("kinematic", "rigid", "elastic")
MODES = ("const", "var")
SCOPES = ("overall", "each_revolution")


@dataclasses.dataclass(frozen=True)
class Limit:
    signal: str
    metric: str
    min: float | None = None
    max: float | None = None

    def check(self, value: float) -> bool:
        v = abs(value) if METRICS[self.metric][1] else value
        if not math.isfinite(v):
            return False
        return (self.min is None or v >= self.min) and (self.max is None or v <= self.max)

    def describe(self) -> str:
        name = f"|{self.metric}|" if METRICS[self.metric][1] else self.metric
        parts = []
        if self.min is not None:
            parts.append(f">= {self.min:g}")
        if self.max is not None:
            parts.append(f"<= {self.max:g}")
        return f"{self.signal} {name} {' and '.join(parts)}"


@dataclasses.dataclass(frozen=True)
class Thresholds:
    limits: tuple
    models: tuple = MODELS
    omega1: tuple = MODES
    scope: str = "overall"
    source: str = ""

    def applies(self, model: str, mode: str) -> bool:
        return model in self.models and mode in self.omega1


_NAMES = {"models": MODELS, "omega1": MODES}
_LIMIT = OneOf(Number(), Table({"min": Number(required=False), "max": Number(required=False)}))
SCHEMA = Table({
    **{signal: MapOf(_LIMIT, keys=tuple(METRICS), noun="metric", required=False) for signal in SIGNALS},
    "apply": Table({
        **{key: OneOf(String(choices=names), ListOf(String(choices=names)), required=False)
           for key, names in _NAMES.items()},
        "scope": String(choices=SCOPES, default="overall"),
    }, default={}),
})


def parse_thresholds(data: dict, source: str = "thresholds") -> Thresholds:
    """Thresholds from the parsed TOML ``data``; ``source`` names the file in error messages."""
    doc = SCHEMA.check(data, where=source)
    limits = []
    for signal in SIGNALS:
        for metric, spec in doc.get(signal, {}).items():
            where = f"{source}: [{signal}] {metric}"
            if isinstance(spec, dict):
                if not spec:
                    raise InputError(f"{where}: expected {{min = ..}} and/or {{max = ..}}, got an empty table")
                lo, hi = spec.get("min"), spec.get("max")
                if lo is not None and hi is not None and lo > hi:
                    raise InputError(f"{where}: min {lo:g} is above max {hi:g}")
                limits.append(Limit(signal, metric, lo, hi))
            elif METRICS[metric][0] == "high":      # a bare number: a minimum for scores, a maximum for errors
                limits.append(Limit(signal, metric, spec, None))
            else:
                limits.append(Limit(signal, metric, None, spec))
    apply = doc["apply"]

    def names(key):
        value = apply.get(key, list(_NAMES[key]))
        return (value,) if isinstance(value, str) else tuple(value)

    return Thresholds(limits=tuple(limits), models=names("models"), omega1=names("omega1"),
                      scope=apply["scope"], source=source)


def load_thresholds(path: Path) -> Thresholds:
    """Read and check a threshold file (TOML, labtool.common.schema)."""
    return parse_thresholds(load_toml(path, "threshold file"), source=f"threshold file {path}")


def evaluate(thresholds: Thresholds, comparisons) -> list[dict]:
    """Check every limit on every comparison it applies to.

    ``comparisons``: iterables of dicts with ``model`` (the level actually used), ``omega1``,
    ``signal``, ``overall`` (metric dict) and ``per_revolution`` (list of metric dicts).
    Returns one row per (limit, comparison): model, omega1, signal, metric, limit, value, passed.
    """
    rows = []
    for comp in comparisons:
        # [apply] models name the model asked for (a fallback level still answers for it)
        if not thresholds.applies(comp.get("requested_model", comp["model"]), comp["omega1"]):
            continue
        for lim in thresholds.limits:
            if lim.signal != comp["signal"]:
                continue
            if thresholds.scope == "overall":
                value = comp["overall"][lim.metric]
            else:
                # the worst revolution: the one that fails, else the one closest to failing
                # metrics of the cycle statistics (band_overlap) exist only overall
                vals = [r.get(lim.metric, comp["overall"][lim.metric]) for r in comp["per_revolution"]] \
                    or [comp["overall"][lim.metric]]
                key = (lambda v: abs(v)) if METRICS[lim.metric][1] else (lambda v: v)
                worst_high = METRICS[lim.metric][0] == "high"
                value = min(vals, key=key) if worst_high else max(vals, key=key)
            rows.append({
                "model": comp["model"], "requested_model": comp.get("requested_model", comp["model"]),
                "omega1": comp["omega1"], "signal": comp["signal"], "metric": lim.metric,
                "limit": lim.describe(), "min": lim.min, "max": lim.max, "scope": thresholds.scope,
                "value": float(value), "passed": bool(lim.check(value)),
            })
    return rows
