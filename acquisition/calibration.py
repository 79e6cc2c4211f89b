"""Calibration: Ka (m/s^2 per V) of a channel from a recording of a reference sine excitation.

The paper calibrates on a B&K 4291 exciter giving 9.81 m/s^2 at 79.6 Hz (sec. 2.4) and finds
Ka = 86.43 m/s^2/V. Here the recorded volts are fitted, by least squares, with
``v(t) = a sin(2 pi f t) + b cos(2 pi f t) + c0 + c1 t`` where the frequency f is refined too
(Gauss-Newton via scipy.optimize.least_squares, started from the largest FFT peak within 10 % of the
nominal frequency). The voltage amplitude is V = hypot(a, b) (peak) and

    Ka = A_peak / V_peak,   A_peak = reference accel        (convention "peak")
                            A_peak = reference accel * sqrt(2)  (convention "rms")

Its standard uncertainty is the fit's (residual variance x (J^T J)^-1, propagated to V; white
residuals assumed) combined in quadrature with the reference's own relative uncertainty if given.
Times are row / sample rate, shifted after each gap event by the samples it says are missing
(the fit spans gaps with the true time); NaN rows are left out.

Calibration file (TOML), read by ``load_calibration`` and by ``labtool process``::

    format = "labtool.calibration"
    format_version = 1
    created_utc = "2026-11-22T04:30:00+00:00"
    source = "sample_data/calibration_79p6Hz.h5"
    [reference]
    accel_m_s2 = 9.81        # as given on the command line
    convention = "peak"      # "peak" or "rms": what accel_m_s2 means
    freq_hz = 79.6           # nominal
    rel_uncertainty = 0.0    # of the exciter, relative, as given
    [channels.aE_t]
    ka_m_s2_per_v = 86.43    # the factor: acceleration = Ka * volts
    uncertainty_m_s2_per_v = 0.01  # standard uncertainty (k = 1), fit and reference combined
    ka_std_fit_m_s2_per_v = 0.01
    fitted_freq_hz = 79.6
    amplitude_v_peak = 0.1135
    residual_rms_v = 0.0006
    n_samples = 20000
"""
from __future__ import annotations

import dataclasses
import datetime as _dt
import math
import tomllib
from pathlib import Path

import numpy as np
from scipy import optimize

from common.errors import FileFormatError, InputError

CAL_FORMAT = "labtool.calibration"
CAL_VERSION = 1


@dataclasses.dataclass(frozen=True)
class SineFit:
    """Least-squares sine fit: amplitude (peak, signal units), frequency (Hz), their std, residual rms."""

    amplitude: float
    amplitude_std: float
    freq_hz: float
    freq_std_hz: float
    phase_rad: float
    offset: float
    residual_rms: float
    n: int


