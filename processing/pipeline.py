"""The processing chain, recording -> measured.nc, in bounded memory.

Two passes over the recording, chunk by chunk (``chunk_samples`` at a time, default 2^18):

1. revolution marks (tacho edges, or matched filter with the kinematics) and each channel's
   extreme values (for clip detection); the cam speed from the marks (speed.py);
2. per chunk, on a window widened by a margin of > 1 revolution on each side (so every motion
   interval and dwell that touches the chunk is whole, and the zero-phase filter has settled):
   Ka -> low-pass (zero-phase) -> gravity removal -> dwell reference -> epsilon2 -> omega2 with
   drift control (kernels.py, compiled); spikes, the normal-axis check and clipping
   (accumulators.py); cycle statistics; spectra; the chunk's core is written (writer.py).

Segments (split by gap/overrun events) are processed independently: nothing is filtered,
integrated or interpolated across a gap. Clipped samples (recorder 'clip' events, or runs of >= 3
samples at a channel's extreme value) are flagged, set to NaN in the outputs, and the motion
intervals, revolutions and spectral segments holding them are left out of the estimates.

Every step is recorded in the history from the parameters it was called with (common/history.py).
The output is written to a temporary file and renamed at the end (labtool.common.files.atomic_write): an
interrupted or failed run leaves nothing that looks complete.
"""
from __future__ import annotations

import dataclasses
import math
import warnings
from pathlib import Path
from typing import Callable

import numpy as np

from labtool.common import cf
from labtool.common import history as H
from labtool.common import recording_attrs
from labtool.common.errors import InputError
from labtool.common.files import atomic_write
from labtool.common.invocation import command_line
from labtool.common.names import shown
from labtool.models.mechanism import Mechanism, sensor_point
from labtool.models.mechanism.motion_laws import CamProgram
from labtool.processing import cam_angle, cycles, events, filters, follower, kernels, orientation, speed, spectra
from labtool.processing.accumulators import LARGER_RANGE, ClipCounter, NormalCheck, SpikeCollector
from labtool.processing.ka import ka_for_channels
from labtool.processing.readers import Recording
from labtool.processing.readers.base import MAX_SAMPLE, check_finite, stated_number
from labtool.processing.workspace import Workspace
from labtool.processing.writer import CoreBlock, MeasuredWriter

CYCLE_NAMES = ["aE_t", "aE_n", "epsilon2", "omega2", "omega2_abs_from_aE_n"]  # kernels.resample_cycles' order


class ProcessingWarning(UserWarning):
    """Something the user should know about the data, processing continued."""


@dataclasses.dataclass
class ProcessOptions:
    """Processing parameters (SI, except rpm); None means: from the file or the default."""
    calibration: dict | None = None     # {channel: ChannelCalibration} from a calibration file
    calibration_source: str = ""
    law: str | None = None
    cam_speed_rpm: float | None = None
    lowpass_hz: float | None = None
    harmonics: float = filters.DEFAULT_HARMONICS
    filter_order: int = filters.DEFAULT_ORDER
    chunk_samples: int = 1 << 17
    grid_points: int = 720
    dwell_margin_deg: float = 10.0
    spike_k_sigma: float = events.DEFAULT_K_SIGMA
    tacho_channel: str = "tacho"
    invert: tuple = ()                  # chain names (aE_t, aE_n) of channels whose sensor reads the other way round
    ac_tau_s: float | None = None       # sensor chain's AC-coupling time constant (s), undone if given
    mechanism: object | None = None     # labtool.models.mechanism.Mechanism; default: the paper's STB-216


def process_recording(rec: Recording, output: Path, options: ProcessOptions | None = None,
                      progress: Callable[[int], None] | None = None,
                      warn: Callable[[str], None] | None = None) -> dict:
    """Process ``rec`` into the NetCDF file ``output`` (written atomically); returns a summary dict."""
    opts = options or ProcessOptions()
    warn = warn or (lambda msg: warnings.warn(msg, ProcessingWarning, stacklevel=3))
    summary: dict = {}

    def writer(tmp: Path):
        summary.update(_run(rec, tmp, opts, progress or (lambda n: None), warn))

    atomic_write(Path(output), writer)
    return summary


