"""From ``measured.nc`` to the report's content: read, simulate, align, compare, check.

``build_report(...)`` returns a ``Report`` (plain data, SI inside); reports/html.py, pdf.py and
summary.py render it. Nothing here draws or writes files.
"""
from __future__ import annotations

import dataclasses
import math
import time
import warnings
from pathlib import Path

import numpy as np
import xarray as xr

from labtool.common.cf import in_seconds, udunits
from labtool.common.names import shown
from labtool.common.errors import FileFormatError, InputError, LabtoolError
from labtool.processing import impacts
from labtool.common.operating_point import FIELD, FIELDS, SOURCE_SUFFIX, Sourced, resolve
from labtool.common.units import RPM
from labtool.processing.readers.base import as_text
from labtool.processing.readers import recording_kind
from labtool.reports import align, events, metrics, verdict
from labtool.reports.simulation import (CHAIN_KEYS, SimRun, chain_view, max_cam_speed_rpm, model_scene,  # noqa: F401
                                        no_load_factor, point_of, run_simulation)
from labtool.reports.thresholds import Thresholds, evaluate

SIGNALS = ("omega2", "epsilon2")
# the units (UDUNITS spelling) the comparison reads the measured file in; another stated unit is refused
MEASURED_UNITS = {"omega2": "rad s-1", "epsilon2": "rad s-2", "phi1": "rad"}
MODELS = ("rigid", "elastic")
MODES = ("const", "var")
# the robustness check: the verdict again at the other preset and at half the simulated length
OTHER_PRESET = {"fast": "standard", "standard": "fast", "reference": "standard"}
DEFAULT_REVOLUTIONS = 6      # simulated cam revolutions: transient, then steady state or statistics


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
    measured_events: dict | None = None            # labtool.reports.events.measured
    robustness: list = dataclasses.field(default_factory=list)   # rows: preset, revolutions, closest, grades
    verdict: dict | None = None        # labtool.reports.verdict.judge, with its ``sentence``

    @property
    def passed(self) -> bool:
        return all(r["passed"] for r in self.threshold_rows)


# --------------------------------------------------------------------------- input

