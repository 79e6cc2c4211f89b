"""The report's figures (matplotlib, object API, no global state), of the paper's kinds:

- MR13D of each model in its own panel and the impacts' percussions (paper Figs 7-9);
- amplitude spectra and time histories of the measured accelerations (Fig 11);
- measured against simulated omega2 and epsilon2, omega1 constant and variable (Figs 12-14), with
  the measured and predicted impacts marked;
- the mechanism at the first impact (labtool.reports.drawing);
- residuals (simulated minus the measured cycle average) against the measured scatter;
- the measured epsilon2 against frequency and against cam order (tacho-resampled).

Colours: the measurement black (its ±2σ band grey), each run (model x omega1 mode) its own
Okabe-Ito colour (colour-blind safe, ``run_color``), thin lines, omega1 var dashed.

Each function returns ``(title, Figure)`` or None when the data it needs is absent. Degrees and
millimetres appear only on the axes; the data stay SI. The y-range of a comparison is set by the
measurement; model curves beyond it are clipped and marked (``plot_clipped``).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure

from labtool.common.cf import elapsed_seconds

# Okabe & Ito's colour-blind-safe palette: each compared run (model x omega1 mode) its own colour,
# the measurement black; omega1 var dashed (a model whose two modes coincide shows both)
OKABE_ITO = {"blue": "#0072B2", "vermillion": "#D55E00", "green": "#009E73", "purple": "#CC79A7",
             "orange": "#E69F00", "sky": "#56B4E9", "yellow": "#F0E442"}
RUN_COLORS = {("rigid", "const"): OKABE_ITO["blue"], ("rigid", "var"): OKABE_ITO["vermillion"],
              ("elastic", "const"): OKABE_ITO["green"], ("elastic", "var"): OKABE_ITO["purple"],
              ("kinematic", "const"): OKABE_ITO["orange"], ("kinematic", "var"): OKABE_ITO["sky"]}
SPARE = (OKABE_ITO["orange"], OKABE_ITO["sky"], OKABE_ITO["purple"], OKABE_ITO["green"])
COLORS = {"const": OKABE_ITO["blue"], "var": OKABE_ITO["vermillion"]}     # by omega1 mode alone
STYLES = {"const": "-", "var": (0, (4, 2))}
MODEL_LW = 1.0           # thin: the measurement stays visible under the models
SIGNAL_LABEL = {"omega2": ("ω2", "rad/s"), "epsilon2": ("ε2", "rad/s²")}


def run_color(requested: str, omega1: str) -> str:
    """The colour of a compared run, the same in every figure of the report and the campaign page:
    the nominal models' fixed ones, a fitted or other run one of the spare colours."""
    key = (str(requested), str(omega1))
    if key in RUN_COLORS:
        return RUN_COLORS[key]
    return SPARE[sum(map(ord, f"{requested}{omega1}")) % len(SPARE)]


def plain(text) -> str:
    """A string from a file, shown literally by matplotlib ('$' would start mathtext and an
    unbalanced one would fail the drawing)."""
    return str(text).replace("$", r"\$")


def measured_limits(values: np.ndarray, margin: float = 0.15) -> tuple[float, float]:
    """y-range set by the measurement: its extremes (all revolutions and the band) plus ``margin``."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return -1.0, 1.0
    lo, hi = float(v.min()), float(v.max())
    pad = margin * max(hi - lo, 1e-12)
    return lo - pad, hi + pad


def plot_clipped(ax, x, y, lim, **style) -> int:
    """Plot y clipped to the axis range ``lim``; the clipped stretches are marked with small
    triangles on the axis' edge. Returns the number of clipped points."""
    y = np.asarray(y, dtype=float)
    lo, hi = lim
    ax.plot(x, np.clip(y, lo, hi), **style)
    above, below = y > hi, y < lo
    color = style.get("color")
    if above.any():
        ax.plot(np.asarray(x)[above], np.full(above.sum(), hi), "^", ms=3, color=color, clip_on=False)
    if below.any():
        ax.plot(np.asarray(x)[below], np.full(below.sum(), lo), "v", ms=3, color=color, clip_on=False)
    return int(above.sum() + below.sum())


