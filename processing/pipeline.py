"""The processing chain, recording -> measured.nc, in bounded memory.

Two passes over the recording, chunk by chunk (``chunk_samples`` at a time, default 2^18):

1. revolution marks (tacho edges, or matched filter with the kinematics) and each channel's
   extreme values (for clip detection);
2. per chunk, on a window widened by a margin of > 1 revolution on each side (so every motion
   interval and dwell that touches the chunk is whole, and the zero-phase filter has settled):
   Ka -> low-pass (zero-phase) -> gravity removal -> dwell reference -> epsilon2 -> omega2 with
   drift control; spikes; cycle statistics; spectra; the chunk's core is written to the output.

Segments (split by gap/overrun events) are processed independently: nothing is filtered,
integrated or interpolated across a gap. Clipped samples (recorder 'clip' events, or runs of >= 3
samples at a channel's extreme value) are flagged, set to NaN in the outputs, and the motion
intervals, revolutions and spectral segments holding them are left out of the estimates.

The output is written to a temporary file and renamed at the end (labtool.output.atomic_write):
an interrupted or failed run leaves nothing that looks complete.
"""
from __future__ import annotations

import dataclasses
import json
import math
import warnings
from pathlib import Path
from typing import Callable

import numpy as np
import xarray as xr

from common.errors import InputError
from processing import cam_angle, cycles, events, filters, follower, spectra
from processing.calibration_file import PAPER_KA_M_S2_PER_V, ChannelCalibration
from common.history import History
from common.names import shown
from processing.readers import Recording

REQUIRED = ("aE_t", "aE_n")
MAX_SPIKES = 100_000  # stored spike records (a noisy hour could otherwise hold millions)
TIME_VARS = {
    # name: (dtype, units, long_name)
    "aE_t": ("f4", "m/s^2", "tangential acceleration of E, + along increasing psi (filtered, gravity and offset removed)"),
    "aE_n": ("f4", "m/s^2", "normal acceleration of E, + towards D (filtered, gravity and offset removed)"),
    "epsilon2": ("f4", "rad/s^2", "follower angular acceleration, aE_t / DE"),
    "omega2": ("f4", "rad/s", "follower angular velocity, integral of epsilon2 with dwell drift control"),
    "phi1": ("f4", "rad", "cam angle from the start of the rise"),
    "revolution": ("i4", "1", "cam revolution index (-1 before the first revolution mark of a segment)"),
    "clipped": ("i1", "1", "1 where a sample is clipped (kept out of the estimates)"),
}


class ProcessingWarning(UserWarning):
    """Something the user should know about the data, processing continued."""


@dataclasses.dataclass
class ProcessOptions:
    """Processing parameters (SI, except rpm); None means: from the file or the default."""
    calibration: dict[str, ChannelCalibration] | None = None
    calibration_source: str = ""
    law: str | None = None
    cam_speed_rpm: float | None = None
    lowpass_hz: float | None = None
    harmonics: float = filters.DEFAULT_HARMONICS
    filter_order: int = filters.DEFAULT_ORDER
    chunk_samples: int = 1 << 18
    grid_points: int = 720
    dwell_margin_deg: float = 10.0
    spike_k_sigma: float = events.DEFAULT_K_SIGMA
    tacho_channel: str = "tacho"
    ac_tau_s: float | None = None       # sensor chain's AC-coupling time constant (s), undone if given
    mechanism: object | None = None     # models.mechanism.Mechanism; default: the paper's STB-216


def process_recording(rec: Recording, output: Path, options: ProcessOptions | None = None,
                      progress: Callable[[int], None] | None = None,
                      warn: Callable[[str], None] | None = None) -> dict:
    """Process ``rec`` into the NetCDF file ``output`` (written atomically); returns a summary dict."""
    from common.files import atomic_write

    opts = options or ProcessOptions()
    warn = warn or (lambda msg: warnings.warn(msg, ProcessingWarning, stacklevel=3))
    summary: dict = {}

    def writer(tmp: Path):
        summary.update(_run(rec, tmp, opts, progress or (lambda n: None), warn))

    atomic_write(Path(output), writer)
    return summary


