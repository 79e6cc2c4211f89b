"""The compiled chunk kernels compute what the readable numpy/scipy definitions compute."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy import signal

import scipy.fft as scipy_fft

from labtool.processing import accumulators, cam_angle, cycles, events, filters, follower, kernels
from labtool.models.mechanism import sensor_point


@settings(max_examples=20, deadline=None)
@given(n=st.integers(30, 3000), order=st.integers(1, 8), frac=st.floats(0.01, 0.45), seed=st.integers(0, 99))
def test_sosfiltfilt_equals_scipy(n, order, frac, seed):
    x = np.random.default_rng(seed).normal(size=(n, 2)).cumsum(axis=0)
    sos = signal.butter(order, frac, output="sos")
    pad = min(filters.padlen(sos), n - 1)
    ref = signal.sosfiltfilt(sos, x, axis=0, padlen=pad)
    got = kernels.sosfiltfilt(sos, signal.sosfilt_zi(sos), np.ascontiguousarray(x), pad)
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())
    np.testing.assert_allclose(filters.zero_phase(sos, x[:, 1]), ref[:, 1], rtol=1e-9, atol=1e-9 * np.abs(ref).max())


@settings(max_examples=40, deadline=None)
@given(order=st.integers(1, 10), frac=st.floats(0.001, 0.49), fs=st.sampled_from([1000.0, 10000.0, 51200.0]))
def test_butterworth_design_equals_scipy(order, frac, fs):
    """The design itself (sections, their order, the gain), its response, and the step state."""
    cutoff = frac * fs
    ref = signal.butter(order, cutoff, fs=fs, output="sos")
    got = filters.lowpass_sos(fs, cutoff, order)
    assert got.shape == ref.shape
    f = np.array([0.0, 0.1 * cutoff, cutoff, min(3 * cutoff, 0.49 * fs)])
    _, h_ref = signal.sosfreqz(ref, worN=f, fs=fs)
    _, h_got = signal.sosfreqz(got, worN=f, fs=fs)
    np.testing.assert_allclose(h_got, h_ref, rtol=1e-9, atol=1e-12)
    if order % 2 == 0:  # scipy pairs an odd order's extra zero otherwise: same product, other sections
        np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-15)
    np.testing.assert_allclose(filters.sosfilt_zi(got), signal.sosfilt_zi(got), rtol=1e-9, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(n=st.integers(0, 400), levels=st.integers(2, 50), height=st.floats(-1, 1), distance=st.floats(1, 40),
       seed=st.integers(0, 999))
def test_find_peaks_equals_scipy(n, levels, height, distance, seed):
    """Distinct heights: the same peaks. Quantized values (plateaus, equal heights, which scipy
    takes in the order of an unstable sort): the same local maxima, kept at the distance."""
    rng = np.random.default_rng(seed)
    x = np.round(rng.normal(size=n) * levels / 4) / (levels / 4) if seed % 2 else rng.normal(size=n)
    ref, _ = signal.find_peaks(x, height=height, distance=distance)
    got = kernels.find_peaks(x, height, distance)
    candidates, _ = signal.find_peaks(x, height=height)
    if len(np.unique(x[candidates])) == len(candidates):
        assert got.tolist() == ref.tolist()
    else:
        assert set(got) <= set(candidates) and len(got) >= (1 if len(candidates) else 0)
        assert np.all(np.diff(got) >= math.ceil(distance))


@settings(max_examples=20, deadline=None)
@given(n=st.integers(5, 3000), m=st.integers(1, 400), seed=st.integers(0, 99))
def test_correlate_valid_equals_scipy(n, m, seed):
    rng = np.random.default_rng(seed)
    x, t = rng.normal(size=n), rng.normal(size=m)
    ref = signal.correlate(x, t, mode="valid") if n >= m else np.empty(0)
    got = cam_angle.correlate_valid(x, t)
    assert got.shape == ref.shape
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-9 * (np.abs(ref).max() if len(ref) else 1))


@settings(max_examples=20, deadline=None)
@given(first=st.integers(0, 5000), n=st.integers(1, 4000), k=st.integers(1, 12), seed=st.integers(0, 99))
def test_phi1_from_marks_equals_numpy(first, n, k, seed):
    rng = np.random.default_rng(seed)
    marks = np.sort(rng.uniform(0, 9000, size=k))
    marks = marks[np.concatenate([[True], np.diff(marks) > 1.0])]
    ref_phi, ref_rev = cam_angle.phi1_from_marks(np.arange(first, first + n), marks, 333.3)
    phi, rev = kernels.phi1_from_marks(first, n, marks, 333.3)
    assert np.array_equal(rev, ref_rev)
    d = np.abs(phi - ref_phi)
    d = np.minimum(d, 2 * math.pi - d)  # the same angle either side of 0 / 2 pi
    assert d.max() < 1e-9


def _numpy_chain(lp, phi1, rev, irregular, clipped, gravity, moving_table, DE, fs, middle, min_len, margin):
    """pipeline._process_window's steps after the low-pass, with the numpy definitions."""
    N = len(gravity)
    k = (phi1 * (N / (2 * math.pi)) + 0.5).astype(np.int64) & (N - 1)
    acc = lp - gravity[k]
    moving = moving_table[k]
    acc -= follower.dwell_baseline(acc, ~moving, middle, min_len)
    bad = clipped | ((rev >= 0) & (rev < len(irregular)) & irregular[np.clip(rev, 0, len(irregular) - 1)])
    acc[bad] = np.nan
    eps = acc[:, 0] / DE
    omega = follower.integrate_motion(np.nan_to_num(eps), moving, fs, margin, bad=bad)
    omega[bad] = np.nan
    absn = sensor_point.omega2_abs_from_normal(np.nan_to_num(acc[:, 1]), DE)
    absn[bad] = np.nan
    return acc, eps, omega, absn, moving