def load_measured(path: Path) -> xr.Dataset:
    """Open ``measured.nc`` (as written by ``labtool process``) and check what the report needs."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"measured file {path} not found")
    raw = recording_kind(path)
    if raw:
        raise InputError(f"{shown(str(path))} is a {raw}, not a measured file: run 'labtool process "
                         f"{shown(str(path))} -o measured.nc' first and report measured.nc")
    try:
        # lazily and without the time index (a 1-hour recording's is 288 MB): the report reads only
        # the revolutions it uses (align.read_measured); the CF time ('seconds since <start>') kept
        # in seconds, as revolution_start_time and spike_time are
        with warnings.catch_warnings():   # h5netcdf's phony_dims notice for HDF5 that is not NetCDF
            warnings.simplefilter("ignore")
            ds = xr.open_dataset(path, engine="h5netcdf", decode_times=False, create_default_indexes=False)
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
        if ds[name].dims != ("time",):
            raise InputError(f"{where}: {name} is not a signal over time (dims {ds[name].dims}; "
                             "the report takes one value per sample, dims ('time',))")
    if "phi1" not in ds:
        raise InputError(f"{where} has no cam angle phi1; run 'labtool process' on a recording with a tacho channel")
    if ds["phi1"].dims != ("time",):
        raise InputError(f"{where}: phi1 is not a cam angle over time (dims {ds['phi1'].dims}; "
                         "the report takes one value per sample, dims ('time',))")
    if "time" in ds.variables and not in_seconds(ds["time"].attrs.get("units")):
        raise InputError(f"{where}: its time is in '{shown(as_text(ds['time'].attrs['units']))}', the report reads it "
                         "in seconds (s, or 'seconds since <start>', as 'labtool process' writes it); convert time to s")
    # every variable the report, fit and campaign report read as numbers, checked where the file is
    # opened: text there fails deep in numpy (could not convert string to float) where it is first used
    read = [n for n in ("time", "phi1", *SIGNALS, "aE_n", "revolution_start_time", "frequency") if n in ds.variables]
    for name in read + [n for n in ds.data_vars if ds[n].dims == ("frequency",)]:
        kind = ds[name].dtype.kind
        if kind not in "fiu":
            held = "text" if kind in "OSU" else f"{ds[name].dtype} values"
            raise InputError(f"{where}: {name} holds {held}, not numbers; the file is damaged or not written by "
                             "'labtool process': process the recording again")
    for name, unit in MEASURED_UNITS.items():
        stated = ds[name].attrs.get("units")
        if stated is not None and udunits(as_text(stated)) != unit:
            raise InputError(f"{where}: {name} is in '{shown(as_text(stated))}', the report compares it in '{unit}' "
                             f"(SI, as 'labtool process' writes it); convert {name} to {unit}")


CONTRADICTION = 0.10    # a stated or given cam speed this far from the measured one contradicts it


def operating_point(ds: xr.Dataset, measured_rpm: float, overrides: dict) -> dict:
    """The operating point the models simulate, as a dict of the owner's attributes (edge units,
    labtool.common.operating_point), each ``<attr>_source`` beside it, plus ``cam_speed_rpm_stated``
    (the nominal speed the file states, or None), ``omega1_var_n1_rpm`` and ``assumed`` (the
    stated fields that no option and no file gave: a default stood in).

    ``overrides``: SI values by field name (options). Each field is the option, else the measured
    file's attribute, else the owner's default. The cam speed is ``cam_speed`` if given, else the
    **measured** mean speed of the whole revolutions, not the nominal one the file states: a stand's
    drive slips under load and its speed setting is not the paper's, so only the measured speed puts
    a model's cycle on the measured one. omega1 const runs at that speed; omega1 var has its drive
    set so that its no-load speed is that speed (nominal n1 = speed x n_nominal / n_sync,
    ``omega1_var_n1_rpm``), as the stand's operator sets the variator. A given speed that
    contradicts the measured one by more than CONTRADICTION is refused, before any simulation."""
    where = shown(ds.encoding.get("source", "the measured file"))
    sourced = resolve(overrides, ds.attrs, where=where)
    stated = sourced.point.cam_speed_rpm if sourced.sources["cam_speed"].startswith("file attribute") else None
    given = overrides.get("cam_speed")
    rpm, src = ((given / RPM, sourced.sources["cam_speed"]) if given is not None else
                (measured_rpm, "measured: mean over the whole revolutions"))
    limit = max_cam_speed_rpm()
    if not (math.isfinite(rpm) and 0 < rpm <= limit):
        raise InputError(f"cam speed {rpm:g} rpm ({src}) is outside what the models can simulate: "
                         f"0 < n1 <= {limit:g} rpm (the drive motor's synchronous speed)")
    if given is not None and math.isfinite(measured_rpm) and abs(rpm / measured_rpm - 1.0) > CONTRADICTION:
        raise InputError(f"--rpm {rpm:g} contradicts the measured cam speed {measured_rpm:.1f} rpm (the mean over "
                         f"the whole revolutions of {where}): the models would not run where the stand did; "
                         "drop --rpm to simulate at the measured speed")
    point = sourced.point.replace(cam_speed=rpm * RPM)
    out = {**point.attrs(), **Sourced(point, {**sourced.sources, "cam_speed": src}).source_attrs()}
    out.update(cam_speed_rpm_stated=stated, omega1_var_n1_rpm=float(rpm) / no_load_factor(),
               assumed=sourced.assumed(), source_notes=list(sourced.notes))
    return out


def point_rows(op: dict) -> list[tuple[str, str, str]]:
    """(what, value with its unit, where it came from) for every operating-point field of ``op``."""
    point = point_of(op)
    return [(f.named, f.shown(getattr(point, f.name)), op.get(f.attr + SOURCE_SUFFIX, "")) for f in FIELDS]


# --------------------------------------------------------------------------- comparison

def band_statistics(meas_mean, meas_std, sim_mean, sim_std) -> dict:
    """How a model's cycle statistics sit against the measured ones (for motion that is not
    periodic, where a pointwise comparison of one revolution is meaningless): ``band_overlap`` =
    fraction of the grid where the two cycle averages differ by less than two combined standard
    deviations; ``scatter_ratio`` = rms of the model's revolution-to-revolution scatter over the
    measured one's (0 for a periodic model, ~1 when the model varies as much as the stand)."""
    tol = 2.0 * np.sqrt(np.asarray(meas_std) ** 2 + np.asarray(sim_std) ** 2)
    inside = np.abs(np.asarray(sim_mean) - np.asarray(meas_mean)) <= tol
    ms = float(np.sqrt(np.mean(np.asarray(meas_std) ** 2)))
    return {"band_overlap": float(inside.mean()),
            "scatter_ratio": float(np.sqrt(np.mean(np.asarray(sim_std) ** 2)) / ms) if ms > 0 else math.nan}


