"""Bounded work: before a large request runs, estimate its time and memory; refuse past a limit.

A request whose size the user sets (points per revolution, revolutions, runs of a design) is
measured on two small probes of the same computation, extrapolated linearly, and compared with
the limits: time against ``max_seconds`` (the user's ``--max-seconds``; on a terminal the user may
confirm instead), memory against what the machine has available (never overridable: a run that
swaps for hours helps nobody). The refusal is one line with the estimate, its basis and how to go
on::

    labtool: error: --points 100000000 would take about 21 min and 90 GB of memory (measured 12.6 us
    and 897 bytes per point on 50000 points); 22 GB are available: use fewer --points

Work that takes long or writes much by its nature (a recording, a campaign, a design) is not
refused for it: past ~10 min or ~100 MB it is asked for on a terminal, and elsewhere refused in one
line stating the figures until ``--yes`` is given (``check_work``).

Usage::

    est = probe_linear(lambda n: analyze(..., n_points=n), sizes=(2_000, 50_000), target=points,
                       unit="point", nbytes=lambda ds: 2.1 * ds.nbytes, large_factor=2.0)
    check(est, what=f"--points {points}", max_seconds=max_seconds, reduce="use fewer --points")
"""
from __future__ import annotations

import dataclasses
import math
import os
import time
from typing import Callable

from labtool.common.errors import InputError

DEFAULT_MAX_SECONDS = 120.0
MEMORY_FRACTION = 0.8          # of the memory available now
# a request past either is asked for on a terminal and refused elsewhere unless --yes (check_work)
LONG_RUN_S = 600.0
LARGE_OUTPUT_BYTES = 100e6


@dataclasses.dataclass(frozen=True)
class Estimate:
    """Expected wall time (s) and peak memory (bytes) of a request, and how they were found."""

    seconds: float
    bytes: float
    basis: str


def available_memory() -> float:
    """Bytes of memory available to a new allocation now: Linux MemAvailable (else the free
    physical memory), and no more than the process's address-space limit (ulimit -v) allows."""
    return min(_system_available(), _rlimit_available())


def _rlimit_available() -> float:
    try:
        import resource
        soft, _hard = resource.getrlimit(resource.RLIMIT_AS)
        if soft == resource.RLIM_INFINITY:
            return math.inf
        with open("/proc/self/statm") as f:
            used = int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
        return max(float(soft - used), 0.0)
    except (ImportError, OSError, ValueError):
        return math.inf


def _system_available() -> float:
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):   # pragma: no cover - not Linux
        return math.inf


def probe_linear(run: Callable[[float], object], sizes: tuple[float, float], target: float, unit: str,
                 nbytes: Callable[[object], float] = lambda result: 0.0, large_factor: float = 1.0) -> Estimate:
    """Estimate ``run(target)`` from ``run(warm)`` (pays for compilation and caches, not timed)
    and ``run(probe)``, ``sizes = (warm, probe)``: time and memory per unit as measured on the probe,
    times ``target`` (or the probe's own cost if its result is no larger than the warm-up's). ``nbytes(result)`` is the peak memory of one result. ``large_factor``: the
    measured growth of the cost per unit from the probe's size to sizes 10x larger and more (memory
    bandwidth once the arrays leave the caches), applied past 10x the probe."""
    warm, probe = sizes
    warm_bytes = float(nbytes(run(warm)))
    t0 = time.perf_counter()
    result = run(probe)
    seconds = time.perf_counter() - t0
    probe_bytes = float(nbytes(result))
    if 0 < probe_bytes <= 1.01 * warm_bytes:
        # the result did not grow from the warm-up size to the probe's: the work does not depend
        # on this size (e.g. a model that simulates the rise only, whatever --revolutions says)
        return Estimate(seconds, probe_bytes, f"measured: the work does not grow with the {unit}s")
    per_s, per_b = seconds / probe, probe_bytes / probe
    factor = large_factor if target > 10 * probe else 1.0
    basis = (f"measured {_duration(per_s, per_unit=True)} and {_bytes(per_b)} per {unit} on {probe:g} {unit}s"
             + (f", x{factor:g} for the size" if factor != 1.0 else ""))
    return Estimate(per_s * factor * target, per_b * target, basis)


