"""From ``measured.nc`` to the report's content: read, simulate, align, compare, check.

``build_report(...)`` returns a ``Report`` (plain data, SI inside); reports/html.py, pdf.py and
summary.py render it. Nothing here draws or writes files.
"""
from __future__ import annotations

import dataclasses
import importlib
import math
import time
from pathlib import Path

import numpy as np
import xarray as xr

from common.names import shown
from common.errors import FileFormatError, InputError, LabtoolError
from reports import align, metrics
from reports.thresholds import Thresholds, evaluate

SIGNALS = ("omega2", "epsilon2")
MODELS = ("rigid", "elastic")
MODES = ("const", "var")
# the paper's experiment (sec. 2.4, 3.3): sine law, no load, j = 0.128 mm, nominal inertia
EXPERIMENT = {"law": "sine", "Fu": 0.0, "backlash_mm": 0.128, "jt_factor": 1.0}
# model options (not properties of the recording): the paper's idealisations unless the user sets
# them (k = 1, no contact damping, lw = 6 mm, the follower crosses the backlash)
MODEL_OPTIONS = {"restitution": 1.0, "contact_damping": 0.0, "contact_length_mm": 6.0, "elastic_gap": "physical"}


@dataclasses.dataclass
class SimRun:
    requested: str            # model asked for (rigid, elastic, kinematic)
    model: str                # level that ran
    omega1: str               # const | var
    dataset: xr.Dataset
    indicators: dict
    cycle: align.SimulatedCycle
    wall_s: float
    note: str = ""
    revolutions: float = 1.0  # cam revolutions simulated (event counts are divided by it)
    warning: str = ""         # what the reader must know (a stand-in level, a partial revolution)

    @property
    def label(self) -> str:
        name = self.requested if self.model == self.requested else f"{self.requested} (ran {self.model})"
        return f"{name}, w1 = {'ct.' if self.omega1 == 'const' else 'var.'}"


@dataclasses.dataclass
class Report:
    measured_path: str
    measured: xr.Dataset
    cycles: align.MeasuredCycles
    conditioning: align.Conditioning
    scene: dict                       # operating point used for the simulations (edge units)
    sims: list                        # SimRun
    comparisons: list                 # dicts: requested_model, model, omega1, signal, overall, per_revolution
    events: list                      # dicts: jumps/impacts measured vs predicted
    threshold_rows: list
    thresholds_source: str | None
    notes: list                       # what was skipped or replaced, and why
    wall_s: float = 0.0
    time_filter: align.TimeFilter | None = None   # the processing low-pass, re-applied to the simulations

    @property
    def passed(self) -> bool:
        return all(r["passed"] for r in self.threshold_rows)


# --------------------------------------------------------------------------- input

def load_measured(path: Path) -> xr.Dataset:
    """Open ``measured.nc`` (as written by ``labtool process``) and check what the report needs."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"measured file {path} not found")
    try:
        ds = xr.open_dataset(path, engine="h5netcdf").load()
    except Exception as exc:   # h5py/xarray raise many types for a file that is not NetCDF4
        raise FileFormatError(f"{path} is not a NetCDF4 file written by 'labtool process' "
                              f"({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})") from None
    check_measured(ds, str(path))
    return ds


def check_measured(ds: xr.Dataset, where: str = "measured file") -> None:
    for name in SIGNALS:
        if name not in ds:
            raise InputError(f"{where} has no {name}; the report compares measured omega2 and epsilon2 "
                             "(run 'labtool process' on the recording)")
        if "time" not in ds[name].dims:
            raise InputError(f"{where}: {name} is not a signal over time (dims {ds[name].dims})")
    if "phi1" not in ds:
        raise InputError(f"{where} has no cam angle phi1; run 'labtool process' on a recording with a tacho channel")


def _attr_float(ds, *names):
    for n in names:
        if n in ds.attrs:
            try:
                v = float(np.asarray(ds.attrs[n]).ravel()[0])
            except (TypeError, ValueError, IndexError):
                continue
            return v
    return None


def max_cam_speed_rpm() -> float:
    """The fastest cam speed the models take (rpm): the drive motor's synchronous speed."""
    from models.mechanism import Mechanism
    return Mechanism.default().max_cam_speed_rpm