@settings(max_examples=25, deadline=None)
@given(n=st.integers(200, 6000), period=st.floats(150, 1500), seed=st.integers(0, 999),
       n_clip=st.integers(0, 5), irr=st.integers(0, 3))
@pytest.mark.slow
def test_follower_chain_equals_numpy(n, period, seed, n_clip, irr):
    rng = np.random.default_rng(seed)
    N = 1 << 12
    grid = 2 * math.pi * np.arange(N) / N
    gravity = np.ascontiguousarray(np.column_stack([np.cos(grid), -np.sin(grid)]))
    moving_table = (grid > 0.3) & (grid < 2.2) | (grid > 3.5) & (grid < 5.0)
    marks = np.arange(rng.uniform(0, period), n, period)
    if len(marks) < 2:
        return
    phi1, rev = cam_angle.phi1_from_marks(np.arange(n), marks, period)
    lp = np.ascontiguousarray(rng.normal(size=(n, 2)) + np.sin(phi1)[:, None])
    clipped = np.zeros(n, bool)
    clipped[rng.integers(0, n, n_clip)] = True
    irregular = np.zeros(len(marks) - 1, bool)
    irregular[rng.integers(0, len(irregular), irr)] = True
    args = (gravity, moving_table, 0.2, 10000.0, 0.6, 8, 17)
    ref = _numpy_chain(lp, phi1.copy(), rev, irregular, clipped, *args)
    got = kernels.follower_chain(lp, phi1.copy(), rev, irregular, clipped, *args)
    for r, g in zip(ref, got):
        np.testing.assert_array_equal(np.isnan(r), np.isnan(g))
        ok = np.isfinite(r)
        scale = max(1.0, float(np.abs(r[ok]).max()) if ok.any() else 1.0)
        np.testing.assert_allclose(g[ok], r[ok], rtol=0, atol=1e-9 * scale)


@pytest.mark.parametrize("rail", [0.0, 0.9])
def test_clip_mask_equals_numpy(rail):
    rng = np.random.default_rng(3)
    v = np.round(rng.normal(size=(5000, 2)), 1).astype(np.float32).astype(float)
    lo, hi = v.min(axis=0), v.max(axis=0)
    v[100:104, 0] = hi[0]
    v[2000:2002, 1] = lo[1]  # two samples only: not a clip
    ref = np.zeros(len(v), bool)
    if rail:
        ref |= (np.abs(v) >= rail).any(axis=1)
    for j in range(2):
        at = (v[:, j] == hi[j]) | (v[:, j] == lo[j])
        for a, b in follower.runs(at):
            if b - a >= 3:
                ref[a:b] = True
    block = np.column_stack([np.zeros(len(v)), v[:, 0], np.ones(len(v)), v[:, 1]]).astype(np.float32)
    got = np.ones(len(v), bool)
    kernels.clip_mask(block, np.array([1, 3]), lo, hi, rail, 3, 0.0, got)
    assert np.array_equal(got, ref) and got[100:104].all()
    assert rail or not got[2000:2002].any()


