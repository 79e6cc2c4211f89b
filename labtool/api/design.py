"""``labtool.suggest``: the operating point to record next, where a recording would narrow the
identified parameters' intervals most."""
from __future__ import annotations

from pathlib import Path


def suggest(measured, *, goal: str = "identify", model: str = "rigid", free: str = "backlash,restitution",
            models=("rigid", "elastic"), shared: str | None = None, rpm_range: tuple = (120.0, 600.0, 20.0), loads=None, accuracy: str = "fast",
            revolutions: int = 3, progress=None, **fit_options):
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
    from labtool.identification.design import SuggestRequest
    from labtool.identification.design import suggest as run

    files = [Path(m) for m in measured] if isinstance(measured, (list, tuple)) else [Path(measured)]
    req = SuggestRequest(files, model, free, goal, shared, tuple(float(v) for v in rpm_range),
                         None if loads is None else tuple(float(v) for v in loads), accuracy, int(revolutions),
                         fit=dict(fit_options), models=tuple(models))
    return run(req, progress=progress)
