"""labtool: the software of the STB-216 cam-follower test stand.

A library first, with a command line over it: these functions and the commands of the same names
are two thin layers over the same library calls (docs/architecture.md, "The API layer").

>>> import labtool
>>> from labtool.units import RPM
>>> sim = labtool.simulate(model="rigid", cam_speed=300 * RPM, revolutions=3, rise_only=False)  # doctest: +SKIP
>>> measured = labtool.process("recording.h5", "measured.nc")                                   # doctest: +SKIP
>>> rep = labtool.report("measured.nc", "report.html")                                         # doctest: +SKIP

The operating point and the model options are one type, :class:`OperatingPoint` (SI), with
labtool's defaults (the simulated stand's) and :data:`PAPER_EXPERIMENT` (the paper's simulated
experiment). The names are loaded on first use, so ``import labtool`` costs nothing.
"""
from __future__ import annotations

import importlib

__version__ = "0.1.0"

# public name -> module that defines it
_EXPORTS = {
    "simulate": "labtool.api.simulation",
    "Simulation": "labtool.api.simulation",
    "process": "labtool.api.processing",
    "report": "labtool.api.reporting",
    "fit": "labtool.api.fitting",
    "suggest": "labtool.api.design",
    "acquire": "labtool.api.acquisition",
    "run_design": "labtool.api.doe",
    "kinematics": "labtool.api.kinematics",
    "Kinematics": "labtool.api.kinematics",
    "DesignRun": "labtool.api.doe",
    "Acquisition": "labtool.api.acquisition",
    "OperatingPoint": "labtool.common.operating_point",
    "DEFAULT": "labtool.common.operating_point",
    "PAPER_EXPERIMENT": "labtool.common.operating_point",
    "resolve": "labtool.common.operating_point",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'labtool' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value           # found once
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