def _calibration(rec: Recording, opts: ProcessOptions, warn, hist: History) -> dict[str, tuple[float, float, str]]:
    out = {}
    for name in REQUIRED:
        j = rec.channel_index(name)
        cal = None
        if opts.calibration is not None:
            cal = opts.calibration.get(name) or next(
                (v for k, v in opts.calibration.items() if k.lower() == name.lower()), None)
        if cal is not None:
            out[name] = (cal.ka_m_s2_per_v, cal.uncertainty_m_s2_per_v, f"calibration file {opts.calibration_source}")
            continue
        if math.isfinite(rec.ka_m_s2_per_v[j]) and rec.ka_m_s2_per_v[j] != 0:
            out[name] = (float(rec.ka_m_s2_per_v[j]), math.nan, "recording attribute ka_m_s2_per_v")
        else:
            out[name] = (PAPER_KA_M_S2_PER_V, math.nan, "paper default (Ka = 86.43 m/s^2/V)")
        if opts.calibration is not None:
            # say what is used instead, so the user can tell whether to calibrate that channel too
            warn(f"calibration file {opts.calibration_source} has no entry for channel {name}; "
                 f"using the {out[name][2]} (Ka = {out[name][0]:.4g} m/s^2/V)")
    hist.add("apply_ka", **{f"{k}_ka_m_s2_per_v": v[0] for k, v in out.items()},
             **{f"{k}_uncertainty_m_s2_per_v": v[1] for k, v in out.items()},
             **{f"{k}_source": v[2] for k, v in out.items()})
    return out


