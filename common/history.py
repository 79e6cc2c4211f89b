"""The processing-history schema: every step with the parameters it really used, in order.

As in ObsPy's ``trace.stats.processing``, each step records itself from the call that made it: the
processing code builds one of the step records below, passes its fields to the function that does
the work, and appends the same record to the :class:`History`. So the history can only say what was
done. One schema for the writer (``processing``) and the readers (``reports``): a reader asks for a
step by its class (``History.parse(text).find(Lowpass)``) instead of by key names.

Stored in a NetCDF file as the global attribute ``processing_history``: a JSON list of
``{"step": name, "parameters": {...}}`` (attributes hold no nested objects); in JSON outputs as that
list itself (:meth:`History.to_list`). Units are in the field names (SI).
"""
from __future__ import annotations

import dataclasses
import json
import math
from typing import ClassVar

import numpy as np

from labtool.common.names import utf8_text

ATTRIBUTE = "processing_history"


def _plain(v):
    """JSON-ready Python (numbers stay numbers; NaN/inf become None)."""
    if dataclasses.is_dataclass(v) and not isinstance(v, type):
        return _plain(dataclasses.asdict(v))
    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, np.ndarray):
        return _plain(v.tolist())
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.floating, float)):
        f = float(v)
        return f if math.isfinite(f) else None
    if isinstance(v, str):   # a non-UTF-8 file name (lone surrogates) is kept, escaped as \xff
        return utf8_text(v)
    return v


@dataclasses.dataclass(frozen=True)
class Step:
    """Base of every step record; ``name`` is the key stored in the file."""
    name: ClassVar[str] = ""

    def parameters(self) -> dict:
        return _plain({f.name: getattr(self, f.name) for f in dataclasses.fields(self)})

    def to_dict(self) -> dict:
        return {"step": self.name, "parameters": self.parameters()}


@dataclasses.dataclass(frozen=True)
class Read(Step):
    name: ClassVar[str] = "read"
    source: str
    format: str
    sample_rate_hz: float
    n_samples: int
    channels: list
    complete: bool
    start_time_utc: str
    segments: list
    assumptions: list = dataclasses.field(default_factory=list)  # what the reader assumed, in words


@dataclasses.dataclass(frozen=True)
class ApplyKa(Step):
    """Ka per channel: {name: {"ka_m_s2_per_v", "uncertainty_m_s2_per_v", "source"}}."""
    name: ClassVar[str] = "apply_ka"
    channels: dict


@dataclasses.dataclass(frozen=True)
class CheckChannels(Step):
    """Which recorded channel reads the tangential and which the normal acceleration, and their
    signs (processing/orientation.py): the verdict, what was applied, and the evidence."""
    name: ClassVar[str] = "check_channels"
    verdict: str                 # "as labelled", "corrected", "inconclusive", "not checked"
    swapped: bool                # aE_t and aE_n exchanged by the check
    inverted: list               # channels whose sign is inverted in processing (by --invert or the check)
    inverted_by_option: list     # ... of which by --invert
    r: dict                      # Pearson's r of each channel with an ideal sensor's readings (T, N)
    templates_r: float | None    # r(T, N): near +-1 the check cannot tell the channels apart
    marks: str                   # the cam angle of the span checked: "tacho" or "correlation"
    revolutions: int
    finding: str                 # in words, with the evidence


@dataclasses.dataclass(frozen=True)
class CamAngle(Step):
    name: ClassVar[str] = "cam_angle"
    method: str                  # "tacho" or "correlation"
    revolution_marks: int
    cam_speed_rpm_mean: float
    period_median_s: float
    period_min_s: float
    period_max_s: float
    irregular_revolutions: int
    irregular_tolerance: float   # a revolution outside (1 -/+ tol) x median period is irregular
    law: str
    mechanism: str
    autocorrelation_period_s: float | None = None
    search_rpm: list | None = None       # [lo, hi] rpm searched by the correlation, and why
    search_reason: str | None = None
    search_averaged_samples: int | None = None   # samples averaged into one for the search (slow cams)
    cam_speed_rpm_min: float | None = None       # per revolution, the regular ones
    cam_speed_rpm_max: float | None = None
    cam_speed_trend: float | None = None         # relative change over the recording of a line through them
    assumption: str | None = None                # what the cam angle rests on that the data cannot show


@dataclasses.dataclass(frozen=True)
class Lowpass(Step):
    name: ClassVar[str] = "lowpass"
    kind: str                    # "butterworth"
    order: int
    cutoff_hz: float
    zero_phase: bool
    rule: str
    chunk_samples: int
    overlap_samples: int


@dataclasses.dataclass(frozen=True)
class UndoAcCoupling(Step):
    name: ClassVar[str] = "undo_ac_coupling"
    tau_s: float
    formula: str = "x = y + (1/tau) * integral(y dt), first-order high-pass inverted"