def process_file(recording: Path, output: Path, calibration_files=(), channels: dict | None = None,
                 options: ProcessOptions | None = None, progress: Callable[[int], None] | None = None,
                 warn: Callable[[str], None] | None = None, on_open: Callable | None = None, invert=(),
                 **reader_options) -> dict:
    """A recording file -> ``output`` (measured.nc, written atomically); returns the summary dict.

    ``calibration_files``: calibration TOML files (labtool calibrate), merged; ``channels``: the
    file's channel for each of aE_t, aE_n, tacho (``{"aE_t": "ai0"}``); ``options``: processing
    parameters (their calibration is replaced by the files'); ``invert``: aE_t and/or aE_n, channels
    whose sensor reads the other way round (after ``channels``); ``reader_options``: what the
    reader of the format takes (sample_rate_hz, group, delimiter, decimal, time_unit_s, units, ...);
    ``on_open(recording)`` is called once the file is open (a progress bar sized on it)."""
    from labtool.processing.calibration_file import read_calibrations
    from labtool.processing.readers import open_recording

    opts = options or ProcessOptions()
    if invert:
        opts = dataclasses.replace(opts, invert=tuple(invert))
    bad = [c for c in opts.invert if c not in orientation.CHANNELS]
    if bad:
        raise InputError(f"--invert: {bad[0]!r} is not one of {', '.join(orientation.CHANNELS)}")
    if calibration_files:
        opts = dataclasses.replace(opts, calibration=read_calibrations(list(calibration_files)),
                                   calibration_source="; ".join(str(c) for c in calibration_files))
    rec = open_recording(recording, channels=channels or {}, **reader_options)
    try:
        rec.rename_channels(channels or {})
        if on_open is not None:
            on_open(rec)
        return process_recording(rec, output, opts, progress=progress, warn=warn)
    finally:
        rec.close()


@dataclasses.dataclass
class Chain:
    """Everything the per-window chain needs, fixed before pass 2; ``steps``: the history records of
    the steps it runs, with the parameters they run with, added to the history once pass 2 has run."""
    fs: float
    ka: np.ndarray               # (2,) factor from the file's unit to m/s^2 of aE_t, aE_n
    sos: np.ndarray
    zi: np.ndarray               # sosfilt_zi(sos)
    padlen: int
    margin: int                  # overlap (samples) on each side of a chunk
    tables: "KinematicTables"
    dwell: H.DwellReference
    omega: H.Omega2
    DE: float
    tau: float | None
    steps: list


def _run(rec: Recording, tmp: Path, opts: ProcessOptions, progress, warn) -> dict:
    for w in rec.warnings:
        warn(w)
    hist = H.History()
    segs = rec.segments()
    hist.add(H.Read(source=rec.source, format=rec.format, sample_rate_hz=rec.sample_rate_hz, n_samples=rec.n_samples,
                    channels=rec.channel_names, complete=rec.complete, start_time_utc=rec.start_time_utc,
                    segments=[[a, b] for a, b in segs], assumptions=list(rec.assumptions)))
    mech = opts.mechanism or Mechanism.default()
    law = opts.law or (rec.attrs.get("law") if isinstance(rec.attrs.get("law"), str) else None)
    program = CamProgram.for_mechanism(mech, law=law)
    # before Ka, so Ka follows a channel the check renames; what it says is said once the marks are
    # found (before an error that ends the run, it is not the news)
    check_said: list[str] = []
    check, signs = orientation.check_recording(rec, segs, mech, program, _rpm_hint(rec, opts), opts.invert,
                                               opts.tacho_channel, check_said.append)
    hist.add(check)
    cal = hist.add(ka_for_channels(rec, opts.calibration, opts.calibration_source, warn)).channels
    # a channel's sign (--invert, or the check's correction) rides on its Ka: every later step sees it
    ka = np.array([cal["aE_t"]["ka_m_s2_per_v"], cal["aE_n"]["ka_m_s2_per_v"]]) * np.asarray(signs, dtype=float)
    marks, cam = _revolutions(rec, segs, opts, ka[0], mech, program, hist, warn, progress)
    for msg in check_said:
        warn(msg)
    chain = _design(rec, opts, ka, cam, mech, program)
    _say_ac_coupling(rec, chain, cam, warn)
    out = MeasuredWriter(tmp, rec.n_samples, rec.start_time_utc)
    try:
        state = _pass2(rec, segs, marks, cam, chain, opts, out, warn, progress)
        for step in chain.steps:            # recorded once they have run
            hist.add(step)
        attrs = _finish(rec, segs, marks, cam, chain, opts, state, program, law, cal, hist, out, warn)
    except BaseException:
        out.abort()
        raise
    out.close(attrs)
    return {"cam_speed_rpm": cam.rpm, "revolutions_averaged": state.cycles.count, "spikes": state.spikes.seen,
            "clipped": state.clip.flagged, "normal_check_rel_rms": state.normal.value,
            "lowpass_hz": attrs["lowpass_hz"], "phi1_method": attrs["phi1_method"], "segments": len(segs),
            "history": hist.to_list()}