def operating_point(ds: xr.Dataset, measured_rpm: float, overrides: dict) -> dict:
    """Scene parameters (edge units) for the simulations: CLI overrides, else the file's attributes,
    else the paper's experiment; the cam speed is the file's nominal speed, else the measured one."""
    rpm = overrides.get("cam_speed_rpm")
    src = "option"
    if rpm is None:
        # the nominal speed the stand was set to; labtool process keeps it as cam_speed_rpm_stated
        for name in ("cam_speed_rpm_stated", "cam_speed_rpm", "n1_rpm"):
            rpm = _attr_float(ds, name)
            if rpm is not None:
                src = f"file attribute {name}"
                break
    if rpm is None:
        rpm, src = measured_rpm, "measured from phi1"
    limit = max_cam_speed_rpm()
    if not (math.isfinite(rpm) and 0 < rpm <= limit):
        raise InputError(f"cam speed {rpm:g} rpm ({src}) is outside what the models can simulate: "
                         f"0 < n1 <= {limit:g} rpm (the drive motor's synchronous speed)")
    out = {"cam_speed_rpm": float(rpm), "cam_speed_source": src}
    for key, attr_names in (("law", ("law",)), ("Fu", ("Fu_N", "Fu")), ("backlash_mm", ("backlash_mm",)),
                            ("jt_factor", ("jt_factor",))):
        if overrides.get(key) is not None:
            out[key] = overrides[key]
        elif key == "law":
            out[key] = str(ds.attrs.get("law", EXPERIMENT["law"]))
        else:
            v = _attr_float(ds, *attr_names)
            if v is None and key == "backlash_mm":
                b = _attr_float(ds, "backlash_m")
                v = None if b is None else b * 1e3
            out[key] = EXPERIMENT[key] if v is None else v
    for key, default in MODEL_OPTIONS.items():
        out[key] = default if overrides.get(key) is None else overrides[key]
    return out


# --------------------------------------------------------------------------- simulations

def model_available(name: str) -> bool:
    """Whether the model level's module can be imported (rigid and elastic land separately)."""
    from models.dynamics.simulate import LEVELS
    if name not in LEVELS:
        return False
    try:
        importlib.import_module(LEVELS[name].split(":")[0])
    except ModuleNotFoundError:
        return False
    return True


def run_simulation(op: dict, requested: str, mode: str, accuracy: str, revolutions: float,
                   cond: align.Conditioning, time_filter: align.TimeFilter | None = None) -> SimRun:
    """One model at one omega1 mode over whole revolutions; a model that is not there yet is
    replaced by the kinematic level, and the note says so."""
    from models.dynamics.scene import Scene
    from models.dynamics.simulate import simulate

    scene = Scene(law=op["law"], cam_speed_rpm=op["cam_speed_rpm"], Fu=op["Fu"], backlash=op["backlash_mm"] * 1e-3,
                  jt_factor=op["jt_factor"], omega1_mode=mode, accuracy=accuracy, revolutions=revolutions,
                  rise_only=False, restitution=op.get("restitution", 1.0),
                  contact_damping=op.get("contact_damping", 0.0),
                  contact_length=op.get("contact_length_mm", 6.0) * 1e-3,
                  elastic_gap=op.get("elastic_gap", "physical"))
    level, note = requested, ""
    if not model_available(requested):
        level = "kinematic"
        note = f"the {requested} model is not available in this installation; the kinematic level stands in for it"
    t0 = time.perf_counter()
    res = simulate(scene, level)
    # the rigid model's impacts are velocity jumps: its epsilon2 omits their impulses
    cycle = align.simulated_cycle(res.dataset, SIGNALS, cond, epsilon2_from_omega2=res.model == "rigid",
                                  time_filter=time_filter)
    warning = "; ".join(x for x in (note, cycle.note if not cycle.covered.all() else "") if x)
    return SimRun(requested, res.model, mode, res.dataset, res.indicators, cycle, time.perf_counter() - t0,
                  "; ".join(x for x in (note, cycle.note) if x), revolutions, warning)