@dataclasses.dataclass(frozen=True)
class RemoveGravity(Step):
    name: ClassVar[str] = "remove_gravity"
    g_m_s2: float
    table_points: int            # psi-dependent gravity reading tabulated over one revolution
    tangential: str = "g cos(phi2)"
    normal: str = "-g sin(phi2)"
    phi2: str = "phiD + psi0 + psi(phi1) from the kinematics"


@dataclasses.dataclass(frozen=True)
class DwellReference(Step):
    name: ClassVar[str] = "dwell_reference"
    middle_fraction: float       # mean over this middle fraction of each dwell
    min_dwell_samples: int
    between_dwells: str = "linear interpolation"


@dataclasses.dataclass(frozen=True)
class Epsilon2(Step):
    name: ClassVar[str] = "epsilon2"
    DE_m: float
    formula: str = "aE_t / DE"


@dataclasses.dataclass(frozen=True)
class Omega2(Step):
    name: ClassVar[str] = "omega2"
    dwell_margin_deg: float
    dwell_margin_samples: int
    method: str = "trapezoidal integral of epsilon2 over each motion interval"
    drift_control: str = "starts at 0 and a linear ramp brings it to 0 in the next dwell"


@dataclasses.dataclass(frozen=True)
class TimeAxis(Step):
    name: ClassVar[str] = "time_axis"
    samples_lost: int
    gaps_with_unknown_loss: int
    rule: str = "time = start + (row + samples lost before it, from the gap events' missing_samples) / fs"


@dataclasses.dataclass(frozen=True)
class Clipping(Step):
    name: ClassVar[str] = "clipping"
    flagged_samples: int
    recorder_clip_events: int
    rail_v: float | None
    min_run_at_extreme: int
    rule: str = ("recorder 'clip' events, |v| within 2.5 LSB of the ADC range when stated, "
                 "or runs of >= min_run_at_extreme samples at the channel's extreme value")


@dataclasses.dataclass(frozen=True)
class CheckNormal(Step):
    name: ClassVar[str] = "check_normal"
    value: float
    quantity: str = "rms(|omega2| - sqrt(aE_n/DE)) / max|omega2| over the motion"


@dataclasses.dataclass(frozen=True)
class CycleAverage(Step):
    name: ClassVar[str] = "cycle_average"
    grid_points: int
    revolutions_used: int
    revolutions_rejected: int


@dataclasses.dataclass(frozen=True)
class Spectra(Step):
    name: ClassVar[str] = "spectra"
    window: str
    nperseg: int
    overlap: float
    segments: int
    segments_skipped_clipped: int
    signal: str = "Ka-scaled, mean removed per segment, unfiltered"


@dataclasses.dataclass(frozen=True)
class Spikes(Step):
    name: ClassVar[str] = "spikes"
    k_sigma: float
    floor_fraction: float
    refractory_s: float
    count: int
    stored: int


STEPS: dict[str, type[Step]] = {c.name: c for c in (Read, CheckChannels, ApplyKa, CamAngle, Lowpass, UndoAcCoupling,
                                                    RemoveGravity, DwellReference, Epsilon2, Omega2, TimeAxis, Clipping,
                                                    CheckNormal, CycleAverage, Spectra, Spikes)}


class History:
    """The ordered steps; ``add`` takes a step record."""

    def __init__(self, steps=()):
        self.steps: list[Step | dict] = list(steps)

    def add(self, step: Step) -> Step:
        if not isinstance(step, Step):
            raise TypeError(f"a history step must be a labtool.common.history.Step, got {type(step).__name__}")
        self.steps.append(step)
        return step

    def to_list(self) -> list[dict]:
        return [s.to_dict() if isinstance(s, Step) else s for s in self.steps]

    def to_json(self) -> str:
        return json.dumps(self.to_list(), allow_nan=False)

    def __iter__(self):
        return iter(self.to_list())

    def find(self, kind: type[Step]) -> Step | None:
        """The last recorded step of class ``kind`` (typed, its fields checked), else None."""
        for s in reversed(self.steps):
            if isinstance(s, kind):
                return s
        return None

    @classmethod
    def parse(cls, value) -> "History":
        """A history from a file: the JSON text of a ``processing_history`` attribute or its list.
        Known steps become their records (unknown fields ignored, missing ones None); other steps stay
        dicts; unreadable input gives an empty history."""
        if isinstance(value, (bytes, str)):
            try:
                value = json.loads(value)
            except ValueError:
                return cls()
        if not isinstance(value, list):
            return cls()
        steps = []
        for item in value:
            if not isinstance(item, dict):
                continue
            kind, par = STEPS.get(item.get("step")), item.get("parameters")
            if kind is None or not isinstance(par, dict):
                steps.append(item)
                continue
            # fields the file lacks read as None (an older or other writer); unknown ones are ignored
            steps.append(kind(**{f.name: par.get(f.name) for f in dataclasses.fields(kind)}))
        return cls(steps)