def _last_revolution(ds):
    """Mask of the simulation's last whole revolution (or everything) and its cam angle in deg."""
    phi = np.asarray(ds["phi1"].values, dtype=float)
    k = max(int(math.floor(np.nanmax(phi) / (2 * math.pi) + 1e-9)) - 1, 0)
    mask = (phi >= 2 * math.pi * k) & (phi <= 2 * math.pi * (k + 1))
    if mask.sum() < 2:
        mask = np.isfinite(phi)
        k = 0
    return mask, np.degrees(phi[mask] - 2 * math.pi * k)


def fig_mr13d(sims) -> tuple[str, Figure] | None:
    """MR13D of each model (its own panel, so the elastic contact spikes do not hide the rigid
    curve; each panel's y-range is its 1-99 % quantiles, spikes beyond it clipped and marked) over
    the last simulated revolution, and the percussions of the events (Figs 7-9)."""
    models = list(dict.fromkeys(r.requested for r in sims if "MR13D" in r.dataset))
    if not models:
        return None
    has_perc = any("event_percussion" in r.dataset and "event_phi1" in r.dataset for r in sims)
    rows = len(models) + int(has_perc)
    fig = Figure(figsize=(9, 2.4 * rows + 0.6))
    axes = fig.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]
    margins(fig, left=0.95, top=0.55, hspace=0.25)
    for ax, model in zip(axes, models):
        runs = [r for r in sims if r.requested == model and "MR13D" in r.dataset]
        vals = []
        for r in runs:
            mask, deg = _last_revolution(r.dataset)
            vals.append((r, deg, np.asarray(r.dataset["MR13D"].values, dtype=float)[mask]))
        pool = np.concatenate([v for _, _, v in vals])
        q1, q99 = np.nanpercentile(pool, [1, 99])
        pad = 0.15 * max(q99 - q1, 1e-9)
        lim = (q1 - pad, q99 + pad)
        for r, deg, v in vals:
            plot_clipped(ax, deg, v, lim, color=run_color(r.requested, r.omega1), lw=0.9, ls=STYLES[r.omega1],
                         label=r.label)
        ax.set_ylim(*lim)
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_ylabel(f"MR13D [N·m]\n{model}")
        ax.legend(fontsize=7, ncol=2)
    if has_perc:
        ax = axes[-1]
        for r in sims:
            ds = r.dataset
            if "event_percussion" not in ds or "event_phi1" not in ds:
                continue
            ph = np.asarray(ds["event_phi1"].values, dtype=float)
            pc = np.asarray(ds["event_percussion"].values, dtype=float)
            k = max(int(math.floor(np.nanmax(np.asarray(ds["phi1"].values)) / (2 * math.pi) + 1e-9)) - 1, 0)
            sel = (ph >= 2 * math.pi * k) & (ph < 2 * math.pi * (k + 1)) & np.isfinite(pc)
            if sel.any():
                c = run_color(r.requested, r.omega1)
                ax.vlines(np.degrees(ph[sel] - 2 * math.pi * k), 0, pc[sel], color=c, lw=1.0)
                ax.plot(np.degrees(ph[sel] - 2 * math.pi * k), pc[sel], "o", ms=3, color=c, label=r.label)
        ax.set_ylabel("Percussion_int [N·s]")
        ax.legend(fontsize=7)
    for ax in axes:
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("cam angle φ1 [deg] (0 = start of the rise)")
    fig.suptitle("MR13D per model and the impacts' percussions, last simulated revolution (cf. paper Figs 7-9); "
                 "▲▼ beyond the axis", fontsize=9)
    return "MR13D per model and percussions (Figs 7-9)", fig


