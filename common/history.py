"""The processing history: every step with its parameters, in order (as ObsPy's trace.stats.processing).

Stored in the output's ``processing_history`` attribute as a JSON list of
``{"step": ..., "parameters": {...}}``, so the report can say exactly what was done.
"""
from __future__ import annotations

import json
import math

import numpy as np


def _plain(v):
    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, np.ndarray):
        return _plain(v.tolist())
    if isinstance(v, (np.floating, float)):
        f = float(v)
        return f if math.isfinite(f) else None
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.bool_,)):
        return bool(v)
    if isinstance(v, str):   # a non-UTF-8 file name (lone surrogates) is kept, escaped as \xff
        return v.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    return v


class History:
    def __init__(self):
        self.steps: list[dict] = []

    def add(self, step: str, **parameters) -> None:
        self.steps.append({"step": step, "parameters": _plain(parameters)})

    def to_json(self) -> str:
        return json.dumps(self.steps, allow_nan=False)

    def __iter__(self):
        return iter(self.steps)
