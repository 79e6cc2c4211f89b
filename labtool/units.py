"""Units at the edges, for scripts and notebooks: ``180 * RPM`` is 180 rpm in rad/s, ``0.128 * MM``
is 0.128 mm in m, ``30 * DEG`` is 30 degrees in rad. labtool works in SI inside."""
from labtool.common.units import DEG, MM, RPM, rad_s_to_rpm, rpm_to_rad_s

__all__ = ["DEG", "MM", "RPM", "rad_s_to_rpm", "rpm_to_rad_s"]
