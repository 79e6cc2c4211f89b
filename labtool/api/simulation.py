"""``labtool.simulate``: one operating point through a model level, as CF datasets."""
from __future__ import annotations

import dataclasses
import functools
import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from labtool.common import budget, cf
from labtool.common.budget import DEFAULT_MAX_SECONDS
from labtool.common.operating_point import DEFAULT, OperatingPoint
from labtool.processing.cycles import phi1_grid, resample_revolution

if TYPE_CHECKING:
    import xarray as xr

PROBE_ABOVE_REVOLUTIONS = 10       # smaller requests take seconds: no estimate needed
# the variables put on the cam-angle grid, when the model has them
CYCLE_VARIABLES = ("phi2", "omega2", "epsilon2", "omega1", "MR13D", "aE_t", "aE_n", "x_el")


@dataclasses.dataclass
class Simulation:
    """A simulation's results, as :func:`labtool.simulate` returns them.

    Attributes
    ----------
    dataset : xarray.Dataset
        The time series (CF: UDUNITS units and a long name on every variable; the scene, the
        mechanism's source and labtool's version as attributes). ``time`` [s] runs from the start
        of the first rise and is not uniform: the solver's steps and events.
    cycles : xarray.Dataset
        The same variables on the uniform cam-angle grid a measurement uses (``labtool.process``:
        ``grid_points`` per revolution, ``phi1`` [rad] from the start of the rise), one row per
        simulated whole revolution (dimension ``revolution``); NaN where the run does not cover
        the angle (a rise-only run).
    indicators : dict
        The paper's indicators, keys with their units as in Tables 2-3 (``MR13D_max_Nm`` [N m],
        ``dphi2_max_deg`` [deg], ``jumps`` [-], ...); None where the level does not compute one.
    model : str
        The level that ran: kinematic, rigid or elastic.
    reason : str
        Why that level ran (``model="auto"`` picks the cheapest the point needs).
    warnings : list of str
        What the model doubts about its own validity, one sentence each.
    scene : labtool.models.dynamics.scene.Scene
        The scene that ran: an :class:`~labtool.OperatingPoint` with ``revolutions``,
        ``rise_only`` and the mechanism.
    wall_s : float
        Wall time of the model run [s].
    sourced : labtool.common.operating_point.Sourced
        The operating point with where each value came from (given, the mechanism file, a default).
    """

    indicators: dict
    model: str
    reason: str
    warnings: list
    scene: object
    wall_s: float
    sourced: object = None
    # the Datasets are built at their first read: a caller that wants the indicators alone (the
    # command's --json) imports no xarray
    _build: object = dataclasses.field(default=None, repr=False)
    _grid_points: int = dataclasses.field(default=720, repr=False)

    @functools.cached_property
    def dataset(self) -> xr.Dataset:
        return self._build()

    @functools.cached_property
    def cycles(self) -> xr.Dataset:
        return cam_angle_cycles(self.dataset, self._grid_points)


def simulate(point: OperatingPoint | None = None, *, model: str = "auto", revolutions: float = 1.0,
             rise_only: bool = True, mechanism=None, grid_points: int = 720, output=None, force: bool = False,
             max_seconds: float = DEFAULT_MAX_SECONDS, confirm=None, history: str = "", option_source=None,
             **changes) -> Simulation:
    """Simulate the mechanism at an operating point.

    Parameters
    ----------
    point : OperatingPoint, optional
        The operating point and model options (SI); default labtool's defaults
        (``labtool.OperatingPoint()``: the simulated stand's), or ``labtool.PAPER_EXPERIMENT``.
    model : {"auto", "kinematic", "rigid", "elastic"}
        The model level; ``auto`` runs the cheapest level the point needs and says why.
    revolutions : float
        Cam revolutions to simulate [-], the first starting at the start of the rise.
    rise_only : bool
        Simulate the rise only, as the paper's tables do (``revolutions`` then counts rises).
    mechanism : path or labtool.models.mechanism.Mechanism, optional
        The mechanism, or its TOML file (default: the paper's STB-216); its ``[program]`` law
        stands where ``law`` is not given.
    grid_points : int
        Points per revolution of the cam-angle grid of ``Simulation.cycles`` [-].
    output : path, optional
        The NetCDF to write: the time series (``Simulation.dataset``), the operating point with
        each value's source among its attributes.
    force : bool
        Overwrite an existing output file.
    max_seconds : float
        Refuse a run of many ``revolutions`` estimated longer [s] (``confirm`` may allow it).
    confirm : callable, optional
        ``confirm(question) -> bool`` asked before such a run.
    history : str
        The dataset's ``history`` (the command line that made it).
    option_source : callable, optional
        ``option_source(field) -> str``: how a given value's source is named (default
        ``"argument <name>"``).
    **changes
        Operating-point fields replacing ``point``'s, in SI (``cam_speed`` [rad/s], ``Fu`` [N],
        ``backlash`` [m], ``restitution`` [-], ...; see ``labtool.OperatingPoint``).

    Returns
    -------
    Simulation
        The time series and the cam-angle cycles as CF datasets, the indicators, the level that ran.

    Examples
    --------
    >>> import labtool
    >>> from labtool.units import RPM
    >>> sim = labtool.simulate(model="rigid", cam_speed=300 * RPM, revolutions=3, rise_only=False)
    >>> sim.cycles["omega2"].sel(revolution=2)          # doctest: +SKIP
    """
    from labtool.common.errors import InputError
    from labtool.common.files import check_output_path, write_netcdf
    from labtool.common.operating_point import FIELD, resolve
    from labtool.models.dynamics.scene import Scene
    from labtool.models.dynamics.simulate import simulate as run
    from labtool.models.mechanism import Mechanism

    unknown = sorted(set(changes) - set(FIELD))
    if unknown:
        raise TypeError(f"simulate() got unexpected keyword arguments {unknown}: the operating point's fields are "
                        f"{', '.join(FIELD)} (SI)")
    if output is not None:
        check_output_path(Path(output), force)
    if not (math.isfinite(revolutions) and revolutions > 0):
        raise InputError(f"--revolutions must be a finite number > 0, got {revolutions}")
    if mechanism is None or isinstance(mechanism, Mechanism):
        mech, where = mechanism if mechanism is not None else Mechanism.default(), "the mechanism"
    else:
        mech, where = Mechanism.from_toml(Path(mechanism)), f"mechanism file {mechanism}"
    # a mechanism's [program] law stands where no law is given
    program_law = ({"law": mech.program["law"], "law_source": "its [program] table"}
                   if mechanism is not None and mech.program.get("law") else None)
    sourced = resolve(changes, program_law, where=where, base=point if point is not None else DEFAULT,
                      option_source=option_source or (lambda f: f"argument {f.name}"))
    scene = Scene.at(sourced.point, revolutions=float(revolutions), rise_only=bool(rise_only), mechanism=mech)
    budget.check_limit(max_seconds)
    if revolutions > PROBE_ABOVE_REVOLUTIONS:
        _check_budget(scene, model, revolutions, max_seconds, output is not None, confirm)
    res = run(scene, model)

    def build():
        ds = res.dataset
        ds.attrs.update(sourced.source_attrs())
        # CF-1.10 (labtool.common.cf): UDUNITS units, Conventions/title/source; the command line in history
        cf.apply(ds, title=f"labtool simulation, {res.model} model", source=f"labtool {res.model} model",
                 history=history)
        return ds

    sim = Simulation(res.indicators, res.model, res.reason, list(res.warnings), scene, res.wall_s, sourced,
                     _build=build, _grid_points=grid_points)
    if output is not None:
        write_netcdf(sim.dataset, Path(output))
    return sim


