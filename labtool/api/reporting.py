"""``labtool.report``: a measurement against the models, with a verdict, as data and files."""
from __future__ import annotations

from pathlib import Path


def report(measured, output=None, *, models=("rigid", "elastic"), omega1=("const", "var"), thresholds=None,
           pdf=None, json=None, accuracy: str = "standard", revolutions: int = 6, robustness: bool = True,
           harmonics: int = 60, grid_points: int = 720, fits=(), progress=None, **changes):
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
    from labtool.reports.align import Conditioning
    from labtool.reports.outputs import write_report
    from labtool.reports.pipeline import build_report
    from labtool.reports.thresholds import load_thresholds

    th = load_thresholds(Path(thresholds)) if thresholds is not None else None
    fitted = None
    if fits:
        from labtool.identification.fit import load_fit
        fitted = [load_fit(Path(p)) for p in fits]
    rep = build_report(Path(measured), tuple(models), tuple(omega1), th, {k: v for k, v in changes.items()
                                                                          if v is not None},
                       accuracy, revolutions, Conditioning(n_grid=grid_points, n_harmonics=harmonics),
                       progress=progress, robustness=robustness, fitted=fitted)
    if output is not None or pdf is not None or json is not None:
        write_report(rep, Path(output) if output is not None else None, Path(pdf) if pdf is not None else None,
                     None if json is None else (json if str(json) == "-" else Path(json)), progress)
    return rep