def _covered(x, cov):
    return x if cov.all() else x[..., cov]


def compare_signal(cycles: align.MeasuredCycles, cycle, sig: str, per_revolution: bool = True) -> tuple[dict, list]:
    """Overall metrics (the model's cycle against the measured cycle average, with the band
    statistics) and, if asked, against every measured revolution (batched)."""
    cov = cycle.covered
    sim = _covered(cycle.signals[sig], cov)
    grid = _covered(cycles.grid, cov)
    overall = metrics.compare(_covered(cycles.mean(sig), cov), sim, grid)
    overall.update(band_statistics(_covered(cycles.mean(sig), cov), _covered(cycles.std(sig), cov), sim,
                                   _covered(cycle.std[sig], cov)))
    per_rev = []
    if per_revolution:
        per_rev = metrics.compare_rows(_covered(cycles.signals[sig], cov), sim, grid)
        for m, rev in zip(per_rev, cycles.revolutions):
            m["revolution"] = int(rev)
    return overall, per_rev


def compare_run(cycles: align.MeasuredCycles, run: SimRun) -> list[dict]:
    """Metrics of one simulation against the cycle average (``overall``) and every whole revolution."""
    out = []
    for sig in SIGNALS:
        overall, per_rev = compare_signal(cycles, run.cycle, sig)
        out.append({
            "requested_model": run.requested, "model": run.model, "omega1": run.omega1, "signal": sig,
            "label": run.label, "overall": overall, "per_revolution": per_rev,
            "covered_fraction": float(run.cycle.covered.mean()), "periodic": bool(run.cycle.periodic),
            "model_revolutions_averaged": int(run.cycle.n_used),
        })
    return out


def detector_for(time_filter: align.TimeFilter | None, ds: xr.Dataset) -> impacts.Detector | None:
    """The impact detector of this recording (its rate and processing low-pass), None without them."""
    if time_filter is None:
        return None
    return impacts.Detector(time_filter.fs, time_filter.cutoff_hz, time_filter.order)


def event_table(measured: dict | None, sims: list) -> list[dict]:
    """One row per simulation: its predicted events (same definitions as the measured ones) beside
    the measured, and the model's own indicators as counted in the paper's tables."""
    rows = []
    for run in sims:
        ind = run.indicators
        row = {"label": run.label, "requested_model": run.requested, "model": run.model, "omega1": run.omega1,
               "predicted": run.events, "measured": measured,
               "jumps_indicator": ind.get("jumps"), "impacts_indicator": ind.get("impacts"),
               "sign_change": ind.get("sign_change"), "MR13D_max_Nm": ind.get("MR13D_max_Nm"),
               "MR13D_min_Nm": ind.get("MR13D_min_Nm")}
        p = run.events or {}
        for key in events.KEYS + ("detectable_impacts_per_rev", "flights_per_rev"):
            row[key] = p.get(key)
        rows.append(row)
    return rows


# --------------------------------------------------------------------------- the whole report