def _check_budget(scene, model: str, revolutions: float, max_seconds: float, writes: bool, confirm) -> None:
    """Refuse (or ask through ``confirm``) a run estimated over ``max_seconds`` or the memory there
    is, from the same scene at 2 and 4 revolutions (peak memory ~2x the Dataset, +1x for the NetCDF)."""
    from labtool.models.dynamics.simulate import simulate as run

    est = budget.probe_linear(lambda n: run(scene.replace(revolutions=float(n)), model).dataset,
                              (2, 4), revolutions, "revolution",
                              nbytes=lambda ds: ds.nbytes * (3.0 if writes else 2.0))
    budget.check(est, f"--revolutions {revolutions:g}", max_seconds, "use fewer --revolutions", confirm)


def cam_angle_cycles(ds: xr.Dataset, grid_points: int = 720) -> xr.Dataset:
    """A simulation's variables on the uniform cam-angle grid, one row per revolution it covers.

    ``ds`` holds ``phi1`` (rad, unwrapped, 0 at the start of the first rise) over ``time`` (the
    dynamic models) or as its coordinate (the kinematic level). Revolution k covers phi1 in
    [2 pi k, 2 pi (k + 1)); grid points the run does not reach are NaN.
    """
    import xarray as xr

    phi = np.asarray(ds["phi1"].values, float)
    dims = ds["phi1"].dims
    names = [n for n in CYCLE_VARIABLES if n in ds and ds[n].dims == dims]
    grid = phi1_grid(grid_points)
    n_rev = max(int(math.ceil(phi[-1] / (2.0 * math.pi) - 1e-9)), 1) if phi.size else 0
    values = {n: np.full((n_rev, grid_points), np.nan) for n in names}
    order = np.argsort(phi, kind="stable")
    phi_sorted = phi[order]
    for k in range(n_rev):
        lo, hi = np.searchsorted(phi_sorted, [2.0 * math.pi * k, 2.0 * math.pi * (k + 1)], side="left")
        lo, hi = max(lo - 1, 0), min(hi + 1, phi.size)
        if hi - lo < 2:
            continue
        sel = order[lo:hi]
        rows = resample_revolution(phi_sorted[lo:hi] - 2.0 * math.pi * k,
                                   np.stack([np.asarray(ds[n].values, float)[sel] for n in names]), grid, np.nan)
        for i, n in enumerate(names):
            values[n][k] = rows[i]
    coords = {"revolution": ("revolution", np.arange(n_rev), {"long_name": "cam revolution from the start of the "
                                                                        "first rise", "units": "1"}),
              "phi1": ("phi1", grid, {"long_name": "cam angle from the start of the rise", "units": "rad"})}
    data = {n: (("revolution", "phi1"), values[n], dict(ds[n].attrs)) for n in names}
    out = xr.Dataset(data, coords=coords)
    out.attrs.update({k: v for k, v in ds.attrs.items() if k not in ("history",)})
    out.attrs["grid_points_per_revolution"] = int(grid_points)
    return out
