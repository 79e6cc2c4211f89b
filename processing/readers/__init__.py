"""Readers of recordings into one lazily read :class:`Recording`, dispatched by content.

``open_recording(path)`` looks at the first bytes, not the file name: HDF5 signature -> labtool
recording v1 (hdf5_v1.py); ``TDSm`` -> LabVIEW TDMS (tdms.py); text starting ``LabVIEW Measurement``
-> LVM (lvm.py); other printable text -> CSV-like exports (csv.py); anything else ->
FileFormatError. One module per format; every reader gives the same :class:`Recording`.
"""
from __future__ import annotations

from pathlib import Path

from labtool.common.errors import FileFormatError, InputError
from labtool.common.names import shown
from labtool.processing.readers.base import Event, Recording

HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
TDMS_SIGNATURE = b"TDSm"

__all__ = ["open_recording", "Recording", "Event", "sniff", "recording_kind"]


def sniff(path) -> str:
    """'hdf5', 'tdms', 'lvm' or 'csv' from the file's content; FileFormatError otherwise."""
    p = Path(path)
    if not p.exists():
        raise InputError(f"recording {p} does not exist")
    if not p.is_file():
        raise InputError(f"recording {p} is not a file")
    try:
        with open(p, "rb") as fh:
            head = fh.read(4096)
    except OSError as exc:
        raise InputError(f"cannot read {p}: {exc.strerror}") from None
    if not head:
        raise FileFormatError(f"{p}: file is empty")
    if head.startswith(HDF5_SIGNATURE):
        return "hdf5"
    if head.startswith(TDMS_SIGNATURE):
        return "tdms"
    try:
        text = head.decode("utf-8")
    except UnicodeDecodeError as exc:
        # a multi-byte character cut at the 4096-byte boundary is still text; so is Latin-1 (LabVIEW
        # on a Western Windows writes 'Press\xe3o' in its channel names)
        text = head[:exc.start].decode("utf-8") if exc.start >= len(head) - 4 else head.decode("latin-1")
    control = sum(1 for ch in text if (ord(ch) < 32 and ch not in "\t\r\n") or 0x7F <= ord(ch) < 0xA0)
    if "\x00" in text or control > len(text) // 100 or not any(ch in text for ch in ",;\t\n"):
        named = {".tdms": ("TDMS", "the lead-in 'TDSm'"), ".tdms_index": ("TDMS", "the lead-in 'TDSh'"),
                 ".h5": ("HDF5", "the HDF5 signature"), ".hdf5": ("HDF5", "the HDF5 signature")}.get(p.suffix.lower())
        if named:   # a damaged file, or another renamed: say what it is not, never npTDMS's struct.error
            raise FileFormatError(f"{p}: not a recording: not {named[0]} (it does not start with {named[1]}); damaged, "
                                  f"or a file of another format named {p.suffix}")
        raise FileFormatError(f"{p}: not a recording (not HDF5, TDMS or CSV text)")
    return "lvm" if text.lstrip("\ufeff").startswith("LabVIEW Measurement") else "csv"


def recording_kind(path) -> str | None:
    """What kind of recording ``path`` is ('labtool recording', 'TDMS recording', 'LVM recording'),
    or None for anything else (a measured NetCDF file, another HDF5 file, text, a missing file).
    For commands that take processed files: a raw recording is named as such, with no h5py or
    xarray warning on the way. HDF5 is opened through common.hdf5.open_file (bounded in time)."""
    try:
        kind = sniff(path)
    except (FileFormatError, InputError):
        return None
    if kind == "tdms":
        return "TDMS recording"
    if kind == "lvm":
        return "LVM recording"
    if kind != "hdf5":
        return None
    from labtool.common import recording_format as fmt
    from labtool.common.hdf5 import open_file
    f, _ = open_file(path)
    with f:
        return "labtool recording" if fmt.as_text(f.attrs.get("format", "")) == fmt.FORMAT else None


def open_recording(path, sample_rate_hz: float | None = None, group: str | None = None,
                   delimiter: str | None = None, decimal: str | None = None,
                   time_unit_s: float | None = None, channels: dict | None = None,
                   units: dict | None = None) -> Recording:
    """Open any supported recording.

    sample_rate_hz (Hz): used when the file states none (TDMS, CSV) or to override a text table's
    rate (header and time column); group: the TDMS group; delimiter, decimal, time_unit_s (s per
    unit of a time column): overrides of what the text readers detect; channels: the ``--channels``
    mapping (chain name: file's name), the channels an LVM file must give at one rate (the others
    of TDMS, LVM and CSV files may be side channels in any unit); units: the ``--units`` mapping
    (the file's or the chain's channel name: unit text, V, mV, m/s^2 or g), replacing the file's.
    """
    kind = sniff(path)
    wanted = list(channels.values()) if channels else None
    units = {(channels or {}).get(k, k): v for k, v in (units or {}).items()} or None
    if units and kind == "hdf5":
        raise InputError(f"{shown(path)}: --units is for TDMS, LVM and CSV files; a labtool recording holds volts")
    if kind == "hdf5":
        from labtool.processing.readers.hdf5_v1 import open_hdf5_v1
        rec = open_hdf5_v1(path)
    elif kind == "tdms":
        from labtool.processing.readers.tdms import open_tdms
        rec = open_tdms(path, sample_rate_hz, group, units, wanted)
    elif kind == "lvm":
        from labtool.processing.readers.lvm import open_lvm
        rec = open_lvm(path, sample_rate_hz, time_unit_s, wanted, units)
    else:
        from labtool.processing.readers.csv import open_csv
        rec = open_csv(path, sample_rate_hz, delimiter, decimal, time_unit_s, units, wanted)
    if rec.n_samples == 0:
        rec.close()
        raise FileFormatError(f"{path}: the recording holds no samples")
    if sample_rate_hz is not None and abs(rec.sample_rate_hz - sample_rate_hz) > 1e-6 * rec.sample_rate_hz:
        rec.close()   # the file's own rate won: the option was passed over without a word
        raise InputError(f"{shown(path)}: the file states {rec.sample_rate_hz:g} Hz; --sample-rate {sample_rate_hz:g} "
                         "is for files that state none (or a text table's time column): leave it out or fix the file")
    return rec
