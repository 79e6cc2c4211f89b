"""The fit's figure: measured vs the model before and after the fit, and the profiles.

Top rows: omega2 and epsilon2 over the cam angle (deg): the measured cycle average with its +-2
sigma band, the model at the scene's values (before) and at the fitted ones (after); the y-range
is the measurement's, a model beyond it is clipped and marked (labtool.reports.figures.plot_clipped).
Bottom row: one panel per free parameter, the profiled objective at the checked points, its
linear-theory parabola, the 95 % threshold and the interval.
"""
from __future__ import annotations

import math

import numpy as np
from matplotlib.figure import Figure

from labtool.reports.figures import SIGNAL_LABEL, measured_limits, plot_clipped

SIGNALS = ("omega2", "epsilon2")


def fit_figure(outcome) -> Figure:
    """The figure of ``labtool.identification.fit.FitOutcome``."""
    s = outcome.summary
    p = len(outcome.space.params)
    fig = Figure(figsize=(11, 8.5), layout="constrained")
    grid = fig.add_gridspec(3, max(p, 1))
    cyc = outcome.target.cycles
    deg = np.degrees(cyc.grid)
    for row, sig in enumerate(SIGNALS):
        ax = fig.add_subplot(grid[row, :])
        sym, unit = SIGNAL_LABEL[sig]
        mean, sd = cyc.mean(sig), cyc.std(sig)
        lim = measured_limits(np.concatenate([mean + 2 * sd, mean - 2 * sd]))
        ax.fill_between(deg, mean - 2 * sd, mean + 2 * sd, color="0.6", alpha=0.4, lw=0, label="measured ±2σ")
        ax.plot(deg, mean, color="k", lw=1.4, label=f"measured (average of {len(cyc.revolutions)} revolutions)")
        for ev, label, color in ((outcome.before, "before (the scene's values)", "tab:red"),
                                 (outcome.after, "after the fit", "tab:blue")):
            if ev.ok:
                grade = (s["metrics_before"] if ev is outcome.before else s["metrics_after"])[sig]
                plot_clipped(ax, deg, ev.cycle.signals[sig], lim, color=color, lw=1.0,
                             label=f"{label}: ISO {grade['iso_rating']:.3f} ({grade['iso_grade']})")
        ax.set_ylim(*lim)
        ax.set_xlim(0, 360)
        ax.set_ylabel(f"{sym} [{unit}]")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="best")
        if row == 0:
            fitted = ", ".join(f"{k} = {v['value']:.4g}" for k, v in s["parameters"].items())
            ax.set_title(f"{s['model']} model, ω1 {s['omega1']}, {s['accuracy']} preset: {fitted}", fontsize=9)
        else:
            ax.set_xlabel("cam angle φ1 [deg] (0 = start of the rise)")
    for i, par in enumerate(outcome.space.params):
        _profile_panel(fig.add_subplot(grid[2, i]), outcome, i, par)
    return fig


def _profile_panel(ax, outcome, i, par) -> None:
    s = outcome.summary
    entry = s["parameters"][par.key]
    prof = s["profiles"][par.key]
    x = np.array([np.nan if v is None else v for v in prof["values"]], float)
    y = np.array(prof["objective"], float)
    base = min(s["objective_after"], float(np.nanmin(y)))
    lin = outcome.linear
    ax.plot(x, y - base, "o-", color="tab:blue", ms=4, lw=1, label="profile (others re-fitted)")
    # linear theory's parabola through the optimum
    half = lin.t * lin.sd_u[i]
    if math.isfinite(half) and half > 0:
        u = np.linspace(max(lin.u[i] - 2.5 * half, 0.0), min(lin.u[i] + 2.5 * half, 1.0), 101)
        xs = [outcome.space.value(i, v) for v in u]
        ax.plot(xs, lin.threshold(i) * ((u - lin.u[i]) / half) ** 2, "--", color="0.4", lw=0.8, label="linear theory")
    # no threshold (null in the JSON) where the objective does not depend on the parameter
    thr = prof["threshold"]
    if thr is not None:
        ax.axhline(thr - base, color="tab:red", lw=0.8, label="95 % threshold")
    lo, hi = entry["ci95"]
    if lo is not None and hi is not None:
        ax.axvspan(lo, hi, color="tab:blue", alpha=0.12, label="95 % interval")
    ax.axvline(entry["value"], color="tab:blue", lw=0.8)
    if par.log:
        ax.set_xscale("log")
    unit = "" if par.unit == "-" else f" [{par.unit}]"
    ax.set_xlabel(f"{par.name}{unit}")
    ax.set_ylabel("objective − minimum")
    ax.set_yscale("symlog", linthresh=max(thr - base, 1e-9) if thr is not None else 1.0)
    ax.set_ylim(bottom=0.0)
    verdict = "identifiable" if entry["identifiable"] else "NOT identifiable"
    ax.set_title(f"{par.name}: {verdict}", fontsize=8)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=6, loc="best")


