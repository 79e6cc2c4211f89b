"""Comparison metrics on signals with a known answer (closed forms derived in the docstrings)."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from labtool.common.errors import InputError
from labtool.reports import metrics

N = 720
X = np.linspace(0.0, 2.0 * math.pi, N, endpoint=False)   # one whole period, uniform grid
SINE = np.sin(X)


def test_identical_signals_have_zero_errors_and_iso_rating_one():
    out = metrics.compare(SINE, SINE.copy(), X)
    for k in ("sg_magnitude", "sg_phase", "sg_comprehensive", "nrmse", "peak_max_error", "peak_min_error",
              "peak_max_shift_deg", "peak_min_shift_deg"):
        assert out[k] == pytest.approx(0.0, abs=1e-7), k
    for k in ("iso_corridor", "iso_phase", "iso_magnitude", "iso_slope", "iso_rating"):
        assert out[k] == pytest.approx(1.0, abs=1e-12), k
    assert out["iso_grade"] == "excellent"


def test_scaled_sine_sprague_geers_magnitude_is_the_scale_minus_one():
    sg = metrics.sprague_geers(SINE, 1.3 * SINE)
    assert sg["sg_magnitude"] == pytest.approx(0.3, abs=1e-12)
    assert sg["sg_phase"] == pytest.approx(0.0, abs=1e-7)
    assert sg["sg_comprehensive"] == pytest.approx(0.3, abs=1e-7)
    # the measurement larger than the simulation: M = 1/1.3 - 1 < 0
    assert metrics.sprague_geers(1.3 * SINE, SINE)["sg_magnitude"] == pytest.approx(1 / 1.3 - 1, abs=1e-12)


@pytest.mark.parametrize("shift_deg", [5.0, 30.0, 90.0, 150.0])
def test_shifted_sine_sprague_geers_phase_is_shift_over_pi(shift_deg):
    """Over whole periods sum sin(x) sin(x+t) = cos(t) sum sin^2(x), so P = arccos(cos t)/pi = t/pi
    exactly for 0 <= t <= pi, and the magnitudes are equal (M = 0)."""
    t = math.radians(shift_deg)
    sg = metrics.sprague_geers(SINE, np.sin(X + t))
    assert sg["sg_phase"] == pytest.approx(t / math.pi, abs=1e-10)
    assert sg["sg_magnitude"] == pytest.approx(0.0, abs=1e-10)
    assert sg["sg_comprehensive"] == pytest.approx(t / math.pi, abs=1e-10)


def test_nrmse_of_a_constant_offset_is_offset_over_range():
    for d in (0.01, 0.2, -0.5):
        assert metrics.nrmse(SINE, SINE + d) == pytest.approx(abs(d) / 2.0, rel=1e-6)   # range of sin is 2


def test_corridor_score_of_a_constant_offset_between_the_corridors():
    """Every point is at |C - T| = d with 0.05 < d < 0.5 (max|T| = 1): Z = ((0.5 - d)/0.45)^2."""
    for d in (0.03, 0.1, 0.3, 0.6):
        expected = 1.0 if d <= 0.05 else (0.0 if d >= 0.5 else ((0.5 - d) / 0.45) ** 2)
        assert metrics.iso_corridor(SINE, SINE + d) == pytest.approx(expected, abs=1e-12)


def test_scaled_sine_iso_slope_and_corridor():
    """C = 1.3 T: slopes scale by 1.3, so the slope error is exactly 0.3 (no shift is found) and
    E_S = (2 - 0.3)/2; the corridor score is the mean of clip((0.5 - 0.3|sin|)/0.45, 0, 1)^2."""
    out = metrics.iso18571(SINE, 1.3 * SINE)
    assert out["iso_shift_samples"] == 0 and out["iso_phase"] == 1.0
    assert out["iso_slope_error"] == pytest.approx(0.3, rel=1e-9)
    assert out["iso_slope"] == pytest.approx(0.85, rel=1e-9)
    d = 0.3 * np.abs(SINE)
    zexp = np.mean(np.clip((0.5 - d) / 0.45, 0, 1) ** 2)
    assert out["iso_corridor"] == pytest.approx(zexp, rel=1e-12)
    # DTW can only lower the amplitude error (it may pair near-equal values): 0 < e_mag <= 0.3
    assert 0.0 < out["iso_magnitude_error"] <= 0.3 + 1e-12
    assert out["iso_rating"] == pytest.approx(0.4 * zexp + 0.2 + 0.2 * out["iso_magnitude"] + 0.2 * 0.85)


@pytest.mark.parametrize("lag", [0, 7, 36, 100])
def test_iso_phase_score_of_a_delayed_copy(lag):
    """A copy delayed by `lag` samples: the cross-correlation finds the lag exactly (the overlaps are
    identical), E_P = (0.2 N - lag)/(0.2 N), and after the shift magnitude and slope are perfect."""
    sig = np.sin(3 * X) * np.exp(-((X - 3.0) ** 2))
    delayed = np.concatenate([np.zeros(lag), sig[: N - lag]])
    out = metrics.iso18571(sig, delayed)
    assert out["iso_shift_samples"] == lag
    assert out["iso_phase"] == pytest.approx((0.2 * N - lag) / (0.2 * N))
    assert out["iso_magnitude"] == pytest.approx(1.0)
    assert out["iso_slope"] == pytest.approx(1.0)
    # and the early copy is found as a negative lag
    if lag:
        early = np.concatenate([sig[lag:], np.zeros(lag)])
        assert metrics.iso18571(sig, early)["iso_shift_samples"] == -lag


def test_iso_phase_score_is_zero_beyond_the_allowed_shift():
    sig = np.exp(-((X - 2.0) ** 2) * 8)
    delayed = np.exp(-((X - 2.0 - 0.3 * 2 * math.pi) ** 2) * 8)   # 30 % of the interval: beyond 20 %
    assert metrics.iso18571(sig, delayed)["iso_phase"] == 0.0


def test_dtw_aligns_a_warped_copy_exactly():
    """y is x sampled on a warped grid that keeps every sample of x: DTW pairs equal values."""
    x = np.sin(np.linspace(0, 3, 200)) + np.linspace(0, 1, 200)
    idx = np.sort(np.concatenate([np.arange(200), np.arange(50, 70)]))   # repeat 20 samples
    y = x[idx]
    pi, pj = metrics.dtw_path(x, y, window=40)
    assert np.allclose(x[pi], y[pj])
    assert pi[0] == 0 and pj[0] == 0 and pi[-1] == 199 and pj[-1] == 219
    assert np.all(np.diff(pi) >= 0) and np.all(np.diff(pj) >= 0)


def test_peak_errors_and_timing():
    shifted = 1.2 * np.sin(X - math.radians(10))   # peak 20 % higher and 10 deg later
    pk = metrics.peak_errors(SINE, shifted, X)
    assert pk["peak_max_error"] == pytest.approx(0.2, abs=1e-3)
    assert pk["peak_min_error"] == pytest.approx(-0.2, abs=1e-3)
    assert math.degrees(pk["peak_max_shift"]) == pytest.approx(10.0, abs=0.5)
    out = metrics.compare(SINE, shifted, X)
    assert out["peak_max_shift_deg"] == pytest.approx(10.0, abs=0.5)


@pytest.mark.parametrize("r,grade", [(0.95, "excellent"), (0.94, "good"), (0.81, "good"), (0.6, "fair"), (0.58, "poor"), (0.1, "poor")])
def test_iso_grades(r, grade):
    assert metrics.iso_grade(r) == grade


@pytest.mark.parametrize("bad", [
    (np.ones(5), np.ones(6)),
    (np.array([1.0, np.nan, 2.0]), np.ones(3)),
    (np.zeros(20), np.ones(20)),
])
def test_bad_signals_raise_input_error(bad):
    with pytest.raises(InputError):
        metrics.compare(bad[0], bad[1], np.arange(bad[0].size, dtype=float))


def test_unknown_iso_parameter_is_input_error():
    with pytest.raises(InputError):
        metrics.iso18571(SINE, SINE, k_z=3)


@settings(max_examples=25, deadline=None)
@given(scale=st.floats(0.2, 5.0), offset=st.floats(-0.5, 0.5), shift=st.integers(0, 60))
def test_scores_stay_in_their_ranges(scale, offset, shift):
    sim = scale * np.roll(SINE, shift) + offset
    out = metrics.compare(SINE, sim, X)
    for k in ("iso_corridor", "iso_phase", "iso_magnitude", "iso_slope", "iso_rating"):
        assert 0.0 <= out[k] <= 1.0 + 1e-12
    assert 0.0 <= out["sg_phase"] <= 1.0
    assert out["sg_magnitude"] >= -1.0
    assert out["nrmse"] >= 0.0


def test_peak_shift_pairs_each_peak_with_its_own_counterpart():
    """Two near-equal peaks (rise and return): the global argmax of the simulation may be the other
    peak; the shift must still be the local one."""
    two = np.exp(-((X - 1.0) ** 2) * 20) + 0.999 * np.exp(-((X - 4.0) ** 2) * 20)
    sim = 0.999 * np.exp(-((X - 1.05) ** 2) * 20) + np.exp(-((X - 4.05) ** 2) * 20)
    pk = metrics.peak_errors(two, sim, X)
    assert pk["peak_max_shift"] == pytest.approx(0.05, abs=X[1])


def test_lag_deg_is_the_correlation_lag_as_cam_angle():
    sig = np.sin(3 * X) * np.exp(-((X - 3.0) ** 2))
    lag = 20
    delayed = np.concatenate([np.zeros(lag), sig[: N - lag]])
    assert metrics.compare(sig, delayed, X)["lag_deg"] == pytest.approx(lag * 360.0 / N)


def _dtw_cost_bruteforce(x, y, window):
    """Textbook row-by-row DTW (same steps, cost and band): the reference for the vectorised one."""
    n, m = len(x), len(y)
    D = np.full((n + 1, m + 1), np.inf)
    D[0, 0] = 0.0
    for i in range(1, n + 1):
        for j in range(1, m + 1):
            if abs(i - j) <= window:
                D[i, j] = (x[i - 1] - y[j - 1]) ** 2 + min(D[i - 1, j], D[i, j - 1], D[i - 1, j - 1])
    return D[n, m]


@settings(max_examples=30, deadline=None)
@given(n=st.integers(5, 40), m=st.integers(5, 40), window=st.integers(0, 12), seed=st.integers(0, 10_000))
def test_vectorised_dtw_matches_the_textbook_recursion(n, m, window, seed):
    rng = np.random.default_rng(seed)
    x, y = rng.standard_normal(n), rng.standard_normal(m)
    pi, pj = metrics.dtw_path(x, y, window)
    w = max(window, abs(n - m))
    # the path is a valid warping path inside the band and its cost is the optimum
    assert pi[0] == 0 and pj[0] == 0 and pi[-1] == n - 1 and pj[-1] == m - 1
    steps = set(zip(np.diff(pi), np.diff(pj)))
    assert steps <= {(1, 0), (0, 1), (1, 1)}
    assert np.all(np.abs(pi - pj) <= w)
    assert float(np.sum((x[pi] - y[pj]) ** 2)) == pytest.approx(_dtw_cost_bruteforce(x, y, w), rel=1e-9, abs=1e-12)
