"""Linkage kinematics: geometric invariants, velocities and accelerations by finite differences."""
import math

import numpy as np
import pytest

from labtool.models.mechanism.linkage import linkage_state
from labtool.models.mechanism import Mechanism

MECH = Mechanism.default()


def _motion(t):
    """A smooth test motion of the follower: phi2(t) over its working range."""
    base = MECH.phiD + MECH.psi0
    return base + 0.13 * (1 - np.cos(7.0 * t)), 0.13 * 7.0 * np.sin(7.0 * t), 0.13 * 49.0 * np.cos(7.0 * t)


def test_link_lengths_and_rod_offset_are_invariant():
    t = np.linspace(0, 1, 301)
    st = linkage_state(MECH, *_motion(t))
    np.testing.assert_allclose(np.hypot(*(st.C - MECH.D[:, None])), MECH.l, rtol=1e-12)
    np.testing.assert_allclose(np.hypot(*(st.E - MECH.D[:, None])), MECH.DE, rtol=1e-12)
    np.testing.assert_allclose(np.hypot(*(st.N - st.E)), MECH.EN, rtol=1e-12)
    np.testing.assert_allclose(np.hypot(*(st.K4 - st.E)), MECH.EK4, rtol=1e-12)
    np.testing.assert_allclose(np.hypot(*(st.H - st.E)), MECH.EH, rtol=1e-12)
    # G lies at the signed distance FG from the rod axis, F is the foot of the perpendicular
    u = np.stack([np.cos(st.phi4), np.sin(st.phi4)])
    r = MECH.G[:, None] - st.E
    np.testing.assert_allclose(u[0] * r[1] - u[1] * r[0], MECH.FG, atol=1e-14)
    np.testing.assert_allclose(np.hypot(*(MECH.G[:, None] - st.F)), abs(MECH.FG), rtol=1e-12)


@pytest.mark.parametrize("point", ["C", "E", "K2", "K4", "K5", "N"])
def test_velocities_and_accelerations_match_finite_differences(point):
    t = np.linspace(0.05, 0.95, 37)
    h = 1e-5
    st = linkage_state(MECH, *_motion(t))
    plus = linkage_state(MECH, *_motion(t + h))
    minus = linkage_state(MECH, *_motion(t - h))
    pos = lambda s: getattr(s, point)
    vel = lambda s: getattr(s, "v" + point)
    fd_v = (pos(plus) - pos(minus)) / (2 * h)
    fd_a = (vel(plus) - vel(minus)) / (2 * h)
    np.testing.assert_allclose(vel(st), fd_v, atol=1e-6 * max(1, np.abs(fd_v).max()))
    np.testing.assert_allclose(getattr(st, "a" + point), fd_a, atol=1e-5 * max(1, np.abs(fd_a).max()))


def test_rod_angular_rates_match_finite_differences():
    t = np.linspace(0.05, 0.95, 37)
    h = 1e-5
    st = linkage_state(MECH, *_motion(t))
    plus, minus = linkage_state(MECH, *_motion(t + h)), linkage_state(MECH, *_motion(t - h))
    np.testing.assert_allclose(st.omega4, (plus.phi4 - minus.phi4) / (2 * h), atol=1e-7)
    np.testing.assert_allclose(st.epsilon4, (plus.omega4 - minus.omega4) / (2 * h), atol=1e-5)
    np.testing.assert_allclose(st.ds, (plus.s - minus.s) / (2 * h), atol=1e-9)
    np.testing.assert_allclose(st.dds, (plus.ds - minus.ds) / (2 * h), atol=1e-7)