def build_report(measured_path: Path, models=MODELS, modes=MODES, thresholds: Thresholds | None = None,
                 overrides: dict | None = None, accuracy: str = "standard", revolutions: float = DEFAULT_REVOLUTIONS,
                 cond: align.Conditioning | None = None, progress=None, stand_in_on_failure: bool = False,
                 robustness: bool = True, fitted: list | None = None, discriminate: bool = True) -> Report:
    """Everything the report shows. ``progress(msg)`` is called before each long step.

    ``stand_in_on_failure`` (the demo): a model that fails is replaced by the kinematic level with a
    note, instead of ending the report (the CLI: exit 2 for a model's InputError/SolverError).
    ``robustness``: also the verdict at the other preset and at half the simulated length.
    ``fitted``: identified models (``labtool fit``) shown beside the nominal ones, each a dict with
    ``model``, ``omega1``, ``operating_point`` (the report's keys, edge units, with the fitted
    values and any ``ka_gain``/``delay_ms``) and ``note`` (what was identified, from where).
    ``discriminate``: when the measurement cannot tell the closest models apart, look for the cam
    speed that would (labtool.reports.discrimination, a few cheap simulations)."""
    t0 = time.perf_counter()
    say = progress or (lambda msg: None)
    cond = cond or align.Conditioning()
    models, modes = _check_choice(models, ("rigid", "elastic", "kinematic"), "model"), _check_choice(modes, MODES, "omega1 mode")
    if not (math.isfinite(revolutions) and revolutions >= 1 and float(revolutions).is_integer()):
        raise InputError(f"--revolutions must be a whole number >= 1 of cam revolutions, got {revolutions:g}")
    ds = load_measured(measured_path)
    say("reading and aligning the measured revolutions")
    cycles = align.read_measured(ds, SIGNALS, cond, extra=("aE_n",))
    op = operating_point(ds, cycles.cam_speed_rpm, overrides or {})
    time_filter = align.processing_filter(ds)
    notes = _measured_notes(ds, cycles, op, time_filter)
    sims = []
    for model in models:
        for mode in modes:
            same = _same_motion(sims, model, mode, accuracy)
            if same is not None:
                sims.append(same)
                continue
            say(f"simulating {model}, omega1 {mode} ({accuracy}, {revolutions:g} revolutions)")
            run = _simulate_or_stand_in(op, model, mode, accuracy, revolutions, cond, time_filter, stand_in_on_failure)
            if run.warning:
                notes.append(f"{run.label}: {run.warning}")
            sims.append(run)
    for fit in fitted or []:
        say(f"simulating the fitted {fit['model']} model, omega1 {fit['omega1']}")
        sims.append(fitted_run(fit, accuracy, revolutions, cond, time_filter))
        notes.append(fit["note"])
    say("finding the measured impacts and jumps")
    det = detector_for(time_filter, ds)
    meas_ev = measured_events(cycles, det, op)
    for run in sims:
        if det is not None and meas_ev is not None and meas_ev.get("threshold_rad_s") is not None:
            run.events = events.predicted(run.dataset, run.steady, det, meas_ev["threshold_rad_s"], cam_program(op))
    say("computing the metrics")
    comparisons, done = [], {}
    for run in sims:
        # a reused run (the same motion, _same_motion) has the same metrics: copied, not recomputed
        key = id(run.cycle)
        rows = [dict(c, omega1=run.omega1, label=run.label) for c in done[key]] if key in done else compare_run(cycles, run)
        done.setdefault(key, rows)
        comparisons += rows
    rows = evaluate(thresholds, comparisons) if thresholds else []
    rep = Report(shown(measured_path), ds, cycles, cond, op, sims, comparisons, event_table(meas_ev, sims),
                 rows, thresholds.source if thresholds else None, notes, 0.0, time_filter, meas_ev)
    if robustness and any(r.model != "kinematic" for r in sims):
        say("checking the verdict at the other preset and half the length")
        rep.robustness = robustness_rows(rep, accuracy, revolutions, say)
    rep.verdict = verdict.judge(headline(rep), rep.comparisons, rep.robustness, same_motion_labels(sims))
    if discriminate and rep.verdict is not None and rep.verdict["cannot_tell_apart"]:
        say("looking for the cam speed that would tell the models apart")
        rep.verdict["discrimination"] = discrimination_for(rep, rep.verdict)
    if rep.verdict is not None:
        rep.verdict["sentence"] = verdict.sentence(rep.verdict)
    rep.wall_s = time.perf_counter() - t0
    return rep


