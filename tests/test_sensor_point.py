"""The sensor relation against finite differences of the position of E (independent of its formulas)."""
from __future__ import annotations

import numpy as np

from labtool.models.mechanism import Mechanism, sensor_point
from labtool.models.mechanism.linkage import linkage_state


def _motion(t):
    """A follower motion over the stroke: phi2 (rad), omega2 (rad/s), epsilon2 (rad/s^2) at t (s)."""
    mech = Mechanism.default()
    w = 2 * np.pi * 3.0
    a = 0.12
    phi2 = mech.phiD + mech.psi0 + a * (1 - np.cos(w * t))
    return phi2, a * w * np.sin(w * t), a * w**2 * np.cos(w * t)


def test_acceleration_at_E_is_the_second_difference_of_its_position_on_the_sensor_axes():
    mech = Mechanism.default()
    t = np.linspace(0.01, 0.3, 37)
    h = 1e-5                                           # s: O(h^2) error ~1e-10 m/s^2 against ~1 m/s^2 peaks
    E = [linkage_state(mech, _motion(t + k * h)[0], 0.0, 0.0).E for k in (-1, 0, 1)]
    a = (E[0] - 2 * E[1] + E[2]) / h**2                # m/s^2 in the fixed frame
    phi2, omega2, epsilon2 = _motion(t)
    tangent = np.stack([-np.sin(phi2), np.cos(phi2)])  # increasing phi2
    to_D = -np.stack([np.cos(phi2), np.sin(phi2)])
    aE_t, aE_n = sensor_point.acceleration_at_E(mech.DE, omega2, epsilon2)
    scale = np.abs(aE_t).max()
    assert scale > 1.0
    np.testing.assert_allclose(aE_t, np.einsum("ij,ij->j", a, tangent), atol=1e-4 * scale)
    np.testing.assert_allclose(aE_n, np.einsum("ij,ij->j", a, to_D), atol=1e-4 * scale)
    assert np.all(aE_n >= 0)                            # the normal component points towards D


def test_linkage_aE_agrees_and_the_inverse_recovers_the_motion():
    mech = Mechanism.default()
    phi2, omega2, epsilon2 = _motion(np.linspace(0.0, 0.3, 11))
    st = linkage_state(mech, phi2, omega2, epsilon2)
    tangent = np.stack([-np.sin(phi2), np.cos(phi2)])
    aE_t, aE_n = sensor_point.acceleration_at_E(mech.DE, omega2, epsilon2)
    np.testing.assert_allclose(aE_t, np.einsum("ij,ij->j", st.aE, tangent), atol=1e-12)
    np.testing.assert_allclose(sensor_point.epsilon2_from_tangential(aE_t, mech.DE), epsilon2, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(sensor_point.omega2_abs_from_normal(aE_n, mech.DE), np.abs(omega2), atol=1e-12)
    assert sensor_point.omega2_abs_from_normal(-0.5, mech.DE) == 0.0   # noise below zero at rest


def test_sensor_reading_adds_minus_g_projected_on_the_axes():
    """A sensor at rest reads -g: (0, +g) in the fixed frame, on the tangent and towards D."""
    phi2 = np.linspace(0.5, 2.5, 7)
    f_t, f_n = sensor_point.sensor_reading(0.0, 0.0, phi2, 9.81)
    specific = np.array([0.0, 9.81])
    np.testing.assert_allclose(f_t, specific @ np.stack([-np.sin(phi2), np.cos(phi2)]), atol=1e-12)
    np.testing.assert_allclose(f_n, specific @ -np.stack([np.cos(phi2), np.sin(phi2)]), atol=1e-12)