def _run(rec: Recording, tmp: Path, opts: ProcessOptions, progress, warn) -> dict:
    import h5netcdf

    from models.mechanism import Mechanism
    from models.mechanism.motion_laws import CamProgram

    hist = History()
    for w in rec.warnings:
        warn(w)
    fs = rec.sample_rate_hz
    n = rec.n_samples
    segs = rec.segments()
    hist.add("read", source=rec.source, format=rec.format, sample_rate_hz=fs, n_samples=n,
             channels=rec.channel_names, complete=rec.complete, start_time_utc=rec.start_time_utc,
             segments=[[a, b] for a, b in segs])
    it, inn = rec.channel_index("aE_t"), rec.channel_index("aE_n")
    cal = _calibration(rec, opts, warn, hist)
    ka = np.array([cal["aE_t"][0], cal["aE_n"][0]])
    itacho = rec.channel_index(opts.tacho_channel) if rec.has_channel(opts.tacho_channel) else None

    mech = opts.mechanism or Mechanism.default()
    law = opts.law or (rec.attrs.get("law") if isinstance(rec.attrs.get("law"), str) else None)
    program = CamProgram.for_mechanism(mech, law=law)
    law_name = program.segments[0].law.name

    # ---- pass 1: revolution marks and channel extremes -------------------------------------------
    chunk = int(opts.chunk_samples)
    rpm_hint = opts.cam_speed_rpm if opts.cam_speed_rpm else rec.cam_speed_rpm
    method = "tacho" if itacho is not None else "correlation"
    marks_by_seg, vmin, vmax, period_est = _find_marks(rec, segs, method, itacho, it, ka[0], chunk, mech, program,
                                                       rpm_hint, warn, progress)
    if method == "tacho" and sum(max(len(m) - 1, 0) for m in marks_by_seg) < 1:
        warn(f"tacho channel '{rec.channel_names[itacho]}' shows fewer than two pulses; "
             "finding the cam angle by correlation with the kinematics instead")
        method = "correlation"
        marks_by_seg, vmin, vmax, period_est = _find_marks(rec, segs, method, itacho, it, ka[0], chunk, mech,
                                                           program, rpm_hint, warn, lambda k: None)
    all_periods = np.concatenate([np.diff(m) for m in marks_by_seg if len(m) >= 2] or [np.empty(0)])
    if len(all_periods) == 0:
        raise InputError(f"{rec.source}: fewer than two cam revolutions found; cannot process "
                         "(is the cam turning, are aE_t and the tacho connected?)")
    period = float(np.median(all_periods))
    regular = (all_periods > 0.8 * period) & (all_periods < 1.25 * period)
    rpm_measured = 60.0 * fs / float(np.mean(all_periods[regular]))
    if rpm_hint and math.isfinite(rpm_hint):
        ratio = rpm_measured / rpm_hint
        if not (1 / 1.5 < ratio < 1.5):
            raise InputError(
                f"{rec.source}: the data give {rpm_measured:.1f} rpm at the stated {fs:g} Hz, but the cam turned at "
                f"{rpm_hint:g} rpm: the sample rate (or the stated cam speed) is wrong; fix the file or give --rpm")
        if abs(ratio - 1) > 0.2:
            warn(f"measured cam speed {rpm_measured:.1f} rpm differs from the stated {rpm_hint:g} rpm by "
                 f"{100 * abs(ratio - 1):.0f} %")
    # a revolution much longer or shorter than the others (missed or extra tacho pulse, a stall):
    # its cam angle is not known, so its samples are NaN and it stays out of the statistics
    irregular_by_seg = [~((np.diff(m) > 0.8 * period) & (np.diff(m) < 1.25 * period)) for m in marks_by_seg]
    n_irregular = int(sum(x.sum() for x in irregular_by_seg))
    if n_irregular:
        warn(f"{n_irregular} revolutions deviate by more than 20 % from the median period "
             f"{period / fs * 1e3:.1f} ms (missed tacho pulses?); their samples are NaN")
    hist.add("cam_angle", method=method, revolution_marks=int(sum(len(m) for m in marks_by_seg)),
             cam_speed_rpm_mean=rpm_measured, period_median_s=period / fs,
             period_min_s=float(all_periods.min()) / fs, period_max_s=float(all_periods.max()) / fs,
             irregular_revolutions=n_irregular,
             law=law_name, mechanism=mech.name, **({"autocorrelation_period_s": period_est / fs} if period_est else {}))

    # ---- filter design, margins ------------------------------------------------------------------
    cutoff = opts.lowpass_hz or filters.lowpass_cutoff_hz(rpm_measured, fs, opts.harmonics)
    sos = filters.lowpass_sos(fs, cutoff, opts.filter_order)
    settle = filters.settle_samples(sos)
    margin = int(math.ceil(1.3 * 1.25 * period)) + settle + 8
    margin_int = max(1, int(round(opts.dwell_margin_deg / 360.0 * period)))
    hist.add("lowpass", kind="butterworth", order=opts.filter_order, cutoff_hz=cutoff, zero_phase=True,
             rule=f"{opts.harmonics:g} x cam frequency, at most 0.4 fs" if not opts.lowpass_hz else "given",
             chunk_samples=chunk, overlap_samples=margin)
    tau = opts.ac_tau_s if opts.ac_tau_s is not None else _float_attr(rec.attrs.get("ac_coupling_tau_s"))
    if tau is not None and not (math.isfinite(tau) and tau > 0):
        raise InputError(f"AC-coupling time constant {tau!r} s must be a positive number")
    if tau:
        hist.add("undo_ac_coupling", tau_s=tau, formula="x = y + (1/tau) * integral(y dt), first-order high-pass inverted")
    hist.add("remove_gravity", g_m_s2=mech.g, tangential="g cos(phi2)", normal="-g sin(phi2)",
             phi2="phiD + psi0 + psi(phi1) from the kinematics")
    hist.add("dwell_reference", statistic="mean of the middle 60 % of each dwell",
             between_dwells="linear interpolation")
    hist.add("epsilon2", formula="aE_t / DE", DE_m=mech.DE)
    hist.add("omega2", method="trapezoidal integral of epsilon2 over each motion interval",
             drift_control="starts at 0 and a linear ramp brings it to 0 in the next dwell",
             dwell_margin_deg=opts.dwell_margin_deg)

    tables = KinematicTables(mech, program)

    # ---- outputs ---------------------------------------------------------------------------------
    nper = spectra.default_nperseg(fs, max(b - a for a, b in segs))
    welch = spectra.WelchAccumulator(fs, nper, 2)
    cyc = cycles.CycleAccumulator(["aE_t", "aE_n", "epsilon2", "omega2", "omega2_abs_from_aE_n"], opts.grid_points)
    spikes = {"index": [], "channel": [], "amplitude": [], "threshold": []}
    n_spikes_seen = 0
    check_sq, check_n, omega_peak = 0.0, 0, 0.0
    n_clipped = 0
    clip_events = rec.clip_indices()
    lost_rows, lost_n, lost_unknown = rec.lost_samples()
    # the ADC's rails, when the recording states its range (the simulated stand and the recorder do)
    adc = _float_attr(rec.attrs.get("adc_range_v"))
    bits = _float_attr(rec.attrs.get("adc_bits")) or 16
    rail = adc - 2.5 * (2 * adc / 2**bits) if adc and adc > 0 else None
    lost_cum = np.concatenate([[0], np.cumsum(lost_n)])

    def row_time(rows):
        """Time (s) of recording rows (float allowed), counting the samples lost before them."""
        rows = np.asarray(rows, dtype=float)
        return (rows + lost_cum[np.searchsorted(lost_rows, rows, side="right")]) / fs
    if lost_unknown:
        warn(f"{lost_unknown} gap/overrun events do not say how many samples were lost; after them the time "
             "axis runs on the sample clock (the segments still split there)")
    rev_offset = 0
    rev_marks_global: list[np.ndarray] = []

    f = h5netcdf.File(tmp, "w")
    try:
        f.dimensions["time"] = n
        tchunk = min(n, 1 << 16)
        tv = f.create_variable("time", ("time",), "f8", chunks=(tchunk,))
        tv.attrs["units"] = "s"
        tv.attrs["long_name"] = "time from the first sample (the samples lost at gaps are counted)"
        tv = tv._h5ds
        outv = {}
        for name, (dt, units, long_name) in TIME_VARS.items():
            v = f.create_variable(name, ("time",), dt, chunks=(tchunk,))
            v.attrs["units"] = units
            v.attrs["long_name"] = long_name
            outv[name] = v._h5ds  # write through h5py: h5netcdf's per-call checks cost 10 % of the run

        for iseg, ((a_seg, b_seg), marks, irregular) in enumerate(zip(segs, marks_by_seg, irregular_by_seg)):
            welch.reset_continuity()
            usable = len(marks) >= 2
            if not usable:
                warn(f"segment {iseg} (samples {a_seg}..{b_seg}) holds fewer than two revolution marks; "
                     "its outputs are NaN")
            rev_marks_global.append(marks)
            for a in range(a_seg, b_seg, chunk):
                b = min(a + chunk, b_seg)
                wa, wb = max(a_seg, a - margin), min(b_seg, b + margin)
                block = rec.read(wa, wb)
                idx = np.arange(wa, wb)
                c0, c1 = a - wa, b - wa
                tv[a:b] = row_time(idx[c0:c1])
                volts = block[:, [it, inn]]
                phys = volts * ka[None, :]
                clipped = _clipped(volts, vmin[[it, inn]], vmax[[it, inn]], clip_events, wa, wb, rail)
                n_clipped += int(clipped[c0:c1].sum())
                outv["clipped"][a:b] = clipped[c0:c1].astype(np.int8)
                welch.feed(phys[c0:c1], clipped[c0:c1])
                if not usable:
                    for name in ("aE_t", "aE_n", "epsilon2", "omega2", "phi1"):
                        outv[name][a:b] = np.full(b - a, np.nan, dtype=np.float32)
                    outv["revolution"][a:b] = np.full(b - a, -1, dtype=np.int32)
                    progress(b - a)
                    continue
                res = _process_window(phys, clipped, idx, marks, period, fs, sos, mech, tables, margin_int, tau,
                                      irregular)
                rev = res["revolution"]
                rev_g = np.where(rev >= 0, rev + rev_offset, -1)
                for name in ("aE_t", "aE_n", "epsilon2", "omega2", "phi1"):
                    outv[name][a:b] = res[name][c0:c1].astype(np.float32)
                outv["revolution"][a:b] = rev_g[c0:c1].astype(np.int32)
                # |omega2| = sqrt(aE_n / DE) check over the motion samples of the core
                mv = res["moving"][c0:c1] & np.isfinite(res["omega2"][c0:c1])
                if mv.any():
                    d = np.abs(res["omega2"][c0:c1][mv]) - res["omega2_abs_from_aE_n"][c0:c1][mv]
                    check_sq += float(np.sum(d * d))
                    check_n += int(mv.sum())
                    omega_peak = max(omega_peak, float(np.max(np.abs(res["omega2"][c0:c1][mv]))))
                # spikes
                for j, name in enumerate(("aE_t", "aE_n")):
                    pk, amp, thr = events.detect_spikes(phys[:, j] - res["lowpassed"][:, j], res["lowpassed"][:, j],
                                                        fs, opts.spike_k_sigma, valid=~clipped)
                    keep = (pk >= c0) & (pk < c1)
                    n_spikes_seen += int(keep.sum())
                    room = MAX_SPIKES - len(spikes["index"])
                    if keep.sum() > room:  # bounded memory: keep the first MAX_SPIKES, count the rest
                        keep &= np.cumsum(keep) <= room
                    spikes["index"].extend((pk[keep] + wa).tolist())
                    spikes["channel"].extend([name] * int(keep.sum()))
                    spikes["amplitude"].extend(amp[keep].tolist())
                    spikes["threshold"].extend([thr] * int(keep.sum()))
                # cycle statistics: revolutions whose start mark lies in this core
                _add_cycles(cyc, res, clipped, marks, a, b, wa, len(idx))
                progress(b - a)
            rev_offset += len(marks)

        # ---- small outputs ---------------------------------------------------------------------
        f.attrs["title"] = "labtool measured follower motion"
    finally:
        f.close()

    if n_clipped:
        warn(f"{n_clipped} clipped samples flagged and kept out of the estimates")
    hist.add("time_axis", rule="time = (row + samples lost before it, from the gap events' missing_samples) / fs",
             samples_lost=int(lost_n.sum()), gaps_with_unknown_loss=lost_unknown)
    hist.add("clipping", flagged_samples=n_clipped, recorder_clip_events=int(len(clip_events)),
             rail_v=rail, rule="recorder 'clip' events, |v| within 2.5 LSB of the ADC range when stated, "
                               "or runs of >= 3 samples at the channel's extreme value")
    check = math.sqrt(check_sq / check_n) / omega_peak if check_n and omega_peak > 0 else math.nan
    hist.add("check_normal", quantity="rms(|omega2| - sqrt(aE_n/DE)) / max|omega2| over the motion",
             value=check)
    stats = cyc.result()
    hist.add("cycle_average", grid_points=opts.grid_points, revolutions_used=cyc.count,
             revolutions_rejected=cyc.rejected)
    hist.add("spectra", window="hann", nperseg=nper, overlap=0.5, segments=welch.count,
             segments_skipped_clipped=welch.skipped, signal="Ka-scaled, mean removed per segment, unfiltered")
    hist.add("spikes", k_sigma=opts.spike_k_sigma, floor_fraction=events.DEFAULT_FLOOR_FRACTION,
             refractory_s=events.DEFAULT_REFRACTORY_S, count=n_spikes_seen, stored=len(spikes["index"]))
    if n_spikes_seen > len(spikes["index"]):
        warn(f"{n_spikes_seen} spikes found; only the first {len(spikes['index'])} are stored")
    small = _small_dataset(rec, fs, welch, cyc, stats, spikes, rev_marks_global, mech, program, rpm_measured, segs,
                           row_time)
    small.attrs.update({
        "title": "labtool measured follower motion",
        "source_file": shown(rec.source),
        "source_format": rec.format,
        "start_time_utc": rec.start_time_utc,
        "recording_complete": int(rec.complete),
        "sample_rate_hz": fs,
        "cam_speed_rpm": rpm_measured,
        "cam_speed_rpm_stated": float(rec.cam_speed_rpm) if math.isfinite(rec.cam_speed_rpm) else "unknown",
        "law": law_name,
        "phi1_method": method,
        "lowpass_hz": cutoff,
        "DE_m": mech.DE,
        "ka_aE_t_m_s2_per_v": cal["aE_t"][0],
        "ka_aE_n_m_s2_per_v": cal["aE_n"][0],
        "ka_aE_t_uncertainty_m_s2_per_v": cal["aE_t"][1] if math.isfinite(cal["aE_t"][1]) else "unknown",
        "ka_aE_n_uncertainty_m_s2_per_v": cal["aE_n"][1] if math.isfinite(cal["aE_n"][1]) else "unknown",
        "ka_source_aE_t": cal["aE_t"][2],
        "ka_source_aE_n": cal["aE_n"][2],
        "omega2_normal_check_rel_rms": check if math.isfinite(check) else "n/a",
        "n_revolutions_averaged": cyc.count,
        "n_clipped_samples": n_clipped,
        "n_segments": len(segs),
        "n_spikes": n_spikes_seen,
        "n_samples_lost": int(lost_n.sum()),
        "processing_history": hist.to_json(),
    })
    try:
        small.to_netcdf(tmp, mode="a", engine="h5netcdf")
    except OSError as exc:
        raise InputError(f"cannot write the output: {exc}") from None
    return {"cam_speed_rpm": rpm_measured, "revolutions_averaged": cyc.count, "spikes": n_spikes_seen,
            "clipped": n_clipped, "normal_check_rel_rms": check, "lowpass_hz": cutoff, "phi1_method": method,
            "segments": len(segs), "history": hist.steps}


