r"""The one event record of every simulation dataset (rigid, elastic, twin) and its counts.

A model's dataset carries its contact events on a dimension ``event`` (length 0 allowed), one row
an event, in time order:

=====================  =====  =================================================================
variable               units  meaning
=====================  =====  =================================================================
``event_time``         s      time from the start of the simulation
``event_phi1``         rad    cam angle (unwrapped; 0 at the start of the rise)
``event_kind``         \-     ``"separation"``: a contact ends, a flight begins;
                              ``"contact"``: a flight ends on a flank (a landing)
``event_side``         \-     ``"interior"`` or ``"exterior"`` flank of the groove (the rigid
                              model's inner / outer flank: interior pushes in the rise direction)
``event_v_rel``        m/s    normal relative speed of roller and flank (>= 0; for a contact the
                              approach speed, for a separation the speed it leaves with)
``event_domega2``      rad/s  change of the follower's omega2 the event causes (rigid: the
                              impact's jump; elastic: over the landing's impact window, see
                              labtool.models.dynamics.elastic); 0 for a lift-off, NaN where undefined
``event_percussion``   N s    impulse of the landing (>= 0; rigid: the impact law's; elastic: the
                              contact force over the impact window); NaN for separations
``event_persistent``   bool   separation: it ends a persistent contact (a lift-off, not a
                              rebound); contact: it starts one (the follower settles on the flank)
=====================  =====  =================================================================

A model may add variables of its own on the same dimension (the rigid model's velocities and
energies before and after each impact). Attributes of the dataset: ``event_record`` = RECORD_VERSION.

One definition of each count, used by the models' indicators, labtool.models.dynamics.accuracy and the
report alike (each a boolean mask over the rows, the count its sum):

- ``flights``: separations, each begins a flight (``side=`` restricts to one flank);
- ``impacts``: contacts, every landing that ends a flight (with or without rebound);
- ``lift_offs``: separations from persistent contact (not rebounds);
- ``settles``: contacts that start persistent contact.

The paper's indicator keys (docs/architecture.md, --json contract) are these counts over the rise:
rigid ``jumps`` = flights (Table 2: every flight, by lift-off or by rebound), elastic ``jumps`` =
flights from the interior flank (Table 3: "the relative displacement becomes zero", x leaving the
interior flank), ``impacts`` = impacts in both models.
"""
from __future__ import annotations

import numpy as np
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # xarray is loaded where a Dataset is built (the indicator path of a sweep needs none)
    import xarray as xr

from labtool.common.errors import FileFormatError

RECORD_VERSION = 1
DIM = "event"
SEPARATION, CONTACT = "separation", "contact"
INTERIOR, EXTERIOR = "interior", "exterior"
# integer codes the compiled loops write (kind, side); names are what the dataset stores
KIND_SEPARATION, KIND_CONTACT = 0, 1
SIDE_INTERIOR, SIDE_EXTERIOR = 0, 1
KIND_CODES = {KIND_SEPARATION: SEPARATION, KIND_CONTACT: CONTACT}
SIDE_CODES = {SIDE_INTERIOR: INTERIOR, SIDE_EXTERIOR: EXTERIOR}
# columns of an event row as the compiled loops write it (rows of labtool.models.dynamics.kernels.dopri5.EV_WIDTH
# numbers): the shared columns first, a model's own from N_SHARED on
COL_TIME, COL_PHI1, COL_KIND, COL_SIDE, COL_V_REL, COL_DOMEGA2, COL_PERCUSSION, COL_PERSISTENT = range(8)
N_SHARED = 8

VARIABLES = {
    "event_time": ("s", "time of the contact event from the start of the simulation"),
    "event_phi1": ("rad", "cam angle of the contact event (0 at the start of the rise)"),
    "event_kind": ("1", "separation: a contact ends, a flight begins; contact: a flight ends on a flank"),
    "event_side": ("1", "flank of the groove: interior (pushes in the rise direction) or exterior"),
    "event_v_rel": ("m/s", "normal relative speed of roller and flank (approach speed for a contact)"),
    "event_domega2": ("rad/s", "change of the follower angular velocity caused by the event"),
    "event_percussion": ("N s", "impulse of the landing on the flank (NaN for separations)"),
    "event_persistent": ("1", "separation: ends a persistent contact (lift-off); contact: starts one (settle)"),
}


