"""The one periodicity measure: closed forms, and both of its users reading it."""
from __future__ import annotations

import math

import numpy as np
import pytest

from labtool.models.dynamics import periodicity
from labtool.reports import align


def test_rms_change_of_a_scaled_revolution_is_the_scale_error():
    phi = np.linspace(0.0, 2 * math.pi, 720, endpoint=False)
    last = np.sin(phi) + 0.3 * np.sin(3 * phi)
    assert periodicity.revolution_change(last, 0.97 * last) == pytest.approx(0.03, rel=1e-12)
    assert periodicity.revolution_change(last, last) == 0.0
    assert periodicity.revolution_change(np.zeros(8), np.ones(8)) == 0.0     # no size to compare with


def test_max_change_kept_samples_and_scale():
    last, prev = np.array([1.0, 2.0, 4.0, 0.0]), np.array([1.0, 2.1, 4.0, 3.0])
    assert periodicity.revolution_change(last, prev, "max") == pytest.approx(3.0 / 4.0)
    keep = np.array([True, True, True, False])                                # the event sample left out
    assert periodicity.revolution_change(last, prev, "max", keep=keep, scale=10.0) == pytest.approx(0.01)
    assert periodicity.revolution_change(last, prev, "max", keep=np.zeros(4, bool)) == 0.0


def test_events_repeat_counts_and_angles():
    tol = periodicity.EVENT_ANGLE_TOL
    assert periodicity.events_repeat([1.0, 2.0], [1.0 + 0.5 * tol, 2.0])
    assert not periodicity.events_repeat([1.0, 2.0], [1.0 + 2 * tol, 2.0])
    assert not periodicity.events_repeat([1.0], [1.0, 2.0])
    assert periodicity.events_repeat([], [])


def test_report_steady_cycle_uses_the_steady_tolerance():
    grid = np.linspace(0.0, 2 * math.pi, 64, endpoint=False)
    base = np.sin(grid)
    tol = periodicity.STEADY_CYCLE_TOL
    settled = {"omega2": np.array([1.5 * base, (1 + 2 * tol) * base, (1 + 0.5 * tol) * base, base])}
    drifting = {"omega2": np.array([1.5 * base, (1 + 4 * tol) * base, (1 + 2 * tol) * base, base])}
    a, b = align.steady_cycles(settled, grid), align.steady_cycles(drifting, grid)
    assert a.periodic and a.change == pytest.approx(0.5 * tol)
    assert not b.periodic and b.n_used == 3