# --------------------------------------------------------------------------- comparison

def _compare(meas: np.ndarray, sim: np.ndarray, covered: np.ndarray, grid: np.ndarray) -> dict:
    if covered.all():
        return metrics.compare(meas, sim, grid)
    return metrics.compare(meas[covered], sim[covered], grid[covered])


def compare_run(cycles: align.MeasuredCycles, run: SimRun) -> list[dict]:
    """Metrics of one simulation against the cycle average (``overall``) and every whole revolution."""
    out = []
    for sig in SIGNALS:
        sim = run.cycle.signals[sig]
        cov = run.cycle.covered
        per_rev = []
        for k, rev in enumerate(cycles.revolutions):
            m = _compare(cycles.signals[sig][k], sim, cov, cycles.grid)
            m["revolution"] = int(rev)
            per_rev.append(m)
        out.append({
            "requested_model": run.requested, "model": run.model, "omega1": run.omega1, "signal": sig,
            "label": run.label, "overall": _compare(cycles.mean(sig), sim, cov, cycles.grid),
            "per_revolution": per_rev, "covered_fraction": float(cov.mean()),
        })
    return out


def _measured_events(ds: xr.Dataset, cycles: align.MeasuredCycles) -> dict:
    """Impacts and jumps the processing found, per whole revolution (None when it reports none).

    Impacts: event times in seconds on an event dimension, ``impact_time`` or the acceleration
    spikes of ``labtool process`` (``spike_time``: an impact shows as a spike above the processing
    band). Jumps: ``jump_time``. Else scalar attributes ``impacts``/``jumps`` (per revolution)."""
    out = {}
    t0, t1 = cycles.time[:, 0], cycles.time[:, -1]
    candidates = {"impacts": ("impact_time", "spike_time"), "jumps": ("jump_time",)}
    for kind, names in candidates.items():
        val = None
        for n in names:
            if n in ds.variables and ds[n].ndim == 1 and "time" not in ds[n].dims:
                arr = np.asarray(ds[n].values, dtype=float)
                counts = [int(np.sum((arr >= a) & (arr <= b))) for a, b in zip(t0, t1)]
                val = float(np.mean(counts))
                break
        if val is None:
            val = _attr_float(ds, kind, f"{kind}_per_revolution")
        out[kind] = val
    return out


def predicted_events(sim: xr.Dataset) -> dict | None:
    """Cam angles (rad, in [0, 2 pi)) of the impacts and of the jumps (contact losses) in the
    simulation's last whole revolution: ``{"impacts": array, "jumps": array}``.

    Rigid model: ``event_phi1`` by ``event_kind`` (flag meanings ``impact_*`` = impact; a jump, i.e. a
    free flight, starts at a ``liftoff`` and after every ``impact_rebound``); elastic model: ``event_kinds``/``event_times_s`` (``leave_*`` = jump, ``land_*`` =
    impact), mapped to phi1 through the simulation's own phi1(time). None when the simulation records
    no events (kinematic level)."""
    out = None
    if "event_phi1" in sim and "event_kind" in sim:
        meanings = str(sim["event_kind"].attrs.get("flag_meanings", "")).split()
        values = list(np.atleast_1d(sim["event_kind"].attrs.get("flag_values", range(1, len(meanings) + 1))))
        kinds = np.asarray(sim["event_kind"].values)
        phi = np.asarray(sim["event_phi1"].values, dtype=float)
        flags = lambda word: [v for v, m in zip(values, meanings) if word in m]   # noqa: E731
        # a flight (jump) starts at a lift-off and again after every rebounding impact
        out = {"impacts": phi[np.isin(kinds, flags("impact"))],
               "jumps": phi[np.isin(kinds, flags("liftoff") + flags("rebound"))]}
    elif "event_times_s" in sim.attrs and "event_kinds" in sim.attrs and "time" in sim.variables:
        times = np.atleast_1d(np.asarray(sim.attrs["event_times_s"], dtype=float))
        kinds = [k for k in str(sim.attrs["event_kinds"]).split(",") if k]
        if len(kinds) != times.size:
            return None
        phi = np.interp(times, np.asarray(sim["time"].values, float), np.asarray(sim["phi1"].values, float))
        out = {"impacts": phi[np.array([k.startswith("land") for k in kinds], dtype=bool)],
               "jumps": phi[np.array([k.startswith("leave") for k in kinds], dtype=bool)]}
    if out is None:
        return None
    top = float(np.nanmax(np.asarray(sim["phi1"].values, float)))
    k = max(int(math.floor(top / (2 * math.pi) + 1e-6)) - 1, 0)
    a = 2 * math.pi * k
    return {name: np.sort(v[np.isfinite(v) & (v >= a) & (v < a + 2 * math.pi)] - a) for name, v in out.items()}