@pytest.mark.slow
def test_clip_mask_a_rounded_top_is_not_a_clip_a_flat_cut_is():
    """A run at the extreme whose neighbours are one level below (a quantised smooth peak) is not
    a clip when min_drop asks for a steeper entry; a run entered by a big step is."""
    q = 0.01
    peak = np.array([0, 3, 6, 8, 9, 10, 10, 10, 10, 9, 8, 6, 3, 0] * 3, float) * q   # rounded top, 4 samples
    cut = np.array([0, 20, 40, 40, 40, 40, 20, 0], float) * q                      # saturated, steep entry
    v = np.concatenate([peak, -cut])[:, None]
    lo, hi = v.min(axis=0), v.max(axis=0)
    old, new = np.empty(len(v), bool), np.empty(len(v), bool)
    kernels.clip_mask(v, np.array([0]), lo, hi, 0.0, 3, 0.0, old)
    kernels.clip_mask(v, np.array([0]), lo, hi, 0.0, 3, 3 * q, new)
    assert old[5:9].all() and not new[:peak.size].any()
    assert new[peak.size + 2:peak.size + 6].all() and new.sum() == 4


@settings(max_examples=25, deadline=None)
@given(n=st.integers(1, 6000), block=st.integers(1, 3000), noise=st.floats(0, 0.5), offset=st.floats(-3, 3),
       seed=st.integers(0, 999), f32=st.booleans())
