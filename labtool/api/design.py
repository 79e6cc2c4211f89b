"""``labtool.suggest``: the operating point to record next, where a recording would narrow the
identified parameters' intervals most."""
from __future__ import annotations

from pathlib import Path


def suggest(measured, *, goal: str = "identify", model: str = "rigid", free: str = "backlash,restitution",
            models=("rigid", "elastic"), shared: str | None = None, rpm_range: tuple = (120.0, 600.0, 20.0), loads=None, accuracy: str = "fast",
            revolutions: int = 3, output=None, figure=None, force: bool = False, progress=None, **fit_options):
    """Suggest the next operating point (cam speed, load) from the measurements so far.

    Parameters
    ----------
    measured : path or list of paths
        measured.nc files (``labtool.process``); several are fitted jointly.
    goal : {"identify", "discriminate"}
        ``identify``: D-optimal on the fit's Jacobian; ``discriminate``: where the ``models``'
        predictions differ most against the measured scatter (docs/identification.md, "The next
        experiment").
    model : {"rigid", "elastic"}
        The model whose parameters are identified.
    free : str
        The identified parameters, comma-separated (as ``labtool.fit``).
    models : sequence of str
        ``discriminate``: the models to tell apart.
    shared : str, optional
        The free parameters every recording shares (default: the stand's properties).
    rpm_range : (lo, hi, step)
        Candidate cam speeds [rpm].
    loads : sequence of float, optional
        Candidate loads Fu [N] (default: the measured ones).
    accuracy : {"fast", "standard"}
        Solver preset of the fit and of the candidates' runs.
    revolutions : int
        Cam revolutions of each candidate's model run [-].
    output : path, optional
        The suggestion to write (JSON, the ``summary``).
    figure : path, optional
        The figure of the criterion against cam speed (PNG; default: beside ``output``, ``.png``).
    force : bool
        Overwrite existing output files.
    progress : callable, optional
        ``progress(text)`` before each long step.
    **fit_options
        The fit's other options (``labtool.identification.fit.FitRequest``: ``max_runs``, ``bounds``, ...).

    Returns
    -------
    labtool.identification.design.SuggestOutcome
        ``summary``: the point, the expected interval widths, every candidate's criterion and a
        ``[[points]]`` snippet for a campaign plan (``plan_points_toml``).
    """
    from labtool.api.fitting import result_files
    from labtool.identification.design import SuggestRequest
    from labtool.identification.design import suggest as run

    figure = result_files(output, figure, force)
    files = [Path(m) for m in measured] if isinstance(measured, (list, tuple)) else [Path(measured)]
    req = SuggestRequest(files, model, free, goal, shared, tuple(float(v) for v in rpm_range),
                         None if loads is None else tuple(float(v) for v in loads), accuracy, int(revolutions),
                         fit=dict(fit_options), models=tuple(models))
    outcome = run(req, progress=progress)
    if output is not None or figure is not None:
        _write(outcome, output, figure, progress)
    return outcome


def _write(outcome, output, figure, progress=None) -> None:
    """The suggestion as JSON (``output``) and the figure of its criterion (PNG, ``figure``)."""
    import json

    from labtool.common.files import atomic_write

    text = json.dumps(outcome.summary, indent=1, allow_nan=False)
    fig = None
    if figure is not None:
        if progress is not None:
            progress("drawing the figure")
        from labtool.identification.figures import suggest_figure
        fig = suggest_figure(outcome)
    if output is not None:
        atomic_write(Path(output), lambda tmp: tmp.write_text(text + "\n", encoding="utf-8"))
    if fig is not None:
        atomic_write(Path(figure), lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