def _measured_first_impact_deg(ds: xr.Dataset, cycles: align.MeasuredCycles) -> float | None:
    """Median over the whole revolutions of the cam angle (deg) of the first spike after phi1 = 0."""
    if "spike_time" not in ds.variables and "impact_time" not in ds.variables:
        return None
    name = "impact_time" if "impact_time" in ds.variables else "spike_time"
    times = np.asarray(ds[name].values, dtype=float)
    firsts = []
    for k in range(cycles.time.shape[0]):
        row = cycles.time[k]
        inside = times[(times >= row[0]) & (times <= row[-1])]
        if inside.size:
            firsts.append(math.degrees(float(np.interp(inside.min(), row, cycles.grid))))
    return float(np.median(firsts)) if firsts else None


def event_table(ds: xr.Dataset, cycles: align.MeasuredCycles, sims: list) -> list[dict]:
    """Jumps and impacts per revolution, predicted (each simulation) and measured, and the cam angle
    of the first impact of a revolution (deg)."""
    meas = _measured_events(ds, cycles)
    first_meas = _measured_first_impact_deg(ds, cycles)
    rows = []
    for run in sims:
        ind = run.indicators
        row = {"label": run.label, "requested_model": run.requested, "model": run.model, "omega1": run.omega1}
        ev = predicted_events(run.dataset)
        for kind in ("jumps", "impacts"):
            # per revolution: the events of the last (steady) simulated revolution, like the measurement
            row[f"{kind}_predicted_per_rev"] = None if ev is None else float(ev[kind].size)
            row[f"{kind}_measured_per_rev"] = meas[kind]
            # the model's own indicator, counted as in the paper's tables (may cover the rise only)
            row[f"{kind}_indicator"] = ind.get(kind)
        angles = None if ev is None else ev["impacts"]
        row["first_impact_deg_predicted"] = None if angles is None or not angles.size else math.degrees(angles[0])
        row["first_impact_deg_measured"] = first_meas
        row["sign_change"] = ind.get("sign_change")
        row["MR13D_max_Nm"] = ind.get("MR13D_max_Nm")
        row["MR13D_min_Nm"] = ind.get("MR13D_min_Nm")
        rows.append(row)
    return rows


# --------------------------------------------------------------------------- the whole report

