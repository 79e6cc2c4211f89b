"""The report's figures (matplotlib, object API, no global state), of the paper's kinds:

- MR13D of each model in its own panel and the impacts' percussions (paper Figs 7-9);
- amplitude spectra and time histories of the measured accelerations (Fig 11);
- measured against simulated omega2 and epsilon2, omega1 constant and variable (Figs 12-14);
- residuals (simulated minus the measured cycle average) against the measured scatter.

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

COLORS = {"const": "tab:blue", "var": "tab:red"}
STYLES = {"const": "-", "var": (0, (4, 3))}
SIGNAL_LABEL = {"omega2": ("ω2", "rad/s"), "epsilon2": ("ε2", "rad/s²")}


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
            plot_clipped(ax, deg, v, lim, color=COLORS[r.omega1], lw=0.9, label=r.label)
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
                ax.vlines(np.degrees(ph[sel] - 2 * math.pi * k), 0, pc[sel], color=COLORS[r.omega1], lw=1.0)
                ax.plot(np.degrees(ph[sel] - 2 * math.pi * k), pc[sel], "o", ms=3, color=COLORS[r.omega1], label=r.label)
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
    """Measured revolutions, their average and +-2 sigma band, and ``model`` at omega1 constant and
    variable (Figs 12-14). The y-range is the measurement's; a model beyond it is clipped and
    marked (triangles on the edge), with its own +-2 sigma band when it is not periodic."""
    runs = [r for r in report.sims if r.requested == model]
    if not runs:
        return None
    cyc = report.cycles
    deg = np.degrees(cyc.grid)
    sym, unit = SIGNAL_LABEL[signal]
    fig = Figure(figsize=(10, 4.2))
    ax = fig.subplots()
    margins(fig, top=0.85)
    revs = cyc.signals[signal]
    mean, sd = cyc.mean(signal), cyc.std(signal)
    lim = measured_limits(np.concatenate([revs.ravel(), mean + 2 * sd, mean - 2 * sd]))
    show = revs[:: max(1, revs.shape[0] // 60)]          # at most ~60 grey lines, whatever the length
    ax.add_collection(LineCollection([np.column_stack([deg, r]) for r in show], colors="0.78", linewidths=0.5,
                                     label=f"measured, each revolution ({revs.shape[0]})"))
    ax.fill_between(deg, mean - 2 * sd, mean + 2 * sd, color="0.55", alpha=0.35, lw=0, label="measured ±2σ")
    ax.plot(deg, mean, color="k", lw=1.4, label="measured values (cycle average)")
    clipped = 0
    for r in runs:
        y = np.where(r.cycle.covered, r.cycle.signals[signal], np.nan)
        if not r.cycle.periodic:
            s2 = 2 * r.cycle.std[signal]
            ax.fill_between(deg, np.clip(y - s2, *lim), np.clip(y + s2, *lim), color=COLORS[r.omega1], alpha=0.15, lw=0)
        label = r.label + ("" if r.cycle.periodic else f" (mean of {r.cycle.n_used} rev, ±2σ)")
        # var dashed: where a model's two modes coincide (elastic: the same constant speed) both show
        clipped += plot_clipped(ax, deg, y, lim, color=COLORS[r.omega1], lw=1.1, ls=STYLES[r.omega1], label=label)
    ax.set_ylim(*lim)
    ax.set_xlabel("cam angle φ1 [deg] (0 = start of the rise)")
    ax.set_ylabel(f"{sym} [{unit}]")
    ax.set_xlim(0, 360)
    # the paper plots against time: a time axis at the measured mean cam speed
    deg_per_s = 6.0 * cyc.cam_speed_rpm
    top = ax.secondary_xaxis("top", functions=(lambda d: d / deg_per_s, lambda t: t * deg_per_s))
    top.set_xlabel(f"time from the start of the rise [s] at {cyc.cam_speed_rpm:.1f} rpm", fontsize=8)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    used = runs[0].model
    name = model if used == model else f"{model} (the {used} level stood in)"
    note = f"; ▲▼ model beyond the measured range ({clipped} points)" if clipped else ""
    ax.set_title(f"{sym}: {name} model vs experiment, {report.scene['cam_speed_rpm']:g} rpm (cf. paper Figs 12-14){note}",
                 fontsize=9)
    return f"{sym}: {model} model vs measurement", fig


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
    ax.fill_between(deg, -2 * sd, 2 * sd, color="tab:green", alpha=0.25, lw=0, label="±2σ of the measured revolutions")
    ax.plot(deg, 2 * sd, color="tab:green", lw=0.7)
    ax.plot(deg, -2 * sd, color="tab:green", lw=0.7)
    for r in report.sims:
        y = np.where(r.cycle.covered, r.cycle.signals[signal] - mean, np.nan)
        plot_clipped(ax, deg, y, lim, color=COLORS[r.omega1], lw=1.0, ls="-" if r.requested == "elastic" else "--",
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
            ax.plot(revs, vals, "o-" if c["requested_model"] == "elastic" else "s--", color=COLORS[c["omega1"]],
                    ms=4, lw=0.8, label=c["label"])
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
    figs += [fig_residuals(report, "omega2"), fig_residuals(report, "epsilon2"), fig_iso_per_revolution(report),
             fig_mr13d(report.sims), fig_spectra(report.measured, block)]
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