def _find_marks(rec, segs, method, itacho, it, ka_t, chunk, mech, program, rpm_hint, warn, progress):
    """Pass 1: revolution marks per segment (tacho edges or matched filter) and channel extremes."""
    fs = rec.sample_rate_hz
    vmin = np.full(rec.n_channels, np.inf)
    vmax = np.full(rec.n_channels, -np.inf)
    period_est = None
    if method == "correlation":
        a0, b0 = max(segs, key=lambda s: s[1] - s[0])
        probe = rec.read(a0, min(b0, a0 + int(20 * fs)))[:, it]
        period_est = cam_angle.estimate_period(probe, fs)
        if rpm_hint and math.isfinite(rpm_hint):
            hinted = fs * 60.0 / rpm_hint
            if abs(period_est / hinted - 1) > 0.2:
                warn(f"cam speed from the data ({60 * fs / period_est:.1f} rpm) differs from the stated "
                     f"{rpm_hint:g} rpm by more than 20 %; using the data")
    marks_by_seg = []
    for a_seg, b_seg in segs:
        marks = []
        if method == "tacho":
            det = cam_angle.TachoEdges()
            for a, block in rec.chunks(chunk, a_seg, b_seg):
                vmin, vmax = _extremes(block, vmin, vmax)
                marks.extend(det.feed(a, block[:, itacho]))
                progress(len(block))
        else:
            corr = cam_angle.CorrelationEdges(mech, program, period_est)
            over = corr.n + 2
            for a in range(a_seg, b_seg, chunk):
                b = min(a + chunk, b_seg)
                block = rec.read(a, min(b + over, b_seg))
                vmin, vmax = _extremes(block[: b - a], vmin, vmax)
                marks.extend(corr.feed(a, block[:, it] * ka_t, a, b))
                progress(b - a)
        marks_by_seg.append(np.asarray(marks, dtype=float))
    return marks_by_seg, vmin, vmax, period_est


