"""Opening HDF5 files without trusting a damaged one: the superblock is checked before h5py sees it.

Why: HDF5 refuses a file shorter than the end-of-file address its superblock stores ("truncated
file") in normal mode, but skips that check in SWMR read mode; a recording cut to its first 100 to
4096 bytes then opens in SWMR mode and h5py loops for ever reading the root group's attributes.
So, before any h5py call:

1. find the superblock signature (offset 0, 512, 1024, 2048, ...: a user block may come first);
2. parse the superblock (versions 0-3 of the HDF5 file format specification, section II.A),
   check its Jenkins lookup3 checksum (versions 2 and 3);
3. refuse the file if it is shorter than base address + stored end-of-file address.

A file that a SWMR writer still holds open (or that was killed) passes these checks: its stored
end-of-file address is never beyond the data already on disk. When the normal open fails and the
SWMR open is the fallback, the SWMR open and the first metadata reads are first tried in a child
process with a time bound (``probe_timeout_s``), so that a damage the checks above miss still ends
with one line, never a hang.

Nothing here imports above ``common``; acquisition's calibration and processing's reader share it.
"""
from __future__ import annotations

import os
import struct
import subprocess
import sys
from pathlib import Path

from labtool.common.errors import FileFormatError, InputError

SIGNATURE = b"\x89HDF\r\n\x1a\n"
PROBE_TIMEOUT_S = 20.0


def _lookup3(data: bytes, initval: int = 0) -> int:
    """Bob Jenkins' lookup3 hashlittle, as HDF5's H5_checksum_lookup3 (little-endian bytes)."""
    mask = 0xFFFFFFFF

    def rot(x, k):
        return ((x << k) | (x >> (32 - k))) & mask

    length = len(data)
    a = b = c = (0xDEADBEEF + length + initval) & mask
    i = 0
    while length - i > 12:
        a = (a + int.from_bytes(data[i:i + 4], "little")) & mask
        b = (b + int.from_bytes(data[i + 4:i + 8], "little")) & mask
        c = (c + int.from_bytes(data[i + 8:i + 12], "little")) & mask
        a = (a - c) & mask; a ^= rot(c, 4); c = (c + b) & mask
        b = (b - a) & mask; b ^= rot(a, 6); a = (a + c) & mask
        c = (c - b) & mask; c ^= rot(b, 8); b = (b + a) & mask
        a = (a - c) & mask; a ^= rot(c, 16); c = (c + b) & mask
        b = (b - a) & mask; b ^= rot(a, 19); a = (a + c) & mask
        c = (c - b) & mask; c ^= rot(b, 4); b = (b + a) & mask
        i += 12
    tail = data[i:]
    if not tail:
        return c
    tail = tail + b"\x00" * (12 - len(tail))
    a = (a + int.from_bytes(tail[0:4], "little")) & mask
    b = (b + int.from_bytes(tail[4:8], "little")) & mask
    c = (c + int.from_bytes(tail[8:12], "little")) & mask
    c ^= b; c = (c - rot(b, 14)) & mask
    a ^= c; a = (a - rot(c, 11)) & mask
    b ^= a; b = (b - rot(a, 25)) & mask
    c ^= b; c = (c - rot(b, 16)) & mask
    a ^= c; a = (a - rot(c, 4)) & mask
    b ^= a; b = (b - rot(a, 14)) & mask
    c ^= b; c = (c - rot(b, 24)) & mask
    return c


def check_superblock(path) -> dict:
    """The superblock's facts ({version, base, eof, size, consistency_flags}); FileFormatError when
    the file is not HDF5, its superblock is cut or corrupt, or the file is shorter than it states."""
    p = Path(path)
    try:
        size = p.stat().st_size
        with open(p, "rb") as fh:
            head = fh.read(64 * 1024)
            base = _find_signature(fh, head, size)
            if base is None:
                raise FileFormatError(f"{p}: not an HDF5 file (no HDF5 signature)")
            fh.seek(base)
            sb = fh.read(256)
    except OSError as exc:
        raise InputError(f"cannot read {p}: {exc.strerror or exc}") from None
    info = _parse(sb, p)
    info["size"] = size
    info["signature_at"] = base
    end = info["base"] + info["eof"]
    if info["eof"] == 0xFFFFFFFFFFFFFFFF or size < end:
        raise FileFormatError(
            f"{p}: truncated HDF5 file ({size} bytes on disk, its superblock says {end}); "
            "copy the whole file again, or give the original")
    return info


