"""``labtool.run_design``: the simulated experiment, every run of a full factorial (paper sec. 2.2)."""
from __future__ import annotations

import dataclasses
import os
from pathlib import Path


@dataclasses.dataclass
class DesignRun:
    """A factorial run, as :func:`labtool.run_design` returns it.

    Attributes
    ----------
    csv : pathlib.Path
        The results table (the columns of Tables 2-3; levels as indices).
    netcdf : pathlib.Path
        The same with the factors as coordinates.
    factors : list of labtool.models.study.doe.Factor
        The design's factors, with their levels in their units.
    n_runs : int
        Runs of the design [-].
    resumed : int
        Runs taken from an interrupted run's finished chunks [-].
    n_failed : int
        Runs that failed, left empty in the table [-].
    failures : dict
        Run number -> why it failed (the first few).
    where : str
        Where the runs went (this process, local processes, a Dask cluster).
    wall_s : float
        Wall time [s].
    cost_s : float or None
        Measured cost of one run [s].
    parts : pathlib.Path
        The folder of finished chunks (kept until the design is whole).
    """

    csv: Path
    netcdf: Path
    factors: list
    n_runs: int
    resumed: int
    n_failed: int
    failures: dict
    where: str
    wall_s: float
    cost_s: float | None
    parts: Path


def run_design(output, *, model: str = "rigid", law: str = "sine", omega1: str = "var", factors=None,
               accuracy: str = "standard", elastic_gap: str = "physical", scheduler: str | None = None,
               scheduler_always: bool = False, workers: int | None = None, chunk_runs: int | None = None,
               fresh: bool = False, yes: bool = False, confirm=None, netcdf=None, force: bool = False,
               progress=None, say=None, history: str = "") -> DesignRun:
    """Simulate every run of a full factorial of the factors at the paper's experiment and write
    the results table (CSV) and its NetCDF.

    Runs go in chunks to this process, local processes or a Dask cluster; each finished chunk is
    kept in ``<output>.parts/``, so an interrupted run resumes where it stopped when called again.

    Parameters
    ----------
    output : path
        The results CSV (the columns of Tables 2-3).
    model : {"rigid", "elastic", "kinematic"}
        The model level (rigid: Table 2, elastic: Table 3).
    law : str
        The motion law (sine, cosine, poly345, ...).
    omega1 : {"var", "const"}
        The cam speed: the motor's characteristic (the paper's tables) or constant.
    factors : path, optional
        A factor file, CSV (``factor,symbol,unit,level_1,...``) or TOML (``[[factor]]``); default Table 1.
    accuracy : {"fast", "standard", "reference"}
        The solver preset.
    elastic_gap : {"physical", "closed"}
        The elastic model crosses the backlash, or has no gap (Table 3's convention).
    scheduler : str, optional
        A Dask scheduler address (``tcp://host:8786``) for a design whose measured work is over 10 s.
    scheduler_always : bool
        Send every design to ``scheduler``, however small.
    workers : int, optional
        Local worker processes [-] (default: all cores when the measured work is over 3 s).
    chunk_runs : int, optional
        Runs per task [-] (default: about 1 s of work per task).
    fresh : bool
        Discard the finished chunks of an interrupted run instead of resuming from them.
    yes : bool
        Run a design estimated at more than 10 min or 100 MB on disk without asking.
    confirm : callable, optional
        ``confirm(question) -> bool`` asks before such a design (without it and ``yes`` it is refused).
    netcdf : path, optional
        The NetCDF to write (default: the CSV's name with .nc).
    force : bool
        Overwrite existing output files.
    progress : callable, optional
        ``progress(done, total)``: runs finished [-].
    say : callable, optional
        ``say(text)`` for what the run does on its own (resuming from finished chunks).
    history : str
        The NetCDF's ``history`` (the command line that made it).

    Returns
    -------
    DesignRun
        The files written, the factors, the runs made, resumed and failed, where and how long.
    """
    from labtool.common.errors import InputError
    from labtool.common.files import check_output_path
    from labtool.common.invocation import named
    from labtool.common.names import shown
    from labtool.common.operating_point import PAPER_EXPERIMENT
    from labtool.execution.backends import backend_for, check_scheduler_address
    from labtool.execution.design import parts_folder
    from labtool.execution.design import run_design as run
    from labtool.models.dynamics.scene import Scene
    from labtool.models.study.doe import Design, read_factors, responses_for, table1_factors

    responses_for(model)
    if scheduler is not None:
        check_scheduler_address(scheduler)
    output = Path(output)
    nc_path = Path(netcdf) if netcdf is not None else output.with_suffix(".nc")
    folder = parts_folder(output)
    if nc_path == output or os.path.abspath(nc_path) == os.path.abspath(folder):
        raise InputError(f"{named('netcdf')}: the NetCDF {shown(nc_path)} must be another file than the CSV and its "
                         "finished chunks")
    for name, value in (("workers", workers), ("chunk_runs", chunk_runs)):
        if value is not None and value < 1:
            raise InputError(f"{named(name)} must be >= 1, got {value}")
    cores = os.cpu_count() or 1
    if workers is not None and workers > 4 * cores:    # a process per queued chunk; 10^20 overflowed the pool
        raise InputError(f"{named('workers')} must be at most {4 * cores} (4 x this machine's {cores} cores: more "
                         f"processes only share them), got {workers}")
    for p in (output, nc_path):
        check_output_path(p, force)
    fset = read_factors(Path(factors)) if factors is not None else table1_factors()
    base = Scene.at(PAPER_EXPERIMENT, law=law, omega1_mode=omega1, accuracy=accuracy, elastic_gap=elastic_gap)
    design = Design(tuple(fset), base, model)
    design.validate()
    n_runs = len(design)

    def on_estimate(cost_s, n_left, n_workers):
        # called once the first runs measured the cost, before any is kept: the time of the runs
        # left and the disk of the whole design, asked for through confirm, else refused without yes
        from labtool.common import budget
        from labtool.execution.chunked import estimate_text
        from labtool.execution.design import disk_bytes

        budget.check_work(f"this design of {n_runs} runs", cost_s * n_left / max(n_workers, 1), disk_bytes(design),
                          f"{estimate_text(cost_s, n_left, n_workers)}; about {disk_bytes(design) / n_runs:.0f} bytes "
                          "a run on disk", confirm, yes, "use fewer levels (finished chunks are kept, "
                          "a rerun resumes)")

    if folder.exists() and not fresh and say is not None:
        say(f"resuming from the finished chunks in {folder} (--fresh discards them)")
    backend = backend_for(workers, scheduler, scheduler_always=scheduler_always)
    try:
        res = run(design, output, nc_path, backend, chunk_items=chunk_runs, fresh=fresh, on_estimate=on_estimate,
                  progress=progress, history=history)
    finally:
        if backend is not None:
            backend.close()
    return DesignRun(output, nc_path, list(fset), n_runs, res.resumed, res.n_failed, dict(res.failures), res.where,
                     res.wall_s, res.cost_s, folder)
