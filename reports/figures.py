"""The report's figures (matplotlib, object API, no global state), of the paper's kinds:

- MR13D and the jump indicators of each simulation (paper Figs 7-9);
- amplitude spectra and time histories of the measured accelerations (Fig 11);
- measured against simulated omega2 and epsilon2, omega1 constant and variable (Figs 12-14);
- residuals (simulated minus the measured cycle average) against the measured scatter.

Each function returns ``(title, Figure)`` or None when the data it needs is absent. Degrees and
millimetres appear only on the axes; the data stay SI.
"""
from __future__ import annotations

import math

import numpy as np
from matplotlib.figure import Figure

from common.cf import elapsed_seconds

COLORS = {"const": "tab:blue", "var": "tab:red"}
SIGNAL_LABEL = {"omega2": ("ω2", "rad/s"), "epsilon2": ("ε2", "rad/s²")}
# jump indicators a simulation may carry: name -> (scale to the plotted unit, unit, label)
JUMP_VARS = {
    "dphi2": (180.0 / math.pi, "deg", "φ2rcj − φ2rfj"),
    "domega2": (1.0, "rad/s", "ω2rcj − ω2rfj"),
    "domega1": (1.0, "rad/s", "ω1rcj − ω1rfj"),
    "percussion": (1.0, "N·s", "Percussion_int"),
    "x_el": (1e3, "mm", "x_el"),
}


def plain(text) -> str:
    """A string from a file, shown literally by matplotlib ('$' would start mathtext and an
    unbalanced one would fail the drawing)."""
    return str(text).replace("$", r"\$")


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
    """MR13D of each simulation over its last revolution, and the jump indicators it computes."""
    if not sims:
        return None
    extra = [v for v in JUMP_VARS if any(v in r.dataset and r.dataset[v].dims == r.dataset["phi1"].dims for r in sims)]
    has_perc = any("event_percussion" in r.dataset and "event_phi1" in r.dataset for r in sims)
    if has_perc:
        extra.append("percussion_events")
    fig = Figure(figsize=(9, 2.6 * (1 + len(extra))), layout="constrained")
    axes = fig.subplots(1 + len(extra), 1, sharex=True, squeeze=False)[:, 0]
    for r in sims:
        ds = r.dataset
        mask, deg = _last_revolution(ds)
        style = dict(color=COLORS[r.omega1], lw=1.0, ls="-" if r.requested == "elastic" else "--", label=r.label)
        if "MR13D" in ds:
            axes[0].plot(deg, np.asarray(ds["MR13D"].values)[mask], **style)
        for ax, v in zip(axes[1:], extra):
            if v == "percussion_events" and "event_percussion" in ds and "event_phi1" in ds:
                ph = np.asarray(ds["event_phi1"].values, dtype=float)
                pc = np.asarray(ds["event_percussion"].values, dtype=float)
                k = max(int(math.floor(np.nanmax(np.asarray(ds["phi1"].values)) / (2 * math.pi) + 1e-9)) - 1, 0)
                sel = (ph >= 2 * math.pi * k) & (ph < 2 * math.pi * (k + 1)) & np.isfinite(pc)
                if sel.any():
                    ax.vlines(np.degrees(ph[sel] - 2 * math.pi * k), 0, pc[sel], color=style["color"], lw=1.0)
                    ax.plot(np.degrees(ph[sel] - 2 * math.pi * k), pc[sel], "o", ms=3, color=style["color"])
                ax.set_ylabel("Percussion_int [N·s]")
            elif v in ds and ds[v].dims == ds["phi1"].dims:
                scale, unit, lab = JUMP_VARS[v]
                ax.plot(deg, np.asarray(ds[v].values)[mask] * scale, **style)
                ax.set_ylabel(f"{lab} [{unit}]")
    axes[0].axhline(0.0, color="k", lw=0.6)
    axes[0].set_ylabel("MR13D [N·m]")
    axes[0].legend(fontsize=8, ncol=2)
    for ax in axes:
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("cam angle φ1 [deg] (0 = start of the rise)")
    fig.suptitle("MR13D and jump indicators of the simulations, last simulated revolution (cf. paper Figs 7-9)",
                 fontsize=10)
    return "MR13D and jump indicators (Figs 7-9)", fig