def _revolutions(rec, segs, opts, ka_t, mech, program, hist, warn, progress):
    """Pass 1 (marks, extremes) and the cam speed; falls back to correlation without tacho pulses."""
    itacho = rec.channel_index(opts.tacho_channel) if rec.has_channel(opts.tacho_channel) else None
    rpm_hint = _rpm_hint(rec, opts)
    method = "tacho" if itacho is not None else "correlation"
    # what the search says on the way is said once the marks are found: before the error that ends
    # the run it misleads ("cam speed from the data (1030.8 rpm)" for a 5 rpm run of 3 s)
    said: list[str] = []
    try:
        found = _find_marks(rec, segs, method, itacho, ka_t, opts.chunk_samples, mech, program, rpm_hint,
                            said.append, progress)
        if method == "tacho" and sum(max(len(m) - 1, 0) for m in found[0]) < 1:
            said.append(f"tacho channel '{rec.channel_names[itacho]}' shows fewer than two pulses; "
                        "finding the cam angle by correlation with the kinematics instead")
            method = "correlation"
            found = _find_marks(rec, segs, method, itacho, ka_t, opts.chunk_samples, mech, program, rpm_hint,
                                said.append, lambda k: None)
        marks_by_seg, vmin, vmax, period_est, (search, q) = found
        if method == "correlation" and not _stated(rpm_hint) and sum(max(len(m) - 1, 0) for m in marks_by_seg) < 1:
            raise InputError(f"{shown(rec.source)}: no whole cam revolution found in aE_t by correlation (searched "
                             f"{search.why}) and no tacho recorded: give the speed the cam turned at with --rpm "
                             f"(rpm; it is then searched within a factor {cam_angle.STATED_FACTOR:g} of it)")
        cam = speed.estimate(marks_by_seg, rec.sample_rate_hz, rpm_hint, rec.source, said.append)
    except InputError:
        _check_two_revolutions(rec, segs, rpm_hint, opts)   # the cause, when the stated speed shows it
        raise
    fs = rec.sample_rate_hz
    assumption = None
    if method == "correlation" and orientation.mirror_symmetric(program):
        assumption = ("without a tacho the cam angle comes from aE_t, and this cam's return mirrors its rise half a "
                      "turn later, so an aE_t of the other sign gives the same marks half a turn on: phi1 and the "
                      "sign of omega2 assume aE_t reads positive along the rise")
        said.append(f"{assumption} (a sensor mounted the other way round: give --invert aE_t; a tacho settles it)")
    for msg in said:
        warn(msg)
    hist.add(H.CamAngle(method=method, revolution_marks=int(sum(len(m) for m in marks_by_seg)),
                        cam_speed_rpm_mean=cam.rpm, period_median_s=cam.period_samples / fs,
                        period_min_s=float(cam.periods.min()) / fs, period_max_s=float(cam.periods.max()) / fs,
                        irregular_revolutions=cam.n_irregular, irregular_tolerance=speed.IRREGULAR,
                        law=program.segments[0].law.name, mechanism=mech.name,
                        autocorrelation_period_s=period_est / fs if period_est else None,
                        search_rpm=[search.rpm_lo, search.rpm_hi] if search else None,
                        search_reason=search.why if search else None, search_averaged_samples=q if search else None,
                        cam_speed_rpm_min=cam.rpm_min, cam_speed_rpm_max=cam.rpm_max, cam_speed_trend=cam.drift,
                        assumption=assumption))
    return {"by_segment": marks_by_seg, "vmin": vmin, "vmax": vmax, "method": method}, cam


def _stated(rpm) -> bool:
    return bool(rpm and math.isfinite(rpm) and rpm > 0)


def _rpm_hint(rec, opts):
    """The stated cam speed (rpm): --rpm, else the recording's (NaN when it states none)."""
    return opts.cam_speed_rpm if opts.cam_speed_rpm else rec.cam_speed_rpm


def _check_two_revolutions(rec, segs, rpm_hint, opts) -> None:
    """When no revolutions were found: a recording whose longest contiguous stretch holds fewer than
    two revolutions at the stated speed is refused saying so (the cause, not its symptoms)."""
    if not (rpm_hint and math.isfinite(rpm_hint) and rpm_hint > 0):
        return
    longest = max(b - a for a, b in segs) / rec.sample_rate_hz
    need = 2.0 * 60.0 / rpm_hint
    if longest < need:
        where = "--rpm" if opts.cam_speed_rpm else "the recording's cam_speed_rpm"
        raise InputError(f"{shown(rec.source)}: its longest contiguous stretch lasts {longest:.3g} s, "
                         f"{longest / need * 2:.2g} revolutions at the stated {rpm_hint:g} rpm ({where}); processing "
                         f"needs two whole revolutions: record at least {math.ceil(need * 1.25):g} s at this speed")