def _add_cycles(cyc, res, clipped, marks, a, b, wa, n) -> None:
    """Resample every complete revolution starting in [a, b) on the phi1 grid, all at once.

    phi1 is linear in the sample index within a revolution, so linear interpolation in the sample
    index at m_k + (phi/2 pi)(m_{k+1} - m_k) is linear interpolation in phi1.
    """
    k = np.flatnonzero((marks[:-1] >= a) & (marks[:-1] < b))
    if len(k) == 0:
        return
    m0, m1 = marks[k] - wa, marks[k + 1] - wa
    inside = (m0 >= 0) & (np.floor(m1) + 1 < n)
    k, m0, m1 = k[inside], m0[inside], m1[inside]
    if len(k) == 0:
        return
    bad = clipped.copy()
    for name in cyc.names:
        bad |= ~np.isfinite(res[name])
    bc = np.concatenate([[0], np.cumsum(bad)])
    lo, hi = np.floor(m0).astype(np.int64), np.floor(m1).astype(np.int64) + 2
    good = (bc[hi] - bc[lo]) == 0
    cyc.rejected += int((~good).sum())
    m0, m1 = m0[good], m1[good]
    if len(m0) == 0:
        return
    x = m0[:, None] + (cyc.grid / (2.0 * math.pi))[None, :] * (m1 - m0)[:, None]
    i0 = np.floor(x).astype(np.int64)
    w = x - i0
    cyc.add_block({name: res[name][i0] * (1.0 - w) + res[name][i0 + 1] * w for name in cyc.names})