def fig_spectra(ds, max_time_s: float = 1.0) -> tuple[str, Figure] | None:
    """Amplitude spectra (variables over ``frequency``) and the measured aE_n, aE_t (Fig 11)."""
    spectra = [n for n in ds.data_vars if ds[n].dims == ("frequency",)][:4]
    series = [n for n in ("aE_n", "aE_t") if n in ds and ds[n].dims == ("time",)]
    if not spectra and not series:
        return None
    rows = max(len(spectra), len(series))
    fig = Figure(figsize=(11, 2.6 * rows), layout="constrained")
    axes = fig.subplots(rows, 2, squeeze=False)
    f = np.asarray(ds["frequency"].values, dtype=float) if spectra else None
    for i, n in enumerate(spectra):
        ax = axes[i, 0]
        y = np.abs(np.asarray(ds[n].values, dtype=float))
        ax.semilogy(f, np.where(y > 0, y, np.nan), lw=0.7)
        ax.set_xlim(0, min(float(f.max()), 1000.0))
        ax.set_ylabel(plain(f"[{ds[n].attrs.get('units', '')}]"))
        ax.set_title(plain(ds[n].attrs.get("long_name", n)), fontsize=9)
        ax.grid(True, alpha=0.3)
    if spectra:
        axes[len(spectra) - 1, 0].set_xlabel("frequency [Hz]")
    t = elapsed_seconds(ds["time"].values) if series else None  # CF time may decode to datetime64
    for i, n in enumerate(series):
        ax = axes[i, 1]
        sel = t <= t[0] + max_time_s
        ax.plot(t[sel], np.asarray(ds[n].values, dtype=float)[sel], lw=0.6)
        ax.set_ylabel(plain(f"{n} [{ds[n].attrs.get('units', 'm/s²')}]"))
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
    """Measured revolutions, their average, and ``model`` at omega1 constant and variable (Figs 12-14)."""
    runs = [r for r in report.sims if r.requested == model]
    if not runs:
        return None
    cyc = report.cycles
    deg = np.degrees(cyc.grid)
    sym, unit = SIGNAL_LABEL[signal]
    fig = Figure(figsize=(10, 4.2), layout="constrained")
    ax = fig.subplots()
    for k in range(cyc.signals[signal].shape[0]):
        ax.plot(deg, cyc.signals[signal][k], color="0.75", lw=0.6, label="measured, each revolution" if k == 0 else None)
    ax.plot(deg, cyc.mean(signal), color="k", lw=1.4, label="measured values (cycle average)")
    for r in runs:
        y = np.where(r.cycle.covered, r.cycle.signals[signal], np.nan)
        ax.plot(deg, y, color=COLORS[r.omega1], lw=1.1, label=r.label)
    ax.set_xlabel("cam angle φ1 [deg] (0 = start of the rise)")
    ax.set_ylabel(f"{sym} [{unit}]")
    ax.set_xlim(0, 360)
    # the paper plots against time: a time axis at the measured mean cam speed
    deg_per_s = 6.0 * cyc.cam_speed_rpm
    top = ax.secondary_xaxis("top", functions=(lambda d: d / deg_per_s, lambda t: t * deg_per_s))
    top.set_xlabel(f"time from the start of the rise [s] at {cyc.cam_speed_rpm:.1f} rpm", fontsize=8)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    used = runs[0].model
    name = model if used == model else f"{model} (the {used} level stood in)"
    ax.set_title(f"{sym} of the follower: {name} model vs experiment, {report.scene['cam_speed_rpm']:g} rpm (cf. paper Figs 12-14)")
    return f"{sym}: {model} model vs measurement", fig


def fig_residuals(report, signal: str) -> tuple[str, Figure] | None:
    """Simulated minus the measured cycle average, with +-2 standard deviations of the measured scatter."""
    if not report.sims:
        return None
    cyc = report.cycles
    deg = np.degrees(cyc.grid)
    sym, unit = SIGNAL_LABEL[signal]
    fig = Figure(figsize=(10, 3.6), layout="constrained")
    ax = fig.subplots()
    sd = cyc.std(signal)
    ax.fill_between(deg, -2 * sd, 2 * sd, color="0.85", label="±2σ of the measured revolutions")
    for r in report.sims:
        y = np.where(r.cycle.covered, r.cycle.signals[signal] - cyc.mean(signal), np.nan)
        ax.plot(deg, y, color=COLORS[r.omega1], lw=1.0, ls="-" if r.requested == "elastic" else "--", label=r.label)
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_xlim(0, 360)
    ax.set_xlabel("cam angle φ1 [deg]")
    ax.set_ylabel(f"Δ{sym} [{unit}]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, ncol=2)
    ax.set_title(f"Residuals of {sym}: simulated − measured cycle average")
    return f"Residuals of {sym}", fig


def fig_iso_per_revolution(report) -> tuple[str, Figure] | None:
    """ISO/TS 18571 rating of every simulation against each measured revolution."""
    if not report.comparisons:
        return None
    fig = Figure(figsize=(10, 3.4), layout="constrained")
    axes = fig.subplots(1, 2, sharey=True)
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
    figs += [fig_residuals(report, "omega2"), fig_residuals(report, "epsilon2"), fig_iso_per_revolution(report),
             fig_mr13d(report.sims), fig_spectra(report.measured)]
    return [f for f in figs if f is not None]


def png_bytes(fig: Figure, dpi: int = 90) -> bytes:
    """The figure as PNG bytes (Agg canvas; no display needed)."""
    import io

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()