def same_motion_labels(sims: list) -> dict[str, str]:
    """label -> the label of the earlier run whose motion it repeats (simulated once, _same_motion)."""
    first, out = {}, {}
    for run in sims:
        key = id(run.cycle)
        if key in first:
            out[run.label] = first[key]
        else:
            first[key] = run.label
    return out


def discrimination_for(rep: "Report", v: dict) -> dict | None:
    """Where the runs the measurement cannot tell apart (the closest's group, else the first group)
    would differ most (labtool.reports.discrimination), as plain data; None when fewer than two of
    them are nominal models (a fitted model has its own operating point)."""
    from labtool.reports.discrimination import discriminate

    groups = v["cannot_tell_apart"]
    group = next((g for g in groups if v["closest"] in g), groups[0])
    runs = {r.label: r for r in rep.sims if r.op is None}
    cands = [(lab, runs[lab].model, runs[lab].omega1) for lab in group if lab in runs]
    if len(cands) < 2:
        return None
    scatter = {s: rep.cycles.std(s) for s in SIGNALS}
    return discriminate(rep.scene, cands, scatter, rep.cycles.cam_speed_rpm, cond=rep.conditioning).as_dict()


def fitted_run(fit: dict, accuracy: str, revolutions: float, cond, time_filter) -> SimRun:
    """An identified model (labtool fit) through the report's own comparison, labelled '<model> (fitted)'."""
    op = fit["operating_point"]
    try:
        run = run_simulation(op, fit["model"], fit["omega1"], accuracy, revolutions, cond, time_filter)
    except (ValueError, ArithmeticError) as exc:
        if isinstance(exc, LabtoolError):
            raise
        raise InputError(f"the fitted {fit['model']} model cannot be simulated: {exc}") from None
    run.requested, run.op = f"{fit['model']} (fitted)", op
    return run


def assumed_note(op: dict) -> str:
    """The note naming the operating-point values the measured file does not state (``op["assumed"]``)."""
    fields = [FIELD[n] for n in op["assumed"]]
    said = ", ".join(f"{f.named} = {f.shown(f.from_edge(op[f.attr]))}" for f in fields)
    return (f"the measured file does not state {', '.join(f.named for f in fields)}: the models use labtool's "
            f"defaults ({said}); give {', '.join(f.option for f in fields)} if the stand ran otherwise")


def _measured_notes(ds, cycles, op, time_filter) -> list[str]:
    notes = []
    if time_filter is None:
        notes.append("the measured file records no processing low-pass that the report can reproduce: "
                     "the simulations see only the common harmonic low-pass, and no impacts are detected")
    if ds.attrs.get("source") == "synthetic":
        notes.append("the measured file is SYNTHETIC (kinematics + noise, labtool.reports.synthetic), not a recording")
    notes.extend(op.get("source_notes", ()))
    if op.get("assumed"):
        notes.append(assumed_note(op))
    stated = op.get("cam_speed_rpm_stated")
    if stated and abs(cycles.cam_speed_rpm / stated - 1.0) > CONTRADICTION:
        notes.append(f"the file states {stated:g} rpm, but the cam turned at {cycles.cam_speed_rpm:.2f} rpm: the "
                     f"stated speed is wrong or belongs to another run; the models run at {op['cam_speed_rpm']:.2f} "
                     f"rpm ({op['cam_speed_rpm_source']})")
    elif stated and abs(cycles.cam_speed_rpm / stated - 1.0) > 0.002:
        notes.append(f"the file states {stated:g} rpm, the cam turned at {cycles.cam_speed_rpm:.2f} rpm: the models "
                     f"run at {op['cam_speed_rpm']:.2f} rpm ({op['cam_speed_rpm_source']})")
    if cycles.partial:
        notes.append(f"{cycles.partial} partial revolution(s) of the recording left out (ends or gaps)")
    if cycles.in_file is not None:
        notes.append(f"a long recording: {len(cycles.revolutions)} of its ~{cycles.in_file} revolutions are used, in "
                     f"{len(cycles.blocks)} blocks of consecutive revolutions spread evenly over it (the report's cost "
                     "does not grow with the length)")
    return notes