def record(time, phi1, kind, side, v_rel, domega2, percussion, persistent, extra: dict | None = None) -> dict:
    """The data variables of an event record (``xr.Dataset(data_vars=...)``), rows in time order.

    ``kind`` and ``side``: names or the integer codes of KIND_CODES / SIDE_CODES; the other
    columns arrays of one value per event in the units of VARIABLES. ``extra``: a model's own
    columns, name -> (values, units, long_name).
    """
    time = np.asarray(time, dtype=float).reshape(-1)
    cols = {
        "event_time": time,
        "event_phi1": np.asarray(phi1, dtype=float).reshape(-1),
        "event_kind": _names(kind, KIND_CODES),
        "event_side": _names(side, SIDE_CODES),
        "event_v_rel": np.abs(np.asarray(v_rel, dtype=float).reshape(-1)),
        "event_domega2": np.asarray(domega2, dtype=float).reshape(-1),
        "event_percussion": np.asarray(percussion, dtype=float).reshape(-1),
        "event_persistent": np.asarray(persistent, dtype=bool).reshape(-1),
    }
    for name, values in cols.items():
        if values.shape != time.shape:
            raise ValueError(f"event record: {name} has {values.size} rows, event_time {time.size}")
    out = {name: (DIM, values, {"units": VARIABLES[name][0], "long_name": VARIABLES[name][1]})
           for name, values in cols.items()}
    for name, (values, units, long_name) in (extra or {}).items():
        out[name] = (DIM, np.asarray(values).reshape(-1), {"units": units, "long_name": long_name})
    return out


def from_rows(rows, extra: dict | None = None) -> dict:
    """``record`` from event rows (n, >= N_SHARED) in the column layout above; ``extra``: a model's
    own columns, name -> (column, units, long_name)."""
    rows = np.asarray(rows, dtype=float)
    if rows.ndim != 2 or rows.shape[1] < N_SHARED:
        raise ValueError(f"event rows must be an array (n, >= {N_SHARED}), got shape {rows.shape}")
    return record(rows[:, COL_TIME], rows[:, COL_PHI1], rows[:, COL_KIND].astype(int), rows[:, COL_SIDE].astype(int),
                  rows[:, COL_V_REL], rows[:, COL_DOMEGA2], rows[:, COL_PERCUSSION], rows[:, COL_PERSISTENT] > 0,
                  {name: (rows[:, col], units, long_name) for name, (col, units, long_name) in (extra or {}).items()})


def _names(values, codes: dict) -> np.ndarray:
    arr = np.asarray(values).reshape(-1)
    if arr.dtype.kind in "iuf":
        # integer codes (what the compiled loops write) -> names, vectorised: the codes are 0 .. n-1
        table = np.array([codes[k] for k in range(len(codes))])
        ints = arr.astype(np.int64)
        if ints.size and (ints.min() < 0 or ints.max() >= table.size or np.any(ints != arr)):
            raise ValueError(f"event record: unknown code(s) {sorted(set(arr.tolist()) - set(codes))}; "
                             f"known: {sorted(codes)}")
        return table[ints] if arr.size else np.zeros(0, dtype="<U10")
    out = np.asarray(arr, dtype=str) if arr.size else np.zeros(0, dtype="<U10")
    bad = set(out.tolist()) - set(codes.values())
    if bad:
        raise ValueError(f"event record: unknown value(s) {sorted(bad)}; known: {sorted(codes.values())}")
    return out


def read(ds: xr.Dataset) -> xr.Dataset:
    """The event record of a simulation dataset (the ``event`` variables only), checked.

    FileFormatError when the dataset has none (a kinematic result, or a file written before the
    record existed) or when its columns disagree.
    """
    missing = [name for name in VARIABLES if name not in ds.variables]
    if missing:
        raise FileFormatError("the simulation dataset has no event record (missing "
                              f"{', '.join(missing)}); simulate it again with this labtool")
    ev = ds[list(VARIABLES) + [v for v in ds.data_vars if v.startswith("event_") and v not in VARIABLES
                               and ds[v].dims == (DIM,)]]
    ev = ev.drop_vars([c for c in ev.coords if c != DIM])
    kinds = set(np.asarray(ev["event_kind"].values, dtype=str).tolist())
    if kinds - set(KIND_CODES.values()):
        raise FileFormatError(f"event record: unknown event_kind value(s) {sorted(kinds - set(KIND_CODES.values()))}")
    return ev