@pytest.mark.slow
def test_compiled_tacho_edges_equal_numpy(n, block, noise, offset, seed, f32):
    """The same edges over any split into blocks: pulses, noise, a silent start, float32 input."""
    rng = np.random.default_rng(seed)
    i = np.arange(n)
    x = offset + 5.0 * ((i % 713) < 40) * (i > n // 5) + rng.normal(0, noise, n)
    x = x.astype(np.float32) if f32 else x
    ref_det, got_det = cam_angle.TachoEdges(), cam_angle.CompiledTachoEdges()
    ref = np.concatenate([ref_det.feed(a, x[a:a + block]) for a in range(0, n, block)] or [np.empty(0)])
    got = np.concatenate([got_det.feed(a, x[a:a + block]) for a in range(0, n, block)] or [np.empty(0)])
    assert got.tolist() == ref.tolist()


def test_scan_block_extremes_and_first_bad_sample():
    x = np.random.default_rng(0).normal(size=(1000, 3)).astype(np.float32)
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    assert kernels.scan_block(x, lo, hi) == -1
    assert lo.tolist() == x.min(axis=0).tolist() and hi.tolist() == x.max(axis=0).tolist()
    x[700, 2], x[701, 0] = np.nan, np.inf
    assert kernels.scan_block(x, lo, hi) == 700 * 3 + 2


@settings(max_examples=25, deadline=None)
@given(n=st.integers(3, 9000), bursts=st.integers(0, 6), seed=st.integers(0, 999), n_clip=st.integers(0, 50))
def test_spikes_kernel_equals_detect_spikes(n, bursts, seed, n_clip):
    rng = np.random.default_rng(seed)
    lp = np.column_stack([np.sin(np.arange(n) / 50.0), 0.3 * np.cos(np.arange(n) / 70.0)]) * 10
    phys = lp + rng.normal(0, 0.05, (n, 2))
    for t in rng.integers(0, n, bursts):
        phys[t:t + 5, rng.integers(0, 2)] += rng.normal(0, 5, len(phys[t:t + 5]))
    clipped = np.zeros(n, bool)
    clipped[rng.integers(0, n, n_clip)] = True
    for c in range(2):
        res = np.where(~clipped, phys[:, c] - lp[:, c], 0.0)
        ref = events.detect_spikes(res, lp[:, c], 10000.0)
        got = kernels.spikes(phys, lp, clipped, c, events.DEFAULT_K_SIGMA, events.DEFAULT_FLOOR_FRACTION, 20.0,
                             np.empty(n + 5))
        assert got[0].tolist() == ref[0].tolist()
        np.testing.assert_array_equal(got[1], ref[1])
        assert got[2] == pytest.approx(ref[2], rel=1e-12)


def _numpy_cycles(acc, eps, omega, absn, clipped, m0, m1, grid):
    """pipeline._add_cycles as it was in numpy (93b2959): (sums, sumsqs, used, rejected)."""
    n = len(eps)
    vals = [acc[:, 0], acc[:, 1], eps, omega, absn]
    inside = (m0 >= 0) & (np.floor(m1) + 1 < n)
    m0, m1 = m0[inside], m1[inside]
    bad = clipped.copy()
    for v in vals:
        bad |= ~np.isfinite(v)
    bc = np.concatenate([[0], np.cumsum(bad)])
    lo, hi = np.floor(m0).astype(np.int64), np.floor(m1).astype(np.int64) + 2
    good = (bc[hi] - bc[lo]) == 0
    m0, m1 = m0[good], m1[good]
    x = m0[:, None] + (grid / (2.0 * math.pi))[None, :] * (m1 - m0)[:, None]
    i0 = np.floor(x).astype(np.int64)
    w = x - i0
    res = [v[i0] * (1.0 - w) + v[i0 + 1] * w for v in vals]
    return (np.array([r.sum(axis=0) for r in res]), np.array([(r * r).sum(axis=0) for r in res]),
            int(good.sum()), int((~good).sum()))


@settings(max_examples=25, deadline=None)
@given(n=st.integers(50, 5000), period=st.floats(20, 900), start=st.floats(-300, 300), seed=st.integers(0, 999),
       n_nan=st.integers(0, 4))
def test_resample_cycles_equals_numpy(n, period, start, seed, n_nan):
    rng = np.random.default_rng(seed)
    acc = rng.normal(size=(n, 2))
    eps, omega, absn = rng.normal(size=n), rng.normal(size=n), rng.normal(size=n)
    omega[rng.integers(0, n, n_nan)] = np.nan
    clipped = np.zeros(n, bool)
    clipped[rng.integers(0, n, n_nan)] = True
    marks = start + period * np.arange(int((n - start) / period) + 2)
    m0, m1 = marks[:-1], marks[1:]
    grid = cycles.phi1_grid(72)
    ref_s, ref_q, ref_used, ref_rej = _numpy_cycles(acc, eps, omega, absn, clipped, m0, m1, grid)
    rows = np.full((len(m0), 5, 72), np.nan)
    used, rejected = kernels.resample_cycles(acc, eps, omega, absn, clipped, m0, m1, grid / (2 * math.pi), rows)
    assert (used, rejected) == (ref_used, ref_rej)
    sums, sumsq = rows[:used].sum(axis=0), (rows[:used] ** 2).sum(axis=0)
    np.testing.assert_allclose(sums, ref_s if ref_used else 0.0, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(sumsq, ref_q if ref_used else 0.0, rtol=1e-13, atol=1e-13)


def test_core_outputs_equal_numpy():
    rng = np.random.default_rng(5)
    n, c0, c1 = 3000, 400, 2600
    acc, eps, omega, absn = rng.normal(size=(n, 2)), rng.normal(size=n), rng.normal(size=n), rng.random(n)
    omega[::97] = np.nan
    phi1 = rng.uniform(0, 2 * np.pi, n)
    rev = rng.integers(-1, 30, n)
    moving, clipped = rng.random(n) < 0.6, rng.random(n) < 0.01
    out_f, out_rev = np.empty((5, c1 - c0), np.float32), np.empty(c1 - c0, np.int32)
    out_clip, out_time, normal = np.empty(c1 - c0, np.int8), np.empty(c1 - c0), np.zeros(3)
    kernels.core_outputs(acc, eps, omega, phi1, rev, absn, moving, clipped, c0, c1, 7, 12345.0, 10000.0,
                         out_f, out_rev, out_clip, out_time, normal)
    core = slice(c0, c1)
    for j, v in enumerate((acc[core, 0], acc[core, 1], eps[core], omega[core], phi1[core])):
        np.testing.assert_array_equal(out_f[j], v.astype(np.float32))
    assert out_rev.tolist() == np.where(rev[core] >= 0, rev[core] + 7, -1).tolist()
    assert out_clip.tolist() == clipped[core].astype(int).tolist()
    np.testing.assert_array_equal(out_time, (12345.0 + np.arange(c1 - c0)) / 10000.0)
    ref = accumulators.NormalCheck()
    ref.feed(omega[core], absn[core], moving[core])
    np.testing.assert_allclose(normal, ref.sums, rtol=1e-12)


def test_welch_accumulate_equals_numpy():
    rng = np.random.default_rng(2)
    segs = rng.normal(size=(2, 5, 4096)).astype(np.float32)
    w = np.hanning(4097)[:-1].astype(np.float32)
    spec = scipy_fft.rfft(segs * w, axis=-1)
    wfft = np.fft.rfft(np.hanning(4097)[:-1]).astype(np.complex64)
    means = segs.mean(axis=-1)
    ref = spec - means[:, :, None] * wfft
    mag = np.abs(ref)
    sa, sp = np.ones((2049, 2)), np.ones((2049, 2))
    kernels.welch_accumulate(spec, means, wfft, sa, sp)
    np.testing.assert_allclose(sa, 1 + mag.sum(axis=1, dtype=np.float64).T, rtol=1e-6)
    np.testing.assert_allclose(sp, 1 + np.square(mag).sum(axis=1, dtype=np.float64).T, rtol=1e-6)