def _design(rec, opts, ka, cam, mech, program) -> Chain:
    """Filter, margins, tables: fixed before pass 2, each step's record made from what it uses."""
    fs = rec.sample_rate_hz
    cutoff = opts.lowpass_hz or filters.lowpass_cutoff_hz(cam.rpm, fs, opts.harmonics)
    sos = filters.lowpass_sos(fs, cutoff, opts.filter_order)
    margin = int(math.ceil(1.3 * 1.25 * cam.period_samples)) + filters.settle_samples(sos) + 8
    steps = [H.Lowpass(kind="butterworth", order=opts.filter_order, cutoff_hz=cutoff, zero_phase=True,
                       rule=f"{opts.harmonics:g} x cam frequency, at most 0.4 fs" if not opts.lowpass_hz else "given",
                       chunk_samples=int(opts.chunk_samples), overlap_samples=margin)]
    tau = opts.ac_tau_s if opts.ac_tau_s is not None else stated_number(rec.attrs, "ac_coupling_tau_s", rec.source,
                                                                         "--ac-tau")
    if tau is not None and not (math.isfinite(tau) and tau > 0):
        raise InputError(f"AC-coupling time constant {tau!r} s must be a positive number")
    if tau and tau <= 1.0 / (math.pi * fs):
        # corner 1/(2 pi tau) at or above Nyquist: such a coupling removed all it sampled, and
        # undoing it divides by fs tau (1e-300 s wrote omega2 = inf with exit 0)
        raise InputError(f"AC-coupling time constant {tau:g} s puts the coupling's corner at "
                         f"{1.0 / (2.0 * math.pi * tau):.3g} Hz, at or above half the sample rate ({fs / 2:g} Hz): "
                         f"nothing sampled would be left (--ac-tau, s)")
    if tau:
        steps.append(H.UndoAcCoupling(tau_s=tau))
    tables = KinematicTables(mech, program)
    dwell = H.DwellReference(middle_fraction=follower.DWELL_MIDDLE, min_dwell_samples=follower.DWELL_MIN_LEN)
    omega = H.Omega2(dwell_margin_deg=opts.dwell_margin_deg,
                     dwell_margin_samples=max(1, int(round(opts.dwell_margin_deg / 360.0 * cam.period_samples))))
    steps += [H.RemoveGravity(g_m_s2=mech.g, table_points=tables.N), dwell, H.Epsilon2(DE_m=mech.DE), omega]
    return Chain(fs=fs, ka=ka, sos=sos, zi=filters.sosfilt_zi(sos), padlen=filters.padlen(sos), margin=margin,
                 tables=tables, dwell=dwell, omega=omega, DE=mech.DE, tau=tau, steps=steps)


AC_BEND = 10.0   # a stated AC-coupling corner within this factor of the cam frequency bends the motion


def _say_ac_coupling(rec, chain, cam, warn) -> None:
    """A chain's AC coupling (the recording's ``highpass_hz``, first order) not undone and within
    AC_BEND of the cam frequency: said, with the --ac-tau that undoes it (on the simulated stand at
    30 rpm, 0.1 Hz: omega2 2.8 % and epsilon2 14 % off; undone 0.2 % and 0.8 %)."""
    hp = _float_attr(rec.attrs.get("highpass_hz"))
    f1 = cam.rpm / 60.0
    if chain.tau or not (hp and math.isfinite(hp) and hp > 0) or f1 >= AC_BEND * hp:
        return
    warn(f"the chain's AC coupling (highpass_hz = {hp:g} Hz, the recording states) lies within a factor "
         f"{AC_BEND:g} of the cam frequency {f1:.3g} Hz and bends the motion: give --ac-tau {1 / (2 * math.pi * hp):.3g} "
         "(s) to undo it" + (" (below the corner little is left to undo: record with a DC-coupled chain)"
                             if f1 < hp else ""))


@dataclasses.dataclass
class PassState:
    """The accumulators of pass 2."""
    welch: spectra.WelchAccumulator
    cycles: cycles.CycleAccumulator
    spikes: SpikeCollector
    normal: NormalCheck
    clip: ClipCounter
    time: "TimeAxis"


