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
end-of-file address is never beyond the data already on disk.

Then every piece of metadata a reader touches is walked in a child process with a time limit
(``probe_metadata``), which also finds the open mode that works (normal, else SWMR): a flipped byte
in an attribute heap or a chunk index can make the HDF5 library loop inside one C call, where no
signal handler runs (100 % CPU, SIGTERM ignored). This process meanwhile only waits on a pipe, so a
damaged file ends with one line and a signal always ends the command.

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


MAX_WALK_OBJECTS = 10_000        # groups and datasets visited by the metadata walk (a recording has 2)
SMALL_DATASET_BYTES = 64 << 20   # variable-length datasets up to this size are read in full by the walk
FIXED_DATASET_BYTES = 1 << 20    # ... and fixed-size ones up to this (events; never the samples)


def _has_vlen(dtype) -> bool:
    import h5py
    if dtype.names:
        return any(_has_vlen(dtype.fields[n][0]) for n in dtype.names)
    return h5py.check_vlen_dtype(dtype) is not None or h5py.check_string_dtype(dtype) is not None and \
        h5py.check_string_dtype(dtype).length is None


def walk_metadata(path, swmr: bool = False) -> None:
    """Open ``path`` and touch every piece of metadata labtool's readers touch: every attribute of
    every object, every dataset's shape, type and chunk index, and every small dataset in full
    (events). Run by :func:`probe_metadata` in a child process: on damaged metadata the HDF5
    library can loop for ever inside one C call, where no signal handler of this process runs."""
    import h5py

    with h5py.File(path, "r", swmr=swmr) as f:
        seen = [0]

        def touch(obj) -> None:
            for k in obj.attrs:
                obj.attrs[k]
            if isinstance(obj, h5py.Dataset):
                obj.shape, obj.dtype, obj.chunks, obj.compression
                if obj.chunks is not None:
                    obj.id.get_num_chunks()          # walks the whole chunk index
                else:
                    obj.id.get_storage_size()
                # variable-length data (strings in the global heap) are where a damaged address
                # loops: read them up to the bound; fixed-size data only when small (no 288 MB time axis)
                limit = SMALL_DATASET_BYTES if _has_vlen(obj.dtype) else FIXED_DATASET_BYTES
                if obj.size * obj.dtype.itemsize <= limit:
                    obj[()]

        def visit(_name, obj):
            seen[0] += 1
            touch(obj)
            return True if seen[0] >= MAX_WALK_OBJECTS else None

        touch(f)
        f.visititems(visit)


def _child_walk(path: str) -> str:
    """'normal' or 'swmr' (the mode that opened the file and walked its metadata), else raises the
    normal open's error."""
    try:
        walk_metadata(path, swmr=False)
        return "normal"
    except Exception as first:                       # noqa: BLE001 - reported, in one line, by the parent
        try:
            walk_metadata(path, swmr=True)
            return "swmr"
        except Exception:                            # noqa: BLE001
            raise first from None


_CHILD = r"""
import os, sys
os.environ["HDF5_USE_FILE_LOCKING"] = "FALSE"
from labtool.common.hdf5 import _child_walk
try:
    print("ok " + _child_walk(sys.argv[1]))
except Exception as exc:
    print("error " + (" ".join(str(exc).split()) or type(exc).__name__)[:300])
"""


def probe_metadata(path, timeout_s: float | None = None) -> str:
    """Walk the file's metadata (:func:`walk_metadata`) in a child process bounded by ``timeout_s``
    (default PROBE_TIMEOUT_S); 'normal' or 'swmr', the open mode that works.

    FileFormatError when the walk fails or does not finish in time (the child is killed). This
    process only waits on a pipe meanwhile, so SIGTERM and Ctrl-C reach it (and kill the child).
    The child is forked when this process runs one thread (a few ms), else a fresh interpreter
    (about 0.3 s): forking a process whose other threads may hold locks can deadlock the child.
    """
    import select
    import signal
    import threading

    timeout_s = PROBE_TIMEOUT_S if timeout_s is None else timeout_s
    path = os.fspath(path)
    if hasattr(os, "fork") and threading.active_count() == 1:
        rfd, wfd = os.pipe()
        pid = os.fork()
        if pid == 0:                                   # the child: walk, answer, leave without cleanup
            try:
                os.close(rfd)
                signal.signal(signal.SIGTERM, signal.SIG_DFL)
                signal.signal(signal.SIGINT, signal.SIG_DFL)
                os.environ["HDF5_USE_FILE_LOCKING"] = "FALSE"
                try:
                    answer = "ok " + _child_walk(path)
                except BaseException as exc:           # noqa: BLE001
                    answer = "error " + (" ".join(str(exc).split()) or type(exc).__name__)[:300]
                os.write(wfd, answer.encode("utf-8", "replace"))
            finally:
                os._exit(0)
        os.close(wfd)
        try:
            ready, _, _ = select.select([rfd], [], [], timeout_s)
            answer = os.read(rfd, 4096).decode("utf-8", "replace") if ready else None
        finally:
            os.close(rfd)
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            os.waitpid(pid, 0)
    else:
        try:
            r = subprocess.run([sys.executable, "-c", _CHILD, path], capture_output=True, text=True,
                               timeout=timeout_s)
            answer = r.stdout.strip() or "error " + ((r.stderr.strip().splitlines() or ["unknown error"])[-1])
        except subprocess.TimeoutExpired:
            answer = None
    if answer is None:
        raise FileFormatError(f"{path}: HDF5 file's metadata cannot be read within {timeout_s:g} s (damaged "
                              "file); give an undamaged copy")
    if answer.startswith("ok "):
        return answer[3:].strip()
    raise FileFormatError(f"{path}: not a readable HDF5 file (truncated or corrupt?): {answer[6:] or 'unknown error'}")



def open_file(path, probe_timeout_s: float | None = None):
    """(h5py.File opened read-only, note) after the checks above; note says when the file was
    opened in SWMR mode (still marked open by a writer), else ''. FileFormatError on damage.

    The superblock is checked in this process; then every piece of metadata a reader touches is
    walked in a child process bounded in time (probe_metadata): a flipped byte in an attribute heap
    made h5py loop for ever inside one C call, deaf to SIGTERM. The walk is deterministic, so the
    same reads in this process then end too.
    """
    import h5py

    check_superblock(path)
    mode = probe_metadata(path, probe_timeout_s)
    if mode == "normal":
        try:
            return h5py.File(path, "r"), ""
        except (OSError, ValueError, RuntimeError):
            pass   # the writer may have marked it open since: the SWMR open below
    # a recorder writing in SWMR mode that is still running, or was killed, leaves the file's
    # consistency flags set: a SWMR reader may still open it and read what was flushed
    try:
        f = h5py.File(path, "r", swmr=True)
    except Exception as exc:  # h5py raises OSError, ValueError or RuntimeError on damaged files
        raise FileFormatError(f"{path}: not a readable HDF5 file (truncated or corrupt?): {exc}") from None
    return f, (f"{path}: the file is still marked open for writing (recorder running or killed); "
               "read in SWMR mode, up to the last flushed block")
