"""The compiled chunk kernels compute what the readable numpy/scipy definitions compute."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy import signal

from processing import cam_angle, filters, follower, kernels


@settings(max_examples=20, deadline=None)
@given(n=st.integers(30, 3000), order=st.integers(1, 8), frac=st.floats(0.01, 0.45), seed=st.integers(0, 99))
def test_sosfiltfilt_equals_scipy(n, order, frac, seed):
    x = np.random.default_rng(seed).normal(size=(n, 2)).cumsum(axis=0)
    sos = signal.butter(order, frac, output="sos")
    pad = min(filters.padlen(sos), n - 1)
    ref = filters.zero_phase(sos, x)
    got = kernels.sosfiltfilt(sos, signal.sosfilt_zi(sos), np.ascontiguousarray(x), pad)
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())


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
    absn = follower.omega2_from_normal(np.nan_to_num(acc[:, 1]), DE)
    absn[bad] = np.nan
    return acc, eps, omega, absn, moving


@settings(max_examples=25, deadline=None)
@given(n=st.integers(200, 6000), period=st.floats(150, 1500), seed=st.integers(0, 999),
       n_clip=st.integers(0, 5), irr=st.integers(0, 3))
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
    v = np.round(rng.normal(size=(5000, 2)), 1)
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
    got = kernels.clip_mask(np.ascontiguousarray(v), lo, hi, rail, 3)
    assert np.array_equal(got, ref) and got[100:104].all()
    assert rail or not got[2000:2002].any()