def _pass2(rec, segs, marks, cam, chain, opts, out, warn, progress) -> PassState:
    """Every chunk of every segment through the chain; outputs written, accumulators fed."""
    fs = chain.fs
    cols = np.array([rec.channel_index("aE_t"), rec.channel_index("aE_n")], dtype=np.int64)
    adc = _float_attr(rec.attrs.get("adc_range_v"))
    bits = _float_attr(rec.attrs.get("adc_bits")) or 16
    # the ADC's rails, when the recording states its range (the simulated stand and the recorder do)
    rail = adc - 2.5 * (2 * adc / 2**bits) if adc and adc > 0 else None
    lsb = 2 * adc / 2**bits if rail else None
    st = PassState(welch=spectra.WelchAccumulator(fs, spectra.default_nperseg(fs, max(b - a for a, b in segs)), 2),
                   cycles=cycles.CycleAccumulator(CYCLE_NAMES, opts.grid_points),
                   spikes=SpikeCollector(fs, opts.spike_k_sigma), normal=NormalCheck(),
                   clip=ClipCounter(rail, rec.clip_indices(), lsb), time=TimeAxis(rec, warn))
    lo, hi = marks["vmin"][cols], marks["vmax"][cols]
    # samples checked finite by pass 1 (_scan): read as stored into the workspace, reused by every window
    ws = Workspace(min(opts.chunk_samples + 2 * chain.margin, rec.n_samples), chain.padlen, rec.n_channels,
                   rec.raw_dtype)
    core = CoreBlock(min(opts.chunk_samples, rec.n_samples))
    rev_offset = 0
    for iseg, ((a_seg, b_seg), m, irregular) in enumerate(zip(segs, marks["by_segment"], cam.irregular_by_segment)):
        st.welch.reset_continuity()
        if len(m) < 2:
            warn(f"segment {iseg} (samples {a_seg}..{b_seg}) holds fewer than two revolution marks; "
                 "its outputs are NaN")
        for a in range(a_seg, b_seg, opts.chunk_samples):
            b = min(a + opts.chunk_samples, b_seg)
            wa, wb = max(a_seg, a - chain.margin), min(b_seg, b + chain.margin)
            w = ws.window(wb - wa)
            block = rec.read_unchecked(wa, wb, ws.block)
            c0, c1 = a - wa, b - wa
            clipped = st.clip.mask(block, cols, lo, hi, wa, wb, w["clipped"])
            st.clip.count(clipped[c0:c1])
            kernels.scaled_columns(block, cols, chain.ka, w["phys"])
            st.welch.feed(w["phys"][c0:c1], clipped[c0:c1])
            t_first = float(a + st.time.lost_before(a))
            if len(m) >= 2:
                res = _process_window(w, ws.ext, wa, m, cam.period_samples, chain, irregular)
                st.spikes.feed(w["phys"], res["lowpassed"], clipped, wa, c0, c1, w["mag"])
                _add_cycles(st.cycles, res, clipped, m, a, b, wa, wb - wa)
                kernels.core_outputs(res["acc"], res["epsilon2"], res["omega2"], res["phi1"], res["revolution"],
                                     res["omega2_abs_from_aE_n"], res["moving"], clipped, c0, c1, rev_offset,
                                     t_first, fs, core.floats, core.revolution, core.clipped, core.time,
                                     st.normal.sums)
            else:
                core.unusable(b - a)
                core.clipped[:b - a] = clipped[c0:c1]
                core.time[:b - a] = (t_first + np.arange(b - a)) / fs
            out.write_block(a, b, core.arrays(b - a))
            progress(b - a)
        rev_offset += len(m)
    return st


def _process_window(w: dict, ext, wa, marks, period, chain: Chain, irregular) -> dict:
    """The chain on one window of one segment (samples wa.. of the recording), compiled kernels
    writing into the workspace's views ``w`` (phys and clipped filled; ext the filter's scratch).

    Defined by the pure functions it fuses: filters.zero_phase, cam_angle.phi1_from_marks,
    sensor_point.gravity_reading (tabulated), follower.dwell_baseline, follower.integrate_motion,
    sensor_point.omega2_abs_from_normal (tests/test_proc_kernels.py checks the equality).
    """
    phys, lp, n = w["phys"], w["lp"], len(w["phys"])
    kernels.sosfiltfilt_into(chain.sos, chain.zi, phys, min(chain.padlen, n - 1), ext, lp)
    if chain.tau:
        # inverse of the first-order high-pass; the integration constant and the ramp an offset
        # makes are constant/linear, and the dwell reference below removes both
        lp += np.cumsum(lp - lp[0], axis=0) / (chain.fs * chain.tau)
    kernels.phi1_from_marks_into(wa, n, marks, float(period), w["phi1"], w["rev"])
    t = chain.tables
    kernels.follower_chain_into(
        lp, w["phi1"], w["rev"], irregular.astype(np.bool_), w["clipped"], t.gravity, t.moving, chain.DE, chain.fs,
        chain.dwell.middle_fraction, chain.dwell.min_dwell_samples, chain.omega.dwell_margin_samples,
        w["acc"], w["moving"], w["bad"], w["eps"], w["omega"], w["absn"], w["starts"], w["stops"])
    acc = w["acc"]
    return {"acc": acc, "aE_t": acc[:, 0], "aE_n": acc[:, 1], "epsilon2": w["eps"], "omega2": w["omega"],
            "omega2_abs_from_aE_n": w["absn"], "phi1": w["phi1"], "revolution": w["rev"], "moving": w["moving"],
            "lowpassed": lp}