def fig_spectra(ds, block=None, max_time_s: float = 1.0) -> tuple[str, Figure] | None:
    """Amplitude spectra (variables over ``frequency``) of the measured file ``ds`` and the
    measured aE_n, aE_t over the first ``max_time_s`` of ``block`` (the first samples the report
    read; default ``ds``) (Fig 11)."""
    block = ds if block is None else block
    spectra = [n for n in ds.data_vars if ds[n].dims == ("frequency",)]
    # the amplitude spectra (the paper's Fig 11a-b); the PSDs say the same in other units
    spectra = [n for n in spectra if n.endswith("_amplitude")][:2] or spectra[:2]
    series = [n for n in ("aE_n", "aE_t") if n in block and block[n].dims == ("time",)]
    if not spectra and not series:
        return None
    rows = max(len(spectra), len(series))
    fig = Figure(figsize=(11, 2.6 * rows))
    axes = fig.subplots(rows, 2, squeeze=False)
    margins(fig, left=0.8, top=0.55, hspace=0.5, wspace=0.22)
    f = np.asarray(ds["frequency"].values, dtype=float) if spectra else None
    for i, n in enumerate(spectra):
        ax = axes[i, 0]
        y = np.abs(np.asarray(ds[n].values, dtype=float))
        top = min(float(f.max()), 1000.0)
        keep = f <= top
        ax.semilogy(f[keep], np.where(y[keep] > 0, y[keep], np.nan), lw=0.7)
        ax.set_xlim(0, top)
        ax.set_ylabel(plain(f"[{ds[n].attrs.get('units', '')}]"))
        ax.set_title(plain(ds[n].attrs.get("long_name", n)), fontsize=9)
        ax.grid(True, alpha=0.3)
    if spectra:
        axes[len(spectra) - 1, 0].set_xlabel("frequency [Hz]")
    t = elapsed_seconds(block["time"].values) if series else None  # CF time may decode to datetime64
    sel = slice(0, int(np.searchsorted(t, t[0] + max_time_s, side="right"))) if series else None
    for i, n in enumerate(series):
        ax = axes[i, 1]
        ax.plot(t[sel], np.asarray(block[n][sel].values, dtype=float), lw=0.6)
        ax.set_ylabel(plain(f"{n} [{block[n].attrs.get('units', 'm/s²')}]"))
        ax.set_title(f"{n}, filtered and translated (first {max_time_s:g} s)", fontsize=9)
        ax.grid(True, alpha=0.3)
    if series:
        axes[len(series) - 1, 1].set_xlabel("time [s]")
    for i in range(len(spectra), rows):
        axes[i, 0].set_visible(False)
    for i in range(len(series), rows):
        axes[i, 1].set_visible(False)
    fig.suptitle("Measured accelerations: amplitude spectra and time histories (cf. paper Fig 11)")
    return "Measured spectra and accelerations (Fig 11)", fig


