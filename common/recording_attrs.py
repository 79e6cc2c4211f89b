"""Names of the recording attributes that describe a run (docs/architecture.md, recording format v1).

acquisition writes them (root attributes of the HDF5 recording, for every device); processing
carries them into measured.nc; reports show them with where each value came from. One list, so
the three never disagree on a name.

Operating point (edge units as named): ``law``, ``cam_speed_rpm``, ``Fu_N``, ``backlash_mm``,
``jt_factor``, ``motor_setting`` (free text: motor/variator setting as the operator states it).
Each value present has ``<name>_source`` beside it: who stated it, e.g. ``"simulated stand scene"``,
``"stated by the operator (--fu)"``, ``"device file stand.toml"``. A name that is absent was not
stated: a reader that falls back to a default must say so.

Run metadata (text unless said): ``test_id``, ``operator``, ``sensor_model``, ``sensor_serial``,
``conditioner_model``, ``conditioner_gain`` (float, x1/x10/x100), ``notes``.

Headroom: ``headroom_summary`` (root, one line). Per channel on the ``signals`` dataset:
``input_range_v``, ``peak_abs_v``, ``rms_v``, ``peak_fraction_of_range``, ``clipped``; measured.nc
keeps the accelerometer channels' ``peak_fraction_of_range_aE_t`` and ``_aE_n``.
"""
from __future__ import annotations

from labtool.common.operating_point import FIELD, SOURCE_SUFFIX, STATED

# the stated operating point (its owner's attribute names, labtool.common.operating_point) and the
# operator's free-text motor setting
OPERATING_POINT = tuple(FIELD[n].attr for n in STATED) + ("motor_setting",)
RUN_METADATA = ("test_id", "operator", "sensor_model", "sensor_serial", "conditioner_model",
                "conditioner_gain", "notes")
HEADROOM_ROOT = ("headroom_summary",)
HEADROOM_PER_CHANNEL = ("input_range_v", "peak_abs_v", "rms_v", "peak_fraction_of_range", "clipped")
# measured.nc's root attributes for the accelerometer channels' peak over their input range (the
# recording's ``peak_fraction_of_range`` of the channels named aE_t and aE_n): how close the run came
# to clipping, which labtool suggest scales to other speeds
ACCELEROMETER_CHANNELS = ("aE_t", "aE_n")


def headroom_name(channel: str) -> str:
    """measured.nc's attribute of ``channel``'s peak over its input range."""
    return f"peak_fraction_of_range_{channel}"


ACCELEROMETER_HEADROOM = tuple(headroom_name(c) for c in ACCELEROMETER_CHANNELS)


def source_name(name: str) -> str:
    """The attribute saying where ``name``'s value came from."""
    return name + SOURCE_SUFFIX


def carried() -> tuple[str, ...]:
    """Every root attribute a derived file (measured.nc) should keep from its recording."""
    return (OPERATING_POINT + tuple(source_name(n) for n in OPERATING_POINT) + RUN_METADATA + HEADROOM_ROOT
            + ACCELEROMETER_HEADROOM)