def _finish(rec, segs, marks, cam, chain, opts, st: PassState, program, law, cal, hist, out, warn) -> dict:
    """History of the accumulated steps, the small outputs, the global attributes."""
    if rec.n_samples and st.clip.flagged >= rec.n_samples:
        # an all-NaN measured.nc with exit 0 said only "0 revolutions averaged" and a warning
        raise InputError(f"{shown(rec.source)}: every one of its {rec.n_samples} samples is flagged as clipped (at "
                         "the ADC's rails, or held at a channel's extreme value, as a channel spanning only a few "
                         "ADC levels is): nothing is left to process; check the chain's gain and range (Ka, the "
                         "conditioner, the ADC range)")
    if st.clip.flagged:
        warn(f"{st.clip.flagged} clipped samples flagged and kept out of the estimates")
    if st.cycles.count == 0 and st.cycles.rejected:
        warn(f"no revolution averaged: each of the {st.cycles.rejected} whole revolutions holds a clipped or irregular "
             "sample, so the cycle statistics are empty and report and fit cannot use this file; if they are clipped, "
             f"{LARGER_RANGE}")
    hist.add(H.TimeAxis(samples_lost=st.time.samples_lost, gaps_with_unknown_loss=st.time.unknown))
    hist.add(H.Clipping(flagged_samples=st.clip.flagged, recorder_clip_events=int(len(st.clip.events)),
                        rail_v=st.clip.rail_v, min_run_at_extreme=ClipCounter.MIN_RUN))
    hist.add(H.CheckNormal(value=st.normal.value))
    hist.add(H.CycleAverage(grid_points=opts.grid_points, revolutions_used=st.cycles.count,
                            revolutions_rejected=st.cycles.rejected))
    hist.add(H.Spectra(window="hann", nperseg=st.welch.nperseg, overlap=0.5, segments=st.welch.count,
                       segments_skipped_clipped=st.welch.skipped))
    hist.add(H.Spikes(k_sigma=opts.spike_k_sigma, floor_fraction=events.DEFAULT_FLOOR_FRACTION,
                      refractory_s=events.DEFAULT_REFRACTORY_S, count=st.spikes.seen, stored=st.spikes.stored))
    if st.spikes.seen > st.spikes.stored:
        warn(f"{st.spikes.seen} spikes found; only the first {st.spikes.stored} are stored")
    _write_small(out, rec, st, marks["by_segment"], program, cam.rpm, segs)
    return _global_attrs(rec, marks["method"], cam, chain, st, program, cal, hist, len(segs), law, opts)


def _global_attrs(rec, method, cam, chain, st, program, cal, hist, n_segs, law, opts) -> dict:
    """Numbers as numbers; an unknown value is left out, never written as text."""
    lp = hist.find(H.Lowpass)
    check = hist.find(H.CheckChannels)
    # CF 'source' (method of production): "recording", the word reports/ reads to tell a measurement
    # from a synthetic one; the file and the command are in source_file and history
    attrs = cf.global_attrs("labtool measured follower motion", source="recording",
                            history=command_line(f"labtool.process({shown(rec.source)!r})"))
    values = {
        "source_file": shown(rec.source), "source_format": rec.format, "start_time_utc": rec.start_time_utc,
        "recording_complete": int(rec.complete), "sample_rate_hz": chain.fs, "cam_speed_rpm_measured": cam.rpm,
        "phi1_method": method, "lowpass_hz": lp.cutoff_hz, "DE_m": chain.DE,
        "cam_speed_rpm_min": cam.rpm_min, "cam_speed_rpm_max": cam.rpm_max, "cam_speed_drift": cam.drift,
        "channel_check": check.verdict, "channel_check_finding": check.finding,
        "channels_inverted": " ".join(check.inverted),
        "omega2_normal_check_rel_rms": st.normal.value, "n_revolutions_averaged": st.cycles.count,
        "n_clipped_samples": st.clip.flagged, "n_segments": n_segs, "n_spikes": st.spikes.seen,
        "n_samples_lost": st.time.samples_lost, H.ATTRIBUTE: hist.to_json(),
    }
    for name in ("aE_t", "aE_n"):
        values[f"ka_{name}_m_s2_per_v"] = cal[name]["ka_m_s2_per_v"]
        values[f"ka_{name}_uncertainty_m_s2_per_v"] = cal[name]["uncertainty_m_s2_per_v"]
        values[f"ka_source_{name}"] = cal[name]["source"]
    # the run's operating point (with its sources), metadata and headroom, as the recording states them;
    # the nominal speed and the law as processing took them (a stated 0 or NaN speed is no speed)
    values.update({k: rec.attrs[k] for k in recording_attrs.carried() if k in rec.attrs and k not in values})
    if math.isfinite(rec.cam_speed_rpm) and rec.cam_speed_rpm > 0:
        values["cam_speed_rpm"] = float(rec.cam_speed_rpm)
    else:
        values.pop("cam_speed_rpm", None)
        values.pop("cam_speed_rpm_source", None)
    if law is not None:
        values["law"] = program.segments[0].law.name
        values["law_source"] = ("option --law of labtool process" if law == opts.law else
                                rec.attrs.get("law_source", "the recording"))
    for k, v in values.items():
        if v is None or v == "" or (isinstance(v, float) and not math.isfinite(v)):
            continue
        attrs[k] = v
    return attrs