def fit_sine(x, rate_hz: float, freq_hz: float, t=None, search: float = 0.10) -> SineFit:
    """Fit a sine near ``freq_hz`` (Hz) to samples x taken at ``rate_hz`` (or at times t, s).

    InputError when there is nothing sinusoidal near freq_hz (no data, no peak, no signal).
    """
    x = np.asarray(x, dtype=float)
    t = np.arange(x.size) / rate_hz if t is None else np.asarray(t, dtype=float)
    ok = np.isfinite(x)
    x, t = x[ok], t[ok]
    if x.size < 64:
        raise InputError("calibration: fewer than 64 valid samples to fit")
    duration = t[-1] - t[0]
    if duration * freq_hz < 5:
        raise InputError(f"calibration: the recording holds {duration * freq_hz:.1f} periods of {freq_hz:g} Hz; record at least 5")
    if not (0 < freq_hz < 0.5 * rate_hz):
        raise InputError(f"calibration: reference frequency {freq_hz:g} Hz is not below Nyquist ({0.5 * rate_hz:g} Hz)")
    tc = t - t.mean()  # centred time: phase and frequency decorrelate
    # start: FFT peak (zero-padded, Hann) within +-search of the nominal frequency
    nfft = 1 << int(math.ceil(math.log2(max(8 * x.size, 1 << 16))))
    # gaps make t irregular only by missing rows; the FFT start uses the rows as they are
    spec = np.abs(np.fft.rfft((x - x.mean()) * np.hanning(x.size), nfft))
    freqs = np.fft.rfftfreq(nfft, 1.0 / rate_hz)
    band = (freqs > freq_hz * (1 - search)) & (freqs < freq_hz * (1 + search))
    if not band.any():
        raise InputError(f"calibration: no spectral line near {freq_hz:g} Hz")
    f0 = float(freqs[band][np.argmax(spec[band])])
    peak, floor = spec[band].max(), np.median(spec[1:])
    if not (peak > 20 * floor and peak > 0):
        raise InputError(f"calibration: no sine near {freq_hz:g} Hz stands out of the noise in this channel "
                         "(wrong channel or wrong --reference-freq?)")

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
    p = sol.x
    r = sol.fun
    dof = max(1, x.size - p.size)
    s2 = float(r @ r) / dof
    J = sol.jac
    cov = np.linalg.pinv(J.T @ J) * s2
    a, b = p[0], p[1]
    A = math.hypot(a, b)
    if A == 0:
        raise InputError("calibration: fitted amplitude is zero")
    if math.sqrt(float(r @ r) / x.size) > 0.5 * A:  # the sine must dominate the residual
        raise InputError(f"calibration: this channel is not a clean sine near {freq_hz:g} Hz (residual "
                         f"{math.sqrt(float(r @ r) / x.size):.3g} V rms vs amplitude {A:.3g} V): "
                         "is it the reference recording and the channel on the exciter?")
    g = np.array([a / A, b / A])
    varA = float(g @ cov[:2, :2] @ g)
    return SineFit(amplitude=A, amplitude_std=math.sqrt(max(varA, 0.0)), freq_hz=float(p[4]),
                   freq_std_hz=math.sqrt(max(cov[4, 4], 0.0)), phase_rad=math.atan2(b, a), offset=float(p[2]),
                   residual_rms=math.sqrt(float(r @ r) / x.size), n=int(x.size))


@dataclasses.dataclass(frozen=True)
class ChannelCalibration:
    channel: str
    ka_m_s2_per_v: float
    ka_std_m_s2_per_v: float
    ka_std_fit_m_s2_per_v: float
    fit: SineFit


def ka_from_fit(fit: SineFit, reference_accel: float, convention: str = "peak", reference_rel_uncertainty: float = 0.0):
    """Ka (m/s^2/V) and its standard uncertainty (fit, combined) from a fit of the volts."""
    if convention not in ("peak", "rms"):
        raise InputError(f"convention must be 'peak' or 'rms', got '{convention}'")
    if not (math.isfinite(reference_accel) and reference_accel > 0):
        raise InputError(f"reference acceleration must be > 0 m/s^2, got {reference_accel}")
    if not (math.isfinite(reference_rel_uncertainty) and 0 <= reference_rel_uncertainty < 1):
        raise InputError("reference uncertainty must be a fraction in [0, 1)")
    a_peak = reference_accel * (math.sqrt(2.0) if convention == "rms" else 1.0)
    ka = a_peak / fit.amplitude
    rel_fit = fit.amplitude_std / fit.amplitude
    return ka, ka * rel_fit, ka * math.hypot(rel_fit, reference_rel_uncertainty)


def row_times(n: int, rate_hz: float, events) -> np.ndarray:
    """Time (s) of each row: index / rate, shifted after each ``gap`` event by its missing samples.

    The recorder joins rows across a loss and writes ``missing_samples=N`` at the start of the gap
    event's detail; a gap without that count raises FileFormatError (the fit must not join silently).
    """
    shift = np.zeros(n, dtype=np.int64)
    for index, kind, detail in events:
        if kind != "gap" or not 0 <= index < n:
            continue
        head = detail.split()[0] if detail else ""
        if not head.startswith("missing_samples="):
            raise FileFormatError(f"gap event at row {index} does not say how many samples are missing")
        shift[index:] += int(head.split("=", 1)[1])
    return (np.arange(n) + shift) / rate_hz