# ------------------------------------------------------------------ one definition of each count

# ``ev`` below: an event record, as a Dataset (``read``) or any mapping of the variable names to
# arrays (what ``columns`` returns, cheaper inside a model)

def columns(record: dict) -> dict:
    """name -> values of a ``record`` (``record(...)``'s data variables)."""
    return {name: spec[1] for name, spec in record.items()}


def _col(ev, name: str) -> np.ndarray:
    return np.asarray(ev[name])


def _side_mask(ev, side: str | None) -> np.ndarray:
    kinds = _col(ev, "event_kind")
    if side is None:
        return np.ones(kinds.size, dtype=bool)
    if side not in (INTERIOR, EXTERIOR):
        raise ValueError(f"side must be {INTERIOR!r} or {EXTERIOR!r}, got {side!r}")
    return _col(ev, "event_side").astype(str) == side


def is_flight(ev, side: str | None = None) -> np.ndarray:
    """Rows that begin a flight: every separation (from ``side`` only, if given)."""
    return (_col(ev, "event_kind").astype(str) == SEPARATION) & _side_mask(ev, side)


def is_impact(ev, side: str | None = None) -> np.ndarray:
    """Rows that end a flight on a flank: every contact (landing), with or without rebound."""
    return (_col(ev, "event_kind").astype(str) == CONTACT) & _side_mask(ev, side)


def is_lift_off(ev, side: str | None = None) -> np.ndarray:
    """Separations from persistent contact (a lift-off, not a rebound)."""
    return is_flight(ev, side) & _col(ev, "event_persistent").astype(bool)


def is_settle(ev, side: str | None = None) -> np.ndarray:
    """Contacts that start persistent contact (the follower stays on the flank)."""
    return is_impact(ev, side) & _col(ev, "event_persistent").astype(bool)


def flights(ev, side: str | None = None) -> int:
    return int(is_flight(ev, side).sum())


def impacts(ev, side: str | None = None) -> int:
    return int(is_impact(ev, side).sum())


def lift_offs(ev, side: str | None = None) -> int:
    return int(is_lift_off(ev, side).sum())


def settles(ev, side: str | None = None) -> int:
    return int(is_settle(ev, side).sum())


# the same counts on the compiled loops' event rows (integer codes in COL_KIND and COL_SIDE), for
# the paths that never build the named record (tests/test_events.py holds them equal to the above)

_SIDE_BY_NAME = {name: code for code, name in SIDE_CODES.items()}


def _count_rows(rows, kind: int, side: str | None) -> int:
    """Rows of ``kind`` (on ``side``): as few numpy calls as possible, a run's rows are ~10-100."""
    of_kind = rows[:, COL_KIND] == kind
    if side is None:
        return int(np.count_nonzero(of_kind))
    if side not in _SIDE_BY_NAME:
        raise ValueError(f"side must be {INTERIOR!r} or {EXTERIOR!r}, got {side!r}")
    return int(np.count_nonzero(of_kind & (rows[:, COL_SIDE] == _SIDE_BY_NAME[side])))


def flights_in_rows(rows, side: str | None = None) -> int:
    """``flights`` of event rows (n, >= N_SHARED)."""
    return _count_rows(rows, KIND_SEPARATION, side)


def impacts_in_rows(rows, side: str | None = None) -> int:
    """``impacts`` of event rows (n, >= N_SHARED)."""
    return _count_rows(rows, KIND_CONTACT, side)


def in_rise(ev, rise_angle: float) -> np.ndarray:
    """Rows whose cam angle lies in a rise, 0 <= phi1 mod 2 pi < rise_angle (rad)."""
    return np.mod(_col(ev, "event_phi1").astype(float), 2.0 * np.pi) < rise_angle


def within_rise(ev, rise_angle: float):
    """The rows of ``in_rise`` (a Dataset's ``isel``, or a mapping's arrays indexed)."""
    keep = in_rise(ev, rise_angle)
    if hasattr(ev, "isel"):                # a Dataset (without loading xarray for a mapping)
        return ev.isel({DIM: keep})
    return {name: np.asarray(values)[keep] for name, values in ev.items()}