class TimeAxis:
    """Time (s from the first sample) of recording rows, counting the samples lost at gaps."""

    def __init__(self, rec, warn):
        rows, lost, self.unknown = rec.lost_samples()
        self.rows, self.fs = rows, rec.sample_rate_hz
        self.cum = np.concatenate([[0], np.cumsum(lost)])
        self.samples_lost = int(lost.sum())
        if self.unknown:
            warn(f"{self.unknown} gap/overrun events do not say how many samples were lost; after them the time "
                 "axis runs on the sample clock (the segments still split there)")

    def lost_before(self, row: int) -> int:
        """Samples lost before ``row`` (at the gaps up to and including it): constant over a segment."""
        return int(self.cum[np.searchsorted(self.rows, row, side="right")])

    def seconds(self, rows) -> np.ndarray:
        rows = np.asarray(rows, dtype=float)
        return (rows + self.cum[np.searchsorted(self.rows, rows, side="right")]) / self.fs


def _find_marks(rec, segs, method, itacho, ka_t, chunk, mech, program, rpm_hint, warn, progress):
    """Pass 1: revolution marks per segment (tacho edges or matched filter) and channel extremes."""
    fs = rec.sample_rate_hz
    it = rec.channel_index("aE_t")
    vmin = np.full(rec.n_channels, np.inf)
    vmax = np.full(rec.n_channels, -np.inf)
    period_est, q, search = None, 1, None
    if method == "correlation":
        period_est, q, search = cam_angle.period_by_correlation(rec, segs, it, rpm_hint, mech, chunk)
        if rpm_hint and math.isfinite(rpm_hint) and abs(period_est / (fs * 60.0 / rpm_hint) - 1) > 0.2:
            warn(f"cam speed from the data ({60 * fs / period_est:.1f} rpm) differs from the stated "
                 f"{rpm_hint:g} rpm by more than 20 %; using the data")
    marks_by_seg = []
    buf = np.empty((min(chunk, rec.n_samples), rec.n_channels), dtype=rec.raw_dtype)
    for a_seg, b_seg in segs:
        marks = []
        if method == "tacho":
            det = cam_angle.CompiledTachoEdges()
            for a in range(a_seg, b_seg, chunk):
                block = rec.read_unchecked(a, min(a + chunk, b_seg), buf)
                _scan(rec, block, a, vmin, vmax)
                marks.extend(det.feed(a, block[:, itacho]))
                progress(len(block))
        else:
            corr = cam_angle.CorrelationEdges(mech, program, period_est, fs, q)
            for a in range(a_seg, b_seg, chunk):
                b = min(a + chunk, b_seg)
                block = rec.read(a, min(b + corr.span, b_seg))
                _scan(rec, block[: b - a], a, vmin, vmax)
                marks.extend(corr.feed(a, block[:, it] * ka_t, a, b))
                corr.retune(marks)          # a drifting speed: the template follows the latest revolutions
                progress(b - a)
        marks_by_seg.append(np.asarray(marks, dtype=float))
    return marks_by_seg, vmin, vmax, period_est, (search, q)


def _scan(rec: Recording, block, first: int, vmin, vmax) -> None:
    """Extremes of every channel; every sample checked finite (pass 2 reads unchecked after this)."""
    if kernels.scan_block(block, vmin, vmax) >= 0 or max(-vmin.min(), vmax.max()) > MAX_SAMPLE:
        check_finite(np.asarray(block, dtype=float), first, rec.channel_names, rec.source)


def _add_cycles(cyc, res, clipped, marks, a, b, wa, n) -> None:
    """Resample every complete revolution starting in [a, b) on the phi1 grid (kernels.resample_cycles)
    and add them to the cycle statistics.

    phi1 is linear in the sample index within a revolution, so linear interpolation in the sample
    index at m_k + (phi/2 pi)(m_{k+1} - m_k) is linear interpolation in phi1.
    """
    k = np.flatnonzero((marks[:-1] >= a) & (marks[:-1] < b))
    if len(k) == 0:
        return
    rows = np.empty((len(k), len(cyc.names), cyc.grid.size))
    used, rejected = kernels.resample_cycles(res["acc"], res["epsilon2"], res["omega2"], res["omega2_abs_from_aE_n"],
                                             clipped, marks[k] - wa, marks[k + 1] - wa, cyc.grid / (2.0 * math.pi),
                                             rows)
    cyc.add_rows(rows[:used])
    cyc.rejected += rejected


class KinematicTables:
    """psi-dependent quantities tabulated over one revolution (2^16 points, 0.1 mrad): gravity
    reading and cam phase direction, looked up per sample instead of evaluating the law."""

    N = 1 << 16

    def __init__(self, mech, program):
        grid = 2.0 * math.pi * np.arange(self.N) / self.N
        psi = program(grid)[0]
        gt, gn = sensor_point.gravity_reading(mech.phiD + mech.psi0 + psi, mech.g)
        self.gravity = np.ascontiguousarray(np.column_stack([gt, gn]))
        self.moving = program.direction(grid) != 0

    def index(self, phi1):
        k = (phi1 * (self.N / (2.0 * math.pi)) + 0.5).astype(np.int64)
        return k & (self.N - 1)