def joint_figure(outcome) -> Figure:
    """The figure of a joint fit (labtool.identification.joint.JointOutcome): one panel per free
    parameter against the measured cam speed (rpm): each file's own fit with its 95 % interval,
    and the joint value, its interval and (when the files disagree) the widened one for a shared
    parameter, or each file's joint value for one fitted per file."""
    s = outcome.summary
    keys = list(s["shared"]) + list(s["per_file"])
    fig = Figure(figsize=(5.5 * max(len(keys), 1), 4.2), layout="constrained")
    rpm = np.array(s["cam_speed_rpm_measured"], float)
    for n, key in enumerate(keys):
        ax = fig.add_subplot(1, len(keys), n + 1)
        singles = [f["parameters"][key] for f in s["single_fits"]]
        vals = np.array([e["value"] for e in singles], float)
        lo = np.array([np.nan if e["ci95"][0] is None else e["ci95"][0] for e in singles], float)
        hi = np.array([np.nan if e["ci95"][1] is None else e["ci95"][1] for e in singles], float)
        ok = np.isfinite(lo) & np.isfinite(hi)
        ax.errorbar(rpm[ok], vals[ok], yerr=[vals[ok] - lo[ok], hi[ok] - vals[ok]], fmt="o", color="k", capsize=4,
                    label="each file alone (95 %)")
        if (~ok).any():
            ax.plot(rpm[~ok], vals[~ok], "x", color="k", label="each file alone (no interval)")
        if key in s["parameters"]:
            e = s["parameters"][key]
            ax.axhline(e["value"], color="tab:blue", lw=1.2, label=f"joint: {e['value']:.4g}")
            a, b = e["ci95_joint"]
            if a is not None and b is not None:
                ax.axhspan(a, b, color="tab:blue", alpha=0.2, lw=0, label="joint 95 %")
            if list(e["ci95"]) != list(e["ci95_joint"]) and None not in e["ci95"]:
                ax.axhspan(*e["ci95"], color="tab:red", alpha=0.08, lw=0, label="widened: the files disagree")
                ax.set_ylim(*_limits(np.r_[lo[ok], hi[ok], a, b]))
            test = s["consistency"][key]
            said = ("consistent" if test["consistent"] else "INCONSISTENT") if test["consistent"] is not None else "untested"
            ax.set_title(f"{key} (shared): {said}" + (f", p = {test['p_value']:.2g}" if test["p_value"] is not None
                                                      else ""), fontsize=9)
        else:
            joint = [f[key] for f in s["per_file_parameters"]]
            jv = np.array([e["value"] for e in joint], float)
            ax.plot(rpm, jv, "s", color="tab:blue", mfc="none", label="joint, per file")
            ax.set_title(f"{key} (per file)", fontsize=9)
        ax.set_xlabel("measured cam speed [rpm]")
        unit = singles[0].get("unit", "-")
        ax.set_ylabel(key if unit == "-" else f"{key} [{unit}]")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    return fig


def _limits(values) -> tuple[float, float]:
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    lo, hi = float(v.min()), float(v.max())
    pad = 0.15 * (hi - lo or abs(hi) or 1.0)
    return lo - pad, hi + pad