CONSTANT_SPEED_VAR = ("elastic", "kinematic")   # levels whose omega1 var is the no-load speed, constant


def _same_motion(runs: list, model: str, mode: str, accuracy: str) -> SimRun | None:
    """The elastic model and the kinematic level with omega1 var turn the cam at constant speed,
    the drive's no-load speed (labtool.models.dynamics.elastic, simulate._kinematic), which the report sets
    to the simulated speed: the same motion as omega1 const. That run is reused (labelled var, with
    a note) instead of simulated again."""
    if model not in CONSTANT_SPEED_VAR or mode != "var":
        return None
    for r in runs:
        if r.requested == model and r.model == model and r.omega1 == "const" and r.accuracy == accuracy:
            note = (f"the {model} model turns its cam at the drive's no-load speed, constant, which is the simulated "
                    "speed: the same motion as omega1 const (not simulated twice)")
            return dataclasses.replace(r, omega1="var", note=note, wall_s=0.0)
    return None


def _simulate_or_stand_in(op, model, mode, accuracy, revolutions, cond, time_filter, stand_in) -> SimRun:
    try:
        return run_simulation(op, model, mode, accuracy, revolutions, cond, time_filter)
    except Exception as exc:
        if not stand_in or model == "kinematic":
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
        return run


def cam_program(op: dict):
    """The cam program of the operating point (the default mechanism, the op's law)."""
    from labtool.models.mechanism import Mechanism
    from labtool.models.mechanism.motion_laws import CamProgram
    return CamProgram.for_mechanism(Mechanism.default(), law=op["law"])


def measured_events(cycles, det, op) -> dict | None:
    """The measured impacts and jumps (labtool.reports.events.measured) at the operating point's cam law;
    None without a detector (no processing low-pass recorded)."""
    if det is None:
        return None
    from labtool.models.mechanism import Mechanism
    return events.measured(cycles, det, Mechanism.default(), cam_program(op))


def _ratings(cycles, cycle) -> dict:
    out = {}
    for sig in SIGNALS:
        o, _ = compare_signal(cycles, cycle, sig, per_revolution=False)
        out[f"{sig}_iso_rating"], out[f"{sig}_iso_grade"] = o["iso_rating"], o["iso_grade"]
    return out


def _variant_row(accuracy, revolutions, entries) -> dict:
    """entries: [(label, ratings)]; the closest is the best mean of the two ISO ratings (whether
    the measurement tells it from the others is labtool.reports.verdict's)."""
    best = max(entries, key=lambda e: verdict.mean_rating(e[1]))
    return {"accuracy": accuracy, "revolutions": float(revolutions), "closest": best[0],
            "models": [{"label": lab, **r} for lab, r in entries]}


