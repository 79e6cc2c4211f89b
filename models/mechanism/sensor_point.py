"""The sensor relation: what an accelerometer at point E of the follower reads, and its inverse.

E lies on the follower at the distance DE (m) from its pivot D, at the follower angle phi2 (rad,
counter-clockwise from x, y up). Its acceleration has two components along the sensor's axes
(docs/architecture.md, "Signs"):

    aE_t = DE epsilon2       tangential, positive along increasing phi2 (the rise),
    aE_n = DE omega2^2       normal, positive towards D (an ideal sensor reads it >= 0),

with omega2 (rad/s) and epsilon2 (rad/s^2) the follower's angular velocity and acceleration. The
inverse is epsilon2 = aE_t / DE and |omega2| = sqrt(aE_n / DE): the normal axis gives the speed's
magnitude only, never its sign.

An accelerometer reads specific force, a - g, with g = (0, -g). On the axes turning with phi2 (the
tangent (-sin phi2, cos phi2), the normal towards D (-cos phi2, -sin phi2)) gravity adds

    tangential  + g cos(phi2),      normal  - g sin(phi2).

This module is the one definition of these relations; the compiled loops of
``labtool.processing.kernels`` keep them inline (a call per sample would cost) and cite it.
"""
from __future__ import annotations

import numpy as np


def acceleration_at_E(DE: float, omega2, epsilon2):
    """Tangential and normal acceleration (m/s^2) of E at ``DE`` (m) from the pivot.

    Parameters
    ----------
    DE : float
        Distance from the follower pivot D to the sensor point E (m).
    omega2 : array_like
        Follower angular velocity (rad/s).
    epsilon2 : array_like
        Follower angular acceleration (rad/s^2).

    Returns
    -------
    aE_t, aE_n : ndarray
        DE epsilon2 (m/s^2, positive in the rise) and DE omega2^2 (m/s^2, positive towards D).
    """
    omega2 = np.asarray(omega2, dtype=float)
    return np.asarray(epsilon2, dtype=float) * DE, omega2**2 * DE


def epsilon2_from_tangential(aE_t, DE: float):
    """Follower angular acceleration epsilon2 = aE_t / DE (rad/s^2).

    Parameters
    ----------
    aE_t : array_like
        Tangential acceleration of E (m/s^2, positive in the rise).
    DE : float
        Distance D-E (m).
    """
    return np.asarray(aE_t, dtype=float) / DE


def omega2_abs_from_normal(aE_n, DE: float):
    """|omega2| = sqrt(aE_n / DE) (rad/s); a reading below zero (noise at rest) counts as 0.

    Parameters
    ----------
    aE_n : array_like
        Normal acceleration of E (m/s^2, positive towards D).
    DE : float
        Distance D-E (m).
    """
    return np.sqrt(np.maximum(np.asarray(aE_n, dtype=float), 0.0) / DE)


def gravity_reading(phi2, g: float):
    """What gravity adds to the sensor's (tangential, normal) readings (m/s^2).

    Parameters
    ----------
    phi2 : array_like
        Follower angle (rad, counter-clockwise from x).
    g : float
        Gravitational acceleration (m/s^2).

    Returns
    -------
    g_t, g_n : ndarray
        g cos(phi2) and -g sin(phi2) (m/s^2).
    """
    phi2 = np.asarray(phi2, dtype=float)
    return g * np.cos(phi2), -g * np.sin(phi2)


def sensor_reading(aE_t, aE_n, phi2, g: float):
    """Specific force on the sensor's axes (m/s^2): the acceleration of E plus gravity's reading.

    Parameters
    ----------
    aE_t, aE_n : array_like
        Tangential and normal acceleration of E (m/s^2), as ``acceleration_at_E``.
    phi2 : array_like
        Follower angle (rad).
    g : float
        Gravitational acceleration (m/s^2).

    Returns
    -------
    f_t, f_n : ndarray
        aE_t + g cos(phi2) and aE_n - g sin(phi2) (m/s^2).
    """
    g_t, g_n = gravity_reading(phi2, g)
    return np.asarray(aE_t, dtype=float) + g_t, np.asarray(aE_n, dtype=float) + g_n
