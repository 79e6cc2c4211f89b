"""The one per-process memo of speed-independent tables (what depends on the mechanism and the cam
program only): the elastic model's cam-angle grids and stroke spline (labtool.models.mechanism.cam_tables),
the cam's sense of rotation (labtool.models.mechanism.cam_profile.cached_sense) and the rigid model's cam
and follower tables (labtool.models.dynamics.rigid.build_model)."""
from __future__ import annotations

import collections
import dataclasses
import threading

import numpy as np

CACHE_SIZE = 64         # tables kept per process (a rise grid of 4001 angles is ~0.4 MB; the elastic
                        # output grid of one cam speed 0.2-0.6 MB, its instants and moment terms two
                        # entries: a sweep over 16+ speeds keeps them all)

_cache: "collections.OrderedDict[tuple, object]" = collections.OrderedDict()
_lock = threading.Lock()


def cached(key: tuple, build):
    """``build()`` once per ``key`` per process (the CACHE_SIZE most recent kept). A result that is
    a numpy array, or a dataclass's numpy arrays, are made read-only: every caller shares them."""
    with _lock:
        hit = _cache.get(key)
        if hit is not None:
            _cache.move_to_end(key)
            return hit
    value = build()
    if isinstance(value, np.ndarray):
        value.flags.writeable = False
    for f in dataclasses.fields(value) if dataclasses.is_dataclass(value) else ():
        arr = getattr(value, f.name)
        if isinstance(arr, np.ndarray):
            arr.flags.writeable = False
    with _lock:
        _cache[key] = value
        while len(_cache) > CACHE_SIZE:
            _cache.popitem(last=False)
    return value


def clear_cache() -> None:
    """Forget every cached table (benchmarks that time a first call use it)."""
    with _lock:
        _cache.clear()