def build_report(measured_path: Path, models=MODELS, modes=MODES, thresholds: Thresholds | None = None,
                 overrides: dict | None = None, accuracy: str = "standard", revolutions: float = 2.0,
                 cond: align.Conditioning | None = None, progress=None, stand_in_on_failure: bool = False) -> Report:
    """Everything the report shows. ``progress(msg)`` is called before each long step.

    ``stand_in_on_failure`` (the demo): a model that fails is replaced by the kinematic level with a
    note, instead of ending the report (the CLI: exit 2 for a model's InputError/SolverError)."""
    t0 = time.perf_counter()
    say = progress or (lambda msg: None)
    cond = cond or align.Conditioning()
    models, modes = _check_choice(models, ("rigid", "elastic", "kinematic"), "model"), _check_choice(modes, MODES, "omega1 mode")
    ds = load_measured(measured_path)
    say("aligning the measured revolutions")
    cycles = align.measured_cycles(ds, SIGNALS, cond)
    op = operating_point(ds, cycles.cam_speed_rpm, overrides or {})
    notes = []
    time_filter = align.processing_filter(ds)
    if time_filter is None:
        notes.append("the measured file records no processing low-pass that the report can reproduce: "
                     "the simulations see only the common harmonic low-pass")
    if ds.attrs.get("source") == "synthetic":
        notes.append("the measured file is SYNTHETIC (kinematics + noise, reports.synthetic), not a recording")
    dev = cycles.cam_speed_rpm / op["cam_speed_rpm"] - 1.0
    if abs(dev) > 0.10:
        notes.append(f"the measured cam speed {cycles.cam_speed_rpm:.1f} rpm differs by {100 * dev:+.0f} % from the "
                     f"simulated {op['cam_speed_rpm']:g} rpm ({op['cam_speed_source']}); check the file or give --rpm")
    if cycles.partial:
        notes.append(f"{cycles.partial} partial revolution(s) of the recording left out (ends or gaps)")
    sims = []
    for model in models:
        for mode in modes:
            say(f"simulating {model}, omega1 {mode}")
            try:
                run = run_simulation(op, model, mode, accuracy, revolutions, cond, time_filter)
            except Exception as exc:
                if not stand_in_on_failure or model == "kinematic":
                    if isinstance(exc, LabtoolError):
                        raise
                    if isinstance(exc, (ValueError, ArithmeticError)):
                        raise InputError(f"the {model} model cannot simulate {op['cam_speed_rpm']:g} rpm "
                                         f"(omega1 {mode}): {exc}") from None
                    raise
                # the demo keeps going: the kinematic level stands in, and the page says why
                run = run_simulation(op, "kinematic", mode, accuracy, revolutions, cond, time_filter)
                run.requested = model
                run.warning = run.note = (f"the {model} model failed ({type(exc).__name__}: "
                                          f"{str(exc).splitlines()[0] if str(exc) else ''}); the kinematic level stands in")
            if run.warning:
                notes.append(f"{run.label}: {run.warning}")
            sims.append(run)
    say("computing the metrics")
    comparisons = [c for run in sims for c in compare_run(cycles, run)]
    rows = evaluate(thresholds, comparisons) if thresholds else []
    return Report(shown(measured_path), ds, cycles, cond, op, sims, comparisons, event_table(ds, cycles, sims),
                  rows, thresholds.source if thresholds else None, notes, time.perf_counter() - t0, time_filter)


def _check_choice(values, allowed, what) -> tuple:
    values = tuple(values)
    if not values:
        raise InputError(f"no {what} given; choose from {', '.join(allowed)}")
    bad = [v for v in values if v not in allowed]
    if bad:
        raise InputError(f"unknown {what} {', '.join(map(repr, bad))}; choose from {', '.join(allowed)}")
    return tuple(dict.fromkeys(values))


def headline(report: Report) -> list[dict]:
    """One row per simulation: overall ISO rating and S&G comprehensive error for omega2 and epsilon2."""
    rows = []
    for run in report.sims:
        row = {"label": run.label, "requested_model": run.requested, "model": run.model, "omega1": run.omega1}
        for c in report.comparisons:
            if c["requested_model"] == run.requested and c["omega1"] == run.omega1:
                o = c["overall"]
                s = c["signal"]
                row.update({f"{s}_iso_rating": o["iso_rating"], f"{s}_iso_grade": o["iso_grade"],
                            f"{s}_sg_comprehensive": o["sg_comprehensive"], f"{s}_nrmse": o["nrmse"]})
        rows.append(row)
    return rows


def closest(report: Report) -> dict | None:
    """The headline row with the highest mean of the omega2 and epsilon2 ISO ratings (None if none)."""
    rows = headline(report)
    if not rows:
        return None
    return max(rows, key=lambda h: 0.5 * (h["omega2_iso_rating"] + h["epsilon2_iso_rating"]))