def _find_signature(fh, head: bytes, size: int) -> int | None:
    off = 0
    while off + 8 <= size:
        if off + 8 <= len(head):
            chunk = head[off:off + 8]
        else:
            fh.seek(off)
            chunk = fh.read(8)
        if chunk == SIGNATURE:
            return off
        off = 512 if off == 0 else 2 * off
    return None


def _parse(sb: bytes, p: Path) -> dict:
    cut = FileFormatError(f"{p}: truncated HDF5 file (its superblock is incomplete); give the whole file")
    if len(sb) < 12:
        raise cut
    version = sb[8]
    if version in (0, 1):
        if len(sb) < 24:
            raise cut
        so, sl = sb[13], sb[14]
        start = 24 if version == 0 else 28
        flags = struct.unpack_from("<I", sb, 20)[0]
    elif version in (2, 3):
        so, sl = sb[9], sb[10]
        start = 12
        flags = sb[11]
    else:
        raise FileFormatError(f"{p}: HDF5 superblock version {version} is not known (corrupt file?)")
    if so not in (2, 4, 8, 16) or sl not in (2, 4, 8, 16):
        raise FileFormatError(f"{p}: corrupt HDF5 superblock (size of offsets {so}, of lengths {sl})")
    need = start + 4 * so + (4 if version >= 2 else 0)
    if len(sb) < need:
        raise cut
    addr = [int.from_bytes(sb[start + k * so:start + (k + 1) * so], "little") for k in range(4)]
    if version >= 2:
        stored = struct.unpack_from("<I", sb, start + 4 * so)[0]
        if _lookup3(sb[:start + 4 * so]) != stored:
            raise FileFormatError(f"{p}: corrupt HDF5 superblock (checksum mismatch); the file is damaged")
        base, eof = addr[0], addr[2]
    else:
        base, eof = addr[0], addr[2]
    return {"version": version, "base": base, "eof": eof, "consistency_flags": flags}


_PROBE = r"""
import sys, h5py
with h5py.File(sys.argv[1], "r", swmr=True) as f:
    dict(f.attrs)
    for k in f:
        node = f[k]
        dict(node.attrs)
        getattr(node, "shape", None)
print("ok")
"""


def probe_in_child(path, timeout_s: float = PROBE_TIMEOUT_S) -> None:
    """Open ``path`` in SWMR mode and read its top-level metadata in a child process, bounded in
    time; FileFormatError if the child fails or does not finish."""
    try:
        r = subprocess.run([sys.executable, "-c", _PROBE, os.fspath(path)], capture_output=True, text=True,
                           timeout=timeout_s, env=dict(os.environ, HDF5_USE_FILE_LOCKING="FALSE"))
    except subprocess.TimeoutExpired:
        raise FileFormatError(f"{path}: HDF5 file does not open within {timeout_s:g} s (damaged metadata); "
                              "give an undamaged copy") from None
    if r.returncode != 0 or "ok" not in r.stdout:
        last = (r.stderr.strip().splitlines() or ["unknown error"])[-1]
        raise FileFormatError(f"{path}: not a readable HDF5 file (truncated or corrupt?): {last}")


def open_file(path, probe_timeout_s: float = PROBE_TIMEOUT_S):
    """(h5py.File opened read-only, note) after the checks above; note says when the file was
    opened in SWMR mode (still marked open by a writer), else ''. FileFormatError on damage."""
    import h5py

    check_superblock(path)
    try:
        return h5py.File(path, "r"), ""
    except (OSError, ValueError, RuntimeError) as exc:
        first = exc
    # a recorder writing in SWMR mode that is still running, or was killed, leaves the file's
    # consistency flags set: a SWMR reader may still open it and read what was flushed
    probe_in_child(path, probe_timeout_s)
    try:
        f = h5py.File(path, "r", swmr=True)
    except Exception:  # h5py raises OSError, ValueError or RuntimeError on damaged files
        raise FileFormatError(f"{path}: not a readable HDF5 file (truncated or corrupt?): {first}") from None
    return f, (f"{path}: the file is still marked open for writing (recorder running or killed); "
               "read in SWMR mode, up to the last flushed block")
