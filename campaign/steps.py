"""The three steps of a point, as narrow adapters over the layers' library functions.

acquire  -> labtool.acquisition.session.run on the plan's device (the simulated stand or NI-DAQmx),
            after waiting for a steady cam speed (labtool.campaign.settle);
process  -> labtool.processing.pipeline.process_recording with the plan's calibration files;
compare  -> labtool.reports.pipeline.build_report, then the per-point page (labtool.reports.html), its JSON
            summary (labtool.reports.summary) and the overlay data the campaign page draws (cycles.nc).

Each step writes its outputs atomically (temp file + rename) or, for the recording, as the
recorder does (``complete`` set last); nothing here calls the CLI. When the layers' interfaces
change, this module is the one place to follow them.
"""
from __future__ import annotations

import math
import signal
from pathlib import Path

import numpy as np
import xarray as xr

from labtool.common.operating_point import FIELD, SOURCE_SUFFIX, STATED
from labtool.campaign.plan import COMPARE_OPTIONS
from labtool.common.errors import InputError, interruption
from labtool.common.names import shown

# --------------------------------------------------------------------------- acquire


def _sim_device(plan, point, duration_s: float):
    """The simulated stand at the point (labtool.acquisition.devices, as 'labtool acquire' builds it)."""
    from labtool.acquisition import signal_chain as sc
    from labtool.acquisition.devices import sim_device

    dev = plan.doc.device
    setup = sim_device({n: getattr(point.point, n) for n in STATED}, truth_model=dev.truth or "twin",
                       ka_m_s2_per_v=float(dev.ka_m_s2_per_v or sc.DEFAULT_KA), seed=point.seed, duration_s=duration_s,
                       realtime=dev.pacing == "realtime",
                       advice=f"point {point.name}: record fewer revolutions or use the twin truth")
    return setup.device, setup.ka_m_s2_per_v, setup.attrs


def _nidaqmx_device(plan, point, duration_s: float):
    """The NI device of the plan: its device file (channels by role, ranges, coupling, IEPE,
    sensitivities, trigger; labtool.acquisition.nidaqmx_config) and/or its physical channels."""
    from labtool.acquisition.devices import nidaqmx_device

    dev = plan.doc.device
    device, cfg, nominal = nidaqmx_device(dev.channels or None, plan.device_file, (), dev.iepe_excitation,
                                          f"device file {shown(plan.device_file)}" if plan.device_file
                                          else f"campaign plan {plan.path.name}")
    # Ka: the plan's calibration files, applied by processing; the nominal one (sensitivity x gain)
    # is stored as the recording's own, as 'labtool acquire' does
    ka = [float(k) if c.kind == "accel" else math.nan for c, k in zip(cfg.channels, nominal)]
    return device, ka, {"ka_source": "nominal from the device configuration; the campaign's calibration files "
                                     "are applied by processing", **dict(cfg.metadata)}


def make_device(plan, point, duration_s: float | None = None):
    """(device, Ka per channel (NaN: none), extra attributes) for one point; ``duration_s`` (s) bounds
    what the simulated stand generates (default: the point's recording)."""
    make = _sim_device if plan.doc.device.kind == "sim" else _nidaqmx_device
    return make(plan, point, point.duration_s if duration_s is None else duration_s)


def point_attrs(plan, point) -> dict:
    """Root attributes every recording of the campaign carries: the operating point as the plan
    states it, the test metadata, and where the point sits in the campaign."""
    t = plan.doc.test
    stated = point.point.attrs(STATED)
    return {**stated, **{name + SOURCE_SUFFIX: f"campaign plan {plan.path.name}, point {point.name}" for name in stated},
            "test_id": t.test_id, "operator": t.operator, "notes": t.notes,
            "campaign": plan.doc.campaign.name, "campaign_point": point.name,
            "campaign_point_index": int(point.index), "seed": int(point.seed)}


def settle(plan, point, ask=None, say=None):
    """Wait for a steady cam speed as the plan says (None when it says "none")."""
    from labtool.campaign import settle as st

    dev = plan.doc.device
    mode = dev.settle_mode
    if mode == "none":
        return None
    msg = (f"point {point.name}: set the stand to {point.rpm:g} rpm (law {point.law}, Fu {point.Fu_N:g} N, "
           f"j {point.backlash_mm:g} mm, Jt x{point.jt_factor:g})")
    if mode == "prompt":
        if ask is None:
            raise InputError("the plan's device.settle = \"prompt\" needs a terminal to ask the operator; "
                             "use settle = \"tacho\" to wait on the tacho instead")
        return st.wait_for_operator(ask, msg + " and press Enter when its speed is steady")
    if say is not None:
        say(msg + "; waiting on the tacho")
    # the simulated stand (a test of this path) generates just enough turns to be judged
    device, _, _ = make_device(plan, point, (dev.settle_revolutions + 3) * 60.0 / point.rpm)
    return st.wait_for_tacho(device, dev.rate_hz, point.rpm, dev.settle_tolerance, dev.settle_revolutions,
                             dev.settle_timeout_s, say=say)