def calibrate_recording(path, channels, reference_accel: float = 9.81, reference_freq: float = 79.6,
                        convention: str = "peak", reference_rel_uncertainty: float = 0.0) -> list[ChannelCalibration]:
    """Fit every named channel of a v1 recording; InputError/FileFormatError on bad input."""
    from acquisition.recorder import read_recording
    path = Path(path)
    if not path.is_file():
        raise InputError(f"recording {path} does not exist")
    try:
        rec = read_recording(path)
    except (OSError, KeyError) as exc:
        raise FileFormatError(f"cannot read {path} as a labtool recording: {' '.join(str(exc).split())}") from None
    rate = float(rec["attrs"]["sample_rate_hz"])
    out = []
    for ch in channels:
        if ch not in rec["channel_names"]:
            raise InputError(f"channel '{ch}' is not in {path} (channels: {', '.join(rec['channel_names'])})")
        x = rec["signals"][:, rec["channel_names"].index(ch)]
        fit = fit_sine(x, rate, reference_freq, t=row_times(x.size, rate, rec["events"]))
        ka, std_fit, std = ka_from_fit(fit, reference_accel, convention, reference_rel_uncertainty)
        out.append(ChannelCalibration(ch, ka, std, std_fit, fit))
    return out


def calibration_toml(cals, source, reference_accel: float, reference_freq: float, convention: str,
                     reference_rel_uncertainty: float = 0.0, created_utc: str | None = None) -> str:
    """The calibration file's text (format in the module docstring)."""
    created = created_utc or _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    lines = [
        "# labtool calibration file: acceleration (m/s^2) = ka_m_s2_per_v * volts",
        f'format = "{CAL_FORMAT}"',
        f"format_version = {CAL_VERSION}",
        f'created_utc = "{created}"',
        f"source = {_toml_str(str(source))}",
        "",
        "[reference]",
        f"accel_m_s2 = {reference_accel!r}",
        f'convention = "{convention}"',
        f"freq_hz = {reference_freq!r}",
        f"rel_uncertainty = {reference_rel_uncertainty!r}",
    ]
    for c in cals:
        f = c.fit
        lines += [
            "",
            f"[channels.{c.channel}]",
            f"ka_m_s2_per_v = {c.ka_m_s2_per_v!r}",
            f"uncertainty_m_s2_per_v = {c.ka_std_m_s2_per_v!r}",
            f"ka_std_fit_m_s2_per_v = {c.ka_std_fit_m_s2_per_v!r}",
            f"fitted_freq_hz = {f.freq_hz!r}",
            f"amplitude_v_peak = {f.amplitude!r}",
            f"residual_rms_v = {f.residual_rms!r}",
            f"n_samples = {f.n}",
        ]
    return "\n".join(lines) + "\n"


def _toml_str(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def load_calibration(path) -> dict[str, dict]:
    """Channel -> {ka_m_s2_per_v, ka_std_m_s2_per_v, ...} from a calibration file; FileFormatError if bad."""
    path = Path(path)
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"calibration file {path} does not exist") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise FileFormatError(f"{path} is not valid TOML: {exc}") from None
    if doc.get("format") != CAL_FORMAT or doc.get("format_version") != CAL_VERSION:
        raise FileFormatError(f"{path} is not a labtool calibration file (format {CAL_FORMAT!r}, version {CAL_VERSION})")
    chans = doc.get("channels", {})
    for name, c in chans.items():
        ka = c.get("ka_m_s2_per_v")
        if not isinstance(ka, (int, float)) or not (math.isfinite(ka) and ka > 0):
            raise FileFormatError(f"{path}: channel {name} has no positive ka_m_s2_per_v")
    return chans