def _extremes(block, vmin, vmax):
    # column by column: a reduction along axis 0 of an (n, 3) array is ~25x slower
    lo = np.array([block[:, j].min() for j in range(block.shape[1])])
    hi = np.array([block[:, j].max() for j in range(block.shape[1])])
    return np.minimum(vmin, lo), np.maximum(vmax, hi)


class KinematicTables:
    """psi-dependent quantities tabulated over one revolution (2^16 points, 0.1 mrad): gravity
    reading and cam phase direction, looked up per sample instead of evaluating the law."""

    N = 1 << 16

    def __init__(self, mech, program):
        grid = 2.0 * math.pi * np.arange(self.N) / self.N
        psi = program(grid)[0]
        gt, gn = follower.gravity_reading(mech.phiD + mech.psi0 + psi, mech.g)
        self.gravity = np.column_stack([gt, gn])
        self.moving = program.direction(grid) != 0

    def index(self, phi1):
        k = (phi1 * (self.N / (2.0 * math.pi)) + 0.5).astype(np.int64)
        return k & (self.N - 1)


def _clipped(volts, lo, hi, clip_events, wa, wb, rail=None) -> np.ndarray:
    """Samples at the ADC's rails (|v| >= ``rail`` V, when the range is known), at a channel's
    extreme value for >= 3 samples in a row, or named by a clip event."""
    out = np.zeros(len(volts), dtype=bool)
    if rail is not None:
        out |= (np.abs(volts) >= rail).any(axis=1)
    for j in range(volts.shape[1]):
        if not hi[j] > lo[j]:
            continue
        at = (volts[:, j] == hi[j]) | (volts[:, j] == lo[j])
        if at.sum() >= 3:
            for a, b in follower.runs(at):
                if b - a >= 3:
                    out[a:b] = True
    sel = clip_events[(clip_events >= wa) & (clip_events < wb)]
    out[sel - wa] = True
    return out


