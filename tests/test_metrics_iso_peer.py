"""reports/metrics.py's ISO/TS 18571 against an independent implementation on the same input:
objective-rating-metrics (PyPI, ``ISO18571``; DTW from dtwalign, lag scan and slope in numpy).

Curves of the report's kind: a cam-follower-like pulse pair with noise, the simulation scaled,
delayed or early; the peer wants a time column at 10 kHz (the grid step cancels in every score)."""
import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from objective_rating_metrics.rating import ISO18571

from labtool.reports import metrics

N = 720
X = np.linspace(0.0, 2.0 * math.pi, N, endpoint=False)
KEYS = ("iso_corridor", "iso_phase", "iso_magnitude", "iso_slope", "iso_rating")


def _peer(reference, comparison) -> dict:
    t = np.arange(reference.size) * 1e-4
    r = ISO18571(np.column_stack([t, reference]), np.column_stack([t, comparison]))
    vals = (r.corridor_rating(-1), r.phase_rating(-1), r.magnitude_rating(-1), r.slope_rating(-1), r.overall_rating(-1))
    return dict(zip(KEYS, map(float, vals))) | {"shift": abs(int(r._n_eps))}


def _curve(shift, scale, noise, rng):
    base = np.sin(X - shift) * np.exp(-((X - 2.0 - shift) ** 2)) - 0.6 * np.exp(-((X - 4.0 - shift) ** 2) * 4)
    return scale * base + noise * rng.standard_normal(N)


@pytest.mark.slow
@settings(max_examples=20, deadline=None)
@given(shift=st.floats(-0.4, 0.4), scale=st.floats(0.5, 1.8), noise=st.floats(0.0, 0.05), seed=st.integers(0, 9999))
@example(shift=0.0, scale=1.5585975976101705, noise=0.0, seed=766)   # equal-cost DTW paths
def test_iso_scores_equal_the_independent_implementation(shift, scale, noise, seed):
    rng = np.random.default_rng(seed)
    measured = _curve(0.0, 1.0, 0.02, rng)
    simulated = _curve(shift, scale, noise, rng)
    ours = metrics.iso18571(measured, simulated)
    peer = _peer(measured, simulated)
    assert abs(ours["iso_shift_samples"]) == peer["shift"]
    for k in KEYS:
        assert ours[k] == pytest.approx(peer[k], abs=1e-9), k


@pytest.mark.slow
def test_batched_rows_equal_the_single_pair_and_the_peer():
    """iso18571_rows (one FFT lag scan for all rows) gives the single-pair and the peer's scores."""
    rng = np.random.default_rng(3)
    rows = np.array([_curve(0.02 * k, 1.0 + 0.05 * k, 0.02, rng) for k in range(3)])
    sim = _curve(0.0, 1.0, 0.0, rng)
    batched = metrics.iso18571_rows(rows, sim)
    for row, b in zip(rows, batched):
        single = metrics.iso18571(row, sim)
        peer = _peer(row, sim)
        for k in KEYS:
            assert b[k] == pytest.approx(single[k], abs=1e-12)
            assert b[k] == pytest.approx(peer[k], abs=1e-9)
