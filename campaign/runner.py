"""``run_campaign``: every point of a plan acquired, processed and compared, resumably.

For each point in the plan's order: acquire (after the settle wait), process, compare; each step
is skipped when ``point.json`` says it finished from today's inputs with its outputs intact
(labtool.campaign.state). A point whose acquisition did not finish (killed, a disconnect, Ctrl-C) is
redone from its acquisition; a finished recording is never thrown away silently: if the plan now
says something else for a point that has one, the run stops with one line unless the point is
named in ``redo``. A step whose inputs changed downstream of the recording (a new calibration,
other models or thresholds) is simply recomputed.

Progress goes to a ``Reporter`` (the CLI draws it); warnings of the layers go to its ``warn``.
"""
from __future__ import annotations

import dataclasses
import secrets
import shutil
import time
from pathlib import Path

from labtool.common.errors import InputError, LabtoolError, interrupt_cause, interruption
from labtool.common.files import check_interrupted
from labtool.common.names import shown
from labtool.campaign import steps
from labtool.campaign.plan import Plan
from labtool.campaign.state import OUTPUTS, STEPS, CampaignLock, PointState, clean_partials, sha256_file, sha256_json

POINTS_DIR = "points"


class Reporter:
    """What the runner tells the user; the default says nothing. Override what you show."""

    def campaign_start(self, plan: Plan, folder: Path, done: int) -> None: ...
    def point_start(self, k: int, n: int, point) -> None: ...
    def step(self, point, step: str, status: str, detail: str = "") -> None: ...
    def point_done(self, k: int, n: int, point, wall_s: float, eta_s: float | None, worked: bool) -> None: ...
    def warn(self, message: str) -> None: ...
    def say(self, message: str) -> None: ...
    def ask(self, message: str) -> None:
        raise InputError("this run cannot ask the operator (no terminal)")
    def acquisition_progress(self, point, recorder, elapsed_s: float) -> None: ...


@dataclasses.dataclass
class CampaignResult:
    folder: Path
    points: list          # (Point, folder)
    ran: list             # names of the points that did some work in this run
    kept: list            # names of the points that were already finished
    wall_s: float


def point_folder(folder: Path, point) -> Path:
    return Path(folder) / POINTS_DIR / point.name


def _inputs(plan: Plan, point, state: PointState, step: str) -> str:
    """sha256 of everything ``step`` of ``point`` is made from (plan parts and files read)."""
    if step == "acquire":
        # how the stand was paced or waited for does not change what it recorded
        device = {k: v for k, v in plan.doc.device.as_dict().items()
                  if k != "pacing" and not k.startswith("settle")}
        return sha256_json({"point": point.spec(), "device": device, "test": plan.digest("test")})
    if step == "process":
        return sha256_json({"recording": state.output_digest("acquire", "recording.h5"),
                            "calibration": [sha256_file(p) for p in plan.calibration_files],
                            "law": point.law, "rpm": point.rpm})
    return sha256_json({"measured": state.output_digest("process", "measured.nc"), "compare": plan.digest("compare"),
                        "thresholds": sha256_file(plan.thresholds) if plan.thresholds else None,
                        "overrides": steps.overrides(plan)})


def _check_existing(plan: Plan, point, state: PointState, redo: set) -> None:
    """Refuse to replace a finished recording the plan no longer describes (unless redo)."""
    if point.name in redo or "acquire" not in state.steps:
        return
    if state.steps["acquire"].get("inputs") == _inputs(plan, point, state, "acquire"):
        return
    keys = state.changed_keys()
    what = f"its {', '.join(keys)} changed" if keys else "the plan's device or test metadata changed"
    raise InputError(f"point {point.name} in {shown(state.folder.parent.parent)} was recorded with other settings "
                     f"({what}); rerun with --redo {point.name} to record it again, or use another output folder")


def _check_point_paths(point, folder: Path) -> None:
    """Refuse a point folder that is a file, or a point output that is a folder: no step can
    replace them, so "rerun to resume" would end the same way for ever (the user's, left alone)."""
    if folder.exists() and not folder.is_dir():
        raise InputError(f"point {point.name}: {shown(folder)} is a file, where the point's folder goes; "
                         "move it away and rerun")
    for name in (n for step in STEPS for n in OUTPUTS[step]):
        if (folder / name).is_dir():
            raise InputError(f"point {point.name}: {shown(folder / name)} is a folder, where the point writes "
                             f"its {name}; move it away and rerun")