def check_limit(max_seconds: float, option: str = "--max-seconds") -> float:
    """``max_seconds`` if it is a usable limit (> 0; inf = none), else InputError."""
    if not max_seconds > 0:
        raise InputError(f"{option} must be > 0 s (inf: no limit), got {max_seconds}")
    return max_seconds


def check(estimate: Estimate, what: str, max_seconds: float = DEFAULT_MAX_SECONDS, reduce: str = "",
          confirm: Callable[[str], bool] | None = None) -> None:
    """InputError if ``estimate`` exceeds the memory available or ``max_seconds`` (then
    ``confirm(question)`` is asked first when given: a terminal). ``what`` names the request
    ("--points 1e8"), ``reduce`` how to make it smaller ("use fewer --points")."""
    about = f"{what} would take about {_duration(estimate.seconds)} and {_bytes(estimate.bytes)} of memory " \
            f"({estimate.basis})"
    avail = available_memory() * MEMORY_FRACTION
    if estimate.bytes > avail:
        raise InputError(f"{about}; {_bytes(avail / MEMORY_FRACTION)} are available" + (f": {reduce}" if reduce else ""))
    if estimate.seconds <= max_seconds:
        return
    if confirm is not None and confirm(f"{about}. Run it?"):
        return
    suggestion = _round_up(estimate.seconds * 1.5)
    raise InputError(f"{about}, over the limit of {max_seconds:g} s: give --max-seconds {suggestion:g} to run it"
                     + (f", or {reduce}" if reduce else ""))


def check_work(what: str, seconds: float = 0.0, nbytes: float = 0.0, basis: str = "",
               confirm: Callable[[str], bool] | None = None, yes: bool = False, reduce: str = "") -> None:
    """Before a run longer than LONG_RUN_S (``seconds``, s) or writing more than LARGE_OUTPUT_BYTES
    (``nbytes``): on a terminal ``confirm(question)`` (InputError "not run" when the answer is no);
    elsewhere InputError stating the figures and that ``--yes`` runs it. Nothing when ``yes`` or
    when both are below. ``what`` names the request, ``basis`` how the figures were found,
    ``reduce`` how to make it smaller."""
    over = []
    if seconds > LONG_RUN_S:
        over.append(f"take about {_duration(seconds)}")
    if nbytes > LARGE_OUTPUT_BYTES:
        over.append(f"write about {_bytes(nbytes)}")
    if yes or not over:
        return
    text = f"{what} would {' and '.join(over)}" + (f" ({basis})" if basis else "")
    if confirm is not None:
        if confirm(f"{text}. Run it?"):
            return
        raise InputError(f"not run: {text}")
    limits = " and ".join(x for x, hit in ((f"{LONG_RUN_S / 60:.0f} min", seconds > LONG_RUN_S),
                                           (f"{_bytes(LARGE_OUTPUT_BYTES)}", nbytes > LARGE_OUTPUT_BYTES)) if hit)
    raise InputError(f"{text}, more than {limits}: pass --yes to run it" + (f", or {reduce}" if reduce else ""))


def _round_up(seconds: float) -> float:
    if seconds < 1:
        return 1.0
    magnitude = 10 ** math.floor(math.log10(seconds))
    return math.ceil(seconds / magnitude) * magnitude


def _duration(seconds: float, per_unit: bool = False) -> str:
    if per_unit and seconds < 1e-3:
        return f"{seconds * 1e6:.3g} us"
    if per_unit and seconds < 1:
        return f"{seconds * 1e3:.3g} ms"
    if seconds < 120:
        return f"{seconds:.2g} s" if seconds < 10 else f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    if seconds < 172800:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.3g} days"


def _bytes(n: float) -> str:
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n:.0f} bytes"