def fig_compare(report, model: str, signal: str) -> tuple[str, Figure] | None:
    """Measured revolutions, their ±2σ band and cycle average (black, drawn on top), and ``model``
    at omega1 constant and variable, each in its own colour, thin (Figs 12-14); the measured
    impacts (black ▼ and dotted lines) and each model's predicted ones (▼ in its colour) along the
    top. The y-range is the measurement's; a model beyond it is clipped and marked (triangles on
    the edge), with its own ±2σ band when it is not periodic."""
    runs = [r for r in report.sims if r.requested == model]
    if not runs:
        return None
    cyc = report.cycles
    deg = np.degrees(cyc.grid)
    sym, unit = SIGNAL_LABEL[signal]
    fig = Figure(figsize=(10, 4.4))
    ax = fig.subplots()
    margins(fig, top=0.85)
    revs = cyc.signals[signal]
    mean, sd = cyc.mean(signal), cyc.std(signal)
    lim = measured_limits(np.concatenate([revs.ravel(), mean + 2 * sd, mean - 2 * sd]), margin=0.22)
    show = revs[:: max(1, revs.shape[0] // 60)]          # at most ~60 grey lines, whatever the length
    ax.add_collection(LineCollection([np.column_stack([deg, r]) for r in show], colors="0.8", linewidths=0.5,
                                     label=f"measured, each revolution ({revs.shape[0]})", zorder=1))
    # the band at least a line wide, so that a small scatter still shows where it lies
    half = np.maximum(2 * sd, 0.004 * (lim[1] - lim[0]))
    ax.fill_between(deg, mean - half, mean + half, color="0.45", alpha=0.45, lw=0, label="measured ±2σ", zorder=2)
    clipped = 0
    for r in runs:
        color = run_color(r.requested, r.omega1)
        y = np.where(r.cycle.covered, r.cycle.signals[signal], np.nan)
        if not r.cycle.periodic:
            s2 = 2 * r.cycle.std[signal]
            ax.fill_between(deg, np.clip(y - s2, *lim), np.clip(y + s2, *lim), color=color, alpha=0.15, lw=0, zorder=3)
        label = r.label + ("" if r.cycle.periodic else f" (mean of {r.cycle.n_used} rev, ±2σ)")
        clipped += plot_clipped(ax, deg, y, lim, color=color, lw=MODEL_LW, ls=STYLES[r.omega1], label=label, zorder=4)
    ax.plot(deg, mean, color="k", lw=1.3, label="measured (cycle average)", zorder=6)
    mark_impacts(ax, report, runs, lim)
    ax.set_ylim(*lim)
    ax.set_xlabel("cam angle φ1 [deg] (0 = start of the rise)")
    ax.set_ylabel(f"{sym} [{unit}]")
    ax.set_xlim(0, 360)
    # the paper plots against time: a time axis at the measured mean cam speed
    deg_per_s = 6.0 * cyc.cam_speed_rpm
    top = ax.secondary_xaxis("top", functions=(lambda d: d / deg_per_s, lambda t: t * deg_per_s))
    top.set_xlabel(f"time from the start of the rise [s] at {cyc.cam_speed_rpm:.1f} rpm", fontsize=8)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="lower right", ncol=2)
    used = runs[0].model
    name = model if used == model else f"{model} (the {used} level stood in)"
    note = f"; ▲▼ model beyond the measured range ({clipped} points)" if clipped else ""
    ax.set_title(f"{sym}: {name} model vs experiment, {report.scene['cam_speed_rpm']:g} rpm (cf. paper Figs 12-14){note}",
                 fontsize=9)
    return f"{sym}: {model} model vs measurement, impacts marked", fig


def mark_impacts(ax, report, runs, lim) -> None:
    """The measured impact angles (black ▼ on the top edge, dotted lines down the plot) and each
    run's predicted ones (▼ in its colour, one row each below), as the events table lists them."""
    m = report.measured_events or {}
    span = lim[1] - lim[0]
    row = lim[1] - 0.035 * span
    angles = list(m.get("impact_angles_deg") or [])
    if m.get("first_impact_deg") is not None and not any(abs(a - m["first_impact_deg"]) < 0.5 for a in angles):
        angles.insert(0, m["first_impact_deg"])
    if angles:
        ax.vlines(angles, lim[0], lim[1], colors="k", linestyles=":", lw=0.6, zorder=5)
        ax.plot(angles, np.full(len(angles), row), "v", color="k", ms=6, zorder=7, label="measured impacts")
    for i, r in enumerate([r for r in runs if r.events and r.events.get("impact_angles_deg")], 1):
        a = list(r.events["impact_angles_deg"])
        ax.plot(a, np.full(len(a), row - 0.045 * span * i), "v", color=run_color(r.requested, r.omega1), ms=5,
                mec="k", mew=0.4, zorder=7, label=f"predicted impacts, {r.label}")


def order_spectrum(phi1: np.ndarray, y: np.ndarray, per_rev: int = 1024) -> tuple[np.ndarray, np.ndarray, int]:
    """Amplitude against cam order of a signal resampled uniformly in cam angle (the tacho's
    phi1, rad, wrapped or not) over its whole revolutions: (orders, amplitudes in y's unit, number
    of revolutions). A sinusoid of amplitude a at order k shows a at k; the resolution is
    1/revolutions of an order (Hann window, amplitude-corrected)."""
    theta = np.unwrap(np.asarray(phi1, dtype=float))
    y = np.asarray(y, dtype=float)
    ok = np.isfinite(theta) & np.isfinite(y)
    theta, y = theta[ok], y[ok]
    if theta.size < 16 or np.any(np.diff(theta) <= 0):
        order = np.argsort(theta, kind="stable")
        theta, y = theta[order], y[order]
    k0 = math.ceil(theta[0] / (2 * math.pi)) if theta.size else 0
    k1 = math.floor(theta[-1] / (2 * math.pi)) if theta.size else 0
    n_rev = k1 - k0
    if n_rev < 1:
        return np.array([]), np.array([]), 0
    grid = 2 * math.pi * k0 + np.arange(n_rev * per_rev) * (2 * math.pi / per_rev)
    u = np.interp(grid, theta, y)
    w = np.hanning(u.size)
    spec = np.abs(np.fft.rfft((u - u.mean()) * w)) * 2.0 / w.sum()
    return np.arange(spec.size) / n_rev, spec, n_rev


def fig_orders(report) -> tuple[str, Figure] | None:
    """The measured epsilon2 against frequency (Hz, with the cam orders on a top axis) beside its
    order spectrum (amplitude against cam order, tacho-resampled: everything a cam stand does
    repeats with the cam's revolution), the models' cycles' orders marked in their colours."""
    block = report.cycles.blocks[0] if report.cycles.blocks else None
    if block is None or "epsilon2" not in block or "phi1" not in block:
        return None
    f_cam = report.cycles.cam_speed_rpm / 60.0
    orders, amp, n_rev = order_spectrum(block["phi1"].values, block["epsilon2"].values)
    if n_rev < 1:
        return None
    tf = report.time_filter
    top_order = min(150.0, (tf.cutoff_hz / f_cam) if tf is not None else 150.0, float(orders[-1]))
    fig = Figure(figsize=(11, 4.0))
    axes = fig.subplots(1, 2)
    margins(fig, left=0.8, top=1.05, wspace=0.25)
    t = elapsed_seconds(block["time"].values)
    e2 = np.asarray(block["epsilon2"].values, dtype=float)
    ok = np.isfinite(e2)
    hz_amp, hz = None, None
    if ok.sum() > 16:
        w = np.hanning(ok.sum())
        hz_amp = np.abs(np.fft.rfft((e2[ok] - e2[ok].mean()) * w)) * 2.0 / w.sum()
        hz = np.fft.rfftfreq(ok.sum(), d=float(np.median(np.diff(t))))
    ax = axes[0]
    if hz is not None:
        keep = hz <= top_order * f_cam
        ax.semilogy(hz[keep], np.where(hz_amp[keep] > 0, hz_amp[keep], np.nan), color="k", lw=0.6)
        ax.set_xlim(0, top_order * f_cam)
        sec = ax.secondary_xaxis("top", functions=(lambda f: f / f_cam, lambda o: o * f_cam))
        sec.set_xlabel("cam order [-]", fontsize=8)
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("amplitude of ε2 [rad/s²]")
    ax.set_title(f"ε2 against frequency ({t[-1] - t[0]:.2g} s read)", fontsize=9, pad=24)
    ax.grid(True, alpha=0.3)
    ax = axes[1]
    keep = orders <= top_order
    ax.semilogy(orders[keep], np.where(amp[keep] > 0, amp[keep], np.nan), color="k", lw=0.7,
                label=f"measured, {n_rev} revolutions (resolution 1/{n_rev} order)")
    for r in report.sims:
        if r.omega1 != "const" and any(q.requested == r.requested and q.omega1 == "const" for q in report.sims):
            continue      # one model, one row of marks: omega1 var moves the orders by little
        y = np.where(r.cycle.covered, r.cycle.signals["epsilon2"], 0.0)
        spec = np.abs(np.fft.rfft(y - y.mean())) * 2.0 / y.size
        # the comparison keeps report.conditioning.n_harmonics orders of both sides: none above
        k = np.arange(1, min(spec.size, int(top_order) + 1, report.conditioning.n_harmonics + 1))
        ax.plot(k, np.where(spec[k] > 0, spec[k], np.nan), "o", ms=3, color=run_color(r.requested, r.omega1),
                mfc="none", mew=0.8, label=f"{r.label}: its cycle's orders")
    ax.set_xlim(0, top_order)
    peak = float(np.nanmax(amp[keep])) if keep.any() else 1.0
    ax.set_ylim(max(float(np.nanmin(np.where(amp[keep] > 0, amp[keep], np.nan))), peak * 1e-6), peak * 3)
    ax.set_xlabel("cam order [-] (harmonic of the cam's revolution)")
    ax.set_ylabel("amplitude of ε2 [rad/s²]")
    ax.set_title("ε2 order spectrum (tacho-resampled, uniform in cam angle)", fontsize=9, pad=24)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="upper right")
    fig.suptitle("Measured ε2: frequency and order spectra (what repeats with the cam is at whole orders)", fontsize=10)
    return "ε2 spectra: against frequency and against cam order", fig


