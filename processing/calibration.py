"""Calibration: Ka (m/s^2 per V) of channels from recordings of a reference sine excitation.

The paper calibrates on a B&K 4291 exciter giving 9.81 m/s^2 at 79.6 Hz (sec. 2.4) and finds
Ka = 86.43 m/s^2/V. Here the recorded volts are fitted, by least squares, with
``v(t) = a sin(2 pi f t) + b cos(2 pi f t) + c0 + c1 t`` where the frequency f is refined too
(Gauss-Newton via scipy.optimize.least_squares, started from the largest FFT peak within 10 % of the
nominal frequency). The voltage amplitude is V = hypot(a, b) (peak) and

    Ka = A_peak / V_peak,   A_peak = reference accel        (convention "peak")
                            A_peak = reference accel * sqrt(2)  (convention "rms")

Its standard uncertainty is the fit's (residual variance x (J^T J)^-1, propagated to V; white
residuals assumed) combined in quadrature with the reference's own relative uncertainty if given.
Times are row / sample rate, shifted after each gap by the samples it says are missing (the fit
spans gaps with the true time).

A reference that is not a clean sine in volts is refused, never fitted: samples at the ADC's
rails or a flat top (clipping), harmonics above 5 % of the fundamental (an overdriven exciter or
chain), integer samples (raw ADC counts, not volts), no sine standing out of the noise.

Several fits of one channel (several reference recordings) are merged: the inverse-variance
weighted mean of the Ka, its fit uncertainty scaled by the Birge ratio when the fits scatter more
than their uncertainties say, then combined with the exciter's uncertainty (common to all the
fits, so not averaged down).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import optimize

from labtool.common.errors import FileFormatError, InputError
from labtool.common.names import shown, utf8_text
from labtool.processing.readers.base import stated_number

MAX_FIT_SAMPLES = 2_000_000     # 200 s at 10 kHz: more adds nothing to a sine fit but memory
MAX_HARMONIC_DISTORTION = 0.05  # (2f, 3f) / fundamental above which the reference is not a clean sine
FLAT_TOP_FRACTION = 0.02        # share of samples at one extreme value that means a clipped sine


@dataclasses.dataclass(frozen=True)
class SineFit:
    """Least-squares sine fit: amplitude (peak, signal units), frequency (Hz), their std, residual rms,
    harmonic distortion (amplitudes at 2f and 3f over the fundamental's, root sum square)."""

    amplitude: float
    amplitude_std: float
    freq_hz: float
    freq_std_hz: float
    phase_rad: float
    offset: float
    residual_rms: float
    n: int
    harmonic_distortion: float = 0.0


def _start_frequency(x, rate_hz, freq_hz, search, where) -> float:
    """Largest zero-padded Hann FFT peak within +-search of the nominal frequency (Hz)."""
    nfft = 1 << int(math.ceil(math.log2(max(4 * x.size, 1 << 16))))
    nfft = min(nfft, 1 << 23)
    spec = np.abs(np.fft.rfft((x - x.mean()) * np.hanning(x.size), nfft))
    freqs = np.fft.rfftfreq(nfft, 1.0 / rate_hz)
    band = (freqs > freq_hz * (1 - search)) & (freqs < freq_hz * (1 + search))
    if not band.any():
        raise InputError(f"{where}: no spectral line near {freq_hz:g} Hz")
    peak, floor = spec[band].max(), np.median(spec[1:])
    if not (peak > 20 * floor and peak > 0):
        raise InputError(f"{where}: no sine near {freq_hz:g} Hz stands out of the noise "
                         "(wrong channel or wrong --reference-freq?)")
    return float(freqs[band][np.argmax(spec[band])])


def fit_sine(x, rate_hz: float, freq_hz: float, t=None, search: float = 0.10, where: str = "calibration") -> SineFit:
    """Fit a sine near ``freq_hz`` (Hz) to samples x taken at ``rate_hz`` (or at times t, s).

    InputError (its message starting with ``where``) when there is nothing sinusoidal near freq_hz."""
    x = np.asarray(x, dtype=float)
    t = np.arange(x.size) / rate_hz if t is None else np.asarray(t, dtype=float)
    ok = np.isfinite(x)
    x, t = x[ok], t[ok]
    if x.size < 64:
        raise InputError(f"{where}: fewer than 64 valid samples to fit")
    if not (0 < freq_hz < 0.5 * rate_hz):
        raise InputError(f"{where}: reference frequency {freq_hz:g} Hz is not below Nyquist ({0.5 * rate_hz:g} Hz)")
    duration = t[-1] - t[0]
    if duration * freq_hz < 5:
        raise InputError(f"{where}: the recording holds {duration * freq_hz:.1f} periods of {freq_hz:g} Hz; record at least 5")
    tc = t - t.mean()  # centred time: phase and frequency decorrelate
    f0 = _start_frequency(x, rate_hz, freq_hz, search, where)

    def design(f):
        w = 2 * np.pi * f * tc
        return np.column_stack([np.sin(w), np.cos(w), np.ones_like(tc), tc])

    lin = np.linalg.lstsq(design(f0), x, rcond=None)[0]
    p0 = np.concatenate([lin, [f0]])

    def resid(p):
        return design(p[4]) @ p[:4] - x

    def jac(p):
        a, b = p[0], p[1]
        w = 2 * np.pi * p[4] * tc
        dfreq = 2 * np.pi * tc * (a * np.cos(w) - b * np.sin(w))
        return np.column_stack([design(p[4]), dfreq])

    sol = optimize.least_squares(resid, p0, jac=jac, method="lm", x_scale="jac")
    p, r = sol.x, sol.fun
    s2 = float(r @ r) / max(1, x.size - p.size)
    cov = np.linalg.pinv(sol.jac.T @ sol.jac) * s2
    a, b = p[0], p[1]
    A = math.hypot(a, b)
    rms = math.sqrt(float(r @ r) / x.size)
    if A == 0:
        raise InputError(f"{where}: fitted amplitude is zero")
    if rms > 0.5 * A:  # the sine must dominate the residual
        raise InputError(f"{where}: not a clean sine near {freq_hz:g} Hz (residual {rms:.3g} V rms vs amplitude "
                         f"{A:.3g} V): is it the reference recording and the channel on the exciter?")
    g = np.array([a / A, b / A])
    varA = float(g @ cov[:2, :2] @ g)
    return SineFit(amplitude=A, amplitude_std=math.sqrt(max(varA, 0.0)), freq_hz=float(p[4]),
                   freq_std_hz=math.sqrt(max(cov[4, 4], 0.0)), phase_rad=math.atan2(b, a), offset=float(p[2]),
                   residual_rms=rms, n=int(x.size), harmonic_distortion=_harmonics(r, tc, float(p[4])) / A)


def _harmonics(residual, tc, f) -> float:
    """Root-sum-square amplitude of the residual's components at 2f and 3f (same units as it)."""
    w = 2 * np.pi * f * tc
    basis = np.column_stack([np.sin(2 * w), np.cos(2 * w), np.sin(3 * w), np.cos(3 * w)])
    c = np.linalg.lstsq(basis, residual, rcond=None)[0]
    return math.hypot(math.hypot(c[0], c[1]), math.hypot(c[2], c[3]))


def check_volts(x: np.ndarray, where: str, adc_range_v: float | None = None) -> None:
    """Refuse samples that cannot be a clean reference sine in volts (InputError naming ``where``):
    raw integer ADC counts, samples at the ADC's rails, a flat top or bottom (clipping).

    A flat top is a share of the samples at the extreme value larger than 2 % plus twice what the
    quantisation explains (a sine of amplitude A sampled with step q stays within q of its peak for
    acos(1 - q/A)/pi of a period: 7 % for the 480C02 at gain x1, 0.0113 V on a 16-bit +-10 V ADC)."""
    x = x[np.isfinite(x)]
    if x.size == 0:
        raise InputError(f"{where}: no finite samples")
    top, bottom = float(x.max()), float(x.min())
    peak = max(abs(top), abs(bottom))
    if peak > 50 and np.all(x == np.round(x)):
        raise InputError(f"{where}: every sample is an integer (up to {peak:g}): these are raw ADC counts, "
                         "not volts; give the recording in volts (or with its scaling)")
    if peak > 1000:
        raise InputError(f"{where}: samples reach {peak:g}, which is not a voltage from an accelerometer chain; "
                         "give the recording in volts")
    if adc_range_v is not None and math.isfinite(adc_range_v) and adc_range_v > 0 and peak >= 0.995 * adc_range_v:
        raise InputError(f"{where}: the reference sine is clipped (samples reach {peak:.4g} V of the ADC's "
                         f"+-{adc_range_v:g} V range): lower the exciter level or the conditioner gain and record again")
    span = top - bottom
    levels = np.unique(x)
    steps = np.diff(levels)
    q = float(steps.min()) if steps.size else 0.0       # the quantisation step (0 for unquantised data)
    tol = max(1e-4 * span, 0.5 * q)
    # a clean quantised sine stays within one step of its extreme for acos(1 - q/A)/pi of a period
    amp = 0.5 * span
    quantised = math.acos(max(-1.0, 1.0 - (q + tol) / amp)) / math.pi if amp > 0 else 1.0
    limit = max(FLAT_TOP_FRACTION, 2.0 * quantised + FLAT_TOP_FRACTION)
    for value, side in ((top, "top"), (bottom, "bottom")):
        share = float(np.mean(np.abs(x - value) <= tol)) if span > 0 else 1.0
        if share >= limit:
            raise InputError(f"{where}: the reference sine is clipped ({100 * share:.1f} % of the samples sit at its "
                             f"{side}, {value:.4g} V): lower the exciter level or the conditioner gain and record again")


def check_distortion(fit: SineFit, where: str) -> None:
    if fit.harmonic_distortion > MAX_HARMONIC_DISTORTION:
        raise InputError(f"{where}: the reference is not a clean sine (harmonics at 2f and 3f are "
                         f"{100 * fit.harmonic_distortion:.1f} % of the fundamental, more than "
                         f"{100 * MAX_HARMONIC_DISTORTION:g} %): clipped or overdriven chain?")


# --------------------------------------------------------------------------- Ka from a fit

@dataclasses.dataclass(frozen=True)
class ReferenceSpec:
    """The exciter: acceleration (m/s^2, peak or rms), frequency (Hz), relative standard uncertainty."""
    accel_m_s2: float = 9.81
    freq_hz: float = 79.6
    convention: str = "peak"
    rel_uncertainty: float = 0.0

    def __post_init__(self):
        if self.convention not in ("peak", "rms"):
            raise InputError(f"convention must be 'peak' or 'rms', got {shown(self.convention)!r}")
        if not (math.isfinite(self.accel_m_s2) and self.accel_m_s2 > 0):
            raise InputError(f"reference acceleration must be > 0 m/s^2, got {self.accel_m_s2}")
        if not (math.isfinite(self.freq_hz) and self.freq_hz > 0):
            raise InputError(f"reference frequency must be > 0 Hz, got {self.freq_hz}")
        if not (math.isfinite(self.rel_uncertainty) and 0 <= self.rel_uncertainty < 1):
            raise InputError("reference uncertainty must be a fraction in [0, 1)")

    @property
    def peak_m_s2(self) -> float:
        return self.accel_m_s2 * (math.sqrt(2.0) if self.convention == "rms" else 1.0)

    def as_dict(self) -> dict:
        return {"accel_m_s2": self.accel_m_s2, "convention": self.convention, "freq_hz": self.freq_hz,
                "rel_uncertainty": self.rel_uncertainty}


def ka_from_fit(fit: SineFit, reference_accel: float, convention: str = "peak", reference_rel_uncertainty: float = 0.0):
    """Ka (m/s^2/V), its fit standard uncertainty and its combined one, from a fit of the volts."""
    ref = ReferenceSpec(reference_accel, 1.0, convention, reference_rel_uncertainty)
    ka = ref.peak_m_s2 / fit.amplitude
    rel_fit = fit.amplitude_std / fit.amplitude
    return ka, ka * rel_fit, ka * math.hypot(rel_fit, reference_rel_uncertainty)


@dataclasses.dataclass(frozen=True)
class ChannelFit:
    """One channel fitted in one reference recording."""
    channel: str
    source: str
    ka_m_s2_per_v: float
    ka_std_fit_m_s2_per_v: float
    fit: SineFit


@dataclasses.dataclass(frozen=True)
class ChannelResult:
    """One channel's Ka merged over its reference recordings (m/s^2/V)."""
    channel: str
    ka_m_s2_per_v: float
    uncertainty_m_s2_per_v: float     # combined: fit (Birge-scaled) and exciter
    ka_std_fit_m_s2_per_v: float
    birge_ratio: float                # NaN with one fit
    fits: tuple                       # ChannelFit

    def entry(self) -> dict:
        """The channel's table in the calibration file (labtool.processing.calibration_file.ChannelEntry)."""
        f = self.fits[0].fit if len(self.fits) == 1 else None
        out = {"ka_m_s2_per_v": self.ka_m_s2_per_v, "uncertainty_m_s2_per_v": self.uncertainty_m_s2_per_v,
               "ka_std_fit_m_s2_per_v": self.ka_std_fit_m_s2_per_v,
               "n_references": len(self.fits), "source": "; ".join(c.source for c in self.fits),
               "harmonic_distortion": max(c.fit.harmonic_distortion for c in self.fits),
               "n_samples": sum(c.fit.n for c in self.fits)}
        if f is not None:
            out.update(fitted_freq_hz=f.freq_hz, amplitude_v_peak=f.amplitude, residual_rms_v=f.residual_rms)
        if math.isfinite(self.birge_ratio):
            out["birge_ratio"] = self.birge_ratio
        return out


def merge_fits(channel: str, fits, reference: ReferenceSpec) -> ChannelResult:
    """Inverse-variance weighted mean of several fits of one channel (module docstring)."""
    ka = np.array([c.ka_m_s2_per_v for c in fits])
    sd = np.array([c.ka_std_fit_m_s2_per_v for c in fits])
    if len(fits) == 1:
        mean, sd_fit, birge = float(ka[0]), float(sd[0]), math.nan
    else:
        # a fit of a noise-free recording can claim ~0 uncertainty; floor it at 1e-9 relative
        w = 1.0 / np.maximum(sd, 1e-9 * ka) ** 2
        mean = float(np.sum(w * ka) / np.sum(w))
        internal = float(1.0 / math.sqrt(np.sum(w)))
        birge = float(math.sqrt(np.sum(w * (ka - mean) ** 2) / (len(fits) - 1)))
        sd_fit = internal * max(1.0, birge)
    combined = math.hypot(sd_fit, mean * reference.rel_uncertainty)
    return ChannelResult(channel, mean, combined, sd_fit, birge, tuple(fits))


# --------------------------------------------------------------------------- from recordings

def row_times(n: int, rate_hz: float, lost_rows, lost_n) -> np.ndarray:
    """Time (s) of each row: index / rate, shifted after each gap by the samples lost before it."""
    shift = np.zeros(n, dtype=np.int64)
    for row, lost in zip(lost_rows, lost_n):
        shift[int(row):] += int(lost)
    return (np.arange(n) + shift) / rate_hz


def fit_recording_channel(rec, channel: str, reference: ReferenceSpec) -> ChannelFit:
    """Fit ``channel`` of an open recording (labtool.processing.readers.Recording); every error names it."""
    where = f"channel {shown(channel)} of {shown(rec.source)}"
    if not rec.has_channel(channel):
        raise InputError(f"channel {shown(channel)} is not in {shown(rec.source)} "
                         f"(channels: {', '.join(shown(c) for c in rec.channel_names)})")
    j = rec.channel_index(channel)
    lost_rows, lost_n, unknown = rec.lost_samples()
    if unknown:
        raise FileFormatError(f"{where}: {unknown} gap/overrun events do not say how many samples are missing; "
                              "the fit cannot place the samples after them in time")
    n = min(rec.n_samples, MAX_FIT_SAMPLES)
    x = rec.read(0, n)[:, j]
    t = row_times(n, rec.sample_rate_hz, lost_rows[lost_rows < n], lost_n[lost_rows < n])
    # a clip event names its channel first ("aE_t: ..."); one that names no channel of the file counts for all
    clip_rows = [e.index for e in rec.events if e.kind == "clip" and (
        e.detail.split(":")[0].strip() == channel or e.detail.split(":")[0].strip() not in rec.channel_names)]
    if clip_rows:
        raise InputError(f"{where}: the recorder marked {len(clip_rows)} clipped samples (first at row {clip_rows[0]}); "
                         "lower the exciter level or the conditioner gain and record again")
    # the text "10" is 10 V, as process reads it; text that is no number was passed over
    check_volts(x, where, stated_number(rec.attrs, "adc_range_v", rec.source))
    fit = fit_sine(x, rec.sample_rate_hz, reference.freq_hz, t=t, where=where)
    check_distortion(fit, where)
    ka, std_fit, _ = ka_from_fit(fit, reference.accel_m_s2, reference.convention, reference.rel_uncertainty)
    return ChannelFit(channel, utf8_text(rec.source), ka, std_fit, fit)   # a non-UTF-8 byte as \xff (TOML holds text)


def pair_channels(recordings, channels) -> list[tuple[str, str]]:
    """(channel, recording) pairs from ``--channel NAME`` (every recording) or ``NAME=RECORDING``.

    A name may hold '=' itself: the text after the last '=' is a RECORDING only when it is one of
    those given (or looks like a file name, then refused). InputError for a channel given twice for
    the same recording."""
    recordings = [str(r) for r in recordings]
    if not recordings:
        raise InputError("give at least one reference recording")
    if not channels:
        raise InputError("give at least one --channel")
    pairs = []
    for spec in channels:
        spec = str(spec)
        name, rec = spec, None
        if "=" in spec:   # NAME=RECORDING when the text after the last '=' is a recording given
            head, _, tail = spec.rpartition("=")
            matches = [r for r in recordings if r == tail or r.endswith("/" + tail) or tail.endswith("/" + r)]
            if len(matches) == 1:
                name, rec = head, matches[0]
            elif tail.endswith((".h5", ".hdf5", ".tdms", ".csv", ".txt")):
                raise InputError(f"--channel {shown(spec)}: {shown(tail)} is not one of the reference recordings given "
                                 f"({', '.join(shown(r) for r in recordings)})")
        if not name.strip():
            raise InputError(f"--channel {shown(spec)!r}: no channel name")
        for r in ([rec] if rec else recordings):
            if (name, r) in pairs:
                raise InputError(f"channel {shown(name)} of {shown(r)} is given twice")
            pairs.append((name, r))
    return pairs


def calibrate_pairs(pairs, reference: ReferenceSpec, open_recording) -> list[ChannelResult]:
    """Fit every (channel, recording) pair and merge the fits per channel, in the order given.

    ``open_recording(path) -> Recording`` (labtool.processing.readers.open_recording)."""
    fits: dict[str, list[ChannelFit]] = {}
    by_file: dict[str, list[str]] = {}
    for ch, path in pairs:
        by_file.setdefault(path, []).append(ch)
    for path, chans in by_file.items():
        rec = open_recording(path)
        try:
            for ch in chans:
                fits.setdefault(ch, []).append(fit_recording_channel(rec, ch, reference))
        finally:
            rec.close()
    order = list(dict.fromkeys(ch for ch, _ in pairs))
    return [merge_fits(ch, fits[ch], reference) for ch in order]
