"""Reader of the labtool recording format version 1 (HDF5, docs/architecture.md "Recording format").

The format, its checks and its reader are labtool.common.recording_format, beside its writer; this
module gives processing its chunked ``Recording`` of such a file (samples checked finite when read
with ``read``). A recording with complete=false (its recorder was killed) is read with a warning.
"""
from __future__ import annotations

import math

from labtool.common import recording_attrs, recording_format as fmt
from labtool.processing.readers.base import Event, Recording, check_finite


def open_hdf5_v1(path) -> Recording:
    f = fmt.open_recording(path)
    names, src = f.channel_names, f.source
    attrs = dict(f.attrs)
    for name, frac in zip(names, f.peak_fraction_of_range if f.peak_fraction_of_range is not None else ()):
        if name in recording_attrs.ACCELEROMETER_CHANNELS and math.isfinite(frac):
            attrs[recording_attrs.headroom_name(name)] = float(frac)

    def read(start: int, stop: int):
        block = f.read_rows(start, stop)
        check_finite(block, start, names, src)
        return block

    return Recording(source=src, format=f.format, sample_rate_hz=f.sample_rate_hz, channel_names=names,
                     n_samples=f.n_samples, read=read, ka_m_s2_per_v=f.ka_m_s2_per_v,
                     start_time_utc=f.start_time_utc, complete=f.complete, cam_speed_rpm=f.cam_speed_rpm,
                     events=[Event(*e) for e in f.events], attrs=attrs, warnings=f.warnings, close=f.close,
                     read_raw=f.read_rows, raw_dtype=f.raw_dtype)