def _run_point(plan: Plan, point, folder: Path, rep: Reporter, redo: set) -> bool:
    """Bring one point up to date; True when it did any work."""
    if point.name in redo and folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for name in clean_partials(folder):
        rep.warn(f"point {point.name}: removed {name}, left by an interrupted write")
    state = PointState.load(folder, point.name, point.spec())
    _check_existing(plan, point, state, redo)
    worked = False
    for step in ("acquire", "process", "compare"):
        check_interrupted()          # a stop signal whose exception Python dropped ends the run here
        inputs = _inputs(plan, point, state, step)
        if state.finished(step, inputs):
            rep.step(point, step, "kept")
            continue
        if step == "acquire" and (folder / "recording.h5").exists():
            own = _own_finished_recording(folder / "recording.h5", state, inputs, point)
            if own is not None:    # stopped between the recording's end and its record: it is whole
                state.record(step, inputs, own)
                rep.warn(f"point {point.name}: its recording had finished when the run was stopped; kept")
                rep.step(point, step, "done", _detail(step, own))
                worked = True
                continue
            if "acquire" not in state.steps and _finished_recording(folder / "recording.h5"):
                raise InputError(f"point {point.name}: {shown(folder / 'recording.h5')} is a finished recording "
                                 "that its point.json does not record (deleted or replaced); rerun with --redo "
                                 f"{point.name} to record it again, or move the recording away")
            rep.warn(f"point {point.name}: its acquisition did not finish (killed or stopped); recording it again")
        t0 = time.perf_counter()
        _ensure_space(folder, point, step, plan)
        try:
            state.forget_from(step)
            token = ""
            if step == "acquire":
                token = secrets.token_hex(8)
                state.begin_acquisition(inputs, token)
            rep.step(point, step, "running")
            info = _do(plan, point, folder, step, rep, token)
            signum = info.pop("stopped_by_signal", None)
            info["wall_s"] = time.perf_counter() - t0
            state.record(step, inputs, info)
        except OSError as exc:   # a full disk, a read-only folder: what is finished stays finished
            raise InputError(f"point {point.name} ({step}): cannot write in {shown(folder)}: "
                             f"{exc.strerror or exc}; the finished points and steps are kept, rerun to resume") from None
        rep.step(point, step, "done", _detail(step, info))
        worked = True
        if signum is not None:   # a stop signal after the recording's last sample: recorded, then the run stops
            raise interruption(signum)
    return worked


def _finished_recording(path: Path) -> bool:
    """True when ``path`` is a recording that says it is complete (an acquisition that ended)."""
    return _complete_recording(path) is not None


def _complete_recording(path: Path) -> dict | None:
    """The root attributes and facts of ``path`` when it is a recording that says it is complete
    (an acquisition that reached its duration), else None (not HDF5, truncated, unfinished)."""
    import h5py
    try:
        with h5py.File(path, "r") as h:
            if h.attrs.get("complete") not in (True, 1):
                return None
            kinds = [bytes(k).decode("ascii", "replace") for k in h["events"]["kind"]] if "events" in h else []
            clipped = [str(n.decode() if isinstance(n, bytes) else n) for n, c in
                       zip(h["signals"].attrs.get("channel_names", []), h["signals"].attrs.get("clipped", [])) if c]
            return {"attrs": dict(h.attrs), "rows": int(h["signals"].shape[0]), "overruns": kinds.count("overrun"),
                    "gaps": kinds.count("gap"), "clipped": clipped}
    except (OSError, ValueError, KeyError, TypeError):   # not HDF5, truncated, not a recording: not finished
        return None


def _own_finished_recording(path: Path, state: PointState, inputs: str, point) -> dict | None:
    """The acquire step's record of ``path`` when it is the complete, whole recording of the
    acquisition ``point.json`` says was under way from today's inputs (its token); else None."""
    if state.acquiring is None or state.acquiring.get("inputs") != inputs:
        return None
    rec = _complete_recording(path)
    if rec is None or str(rec["attrs"].get("campaign_acquisition", "")) != state.acquiring["token"]:
        return None
    rate = float(rec["attrs"].get("sample_rate_hz", 0.0))
    lost = int(rec["attrs"].get("samples_lost", 0))
    if rec["rows"] + lost < int(round(point.duration_s * rate)):
        return None
    return {"n_samples": rec["rows"], "rate_hz": rate, "overruns": rec["overruns"], "gaps": rec["gaps"],
            "samples_lost": lost, "clipped": rec["clipped"], "wall_s": 0.0}


