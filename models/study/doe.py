"""Factorial designs of simulated experiments (paper sec. 2.2): factors, levels, runs, coding.

A design is a list of :class:`Factor` (letter name ``A``, ``B``, ...; symbol ``Fu``, ``j``, ``n1``,
``Jt`` ...; unit; two or more levels) and the full factorial of their levels in the paper's run
order: run 1 has every factor at level 1 and the last factor changes fastest (Table 2's order).

Factor values are kept in the units of the factor file (the table edge: N, mm, rpm, ...); they are
converted to the SI fields of :class:`labtool.models.dynamics.scene.Scene` once, in :func:`scene_for_run`, through
the table :data:`SCENE_FACTORS` (symbol -> Scene field, accepted units and their scale to the
field's unit).

Factor files:

* CSV with columns ``factor,symbol,unit,level_1,level_2[,level_3 ...]`` (as
  ``models/data/table1_factors.csv``); a factor with fewer levels leaves its later cells empty.
* TOML with one ``[[factor]]`` table per factor: ``name = "A"``, ``symbol = "Fu"``, ``unit = "N"``,
  ``levels = [0, 65]``.

Result tables (CSV shaped like the paper's Tables 2 and 3) name the level columns
``<name>_<symbol>_level`` (``A_Fu_level``) holding level indices 1, 2, ...
"""
from __future__ import annotations

import csv
import dataclasses
import io
import itertools
import math
import re
import tomllib
from pathlib import Path

import numpy as np

from labtool.common.units import RPM

from labtool.common.errors import FileFormatError, InputError, interrupt_cause

# symbol -> (Scene field, {unit: scale from the factor's unit to the field's unit}, description)
SCENE_FACTORS: dict[str, tuple[str, dict[str, float], str]] = {
    "Fu": ("Fu", {"N": 1.0}, "load force at point N"),
    "j": ("backlash", {"mm": 1e-3, "m": 1.0, "um": 1e-6}, "cam-follower groove backlash"),
    "n1": ("cam_speed", {"rpm": RPM, "rad/s": 1.0}, "nominal cam speed"),
    "Jt": ("jt_factor", {"factor_of_nominal": 1.0, "-": 1.0, "": 1.0},
           "inertia factor of the follower side"),
    "k": ("restitution", {"-": 1.0, "": 1.0}, "Newton's restitution coefficient"),
    "lw": ("contact_length", {"mm": 1e-3, "m": 1.0}, "roller-groove contact length"),
    "Kc": ("kc_factor", {"factor_of_nominal": 1.0, "-": 1.0, "": 1.0}, "contact stiffness factor"),
}

_NAME_RE = re.compile(r"^[A-Z]$")


@dataclasses.dataclass(frozen=True)
class Factor:
    """One factor of a design.

    name    one capital letter (A, B, ...), the paper's factor label and the ANOVA term letter
    symbol  the physical quantity (a key of SCENE_FACTORS to drive a simulation)
    unit    unit of the level values (edge units: N, mm, rpm, factor_of_nominal ...)
    levels  level values, level 1 first (at least two, all different)
    """

    name: str
    symbol: str
    unit: str
    levels: tuple[float, ...]

    def __post_init__(self):
        if not _NAME_RE.match(self.name):
            raise InputError(f"factor name must be one capital letter A-Z, got '{self.name}'")
        if not re.match(r"^[A-Za-z][A-Za-z0-9]*$", self.symbol):
            raise InputError(f"factor {self.name}: symbol must be letters and digits, got '{self.symbol}'")
        if len(self.levels) < 2:
            raise InputError(f"factor {self.name} ({self.symbol}) has {len(self.levels)} level; "
                             "a factor needs at least two levels")
        if any(not math.isfinite(v) for v in self.levels):
            raise InputError(f"factor {self.name} ({self.symbol}): levels must be finite numbers, got {list(self.levels)}")
        if len(set(self.levels)) != len(self.levels):
            raise InputError(f"factor {self.name} ({self.symbol}): levels repeat a value: {list(self.levels)}")

    @property
    def column(self) -> str:
        """Name of the level column in a result table (``A_Fu_level``)."""
        return f"{self.name}_{self.symbol}_level"

    @property
    def unit_shown(self) -> str:
        """The unit as tables and plots print it ('' for a factor of the nominal value)."""
        return "" if self.unit in ("", "-", "factor_of_nominal") else self.unit

    @property
    def heading(self) -> str:
        """A table heading in physical units: ``Fu [N]``, ``Jt [x nominal]``."""
        unit = "x nominal" if self.unit == "factor_of_nominal" else (self.unit_shown or "-")
        return f"{self.symbol} [{unit}]"

    def level_text(self, level: int) -> str:
        """Level ``level`` (1-based) with its value and unit: ``Fu = 65 N``, ``Jt = 4 x``."""
        v = self.levels[level - 1]
        if self.unit == "factor_of_nominal":
            return f"{self.symbol} = {v:g} x"
        return f"{self.symbol} = {v:g}" + (f" {self.unit_shown}" if self.unit_shown else "")