def _float_attr(v):
    try:
        return float(np.asarray(v).reshape(-1)[0]) if v is not None else None
    except (TypeError, ValueError):
        return None


def _write_small(out: MeasuredWriter, rec, st: PassState, rev_marks, program, rpm, segments) -> None:
    """Spectra, cycle statistics, segments, spikes, revolution marks (each on its dimension)."""
    welch, cyc = st.welch, st.cycles
    amp, psd = welch.amplitude(), welch.psd()
    out.dimension("frequency", welch.frequency, "Hz", "frequency")
    for j, name in enumerate(("aE_t", "aE_n")):
        out.variable(f"{name}_amplitude", "frequency", amp[:, j], "m/s^2",
                     f"amplitude spectrum of {name} (Ka applied, offset removed)")
        out.variable(f"{name}_psd", "frequency", psd[:, j], "(m/s^2)^2/Hz", f"Welch power spectral density of {name}")
    out.dimension("phi1_grid", cyc.grid, "rad", "cam angle of the cycle-average grid")
    units = {"aE_t": "m/s^2", "aE_n": "m/s^2", "epsilon2": "rad/s^2", "omega2": "rad/s", "omega2_abs_from_aE_n": "rad/s"}
    for k, v in cyc.result().items():
        base, what = k.rsplit("_", 1)
        label = "mean over revolutions" if what == "mean" else "standard deviation over revolutions"
        desc = "|omega2| from the normal acceleration, sqrt(aE_n / DE)" if base == "omega2_abs_from_aE_n" else base
        out.variable(k, "phi1_grid", v, units[base], f"{desc}, {label}")
    omega1 = rpm * 2 * math.pi / 60.0
    _, dpsi, ddpsi, _ = program(cyc.grid)
    out.variable("omega2_kinematic", "phi1_grid", dpsi * omega1, "rad/s",
                 "omega2 of the ideal kinematics at the measured mean cam speed")
    out.variable("epsilon2_kinematic", "phi1_grid", ddpsi * omega1**2, "rad/s^2",
                 "epsilon2 of the ideal kinematics at the measured mean cam speed")
    out.dimension("segment", np.arange(len(segments)), "1", "contiguous segment index")
    out.variable("segment_start", "segment", np.array([a for a, _ in segments]), "1", "first sample of the contiguous segment")
    out.variable("segment_stop", "segment", np.array([b for _, b in segments]), "1", "one past the last sample of the segment")
    _write_spikes(out, st, rev_marks, program)
    all_marks = np.concatenate(rev_marks) if rev_marks else np.empty(0)
    out.dimension("revolution_mark", np.arange(len(all_marks)), "1", "revolution mark index")
    out.variable("revolution_start_time", "revolution_mark", st.time.seconds(all_marks), "s",
                 "time of the revolution mark (phi1 = 0) from the first sample")
    per = np.concatenate([np.append(np.diff(m), np.nan) for m in rev_marks if len(m)] or [np.empty(0)])
    out.variable("revolution_omega1", "revolution_mark", 2 * math.pi * st.time.fs / per if len(per) else per, "rad/s",
                 "mean cam angular velocity over the revolution (NaN for the last of a segment)")


def _write_spikes(out: MeasuredWriter, st: PassState, rev_marks, program) -> None:
    si, ch, amp, thr = st.spikes.sorted()
    all_marks = np.concatenate(rev_marks) if rev_marks else np.empty(0)
    ph = np.full(len(si), np.nan)
    if len(all_marks) and len(si):
        k = np.searchsorted(all_marks, si, side="right") - 1
        nxt = np.clip(k + 1, 0, len(all_marks) - 1)
        ok = (k >= 0) & (nxt > k)
        ph[ok] = np.mod(2 * math.pi * (si[ok] - all_marks[k[ok]]) / (all_marks[nxt[ok]] - all_marks[k[ok]]), 2 * math.pi)
    d = program.direction(np.nan_to_num(ph)) if len(si) else np.empty(0)
    phase = np.where(np.isfinite(ph), np.where(d > 0, "rise", np.where(d < 0, "return", "dwell")), "unknown")
    out.dimension("spike", np.arange(len(si)), "1", "spike index")
    out.variable("spike_time", "spike", st.time.seconds(si), "s", "time of the spike peak from the first sample")
    out.variable("spike_sample", "spike", si, "1", "sample index of the spike peak")
    out.variable("spike_channel", "spike", ch.astype(str), "", "channel of the spike")
    out.variable("spike_amplitude", "spike", amp, "m/s^2", "peak of the acceleration above the processing band")
    out.variable("spike_threshold", "spike", thr, "m/s^2", "detection threshold in force at the spike")
    out.variable("spike_phi1", "spike", ph, "rad", "cam angle at the spike")
    out.variable("spike_phase", "spike", phase.astype(str), "", "cam phase at the spike: rise, return, dwell")