def _float_attr(v):
    try:
        return float(np.asarray(v).reshape(-1)[0]) if v is not None else None
    except (TypeError, ValueError):
        return None


def _process_window(phys, clipped, idx, marks, period, fs, sos, mech, tables, margin_int, tau=None,
                    irregular=None) -> dict:
    """The chain on one window of one segment (arrays over the window's samples)."""
    lp = filters.zero_phase(sos, phys, axis=0)
    if tau:
        # inverse of the first-order high-pass; the integration constant and the ramp an offset
        # makes are constant/linear, and the dwell reference below removes both
        lp = lp + np.cumsum(lp - lp[0], axis=0) / (fs * tau)
    phi1, rev = cam_angle.phi1_from_marks(idx, marks, period)
    k = tables.index(phi1)
    acc = lp - tables.gravity[k]
    moving = tables.moving[k]
    acc -= follower.dwell_baseline(acc, ~moving)
    bad = clipped
    if irregular is not None and irregular.any():
        # revolution k spans marks k..k+1; samples in an irregular one have no trustworthy phi1
        bad = clipped | ((rev >= 0) & (rev < len(irregular)) & irregular[np.clip(rev, 0, len(irregular) - 1)])
        phi1 = np.where(bad & ~clipped, np.nan, phi1)
    acc[bad] = np.nan
    eps = acc[:, 0] / mech.DE
    omega = follower.integrate_motion(np.nan_to_num(eps), moving, fs, margin_int, bad=bad)
    omega[bad] = np.nan
    absn = follower.omega2_from_normal(np.nan_to_num(acc[:, 1]), mech.DE)
    absn[bad] = np.nan
    return {"aE_t": acc[:, 0], "aE_n": acc[:, 1], "epsilon2": eps, "omega2": omega, "omega2_abs_from_aE_n": absn,
            "phi1": phi1, "revolution": rev, "moving": moving, "lowpassed": lp}


