"""The one cycle averager against numpy's mean and std, whole and in batches."""
from __future__ import annotations

import numpy as np
import pytest

from labtool.processing import cycles
from labtool.reports import align


def test_one_batch_equals_numpy_exactly():
    rows = np.random.default_rng(1).normal(3.0, 0.2, size=(37, 90))
    st = cycles.cycle_statistics(rows)
    np.testing.assert_array_equal(st.mean, rows.mean(axis=0))
    np.testing.assert_array_equal(st.std, rows.std(axis=0))
    assert st.count == 37
    np.testing.assert_array_equal(cycles.cycle_statistics(rows, ddof=1).std, rows.std(axis=0, ddof=1))


def test_batches_merge_to_the_whole_and_keep_rows():
    rows = np.random.default_rng(2).normal(1e3, 1e-3, size=(50, 2, 16))   # large mean, tiny scatter
    acc = cycles.CycleAccumulator(["a", "b"], 16, keep=True)
    for lo, hi in ((0, 1), (1, 8), (8, 8), (8, 50)):
        acc.add_rows(rows[lo:hi])
    for i, name in enumerate(("a", "b")):
        st = acc.statistics(name)
        np.testing.assert_allclose(st.mean, rows[:, i].mean(axis=0), rtol=1e-15)
        np.testing.assert_allclose(st.std, rows[:, i].std(axis=0, ddof=1), rtol=1e-9)
        np.testing.assert_array_equal(acc.revolutions(name), rows[:, i])
    assert acc.count == 50


def test_identical_revolutions_have_no_scatter_and_few_have_nan():
    row = np.linspace(-5.0, 7.0, 12)
    st = cycles.cycle_statistics(np.tile(1e3 + row, (9, 1)))
    assert np.all(st.std <= 1e-12)          # rounding only (a sum of squares would leave 1.5e-5)
    acc = cycles.CycleAccumulator(["x"], 12)
    assert np.isnan(acc.statistics("x").mean).all() and acc.statistics("x").count == 0
    acc.add_rows(row[None, None, :])
    assert np.isnan(acc.statistics("x").std).all()                  # n - 1 = 0
    with pytest.raises(ValueError):
        acc.revolutions("x")


def test_report_cycles_read_the_same_statistics():
    grid = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    sig = np.random.default_rng(3).normal(size=(6, 32))
    m = align.MeasuredCycles(grid, np.arange(6), {"omega2": sig}, np.zeros((6, 32)), 0, 180.0)
    np.testing.assert_array_equal(m.mean("omega2"), sig.mean(axis=0))
    np.testing.assert_array_equal(m.std("omega2"), sig.std(axis=0))
