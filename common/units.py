"""Unit conversions used at the edges (CLI, tables, plots). SI everywhere inside."""
import math

DEG = math.pi / 180.0          # rad per degree
MM = 1e-3                      # m per mm
RPM = 2.0 * math.pi / 60.0     # rad/s per rpm


def rpm_to_rad_s(n_rpm: float) -> float:
    """A speed in rpm as an angular velocity in rad/s.

    Parameters
    ----------
    n_rpm : float
        Speed [rpm].

    Returns
    -------
    float
        Angular velocity [rad/s].
    """
    return n_rpm * RPM


def rad_s_to_rpm(omega_rad_s: float) -> float:
    """An angular velocity in rad/s as a speed in rpm.

    Parameters
    ----------
    omega_rad_s : float
        Angular velocity [rad/s].

    Returns
    -------
    float
        Speed [rpm].
    """
    return omega_rad_s / RPM