def _need_bytes(folder: Path, point, step: str, plan: Plan) -> int:
    """A generous estimate of what ``step`` writes (bytes), from the files it reads: measured.nc
    was 2.6 x its recording and a point's pages 0.9 x its measured.nc on the paper's points."""
    if step == "acquire":
        return int(point.duration_s * plan.doc.device.rate_hz * 3 * 4 * 1.2) + (64 << 10)
    if step == "process":
        return 3 * (folder / "recording.h5").stat().st_size + (64 << 10)
    return int(1.2 * (folder / "measured.nc").stat().st_size) + (256 << 10)


def _ensure_space(folder: Path, point, step: str, plan: Plan) -> None:
    """Refuse a step that would not fit on the disk, before it writes anything: HDF5 may crash
    (not raise) when a write fails for lack of space, and the finished steps must stay finished."""
    need = _need_bytes(folder, point, step, plan)
    free = shutil.disk_usage(folder).free
    if free < need:
        raise InputError(f"point {point.name} ({step}): {free / 1e6:.1f} MB free in {shown(folder)}, about "
                         f"{need / 1e6:.1f} MB needed; the finished points and steps are kept: free space and rerun")


def _do(plan: Plan, point, folder: Path, step: str, rep: Reporter, token: str = "") -> dict:
    try:
        if step == "acquire":
            (folder / "recording.h5").unlink(missing_ok=True)
            return steps.acquire(plan, point, folder / "recording.h5", ask=rep.ask, say=rep.say,
                                 progress=lambda recorder, t: rep.acquisition_progress(point, recorder, t),
                                 token=token)
        if step == "process":
            return steps.process(plan, point, folder / "recording.h5", folder / "measured.nc",
                                 warn=lambda m: rep.warn(f"point {point.name}: {m}"))
        report = steps.build(folder / "measured.nc", plan.doc.compare, plan.thresholds, steps.overrides(plan),
                             say=lambda m: rep.step(point, "compare", "running", m))
        steps.write_point_outputs(report, folder, {"html": "report.html", "summary": "summary.json",
                                                   "cycles": "cycles.nc"})
        from labtool.reports.pipeline import closest
        best = closest(report)
        return {"closest": None if best is None else best["label"], "passed": bool(report.passed),
                "notes": list(report.notes)}
    except LabtoolError as exc:
        raise type(exc)(f"point {point.name} ({step}): {exc}") from None


def _detail(step: str, info: dict) -> str:
    if step == "acquire":
        return f"{info['n_samples']} samples at {info['rate_hz']:g} Hz, {info['overruns']} overruns"
    if step == "process":
        return (f"cam {info.get('cam_speed_rpm', float('nan')):.2f} rpm, {info.get('revolutions_averaged', 0)} "
                "revolutions averaged")
    return f"closest: {info.get('closest')}"


# what the outputs of a point weigh against its recording (bytes): measured.nc is 3.1 x its
# recording and the pages ~0.7 MB on tests/test_campaign_run.py's quick plan
MEASURED_PER_RECORDING = 3.5
PAGES_BYTES = 1e6


def estimate_work(plan: Plan, states: list, redo=()) -> tuple[float, float, str]:
    """(seconds, bytes, basis) of what a run of ``plan`` has left to do, given each point's
    ``PointState``: the stand's time of the recordings still to make (real time: the simulated
    stand paced so, or NI-DAQmx; a lower bound of the run, which also processes and compares), and
    the disk of their recordings (float32 volts, 3 channels), measured files and pages."""
    dev = plan.doc.device
    paced = dev.kind == "nidaqmx" or dev.pacing == "realtime"
    seconds = nbytes = 0.0
    n_record = n_other = 0
    for point, state in zip(plan.points, states):
        if state.done() and point.name not in redo:
            continue
        recording = point.duration_s * dev.rate_hz * 3 * 4
        if point.name in redo or not state.finished("acquire", _inputs(plan, point, state, "acquire")):
            n_record += 1
            seconds += point.duration_s if paced else 0.0
            nbytes += recording * (1.0 + MEASURED_PER_RECORDING) + PAGES_BYTES
        else:
            n_other += 1
            nbytes += recording * MEASURED_PER_RECORDING + PAGES_BYTES
    basis = (f"{n_record} point(s) to record" + (" in real time" if paced and n_record else "")
             + (f", {n_other} to process and compare" if n_other else "")
             + f"; a measured file ~{MEASURED_PER_RECORDING:g} x its recording")
    return seconds, nbytes, basis


