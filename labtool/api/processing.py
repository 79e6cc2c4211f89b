"""``labtool.process``: a recording -> the follower's motion (measured.nc), as a CF dataset."""
from __future__ import annotations

import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from labtool.common.errors import InputError

if TYPE_CHECKING:     # imported where a Dataset is made: reading a result's attributes needs none
    import xarray as xr


def process(recording, output=None, *, calibration=(), channels: dict | None = None, law: str | None = None,
            cam_speed_rpm: float | None = None, lowpass_hz: float | None = None, ac_tau_s: float | None = None,
            mechanism=None, chunk_samples: int = 1 << 17, progress=None, warn=None, dataset: bool = True,
            **reader_options) -> xr.Dataset | dict:
    """Recorded accelerations at E -> the follower's omega2 and epsilon2, the cam angle, spectra,
    cycle statistics and spikes, with every step in the processing history.

    Parameters
    ----------
    recording : path
        A labtool recording (HDF5 v1), a LabVIEW TDMS or LVM file, or a CSV export.
    output : path, optional
        The NetCDF file to write (measured.nc). Without it the result is held in memory (a long
        recording's is large: give a file, whose variables are then read lazily).
    calibration : sequence of paths
        Calibration files (``labtool calibrate``): Ka [m/s^2/V] per channel, merged.
    channels : dict, optional
        The file's channel for each of ``aE_t``, ``aE_n``, ``tacho`` (``{"aE_t": "ai0"}``).
    law : str, optional
        The cam's motion law (default: the recording's, else sine).
    cam_speed_rpm : float, optional
        Nominal cam speed [rpm] (default: the recording's; the speed used is measured).
    lowpass_hz : float, optional
        Low-pass corner [Hz] (default: 100 x the cam frequency).
    ac_tau_s : float, optional
        AC-coupling time constant of the sensor chain [s], undone when given.
    mechanism : labtool.models.mechanism.Mechanism, optional
        The mechanism (default: the paper's STB-216).
    chunk_samples : int
        Samples per processing chunk: the memory bound [-].
    progress : callable, optional
        ``progress(done, total)``: samples processed of the two passes over the recording [-].
    warn : callable, optional
        ``warn(text)`` for each warning (default: Python warnings, ProcessingWarning).
    dataset : bool
        True: return the measurement as an xarray Dataset. False (``output`` given): return the
        written file's global attributes only (a dict, as the Dataset's ``attrs``), without opening
        it as a Dataset: no index built over its time axis (~300 MB for a 1-hour recording, more
        than the processing itself) and no xarray loaded.
    **reader_options
        What the file's reader takes: ``sample_rate_hz`` [Hz], ``group`` (TDMS), ``delimiter``,
        ``decimal``, ``time_unit_s`` [s per unit of the time column] (text tables), ``units``
        (channel: unit text, ``V``, ``mV``, ``m/s^2`` or ``g``, replacing the file's; TDMS, LVM,
        CSV), and ``invert`` (``("aE_n",)``: the channels whose sensor reads the other way round,
        turned before processing).

    Returns
    -------
    xarray.Dataset
        ``omega2`` [rad s-1], ``epsilon2`` [rad s-2], ``aE_t``, ``aE_n`` [m s-2], ``phi1`` [rad] over
        ``time``; cycle statistics (``omega2_mean``, ``omega2_std``, ...) on the cam-angle grid;
        spectra; the operating point and the processing history as attributes. With
        ``dataset=False``, those attributes alone (dict).
    """
    from labtool.processing.pipeline import ProcessOptions, process_file

    for name, v in (("cam_speed_rpm", cam_speed_rpm), ("lowpass_hz", lowpass_hz), ("ac_tau_s", ac_tau_s)):
        if v is not None and not (0 < v < float("inf")):
            raise InputError(f"{name} must be a positive number, got {v}")
    if chunk_samples < 1024:
        raise InputError("chunk_samples must be at least 1024")
    opts = ProcessOptions(law=law, cam_speed_rpm=cam_speed_rpm, lowpass_hz=lowpass_hz, ac_tau_s=ac_tau_s,
                          chunk_samples=int(chunk_samples), mechanism=mechanism)
    count = {"done": 0, "total": 0}

    def on_open(rec):
        count["total"] = 2 * rec.n_samples

    def step(n):
        count["done"] += n
        progress(count["done"], count["total"])

    reader_options.update(on_open=on_open, progress=step if progress is not None else None)
    if not dataset and output is None:
        raise InputError("dataset=False returns the written file's attributes: give the output file")
    if output is not None:
        output = Path(output)
        if output.resolve() == Path(recording).resolve():
            raise InputError("the output file must not be the recording itself")
        process_file(recording, output, calibration, channels, opts, warn=warn, **reader_options)
        if not dataset:
            return _attributes(output)
        import xarray as xr
        return xr.open_dataset(output, engine="h5netcdf")
    import xarray as xr
    with tempfile.TemporaryDirectory(prefix="labtool-") as tmp:
        path = Path(tmp) / "measured.nc"
        process_file(recording, path, calibration, channels, opts, warn=warn, **reader_options)
        with xr.open_dataset(path, engine="h5netcdf") as ds:
            return ds.load()


def _attributes(path: Path) -> dict:
    """The global attributes of the NetCDF file ``path`` as xarray's h5netcdf backend gives them
    (text read as str)."""
    import h5netcdf

    with h5netcdf.File(path, "r") as f:
        return {k: v.decode("utf-8") if isinstance(v, bytes) else v for k, v in f.attrs.items()}
