"""The cross-point figures (matplotlib object API), in the report's colours and labels
(labtool.reports.figures): each model and omega1 mode its own colour-blind-safe colour (Okabe-Ito),
thin lines, omega1 var dashed (a var run that is the const motion shows both); the measurement black,
drawn on top of a visible ±2σ band.

- ISO/TS 18571 rating of omega2 and epsilon2 against the cam speed, per model and omega1 mode,
  the grade bands shaded and the closest model of each point ringed;
- Sprague & Geers comprehensive error and NRMSE against the cam speed;
- omega2 and epsilon2 over one revolution at each point: measured average +- 2 sigma and every
  model (the paper's Figs 12-14 at each speed);
- measured against predicted events against the cam speed: first impact angle, impacts per
  revolution.

Each function returns ``(title, Figure)`` or None when there is nothing to draw.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from labtool.reports.figures import MODEL_LW, SIGNAL_LABEL, STYLES, plain, run_color
from labtool.reports.metrics import ISO_GRADES

MARKERS = "osD^vP*X"
GRADE_SHADE = {"excellent": "#e3f4e3", "good": "#eef7e0", "fair": "#fff4d6", "poor": "#fbe9e9"}


def _style(model: str, omega1: str) -> dict:
    # omega1 var dashed and on top: where it is the const motion (elastic, kinematic: the report
    # reuses that run) both curves still show
    var = omega1 == "var"
    return {"color": run_color(model, omega1), "ls": STYLES.get(omega1, "-"), "lw": MODEL_LW, "zorder": 4 if var else 3}


def _series(df: pd.DataFrame):
    """(key, label, sub-frame sorted by rpm) per model, omega1 mode and operating-point group."""
    groups = list(dict.fromkeys(zip(df["law"], df["Fu_N"], df["backlash_mm"], df["jt_factor"])))
    for gi, g in enumerate(groups):
        sel = df[(df["law"] == g[0]) & (df["Fu_N"] == g[1]) & (df["backlash_mm"] == g[2]) & (df["jt_factor"] == g[3])]
        for (model, mode), sub in sel.groupby(["model", "omega1"], sort=False):
            label = f"{model}, ω1 {'ct.' if mode == 'const' else 'var.'}"
            if len(groups) > 1:
                label += f" (Fu {g[1]:g} N, j {g[2]:g} mm, Jt x{g[3]:g}, {g[0]})"
            yield (model, mode, gi), label, sub.sort_values("rpm")


def _grade_bands(ax) -> None:
    bounds = [1.02] + [b for b, _ in ISO_GRADES[:-1]] + [0.0]
    for (hi, lo), (_, name) in zip(zip(bounds[:-1], bounds[1:]), ISO_GRADES):
        ax.axhspan(lo, hi, color=GRADE_SHADE[name], zorder=0)
        ax.text(1.005, 0.5 * (lo + hi), name, transform=ax.get_yaxis_transform(), fontsize=7, va="center", color="0.4")


def fig_ratings(df: pd.DataFrame):
    """ISO rating of omega2 and epsilon2 against the cam speed; the closest simulation ringed."""
    if df.empty:
        return None
    fig = Figure(figsize=(11, 4.2), layout="constrained")
    axes = fig.subplots(1, 2, sharey=True)
    for ax, sig in zip(axes, ("omega2", "epsilon2")):
        _grade_bands(ax)
        for (model, mode, gi), label, sub in _series(df):
            y = pd.to_numeric(sub[f"{sig}_iso_rating"], errors="coerce")
            ax.plot(sub["rpm"], y, marker=MARKERS[gi % len(MARKERS)], ms=5, label=label, **_style(model, mode))
        best = df[df["closest"].astype(bool)]
        ax.plot(best["rpm"], pd.to_numeric(best[f"{sig}_iso_rating"], errors="coerce"), "o", ms=13, mfc="none",
                mec="k", mew=1.2, label="closest model of the point")
        ax.set_ylim(0, 1.02)
        ax.set_xlabel("cam speed n1 [rpm]")
        ax.set_title(f"{SIGNAL_LABEL[sig][0]}: ISO/TS 18571 rating R", fontsize=10)
        ax.grid(True, alpha=0.3)
    axes[0].set_ylabel("ISO rating R (1 = identical)")
    axes[0].legend(fontsize=7, loc="lower left")
    fig.suptitle("Agreement of each model with the measurement against the cam speed", fontsize=11)
    return "ISO rating against the cam speed, per model", fig


def fig_errors(df: pd.DataFrame):
    """Sprague & Geers comprehensive error and NRMSE of omega2 and epsilon2 against the cam speed."""
    if df.empty:
        return None
    fig = Figure(figsize=(11, 6.4), layout="constrained")
    axes = fig.subplots(2, 2, sharex=True)
    for col, sig in enumerate(("omega2", "epsilon2")):
        for row, (metric, what) in enumerate((("sg_comprehensive", "S&G comprehensive error C"), ("nrmse", "NRMSE"))):
            ax = axes[row, col]
            for (model, mode, gi), label, sub in _series(df):
                y = pd.to_numeric(sub[f"{sig}_{metric}"], errors="coerce")
                ax.plot(sub["rpm"], y, marker=MARKERS[gi % len(MARKERS)], ms=5, label=label,
                        **_style(model, mode))
            ax.set_title(f"{SIGNAL_LABEL[sig][0]}: {what} (0 = identical)", fontsize=9)
            ax.set_ylim(bottom=0)
            ax.grid(True, alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("cam speed n1 [rpm]")
    axes[0, 0].legend(fontsize=7)
    return "Errors against the cam speed, per model", fig


def fig_overlays(records):
    """omega2 and epsilon2 over one revolution at every point: measured and every model."""
    if not records:
        return None
    n = len(records)
    fig = Figure(figsize=(12, 2.9 * n + 0.6), layout="constrained")
    axes = fig.subplots(n, 2, squeeze=False, sharex=True)
    for i, rec in enumerate(records):
        ds = rec.cycles
        deg = np.degrees(np.asarray(ds["phi1"].values, dtype=float))
        for j, sig in enumerate(("omega2", "epsilon2")):
            ax = axes[i, j]
            sym, unit = SIGNAL_LABEL[sig]
            mean = np.asarray(ds[f"measured_{sig}_mean"].values, dtype=float)
            sd = np.asarray(ds[f"measured_{sig}_std"].values, dtype=float)
            span = float(np.nanmax(mean + 2 * sd) - np.nanmin(mean - 2 * sd)) or 1.0
            half = np.maximum(2 * sd, 0.004 * span)      # at least a line wide: a small scatter still shows
            ax.fill_between(deg, mean - half, mean + half, color="0.45", alpha=0.45, lw=0, label="measured ±2σ", zorder=2)
            for k in range(ds.sizes.get("sim", 0)):
                model, mode = str(ds["sim_requested"].values[k]), str(ds["sim_omega1"].values[k])
                ax.plot(deg, np.asarray(ds[f"sim_{sig}"].values[k], dtype=float),
                        label=plain(str(ds["sim_label"].values[k])), **_style(model, mode))
            ax.plot(deg, mean, color="k", lw=1.2, label="measured (cycle average)", zorder=6)
            ax.set_xlim(0, 360)
            ax.set_ylabel(f"{sym} [{unit}]")
            ax.grid(True, alpha=0.3)
            best = rec.summary.get("closest")
            ax.set_title(plain(f"{sym} at {rec.rpm:g} rpm ({rec.group_label()}), point {rec.name}"
                               + (f": closest {best}" if best and j == 0 else "")), fontsize=9)
        if i == 0:
            axes[0, 1].legend(fontsize=7, ncol=2)
    for ax in axes[-1]:
        ax.set_xlabel("cam angle φ1 [deg] (0 = start of the rise)")
    fig.suptitle("Measured and simulated follower motion at each point (cf. paper Figs 12-14)", fontsize=11)
    return "ω2 and ε2 at each point: measured vs every model (Figs 12-14 per speed)", fig


EVENT_PANELS = (("first_impact_deg_predicted", "first_impact_deg_measured", "cam angle of the first impact [deg]"),
                ("impacts_detectable_per_rev", "impacts_measured_per_rev", "visible impacts per revolution"))


def fig_events(df: pd.DataFrame):
    """First impact angle and visible impacts per revolution, measured against predicted, against speed."""
    if df.empty:
        return None
    have = [pd.to_numeric(df[c], errors="coerce").notna().any() for p in EVENT_PANELS for c in p[:2]]
    if not any(have):
        return None
    fig = Figure(figsize=(11, 4.0), layout="constrained")
    axes = fig.subplots(1, 2)
    for ax, (pred, meas, what) in zip(axes, EVENT_PANELS):
        for (model, mode, gi), label, sub in _series(df):
            ax.plot(sub["rpm"], pd.to_numeric(sub[pred], errors="coerce"), marker=MARKERS[gi % len(MARKERS)], ms=5,
                    label=f"{label}, predicted", **_style(model, mode))
        m = df.drop_duplicates("point")
        ax.plot(m["rpm"], pd.to_numeric(m[meas], errors="coerce"), "k*", ms=11, label="measured")
        ax.set_xlabel("cam speed n1 [rpm]")
        ax.set_ylabel(what)
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle("Events: measured (found in the recording by the processing and report) against predicted "
                 "(last simulated revolution, as the chain would show them)", fontsize=10)
    return "Measured vs predicted events against the cam speed", fig


def all_figures(records, df: pd.DataFrame) -> list:
    figs = [fig_ratings(df), fig_errors(df), fig_overlays(records), fig_events(df)]
    return [f for f in figs if f is not None]