def robustness_rows(rep: Report, accuracy: str, revolutions: float, say) -> list[dict]:
    """The closest model and every model's grades at (preset, length) for the report's preset and
    the other one (OTHER_PRESET), each at the full and at half the simulated length (the first
    half of a causal simulation: no extra run). A preset that fails is a row with its error."""
    half = max(int(revolutions) // 2, 1)
    lengths = [int(revolutions)] + ([half] if half < int(revolutions) else [])
    other = OTHER_PRESET[accuracy]
    rows = []
    for acc in (accuracy, other):
        runs, error = [], None
        done = []
        for run in rep.sims:
            if acc == accuracy or run.model == "kinematic":
                runs.append((run.label, run.cycle))
                continue
            try:
                # a fitted run (run.op set) has its own parameters: never the same motion as a nominal one
                same = _same_motion(done, run.model, run.omega1, acc) if run.op is None else None
                r2 = same or run_simulation(run.op or rep.scene, run.model, run.omega1, acc, revolutions,
                                            rep.conditioning, rep.time_filter)
                if run.op is None:
                    done.append(r2)
                runs.append((run.label, r2.cycle))
            except LabtoolError as exc:
                error = f"{run.label}: {exc}"
                break
        if error is not None:
            rows.append({"accuracy": acc, "revolutions": float(revolutions), "closest": None, "error": error, "models": []})
            continue
        for k in lengths:
            entries = [(lab, _ratings(rep.cycles, cyc.upto(k) if isinstance(cyc, align.SimulatedCycles) else cyc))
                       for lab, cyc in runs]
            rows.append(_variant_row(acc, k, entries))
    return rows


def verdict_lines(report: "Report") -> list[str]:
    """The verdict in plain lines (console, demo): the closest model, what the measurement can
    tell (labtool.reports.verdict.sentence, the same text as the page, the PDF and the JSON), and
    the measured events with their detectability."""
    lines = []
    best = closest(report)
    if best is not None:
        lines.append(f"closest to the measurement: {best['label']} (mean of the omega2 and epsilon2 ISO ratings)")
    if report.verdict is not None and report.verdict.get("sentence"):
        lines.append(report.verdict["sentence"])
    m = report.measured_events
    if m is not None and m.get("impacts_per_rev") is not None:
        first = "-" if m["first_impact_deg"] is None else f"{m['first_impact_deg']:.1f} deg"
        lines.append(f"measured: {m['impacts_per_rev']:.2f} visible impacts and {m['jumps_per_rev']:.2f} jumps per "
                     f"revolution, first impact at {first} (visible: |d omega2| >= {m['threshold_rad_s']:.3g} rad/s)")
        # the models' events with the same definition: where ratings tie, the events may not
        pred = [(r.label, r.events) for r in report.sims if r.events and r.events.get("impacts_per_rev") is not None
                and r.omega1 == "const"]
        if pred:
            lines.append("predicted, same definition: " + "; ".join(
                f"{lab} {e['detectable_impacts_per_rev']:.2f} visible impacts, first at "
                + ("-" if e["first_impact_deg"] is None else f"{e['first_impact_deg']:.1f} deg") for lab, e in pred))
    return lines


def robust_verdict(rows: list[dict]) -> dict | None:
    """Whether the first row's closest model is the closest in every robustness row (None without
    rows); the verdict itself (labtool.reports.verdict) also asks whether it is ahead by more than
    the measurement resolves."""
    names = [r["closest"] for r in rows if r.get("closest") is not None]
    if not names:
        return None
    robust = len(names) == len(rows) and len(set(names)) == 1
    return {"robust": robust, "closest": sorted(set(names))}


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
        row = {"label": run.label, "requested_model": run.requested, "model": run.model, "omega1": run.omega1,
               "periodic": bool(run.cycle.periodic),
               "motion": "periodic" if run.cycle.periodic else f"not periodic ({run.cycle.n_used} rev averaged)"}
        for c in report.comparisons:
            if c["requested_model"] == run.requested and c["omega1"] == run.omega1:
                o = c["overall"]
                s = c["signal"]
                row.update({f"{s}_iso_rating": o["iso_rating"], f"{s}_iso_grade": o["iso_grade"],
                            f"{s}_sg_comprehensive": o["sg_comprehensive"], f"{s}_nrmse": o["nrmse"],
                            f"{s}_band_overlap": o["band_overlap"]})
        rows.append(row)
    return rows


def closest(report: Report) -> dict | None:
    """The headline row with the highest mean of the omega2 and epsilon2 ISO ratings (None if none)."""
    rows = headline(report)
    if not rows:
        return None
    return max(rows, key=lambda h: 0.5 * (h["omega2_iso_rating"] + h["epsilon2_iso_rating"]))