def run_campaign(plan: Plan, folder: Path, reporter: Reporter | None = None, redo=(),
                 check_work=None) -> CampaignResult:
    """Run (or resume) the campaign of ``plan`` into ``folder`` (module docstring).
    ``check_work(seconds, bytes, basis)`` sees what is left to do (``estimate_work``) before any
    point runs, and may refuse it (labtool.common.budget.check_work)."""
    rep = reporter or Reporter()
    folder = Path(folder)
    redo = set(redo)
    names = {p.name for p in plan.points}
    unknown = sorted(redo - names)
    if unknown:
        raise InputError(f"--redo {', '.join(unknown)}: no such point in the plan (points: {', '.join(sorted(names))})")
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{shown(folder)} is a file; give a folder for the campaign")
    if check_work is not None:       # asked before anything is created (read only; checked again under the lock)
        for p in plan.points:
            _check_point_paths(p, point_folder(folder, p))
        states = [PointState.load(point_folder(folder, p), p.name, p.spec()) for p in plan.points]
        for p, st in zip(plan.points, states):
            _check_existing(plan, p, st, redo)
        check_work(*estimate_work(plan, states, redo))
    try:
        (folder / POINTS_DIR).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create the campaign folder {shown(folder)}: {exc.strerror or exc}") from None
    t0 = time.perf_counter()
    ran, kept, walls = [], [], []
    lock = CampaignLock(folder)
    try:
        lock.__enter__()
    except OSError as exc:
        raise InputError(f"cannot write in the campaign folder {shown(folder)}: {exc.strerror or exc}") from None
    try:
        try:
            _keep_plan_copy(plan, folder)
        except OSError as exc:
            raise InputError(f"cannot write in the campaign folder {shown(folder)}: {exc.strerror or exc}") from None
        for p in plan.points:
            _check_point_paths(p, point_folder(folder, p))
        states = [PointState.load(point_folder(folder, p), p.name, p.spec()) for p in plan.points]
        for p, st in zip(plan.points, states):
            _check_existing(plan, p, st, redo)
        rep.campaign_start(plan, folder, sum(1 for s in states if s.done()))
        n = len(plan.points)
        for k, point in enumerate(plan.points, start=1):
            rep.point_start(k, n, point)
            tp = time.perf_counter()
            worked = _run_point(plan, point, point_folder(folder, point), rep, redo)
            wall = time.perf_counter() - tp
            (ran if worked else kept).append(point.name)
            if worked:
                walls.append(wall)
            left = n - k
            eta = (sum(walls) / len(walls)) * left if walls and left else (0.0 if not left else None)
            rep.point_done(k, n, point, wall, eta, worked)
    except (KeyboardInterrupt, SystemError) as exc:   # Ctrl-C, SIGTERM, SIGHUP (in compiled code: a SystemError)
        stop = interrupt_cause(exc)
        if stop is None:
            raise
        stop.add_note(f"{shown(folder)} keeps the finished points and steps; the same command resumes")
        raise stop from None
    finally:
        lock.__exit__(None, None, None)
    return CampaignResult(folder, [(p, point_folder(folder, p)) for p in plan.points], ran, kept,
                          time.perf_counter() - t0)


def _keep_plan_copy(plan: Plan, folder: Path) -> None:
    """plan.toml in the folder: the plan of the latest run (the points' records say what each used)."""
    from labtool.common.files import atomic_write

    data = Path(plan.path).read_bytes()
    target = folder / "plan.toml"
    if target.exists() and target.read_bytes() == data:
        return
    atomic_write(target, lambda tmp: tmp.write_bytes(data))
