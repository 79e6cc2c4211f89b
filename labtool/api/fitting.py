"""``labtool.fit``: model parameters identified from a measurement, or from several at once,
with 95 % intervals."""
from __future__ import annotations

from pathlib import Path


def fit(measured, *, model: str, free: str, shared: str | None = None, omega1: str = "const", accuracy: str = "standard", revolutions: int = 3,
        bounds: dict | None = None, start="scan", scan: bool = True, max_runs: int = 200, ka_gain: float = 1.0,
        delay_ms: float = 0.0, output=None, figure=None, force: bool = False, progress=None, **changes):
    """Identify a model's parameters from a processed measurement.

    Parameters
    ----------
    measured : path or list of paths
        measured.nc (``labtool.process``): the measurement the models are fitted to; several:
        a joint fit, the ``shared`` parameters fitted once for all files, the others per file,
        and the files tested for agreement.
    model : {"rigid", "elastic"}
        The model whose parameters are identified.
    free : str
        The parameters to identify, comma-separated: ``backlash`` [mm], ``restitution`` [-]
        (rigid), ``contact_damping`` [s/m], ``contact_length`` [mm] (elastic), ``ka_gain`` [-],
        ``delay`` [ms].
    shared : str, optional
        Several files: the free parameters they share, comma-separated (default: those that are
        the stand's properties: backlash, contact_length, ka_gain, delay).
    omega1 : {"const", "var"}
        The model's cam speed mode.
    accuracy : {"fast", "standard"}
        Solver preset of the final evaluation (the search runs at fast).
    revolutions : int
        Cam revolutions each model run simulates [-].
    bounds : dict, optional
        Search bounds in edge units by parameter name, ``{"backlash": (0.02, 0.4)}``.
    start : "scan", "scene" or dict
        Where the search starts: a coarse scan (default), the operating point's values, or given
        values in edge units.
    scan : bool
        Also search from the scan's best points when a start is given.
    max_runs : int
        Model runs the search may use [-].
    ka_gain : float
        The measuring chain's gain on the calibrated Ka [-], when it is not free.
    delay_ms : float
        The measuring chain's delay [ms], when it is not free.
    output : path, optional
        The result to write (JSON, the ``summary``).
    figure : path, optional
        The figure of the fit and its profiles (PNG; default: beside ``output``, ``.png``). The
        JSON and the figure are written as one set: both, or neither.
    force : bool
        Overwrite existing output files.
    progress : callable, optional
        ``progress(text)`` before each long step.
    **changes
        Operating-point fields (SI, ``labtool.OperatingPoint``'s names) fixed for the models, or the
        start of a free one; default: the measured file's, else labtool's defaults.

    Returns
    -------
    labtool.identification.fit.FitOutcome or labtool.identification.joint.JointOutcome
        ``summary``: the result as a JSON-ready dict (values, 95 % intervals, identifiability,
        metrics before and after, notes; for several files the joint values, each file's own
        fit and the consistency test); what the figures need.

    Examples
    --------
    >>> import labtool
    >>> out = labtool.fit(["a.nc", "b.nc", "c.nc"], model="rigid", free="backlash,restitution",
    ...                   shared="backlash")                                     # doctest: +SKIP
    >>> out.summary["consistency"]["backlash_mm"]["verdict"]                       # doctest: +SKIP
    """
    import math

    from labtool.common.errors import InputError
    from labtool.common.invocation import named
    from labtool.identification.fit import FitRequest, identify
    from labtool.identification.parameters import parse_assignments

    for name, value in (("ka_gain", ka_gain), ("delay_ms", delay_ms)):
        if not math.isfinite(value):
            raise InputError(f"{named(name)} must be a finite number, got {value}")
    if not ka_gain > 0:
        raise InputError(f"{named('ka_gain')} must be > 0, got {ka_gain:g}")
    files = list(measured) if isinstance(measured, (list, tuple)) else [measured]
    if not files:
        raise InputError("fit: no measured file given")
    if len(files) == 1 and shared is not None:
        raise InputError(f"{named('shared')} needs several measured files (a joint fit); give two or more, or drop "
                         f"{named('shared')}")
    figure = result_files(output, figure, force)
    if isinstance(bounds, str):
        bounds = parse_assignments(bounds, "bounds", ranges=True)
    common = dict(omega1=omega1, accuracy=accuracy, revolutions=int(revolutions), bounds=dict(bounds or {}),
                  start=start, overrides={k: v for k, v in changes.items() if v is not None},
                  chain={"ka_gain": float(ka_gain), "delay_ms": float(delay_ms)}, max_runs=int(max_runs), scan=scan)
    if len(files) > 1:
        from labtool.identification.joint import JointRequest, identify_joint
        outcome = identify_joint(JointRequest([Path(m) for m in files], model, free, shared, **common),
                                 progress=progress)
    else:
        outcome = identify(FitRequest(Path(files[0]), model, free, **common), progress=progress)
    if output is not None or figure is not None:
        write_result(outcome, output, figure, joint=len(files) > 1, progress=progress)
    return outcome


def figure_path(output, figure):
    """The fit's figure: ``figure``, else beside the JSON ``output`` (``.png``), else none."""
    if figure is not None:
        return Path(figure)
    return Path(output).with_suffix(".png") if output is not None else None


def result_files(output, figure, force: bool):
    """The figure's path (default: beside the JSON ``output``, ``.png``), both checked before any
    work: different files, and none there unless ``force``."""
    from labtool.common.errors import InputError
    from labtool.common.files import check_output_path

    output = Path(output) if output is not None else None
    figure = figure_path(output, figure)
    outputs = [p for p in (output, figure) if p is not None]
    if len({p.resolve() for p in outputs}) != len(outputs):
        raise InputError("the JSON and the figure must be different files")
    for p in outputs:
        check_output_path(p, force)
    return figure


def write_result(outcome, output, figure, joint: bool = False, progress=None) -> None:
    """The fit's summary as JSON (``output``) and its figure (PNG, ``figure``), renamed together:
    a rerun after an interruption finds no JSON without its figure."""
    import json

    from labtool.common.files import OutputSet

    text = json.dumps(outcome.summary, indent=1, allow_nan=False)
    fig = None
    if figure is not None:
        if progress is not None:
            progress("drawing the figure")
        from labtool.identification.figures import fit_figure, joint_figure
        fig = joint_figure(outcome) if joint else fit_figure(outcome)
    with OutputSet() as outputs:
        if output is not None:
            outputs.write_text(Path(output), text + "\n")
        if fig is not None:
            outputs.write(Path(figure), lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