def fig_drawing(report) -> tuple[str, Figure] | None:
    """The mechanism at the first impact (measured, else the first model's predicted, else the start
    of the rise's dwell end) with the report's backlash (labtool.reports.drawing)."""
    from labtool.models.mechanism import Mechanism
    from labtool.reports.drawing import fig_mechanism
    from labtool.reports.pipeline import cam_program

    m = report.measured_events or {}
    angle, what = m.get("first_impact_deg"), "the measured first impact"
    if angle is None:
        pred = [r.events["first_impact_deg"] for r in report.sims if r.events and r.events.get("first_impact_deg") is not None]
        angle, what = (pred[0], "the first predicted impact") if pred else (0.0, "the start of the rise")
    from labtool.common.errors import LabtoolError
    try:
        program = cam_program(report.scene)
    except (LabtoolError, ValueError):   # a law the default mechanism does not know: no drawing, the rest stands
        return None
    return fig_mechanism(Mechanism.default(), program, math.radians(angle), report.scene["backlash_mm"] * 1e-3, what)


def fig_residuals(report, signal: str) -> tuple[str, Figure] | None:
    """Simulated minus the measured cycle average, against +-2 standard deviations of the measured
    scatter (shaded and outlined). The y-range is set by the band (at least 3 x its half width) and
    by the measured signal's range; residuals beyond it are clipped and marked."""
    if not report.sims:
        return None
    cyc = report.cycles
    deg = np.degrees(cyc.grid)
    sym, unit = SIGNAL_LABEL[signal]
    fig = Figure(figsize=(10, 3.6))
    ax = fig.subplots()
    margins(fig)
    sd = cyc.std(signal)
    mean = cyc.mean(signal)
    half = max(3.0 * float(np.max(2 * sd)), 0.25 * float(np.ptp(mean)))
    lim = (-half, half)
    # grey like the measured band of the overlays: the colours are the models'
    ax.fill_between(deg, -2 * sd, 2 * sd, color="0.45", alpha=0.35, lw=0, label="±2σ of the measured revolutions")
    ax.plot(deg, 2 * sd, color="0.3", lw=0.7)
    ax.plot(deg, -2 * sd, color="0.3", lw=0.7)
    for r in report.sims:
        y = np.where(r.cycle.covered, r.cycle.signals[signal] - mean, np.nan)
        plot_clipped(ax, deg, y, lim, color=run_color(r.requested, r.omega1), lw=MODEL_LW, ls=STYLES[r.omega1],
                     label=r.label)
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_ylim(*lim)
    ax.set_xlim(0, 360)
    ax.set_xlabel("cam angle φ1 [deg]")
    ax.set_ylabel(f"Δ{sym} [{unit}]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, ncol=3)
    ax.set_title(f"Residuals of {sym}: simulated − measured cycle average (▲▼ beyond the axis)", fontsize=9)
    return f"Residuals of {sym}", fig


def fig_iso_per_revolution(report) -> tuple[str, Figure] | None:
    """ISO/TS 18571 rating of every simulation against each measured revolution."""
    if not report.comparisons:
        return None
    fig = Figure(figsize=(10, 3.4))
    axes = fig.subplots(1, 2, sharey=True)
    margins(fig, top=0.6, wspace=0.08)
    for ax, signal in zip(axes, ("omega2", "epsilon2")):
        for c in report.comparisons:
            if c["signal"] != signal:
                continue
            revs = [r["revolution"] for r in c["per_revolution"]]
            vals = [r["iso_rating"] for r in c["per_revolution"]]
            ax.plot(revs, vals, "o" if c["omega1"] == "const" else "s", ls=STYLES[c["omega1"]],
                    color=run_color(c["requested_model"], c["omega1"]), ms=4, lw=0.8, label=c["label"])
        for bound in (0.58, 0.8, 0.94):
            ax.axhline(bound, color="0.6", lw=0.5, ls=":")
        ax.set_title(f"{SIGNAL_LABEL[signal][0]}: ISO/TS 18571 rating per revolution", fontsize=9)
        ax.set_xlabel("measured revolution")
        ax.set_ylim(0, 1.02)
        ax.grid(True, alpha=0.3)
    axes[0].set_ylabel("ISO rating R")
    fig.suptitle("dotted: grade bounds fair 0.58, good 0.8, excellent 0.94", fontsize=8)
    axes[0].legend(fontsize=7)
    return "ISO rating per revolution", fig


def all_figures(report) -> list[tuple[str, Figure]]:
    """Every figure of the report, in the order it shows them."""
    figs = [fig_compare(report, m, s) for m in dict.fromkeys(r.requested for r in report.sims) for s in ("omega2", "epsilon2")]
    block = report.cycles.blocks[0] if report.cycles.blocks else None
    figs += [fig_drawing(report), fig_residuals(report, "omega2"), fig_residuals(report, "epsilon2"),
             fig_iso_per_revolution(report), fig_mr13d(report.sims), fig_orders(report), fig_spectra(report.measured, block)]
    return [f for f in figs if f is not None]


def margins(fig: Figure, left: float = 0.75, right: float = 0.25, bottom: float = 0.55, top: float = 0.35,
            hspace: float = 0.2, wspace: float = 0.2) -> None:
    """Fixed margins in inches (the layout engines measure every label: ~40 % of a figure's cost)."""
    w, h = fig.get_size_inches()
    fig.subplots_adjust(left=left / w, right=1 - right / w, bottom=bottom / h, top=1 - top / h,
                        hspace=hspace, wspace=wspace)


@dataclasses.dataclass
class Rendered:
    """One figure drawn once (Agg): its PNG for the page and its pixels for the PDF."""

    title: str
    png: bytes
    rgba: np.ndarray          # (height, width, 4) uint8
    dpi: int

    @property
    def size_inches(self) -> tuple[float, float]:
        return self.rgba.shape[1] / self.dpi, self.rgba.shape[0] / self.dpi


def render(figures, dpi: int = 100) -> list[Rendered]:
    """Draw each (title, Figure) once on an Agg canvas; the PNG (fast zlib level) and the pixels
    serve the HTML and the PDF alike, so no figure is drawn twice."""
    import io

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from PIL import Image
    out = []
    for title, fig in figures:
        fig.set_dpi(dpi)
        canvas = FigureCanvasAgg(fig)
        canvas.draw()
        rgba = np.asarray(canvas.buffer_rgba()).copy()
        buf = io.BytesIO()
        Image.fromarray(rgba).save(buf, format="png", compress_level=3)
        out.append(Rendered(title, buf.getvalue(), rgba, dpi))
    return out