def _small_dataset(rec, fs, welch, cyc, stats, spikes, rev_marks, mech, program, rpm, segments,
                   row_time) -> xr.Dataset:
    def var(dims, data, units, long_name):
        return (dims, np.asarray(data), {"units": units, "long_name": long_name})

    amp, psd = welch.amplitude(), welch.psd()
    ds = xr.Dataset()
    ds["frequency"] = var("frequency", welch.frequency, "Hz", "frequency")
    ds["aE_t_amplitude"] = var("frequency", amp[:, 0], "m/s^2", "amplitude spectrum of aE_t (Ka applied, offset removed)")
    ds["aE_n_amplitude"] = var("frequency", amp[:, 1], "m/s^2", "amplitude spectrum of aE_n (Ka applied, offset removed)")
    ds["aE_t_psd"] = var("frequency", psd[:, 0], "(m/s^2)^2/Hz", "Welch power spectral density of aE_t")
    ds["aE_n_psd"] = var("frequency", psd[:, 1], "(m/s^2)^2/Hz", "Welch power spectral density of aE_n")
    ds["phi1_grid"] = var("phi1_grid", cyc.grid, "rad", "cam angle of the cycle-average grid")
    units = {"aE_t": "m/s^2", "aE_n": "m/s^2", "epsilon2": "rad/s^2", "omega2": "rad/s", "omega2_abs_from_aE_n": "rad/s"}
    for k, v in stats.items():
        base, what = k.rsplit("_", 1)
        label = "mean over revolutions" if what == "mean" else "standard deviation over revolutions"
        desc = "|omega2| from the normal acceleration, sqrt(aE_n / DE)" if base == "omega2_abs_from_aE_n" else base
        ds[k] = var("phi1_grid", v, units[base], f"{desc}, {label}")
    ds["segment_start"] = var("segment", [a for a, _ in segments], "1", "first sample of the contiguous segment")
    ds["segment_stop"] = var("segment", [b for _, b in segments], "1", "one past the last sample of the segment")
    omega1 = rpm * 2 * math.pi / 60.0
    _, dpsi, ddpsi, _ = program(cyc.grid)
    ds["omega2_kinematic"] = var("phi1_grid", dpsi * omega1, "rad/s", "omega2 of the ideal kinematics at the measured mean cam speed")
    ds["epsilon2_kinematic"] = var("phi1_grid", ddpsi * omega1**2, "rad/s^2", "epsilon2 of the ideal kinematics at the measured mean cam speed")
    si = np.asarray(spikes["index"], dtype=np.int64)
    order = np.argsort(si, kind="stable")
    si = si[order]
    all_marks = np.concatenate(rev_marks) if rev_marks else np.empty(0)
    ds["spike_time"] = var("spike", row_time(si), "s", "time of the spike peak")
    ds["spike_sample"] = var("spike", si, "1", "sample index of the spike peak")
    ds["spike_channel"] = var("spike", np.asarray(spikes["channel"], dtype=str)[order] if len(si) else np.array([], dtype=str),
                              "1", "channel of the spike")
    ds["spike_amplitude"] = var("spike", np.asarray(spikes["amplitude"], dtype=float)[order], "m/s^2",
                                "peak of the acceleration above the processing band")
    ds["spike_threshold"] = var("spike", np.asarray(spikes["threshold"], dtype=float)[order], "m/s^2",
                                "detection threshold in force at the spike")
    if len(all_marks) and len(si):
        k = np.searchsorted(all_marks, si, side="right") - 1
        nxt = np.clip(k + 1, 0, len(all_marks) - 1)
        ok = (k >= 0) & (nxt > k)
        ph = np.full(len(si), np.nan)
        ph[ok] = np.mod(2 * math.pi * (si[ok] - all_marks[k[ok]]) / (all_marks[nxt[ok]] - all_marks[k[ok]]), 2 * math.pi)
    else:
        ph = np.full(len(si), np.nan)
    phase = np.array(["rise" if d > 0 else "return" if d < 0 else "dwell" for d in program.direction(np.nan_to_num(ph))],
                     dtype=str) if len(si) else np.array([], dtype=str)
    phase = np.where(np.isfinite(ph), phase, "unknown") if len(si) else phase
    ds["spike_phi1"] = var("spike", ph, "rad", "cam angle at the spike")
    ds["spike_phase"] = var("spike", phase, "1", "cam phase at the spike: rise, return, dwell")
    ds["revolution_start_time"] = var("revolution_mark", row_time(all_marks), "s",
                                      "time of the revolution mark (phi1 = 0)")
    per = np.concatenate([np.append(np.diff(m), np.nan) for m in rev_marks if len(m)] or [np.empty(0)])
    ds["revolution_omega1"] = var("revolution_mark", 2 * math.pi * fs / per if len(per) else per, "rad/s",
                                  "mean cam angular velocity over the revolution (NaN for the last of a segment)")
    return ds