def acquire(plan, point, path: Path, ask=None, say=None, progress=None, token: str = "") -> dict:
    """Record the point into ``path`` (format v1); InputError unless the run reached its duration.
    ``token`` is stored as the recording's ``campaign_acquisition``: the run that made it."""
    from labtool.acquisition import session

    settled = settle(plan, point, ask, say)
    device, ka, attrs = make_device(plan, point)
    attrs.update(point_attrs(plan, point))
    if token:
        attrs["campaign_acquisition"] = token
    if settled is not None:
        attrs.update(settled.attrs())
    res = session.run(device, path, plan.doc.device.rate_hz, point.duration_s, attrs, ka_m_s2_per_v=ka,
                      progress=progress)
    target = int(round(point.duration_s * res.rate_hz))
    if res.outcome == "interrupted" and not res.complete:   # closed short and incomplete: redone on rerun
        raise interruption(res.signum or signal.SIGINT)
    if res.outcome not in ("done", "interrupted") or not res.complete or res.n_samples < target:
        raise InputError(f"point {point.name}: the acquisition ended early ({res.message}; {res.n_samples} of "
                         f"{target} samples); the recording {shown(path)} is kept for inspection and redone on rerun")
    # a stop signal after the last sample: the recording is whole, so it is recorded as finished
    # (labtool.campaign.runner) before the run stops
    return {"n_samples": res.n_samples, "rate_hz": res.rate_hz, "overruns": res.overruns, "gaps": res.gaps,
            "samples_lost": res.samples_lost, "clipped": list(res.clipped), "wall_s": res.wall_s,
            **({"stopped_by_signal": int(res.signum)} if res.signum is not None else {})}


# --------------------------------------------------------------------------- process


def process(plan, point, recording: Path, measured: Path, warn=None) -> dict:
    """recording -> measured.nc with the plan's calibration files (labtool.processing.pipeline)."""
    from labtool.processing.pipeline import ProcessOptions, process_file

    summary = process_file(recording, measured, plan.calibration_files,
                           options=ProcessOptions(law=point.law, cam_speed_rpm=point.rpm), warn=warn)
    return {k: summary[k] for k in ("cam_speed_rpm", "revolutions_averaged", "spikes", "clipped",
                                    "normal_check_rel_rms", "lowpass_hz", "phi1_method") if k in summary}


# --------------------------------------------------------------------------- compare


def overrides(plan) -> dict:
    """labtool report's options from the plan's [compare]: its model options (SI, by field name); the
    operating point is the recording's own, as the plan stated it."""
    c = plan.doc.compare if plan is not None else None
    if c is None:
        return {}
    return {n: FIELD[n].check_edge(getattr(c, FIELD[n].attr)) for n in COMPARE_OPTIONS
            if getattr(c, FIELD[n].attr) is not None}


def build(measured: Path, compare, thresholds_path: Path | None, overrides_: dict, say=None):
    """labtool.reports.pipeline.build_report with the plan's [compare] choices."""
    from labtool.reports.pipeline import build_report
    from labtool.reports.thresholds import load_thresholds

    from labtool.reports.pipeline import DEFAULT_REVOLUTIONS

    th = load_thresholds(thresholds_path) if thresholds_path is not None else None
    return build_report(Path(measured), tuple(compare.models), tuple(compare.omega1), th, overrides_,
                        compare.accuracy, compare.revolutions or DEFAULT_REVOLUTIONS, progress=say)


def write_point_outputs(report, folder: Path, names: dict) -> None:
    """The per-point page (labtool.reports.html), its JSON summary and the overlay data, each atomically."""
    from labtool.common.files import atomic_write, write_netcdf
    from labtool.reports.figures import all_figures, render
    from labtool.reports.html import render_html
    from labtool.reports.summary import to_json

    html = render_html(report, render(all_figures(report)))
    atomic_write(folder / names["html"], lambda tmp: tmp.write_text(html, encoding="utf-8"))
    text = to_json(report)
    atomic_write(folder / names["summary"], lambda tmp: tmp.write_text(text + "\n", encoding="utf-8"))
    write_netcdf(cycles_dataset(report), folder / names["cycles"])


def cycles_dataset(report) -> xr.Dataset:
    """What the campaign page overlays: the measured cycle average and scatter of omega2 and
    epsilon2 on the report's cam-angle grid (and every whole revolution read, for 'labtool
    export'), and each simulation's steady revolution on it."""
    from labtool.reports.pipeline import SIGNALS

    cyc = report.cycles
    grid = np.asarray(cyc.grid, dtype=float)
    ds = xr.Dataset(coords={"phi1": ("phi1", grid, {"units": "rad", "long_name": "cam angle from the start of the rise"})})
    units = {"omega2": "rad/s", "epsilon2": "rad/s^2"}
    for s in SIGNALS:
        ds[f"measured_{s}_mean"] = ("phi1", cyc.mean(s), {"units": units[s], "long_name": f"measured {s}, cycle average"})
        ds[f"measured_{s}_std"] = ("phi1", cyc.std(s), {"units": units[s],
                                                         "long_name": f"measured {s}, standard deviation over the revolutions"})
    ds = ds.assign_coords(revolution=("revolution", np.asarray(cyc.revolutions, dtype=int),
                                      {"long_name": "measured cam revolution number"}))
    for s in SIGNALS:
        ds[f"measured_{s}_revolutions"] = (("revolution", "phi1"), cyc.signals[s],
                                           {"units": units[s], "long_name": f"measured {s}, each whole revolution"})
    runs = report.sims
    ds = ds.assign_coords(sim=("sim", np.arange(len(runs))))
    for name in ("label", "requested", "model", "omega1"):
        ds[f"sim_{name}"] = ("sim", np.array([str(getattr(r, name)) for r in runs], dtype=object))
    for s in SIGNALS:
        data = np.array([np.where(r.cycle.covered, r.cycle.signals[s], np.nan) for r in runs]).reshape(len(runs), grid.size)
        ds[f"sim_{s}"] = (("sim", "phi1"), data, {"units": units[s], "long_name": f"simulated {s}, steady revolution"})
    ds.attrs.update({"title": "labtool campaign point: cycle overlays", "cam_speed_rpm_measured": float(cyc.cam_speed_rpm),
                     "whole_revolutions": int(len(cyc.revolutions)), "cam_speed_rpm_simulated": float(report.scene["cam_speed_rpm"])})
    return ds