def suggest_figure(outcome) -> Figure:
    """The criterion of ``labtool suggest`` against the cam speed, one curve per load: the shared
    parameters' expected 95 % interval width after a recording there, as a share of today's (top:
    the criterion), and the measurement's part alone, the D-criterion's gain log det(M after /
    M before) of the shared information (bottom);
    the measured speeds and the suggested point marked. ``--goal discriminate``: the closest pair
    of models' distance against speed."""
    s = outcome.summary
    if s["goal"] == "discriminate":
        return _discriminate_figure(s)
    fig = Figure(figsize=(9, 7), layout="constrained")
    top, bottom = fig.add_subplot(2, 1, 1), fig.add_subplot(2, 1, 2)
    cands = s["candidates"]
    loads = sorted({c["Fu_N"] for c in cands})
    keys = s["shared"]
    for n, Fu in enumerate(loads):
        rows = sorted((c for c in cands if c["Fu_N"] == Fu), key=lambda c: c["cam_speed_rpm"])
        rpm = np.array([c["cam_speed_rpm"] for c in rows])
        gain = np.array([np.nan if c["log_det_gain"] is None else c["log_det_gain"] for c in rows])
        color = f"C{n}"
        bottom.plot(rpm, gain, "o-", ms=3, color=color, label=f"Fu = {Fu:g} N")
        for k, key in enumerate(keys):
            w = np.array([np.nan if not c["interval_width_ratio"] or c["interval_width_ratio"].get(key) is None
                          else 100 * c["interval_width_ratio"][key] for c in rows])
            top.plot(rpm, w, ["o-", "s--", "^:"][k % 3], ms=3, color=color, label=f"{key}, Fu = {Fu:g} N")
        bad = [c["cam_speed_rpm"] for c in rows if c["error"] is not None]
        if bad:
            bottom.plot(bad, [np.nanmin(gain) if np.isfinite(gain).any() else 0.0] * len(bad), "x", color=color,
                        label=f"Fu = {Fu:g} N: model refused or doubtful")
    for ax in (top, bottom):
        for m in s["measured"]:
            ax.axvline(m["cam_speed_rpm"], color="0.5", lw=0.8, ls=":")
        ax.axvline(s["point"]["cam_speed_rpm"], color="tab:red", lw=1.2)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    top.set_ylabel("expected 95 % interval [% of today's]")
    top.set_title(f"labtool suggest --goal {s['goal']}: next point {s['point']['cam_speed_rpm']:g} rpm, "
                  f"Fu = {s['point']['Fu_N']:g} N (red); measured speeds dotted", fontsize=9)
    bottom.set_ylabel("log det gain, the measurement's part")
    bottom.set_xlabel("cam speed of the next recording [rpm]")
    return fig


def _discriminate_figure(s: dict) -> Figure:
    """The closest pair of models' epsilon2 (and omega2) distance in measured scatters against speed."""
    fig = Figure(figsize=(9, 5), layout="constrained")
    ax = fig.add_subplot(1, 1, 1)
    for n, Fu in enumerate(sorted({c["Fu_N"] for c in s["candidates"]})):
        rows = sorted((c for c in s["candidates"] if c["Fu_N"] == Fu), key=lambda c: c["cam_speed_rpm"])
        rpm = [c["cam_speed_rpm"] for c in rows]
        for key, style in (("epsilon2_distance", "o-"), ("omega2_distance", "s:")):
            ax.plot(rpm, [np.nan if c[key] is None else c[key] for c in rows], style, ms=3, color=f"C{n}",
                    label=f"{key.split('_')[0]}, Fu = {Fu:g} N")
    ax.axhline(s["expected"]["tells_apart"], color="0.3", lw=0.8, ls="--", label="tells apart")
    ax.axvline(s["measured"][0]["cam_speed_rpm"], color="0.5", lw=0.8, ls=":")
    ax.axvline(s["point"]["cam_speed_rpm"], color="tab:red", lw=1.2)
    ax.set_yscale("log")
    ax.set_xlabel("cam speed of the next recording [rpm]")
    ax.set_ylabel("closest pair's rms difference / measured scatter")
    ax.set_title(f"labtool suggest --goal discriminate ({', '.join(s['models'])}): next point "
                 f"{s['point']['cam_speed_rpm']:g} rpm, Fu = {s['point']['Fu_N']:g} N (red); measured dotted", fontsize=9)
    ax.grid(True, alpha=0.3, which="both")
    ax.legend(fontsize=7, loc="best")
    return fig
