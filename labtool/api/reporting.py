"""``labtool.report``: a measurement against the models, with a verdict, as data and files."""
from __future__ import annotations

from pathlib import Path

from labtool.common import budget
from labtool.common.budget import DEFAULT_MAX_SECONDS

PROBE_ABOVE_REVOLUTIONS = 20     # the default 6 takes well under a minute: no estimate needed


def report(measured, output=None, *, models=("rigid", "elastic"), omega1=("const", "var"), thresholds=None,
           pdf=None, json=None, accuracy: str = "standard", revolutions: int = 6, robustness: bool = True,
           harmonics: int = 60, grid_points: int = 720, fits=(), curves: bool = True, discriminate: bool = True,
           force: bool = True, max_seconds: float = DEFAULT_MAX_SECONDS, confirm=None, progress=None, **changes):
    """Compare a processed measurement with the models on the cam angle.

    Parameters
    ----------
    measured : path
        measured.nc (``labtool.process``).
    output : path, optional
        The HTML page to write (self-contained). The files asked for (``output``, ``pdf``,
        ``json``) are written as one set, or none.
    models : sequence of {"rigid", "elastic", "kinematic"}
        The models compared.
    omega1 : sequence of {"const", "var"}
        The cam speed modes each model runs in: ``const`` (the cam as input) or ``var`` (the
        motor's characteristic).
    thresholds : path, optional
        A TOML file of limits on the metrics (``Report.passed`` says whether they hold).
    pdf : path, optional
        The PDF report to write beside ``output``.
    json : path or "-", optional
        The JSON summary to write ("-": standard output).
    accuracy : {"fast", "standard", "reference"}
        The models' solver preset.
    revolutions : int
        Cam revolutions simulated [-]: the last is compared when the model's motion is periodic,
        else the cycle statistics of revolutions 2..N.
    robustness : bool
        Also rate at the other preset and half the length: whether the verdict holds.
    harmonics : int
        Low-pass of both sides: the harmonics of the cam frequency kept [-].
    grid_points : int
        Points per revolution of the cam-angle grid both sides are compared on [-].
    fits : sequence of paths
        ``labtool fit`` results: each identified model compared as '<model> (fitted)'.
    curves : bool
        Also write the compared curves beside the page: ``<name>_curves.csv`` and ``<name>_curves.nc``
        (measured mean, std and each revolution, every model; rad/s, rad/s^2).
    discriminate : bool
        When the measurement cannot tell the models apart, simulate them at a few cam speeds (fast
        preset) and name the speed that would.
    force : bool
        Overwrite existing output files (False: refuse them, as the command does without ``--force``).
    max_seconds : float
        Refuse a report whose simulations of many ``revolutions`` are estimated longer [s].
    confirm : callable, optional
        ``confirm(question) -> bool``, asked before such a report instead of refusing it.
    progress : callable, optional
        ``progress(text)`` before each long step.
    **changes
        Operating-point fields (SI, ``labtool.OperatingPoint``'s names): the models' options, or a
        value the file states wrongly; default the file's, else labtool's defaults. The cam speed is
        the measured one unless ``cam_speed`` is given.

    Returns
    -------
    labtool.reports.pipeline.Report
        The comparison: ``scene`` (the operating point with the source of each value), the
        metrics, events, notes, the verdict (``labtool.reports.pipeline.verdict_lines``) and
        ``passed``.
    """
    from labtool.common.files import check_outputs
    from labtool.reports.align import Conditioning
    from labtool.reports.outputs import curves_beside, write_report
    from labtool.reports.pipeline import build_report
    from labtool.reports.thresholds import load_thresholds

    output, pdf = (Path(p) if p is not None else None for p in (output, pdf))
    json = None if json is None else (json if str(json) == "-" else Path(json))
    curve_paths = curves_beside(output, pdf) if curves else {}
    check_outputs({"-o": output, "--pdf": pdf, "--json": json, **{f"curves ({f})": p for f, p in curve_paths.items()}},
                  force)
    budget.check_limit(max_seconds)
    if revolutions > PROBE_ABOVE_REVOLUTIONS:
        _check_budget(models, omega1, accuracy, revolutions, robustness, max_seconds, confirm)
    th = load_thresholds(Path(thresholds)) if thresholds is not None else None
    fitted = None
    if fits:
        from labtool.identification.fit import load_fit
        fitted = [load_fit(Path(p)) for p in fits]
    rep = build_report(Path(measured), tuple(models), tuple(omega1), th, {k: v for k, v in changes.items()
                                                                          if v is not None},
                       accuracy, revolutions, Conditioning(n_grid=grid_points, n_harmonics=harmonics),
                       progress=progress, robustness=robustness, fitted=fitted, discriminate=discriminate)
    if output is not None or pdf is not None or json is not None:
        # the HTML, PDF, JSON and curves are one set: all written, or none (a full disk, Ctrl-C)
        write_report(rep, output, pdf, json, progress, curves=curve_paths)
    return rep


def _check_budget(models, modes, accuracy, revolutions, robustness, max_seconds, confirm) -> None:
    """Estimate the simulations of a long report from each dynamic model at 2 and 4 revolutions
    (the paper's operating point; the file's may differ, so this is an order of magnitude) times
    the runs it makes (models x omega1 modes, x2 with the robustness check at the other preset)."""
    from labtool.models.dynamics.scene import Scene
    from labtool.models.dynamics.simulate import simulate

    seconds, peak, bases = 0.0, 0.0, []
    for model in [m for m in models if m in ("rigid", "elastic")]:
        scene = Scene(accuracy=accuracy, rise_only=False)
        est = budget.probe_linear(lambda n: simulate(scene.replace(revolutions=float(n)), model).dataset,
                                  (2, 4), revolutions, "revolution", nbytes=lambda ds: 2.0 * ds.nbytes)
        runs = len(modes) * (2 if robustness else 1)
        seconds += runs * est.seconds
        peak = max(peak, est.bytes * len(modes))
        bases.append(f"{model}: {est.basis}, {runs} runs")
    if seconds > 0:
        budget.check(budget.Estimate(seconds, peak, "; ".join(bases)), f"--revolutions {revolutions}", max_seconds,
                     "use fewer --revolutions", confirm)
