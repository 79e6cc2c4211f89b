"""``labtool warmup``: compile, once, everything labtool's commands run compiled, into numba's cache.

numba compiles a loop at its first use on a machine and keeps it in its on-disk cache
(labtool.models.dynamics.jit); a command that finds its loops there starts at once. ``warm`` runs
each of STEPS, the work of a command on a small input, so that the first real command finds its
loops compiled: the rigid and elastic models (simulate and the indicators of a sweep), the
stand's twin (``acquire --device sim``), the processing kernels (``process``) and the report's
metrics (``report``). A step whose loops are in the cache already takes well under a second.

The cache is numba's usual one: ``NUMBA_CACHE_DIR`` if set, else ``__pycache__`` beside the
sources (or numba's user-wide cache where those are read-only), so ``make install`` warms the
cache that ``make demo`` and ``make test`` then read.
"""
from __future__ import annotations

import dataclasses
import tempfile
import time
from pathlib import Path
from typing import Callable


@dataclasses.dataclass(frozen=True)
class Step:
    """One piece of warm-up: ``what`` it compiles (labtool.models.dynamics.compiling's wording) and
    ``run(folder)`` doing it in a scratch folder (the files of earlier steps are there)."""

    what: str
    run: Callable[[Path], None]


@dataclasses.dataclass(frozen=True)
class Done:
    """What a step did: functions compiled (0: all were in the cache) and seconds it took."""

    what: str
    compiled: int
    seconds: float


def _models(model: str):
    def run(folder: Path) -> None:
        from labtool.models.dynamics.scene import Scene
        from labtool.models.dynamics.simulate import indicators, simulate

        for scene in (Scene(), Scene(omega1_mode="const", elastic_gap="closed")):
            simulate(scene, model)             # labtool simulate: the Dataset path
            indicators(scene, model)           # doe run, fit: the indicator path
    return run


def _acquire(folder: Path) -> None:
    """What ``labtool acquire --device sim --fast`` runs, through the API the command calls."""
    from labtool.api.acquisition import acquire

    acquire(folder / "warmup.h5", device="sim", stand={"cam_speed_rpm": 180.0, "duration_s": 1.0, "seed": 1},
            realtime=False, warn=lambda msg: None)


def _process(folder: Path) -> None:
    """What ``labtool process`` runs, through the API the command calls."""
    from labtool.api.processing import process

    process(folder / "warmup.h5", folder / "warmup.nc", warn=lambda msg: None)


def _report(folder: Path) -> None:
    from labtool.reports.pipeline import build_report

    build_report(folder / "warmup.nc", ("rigid", "elastic"), ("const", "var"), accuracy="fast", robustness=False)


# what -> (module, compiled function, start of its first argument's numba type or None): the
# function whose cache entry says whether ``what`` is compiled (its main loop; the driver is one
# function for both models, compiled once for each model's struct)
PROBES = {
    "the rigid model": ("labtool.models.dynamics.kernels.dopri5", "run", "RigidModel("),
    "the elastic model": ("labtool.models.dynamics.kernels.dopri5", "run", "ElasticModel("),
    "the stand's twin": ("labtool.models.dynamics.kernels.twin_nb", "advance", None),
    "the processing kernels": ("labtool.processing.kernels", "follower_chain_into", None),
    "the report's metrics": ("labtool.reports.metrics", "_dtw_fill", None),
}
# a command that runs other functions of a group than PROBES' one is probed on its own: the
# report filters with _filtfilt_any and never runs the processing chain
COMMAND_PROBES = {
    ("report", "the processing kernels"): ("labtool.processing.kernels", "_filtfilt_any", None),
}


def _option(args: list[str], name: str, default: str) -> str:
    for k, a in enumerate(args):
        if a == name and k + 1 < len(args):
            return args[k + 1]
        if a.startswith(name + "="):
            return a.split("=", 1)[1]
    return default


def _named_models(text: str) -> list[str]:
    return [f"the {m} model" for m in ("rigid", "elastic") if m in text.split(",")]


def needs(args: list[str]) -> list[str]:
    """What the command line ``args`` (after ``labtool``) will run compiled (PROBES' keys), as far
    as its options tell: the models it names (``simulate --model auto`` starts with the rigid
    model), the twin of the simulated device, the processing kernels, the report's metrics."""
    if not args or {"-h", "--help"} & set(args):
        return []
    command, rest = args[0], args[1:]
    if command == "simulate":
        model = _option(rest, "--model", "auto")
        return _named_models("rigid" if model == "auto" else model)
    if command in ("fit",) or (command == "doe" and rest[:1] == ["run"]):
        return _named_models(_option(rest, "--model", "rigid"))
    if command == "process":
        return ["the processing kernels"]
    if command == "report":
        return _named_models(_option(rest, "--models", "rigid,elastic")) + ["the processing kernels", "the report's metrics"]
    if command == "acquire":
        return ["the stand's twin"] if _option(rest, "--device", "").startswith("sim") else []
    if command == "demo" or (command == "campaign" and rest[:1] == ["run"]):
        return list(PROBES)
    return []


def missing(whats, command: str | None = None) -> list[str]:
    """The ``whats`` whose compiled code for ``command`` is not in numba's cache
    (``compiling.has_entry``)."""
    import importlib

    from labtool.models.dynamics import compiling

    out = []
    for what in whats:
        module, name, first = COMMAND_PROBES.get((command, what), PROBES[what])
        if not compiling.has_entry(getattr(importlib.import_module(module), name), first):
            out.append(what)
    return out


def announce_for(args: list[str]) -> None:
    """Say at once, before the command starts, what it is about to compile (module doc of
    labtool.models.dynamics.compiling): ``labtool report`` reads and aligns its measurement for
    seconds before its first compilation."""
    whats = needs(args)
    if whats:
        from labtool.models.dynamics import compiling

        compiling.announce_now(missing(whats, args[0]))


STEPS = (
    Step("the rigid model", _models("rigid")),
    Step("the elastic model", _models("elastic")),
    Step("the stand's twin", _acquire),
    Step("the processing kernels", _process),
    Step("the report's metrics", _report),
)


def warm(progress: Callable[[int, int, str], None] | None = None, steps=STEPS) -> list[Done]:
    """Run every step (module doc), quietly (the caller shows progress: ``progress(done, total,
    what)`` before each step and once at the end); returns what each did."""
    from labtool.models.dynamics import compiling

    say = progress or (lambda done, total, what: None)
    out = []
    with tempfile.TemporaryDirectory(prefix="labtool-warmup-") as tmp, compiling.quiet():
        for k, step in enumerate(steps):
            say(k, len(steps), step.what)
            n0, _ = compiling.totals()
            t0 = time.perf_counter()
            step.run(Path(tmp))
            out.append(Done(step.what, compiling.totals()[0] - n0, time.perf_counter() - t0))
        say(len(steps), len(steps), "")
    return out
