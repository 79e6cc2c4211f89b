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
import tomllib
from pathlib import Path

from common.errors import InputError
from reports.metrics import METRICS

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


def _number(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(f"{where}: a limit must be a finite number, got {value!r}")
    return float(value)


def _names(value, allowed, where: str) -> tuple:
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise InputError(f"{where}: expected a list of names")
    bad = [v for v in value if v not in allowed]
    if bad:
        raise InputError(f"{where}: unknown {', '.join(map(repr, bad))}; known: {', '.join(allowed)}")
    return tuple(value)


def parse_thresholds(data: dict, source: str = "thresholds") -> Thresholds:
    """Thresholds from the parsed TOML ``data``; ``source`` names the file in error messages."""
    limits = []
    apply = {}
    for key, table in data.items():
        if key == "apply":
            if not isinstance(table, dict):
                raise InputError(f"{source}: [apply] must be a table")
            apply = table
            continue
        if key not in SIGNALS:
            raise InputError(f"{source}: unknown signal [{key}]; known: {', '.join(SIGNALS)}, apply")
        if not isinstance(table, dict):
            raise InputError(f"{source}: [{key}] must be a table of metric = limit")
        for metric, spec in table.items():
            where = f"{source} [{key}] {metric}"
            if metric not in METRICS:
                raise InputError(f"{source}: unknown metric '{metric}' in [{key}]; known: {', '.join(METRICS)}")
            if isinstance(spec, dict):
                extra = set(spec) - {"min", "max"}
                if extra or not spec:
                    raise InputError(f"{where}: expected {{min = ..}} and/or {{max = ..}}, got keys {sorted(spec)}")
                lo = _number(spec["min"], where) if "min" in spec else None
                hi = _number(spec["max"], where) if "max" in spec else None
                if lo is not None and hi is not None and lo > hi:
                    raise InputError(f"{where}: min {lo:g} is above max {hi:g}")
                limits.append(Limit(key, metric, lo, hi))
            else:
                v = _number(spec, where)
                better = METRICS[metric][0]
                limits.append(Limit(key, metric, v, None) if better == "high" else Limit(key, metric, None, v))
    extra = set(apply) - {"models", "omega1", "scope"}
    if extra:
        raise InputError(f"{source}: unknown key(s) in [apply]: {', '.join(sorted(extra))}; known: models, omega1, scope")
    scope = apply.get("scope", "overall")
    if scope not in SCOPES:
        raise InputError(f"{source}: [apply] scope must be one of {', '.join(SCOPES)}, got {scope!r}")
    return Thresholds(
        limits=tuple(limits),
        models=_names(apply.get("models", list(MODELS)), MODELS, f"{source} [apply] models"),
        omega1=_names(apply.get("omega1", list(MODES)), MODES, f"{source} [apply] omega1"),
        scope=scope,
        source=source,
    )


def load_thresholds(path: Path) -> Thresholds:
    """Read and check a threshold file (TOML)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"threshold file {path} not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read threshold file {path}: {exc}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"threshold file {path} is not valid TOML: {exc}") from None
    return parse_thresholds(data, source=str(path))


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