def table1_factors() -> list[Factor]:
    """The paper's Table 1: A = Fu [N], B = j [mm], C = n1 [rpm], D = Jt [factor of nominal]."""
    from importlib import resources
    text = resources.files("labtool.models.data").joinpath("table1_factors.csv").read_text(encoding="utf-8")
    return _factors_from_csv(text, "table1_factors.csv")


def read_factors(path: str | Path) -> list[Factor]:
    """Factors from a CSV or TOML file (see the module docstring for both layouts)."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"factor file {path} is a folder; give the CSV or TOML file inside it")
    if path.exists() and not path.is_file():
        raise InputError(f"factor file {path} is not a regular file (a pipe or a device); give a CSV or TOML file")
    if not path.is_file():
        raise InputError(f"factor file {path} does not exist")
    if path.suffix.lower() == ".toml":
        try:
            data = tomllib.loads(path.read_text())
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise FileFormatError(f"{path}: not a valid TOML file ({exc})") from None
        entries = data.get("factor")
        if not isinstance(entries, list) or not entries:
            raise FileFormatError(f"{path}: expected one [[factor]] table per factor")
        factors = []
        for i, e in enumerate(entries, 1):
            if not isinstance(e, dict):
                raise FileFormatError(f"{path}: factor #{i} is {e!r}, not a table; write one [[factor]] table per "
                                      "factor with name, symbol, unit and levels")
            missing = [k for k in ("name", "symbol", "levels") if k not in e]
            if missing:
                raise FileFormatError(f"{path}: factor #{i} lacks {', '.join(missing)}")
            unknown = sorted(set(e) - {"name", "symbol", "unit", "levels"})
            if unknown:
                raise FileFormatError(f"{path}: factor #{i} has unknown key(s) {', '.join(unknown)}")
            levels = e["levels"]
            if not isinstance(levels, list) or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in levels):
                raise FileFormatError(f"{path}: factor {e['name']}: levels must be a list of numbers")
            factors.append(Factor(str(e["name"]), str(e["symbol"]), str(e.get("unit", "")),
                                  tuple(float(v) for v in levels)))
        return _check_factor_set(factors, path)
    try:
        text = path.read_text(encoding="utf-8-sig")       # a spreadsheet's byte-order mark dropped
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{path}: not a readable CSV file ({exc})") from None
    return _factors_from_csv(text, path)


def _factors_from_csv(text: str, source) -> list[Factor]:
    """Factors from the text of a factor CSV (the csv module's dialect: commas, double quotes).
    Rows with every cell empty are skipped (a spreadsheet's trailing rows); an empty level cell is
    no level; every other level cell must be a finite number (pandas, which read these files
    before, dropped cells such as 'NA' or 'nan' without a word)."""
    try:
        table = [r for r in csv.reader(io.StringIO(text)) if any(c.strip() for c in r)]
    except csv.Error as exc:
        raise FileFormatError(f"{source}: not a readable CSV file ({exc})") from None
    if not table:
        raise FileFormatError(f"{source}: not a readable CSV file (it is empty)")
    header = [c.strip() for c in table[0]]
    required = ["factor", "symbol", "unit"]
    missing = [c for c in required if c not in header]
    level_cols = [c for c in header if re.match(r"^level_\d+$", c)]
    if missing or not level_cols:
        raise FileFormatError(f"{source}: factor CSV needs columns factor,symbol,unit,level_1,level_2[,...]"
                              + (f"; missing {', '.join(missing)}" if missing else "; no level_N columns"))
    unknown = [c or "(unnamed)" for c in header if c not in required and c not in level_cols]
    if unknown:
        raise FileFormatError(f"{source}: unknown column(s) {', '.join(unknown)} in the factor CSV")
    repeated = sorted({c for c in header if header.count(c) > 1})
    if repeated:
        raise FileFormatError(f"{source}: column(s) {', '.join(repeated)} repeated in the factor CSV")
    level_cols.sort(key=lambda c: int(c.split("_")[1]))
    expected = [f"level_{k}" for k in range(1, len(level_cols) + 1)]
    if level_cols != expected:
        missing_levels = sorted(set(expected) - set(level_cols), key=lambda c: int(c.split("_")[1]))
        raise FileFormatError(f"{source}: level columns {', '.join(level_cols)} skip "
                              f"{', '.join(missing_levels) or 'a number'}; number them level_1, level_2, ... "
                              "without a gap (a level's index is its number in the result table)")
    factors = []
    for line, cells in enumerate(table[1:], 2):
        if len(cells) > len(header):
            raise FileFormatError(f"{source}: not a readable CSV file (row {line} has {len(cells)} cells, the "
                                  f"header {len(header)})")
        row = dict(zip(header, cells + [""] * (len(header) - len(cells))))
        values = []
        for c in level_cols:
            v = row[c].strip()
            if not v:
                continue
            try:
                value = float(v)
            except ValueError:
                value = math.nan
            if not math.isfinite(value):
                raise FileFormatError(f"{source}: factor {row['factor']}: level '{v}' is not a number")
            values.append(value)
        factors.append(Factor(row["factor"], row["symbol"], row["unit"].strip(), tuple(values)))
    return _check_factor_set(factors, source)


def _check_factor_set(factors: list[Factor], source) -> list[Factor]:
    if not factors:
        raise InputError(f"{source}: no factors")
    for attr in ("name", "symbol"):
        seen = [getattr(f, attr) for f in factors]
        dup = sorted({s for s in seen if seen.count(s) > 1})
        if dup:
            raise InputError(f"{source}: factor {attr} repeated: {', '.join(dup)}")
    return factors


def full_factorial(factors: list[Factor]):
    """All level combinations, the paper's run order (first factor slowest, last fastest).

    Columns: ``run`` (1-based), one level-index column per factor (``A_Fu_level``, values 1..L)
    and one value column per factor named by its symbol (in the factor's unit).
    """
    rows = []
    for run, idx in enumerate(itertools.product(*[range(len(f.levels)) for f in factors]), 1):
        row = {"run": run}
        for f, i in zip(factors, idx):
            row[f.column] = i + 1
        for f, i in zip(factors, idx):
            row[f.symbol] = f.levels[i]
        rows.append(row)
    import pandas as pd           # the table of a small design; a sweep's process does not load pandas
    return pd.DataFrame(rows)



def scene_for_run(base, factors: list[Factor], values: dict[str, float]):
    """The Scene of one run: ``base`` with each factor's field set to its value, converted to SI.

    ``values`` maps factor symbols to values in the factor's unit.
    """
    changes = {}
    for f in factors:
        field, scale, _ = scene_field(f)
        changes[field] = values[f.symbol] * scale
    return base.replace(**changes)


def scene_field(f: Factor) -> tuple[str, float, str]:
    """(Scene field, scale of the factor's unit to the field, description) or InputError."""
    try:
        field, units, text = SCENE_FACTORS[f.symbol]
    except KeyError:
        raise InputError(f"factor {f.name}: no simulation parameter '{f.symbol}'; "
                         f"known symbols: {', '.join(SCENE_FACTORS)}") from None
    if f.unit not in units:
        raise InputError(f"factor {f.name} ({f.symbol}): unit '{f.unit}' not understood; "
                         f"use one of {', '.join(repr(u) for u in units if u)}")
    return field, units[f.unit], text


def _largest_backlash(base) -> float | None:
    """The largest backlash (m) the groove of ``base``'s mechanism and law takes (the models' own
    check, labtool.models.dynamics.validity.check_scene, by bisection to 1e-12 relative); None when
    it takes none (the law itself undercuts the groove)."""
    from labtool.models.dynamics import validity

    def takes(j: float) -> bool:
        try:
            validity.check_scene(base.replace(backlash=j))
            return True
        except InputError:
            return False

    if not takes(0.0):
        return None
    lo, hi = 0.0, 1e-3
    while takes(hi):
        if hi > 1.0:                 # a groove no backlash undercuts (not a real cam)
            return math.inf
        lo, hi = hi, 2.0 * hi
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if takes(mid) else (lo, mid)
    return lo


# --------------------------------------------------------------------------------------------
# the runs of a design: one simulation per run (execution backends live in the execution layer)

# response columns of the result table per model level, in the paper's order (Tables 2 and 3)
RESPONSES_BY_MODEL = {
    "rigid": ("MR13D_max_Nm", "dphi2_max_deg", "domega2_max_rad_s", "domega1_max_rad_s",
              "percussion_max_Ns", "jumps"),
    "elastic": ("MR13D_max_Nm", "MR13D_min_Nm", "xel_max_mm", "xel_min_mm", "jumps", "impacts"),
    "kinematic": ("MR13D_max_Nm", "MR13D_min_Nm"),
}
COUNT_RESPONSES = ("jumps", "impacts")   # integers in the result table

RESPONSE_ATTRS = {  # units and long names of the NetCDF variables (paper's indicator names)
    "MR13D_max_Nm": ("N m", "(MR13D)max, moment about D of the cam-on-follower reaction, max over the rise"),
    "MR13D_min_Nm": ("N m", "(MR13D)min, moment about D of the cam-on-follower reaction, min over the rise"),
    "dphi2_max_deg": ("deg", "(phi2rcj - phi2rfj)max, follower angle deviation due to the backlash"),
    "domega2_max_rad_s": ("rad/s", "(omega2rcj - omega2rfj)max, follower angular velocity deviation"),
    "domega1_max_rad_s": ("rad/s", "(omega1rcj - omega1rfj)max, cam angular velocity deviation"),
    "percussion_max_Ns": ("N s", "(Percussion_int)max, largest cam-follower impact percussion"),
    "jumps": ("1", "number of follower jumps on the rise"),
    "impacts": ("1", "number of cam-follower impacts on the rise"),
    "xel_max_mm": ("mm", "(xel)max, largest relative cam-follower displacement along the normal"),
    "xel_min_mm": ("mm", "(xel)min, smallest relative cam-follower displacement along the normal"),
}


def simulate_run(scene, model: str) -> dict:
    """Run one simulation; never raises for a user-side failure (it is reported per run).

    Returns ``{"ok": True, "indicators": {...}, "wall_s": s}`` or ``{"ok": False, "error": msg}``.
    """
    import time

    from labtool.common.errors import LabtoolError
    from labtool.models.dynamics.simulate import indicators
    t0 = time.perf_counter()
    try:
        found = indicators(scene, model)          # the Dataset-free path: only the indicators are kept
    except LabtoolError as exc:
        return {"ok": False, "error": str(exc)}
    except Exception as exc:  # a bug in a model must not lose the other runs
        stop = interrupt_cause(exc)
        if stop is not None:      # Ctrl-C or SIGTERM in the compiled model: the run was stopped, not failed
            raise stop from None
        return {"ok": False, "error": f"{type(exc).__name__}: {exc}"}
    found.pop("wall_s", None)
    ind = {k: (None if v is None else float(v)) for k, v in found.items()
           if isinstance(v, (int, float, np.floating, np.integer, type(None))) and not isinstance(v, bool)}
    return {"ok": True, "indicators": ind, "wall_s": time.perf_counter() - t0}


def responses_for(model: str) -> tuple[str, ...]:
    try:
        return RESPONSES_BY_MODEL[model]
    except KeyError:
        raise InputError(f"doe run needs --model one of {', '.join(RESPONSES_BY_MODEL)}, got '{model}'") from None


@dataclasses.dataclass(frozen=True)
class Design:
    """The full factorial of ``factors`` run with ``model`` on ``base`` (a Scene), without listing it.

    Run ``i`` (0-based; the paper's run number is ``i + 1``) has the level indices of
    ``numpy.unravel_index(i, shape)``: the paper's order, first factor slowest. Nothing is built
    per run until it is asked for, so a design of 10^6 runs costs nothing to hold; ``row(i)`` runs
    one simulation (a pure function of the design and ``i``, the unit an executor maps).
    """

    factors: tuple[Factor, ...]
    base: object                 # labtool.models.dynamics.scene.Scene
    model: str

    def __post_init__(self):
        object.__setattr__(self, "factors", tuple(self.factors))
        responses_for(self.model)

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(len(f.levels) for f in self.factors)

    @property
    def responses(self) -> tuple[str, ...]:
        return RESPONSES_BY_MODEL[self.model]

    @property
    def level_columns(self) -> list[str]:
        return [f.column for f in self.factors]

    @property
    def columns(self) -> list[str]:
        """Columns of the result table (Tables 2/3): run, level columns, responses."""
        return ["run"] + self.level_columns + list(self.responses)

    def __len__(self) -> int:
        return math.prod(self.shape)

    def validate(self) -> None:
        """Refuse a factor symbol, unit or level value that no run could use (InputError naming the
        factor, the level and its value in the factor's unit), before anything runs: each level of
        each factor is set alone on the base scene, which applies the bounds ``simulate`` applies
        (the Scene's, the cam speed range), and the groove is checked as the rigid and elastic models
        check it (labtool.models.dynamics.validity.check_scene: an undercut, a self-locking pressure
        angle). Each check depends on one factor alone (the groove on the law and the backlash), so
        this covers every combination."""
        from labtool.models.dynamics import validity

        for f in self.factors:
            field, scale, _ = scene_field(f)
            for k, v in enumerate(f.levels, 1):
                unit = f" {f.unit}" if f.unit not in ("", "-") else ""
                where = f"factor {f.name} ({f.symbol}) level {k} = {v:g}{unit}"
                try:
                    scene = self.base.replace(**{field: v * scale})
                except InputError as exc:
                    # the owner names the command-line option that sets the field; a factor file is
                    # fixed by its level, not by that option
                    raise InputError(f"{where}: {re.sub(r' [(]--[a-z0-9-]+[)]$', '', str(exc))}") from None
                if self.model == "kinematic":      # the kinematic level evaluates the law alone (warnings)
                    continue
                try:
                    validity.check_scene(scene)
                except InputError as exc:
                    largest = _largest_backlash(self.base) if field == "backlash" else None
                    if largest is None:
                        raise InputError(f"{where}: {exc}") from None
                    raise InputError(f"{where}: the groove's outer flank would be undercut; with the {scene.law} law "
                                     f"this cam takes a backlash up to {largest / scale:.4g} {f.unit} (the models "
                                     "refuse more): use levels below it") from None

    def level_indices(self, i: int) -> tuple[int, ...]:
        """1-based level index of each factor in run ``i`` (0-based)."""
        return tuple(int(k) + 1 for k in np.unravel_index(i, self.shape))

    def scene(self, i: int):
        """The Scene of run ``i`` (0-based)."""
        idx = self.level_indices(i)
        return scene_for_run(self.base, list(self.factors),
                             {f.symbol: f.levels[k - 1] for f, k in zip(self.factors, idx)})

    def row(self, i: int) -> dict:
        """Simulate run ``i``: {run, level columns, responses (None if failed), wall_s, error}."""
        out = {"run": i + 1, **dict(zip(self.level_columns, self.level_indices(i)))}
        try:
            scene = self.scene(i)
        except InputError as exc:
            res = {"ok": False, "error": str(exc)}
        else:
            res = simulate_run(scene, self.model)
        ind = res.get("indicators", {})
        missing = [r for r in self.responses if res["ok"] and r not in ind]
        if missing:
            res = {"ok": False, "error": f"model '{self.model}' does not compute {', '.join(missing)}"}
        for r in self.responses:
            out[r] = ind.get(r) if res["ok"] else None
        out["wall_s"] = res.get("wall_s")
        out["error"] = "" if res["ok"] else res["error"]
        return out

    def fingerprint(self) -> dict:
        """What identifies the design's results (a resumed run must match it exactly): the model,
        the factors, the base scene and the code that computes them (an upgrade between a kill and
        the resume would otherwise mix two versions' results in one table)."""
        from labtool.models.dynamics.provenance import labtool_version, models_source_sha256
        return {"model": self.model,
                "factors": [dataclasses.asdict(f) for f in self.factors],
                "base_scene": repr(self.base) + f" mechanism={self.base.mechanism!r}",
                "runs": len(self),
                "labtool": f"{labtool_version()}, models source sha256 {models_source_sha256()[:16]}"}

    def coordinate_attrs(self, f: Factor) -> dict:
        """CF attributes of a factor's coordinate in the design's NetCDF."""
        _field, _scale, text = SCENE_FACTORS.get(f.symbol, (None, None, f.symbol))
        return {"units": f.unit or "1", "long_name": f"factor {f.name}: {text}", "level_column": f.column}
