"""Results streamed to disk, one file per finished chunk, so that nothing finished is lost.

A :class:`PartStore` is a folder (``results.csv.parts/`` beside the output) holding

* ``manifest.json``: what the parts are results of (a fingerprint of the work: for a design its
  model, factors, base scene and number of runs) and the columns of every part;
* ``items-<first>-<last>.csv``: the rows of items ``first..last`` (0-based, inclusive), written to a
  hidden temporary name and renamed when complete, so a part exists only whole (a kill while
  writing leaves a ``.tmp`` file that the next open removes);
* ``lock``: held (``flock``, exclusive) by the one process writing to the store; a second writer
  is refused with one line.

Opening a store whose manifest matches resumes it (the finished items are skipped); a manifest of
other work is refused, naming the first difference. Floats are written with 17 significant digits:
a part read back is bit-identical to what was computed. The parts are written and read with the
csv module (a sweep's process need not load pandas, ~0.3 s; tests/test_execution.py reads them
back with pandas too).
"""
from __future__ import annotations

import contextlib
import csv
import errno
import fcntl
import io
import json
import math
import numbers
import os
import re
from pathlib import Path

from labtool.common.errors import InputError

FORMAT = "labtool.parts"
VERSION = 1
_PART_RE = re.compile(r"^items-(\d{9,})-(\d{9,})\.csv$")


class DiskFull(InputError):
    """The disk filled up (or the folder became read-only) while writing; the message says what was kept."""


def _is_disk_full(exc: OSError) -> bool:
    return exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EFBIG)


class PartStore:
    """Parts of a chunked computation in ``folder`` (see the module docstring)."""

    def __init__(self, folder: Path, fingerprint: dict, columns: list[str], fresh: bool = False):
        self.folder = Path(folder)
        self.fingerprint = json.loads(json.dumps(fingerprint, default=str))
        self.columns = list(columns)
        self._lock_fh = None
        created = not self.folder.exists()
        try:
            self._open(fresh)
        except BaseException:        # refused or interrupted while opening: a folder it made goes again
            if created and not self.part_files_safe():
                self.remove()
            else:
                self.close()
            raise

    def part_files_safe(self) -> list:
        """``part_files``, or [] when the folder cannot be listed."""
        try:
            return self.part_files()
        except OSError:
            return []

    # ---------------------------------------------------------------- opening, locking
    def _open(self, fresh: bool) -> None:
        try:
            self.folder.mkdir(exist_ok=True)
        except OSError as exc:
            raise InputError(f"cannot create {self.folder} for the finished chunks ({exc.strerror})") from None
        self._lock()
        manifest = self.folder / "manifest.json"
        want = {"format": FORMAT, "version": VERSION, "work": self.fingerprint, "columns": self.columns}
        if manifest.exists() and not fresh:
            unknown = (f"so what work the {len(self.part_files())} finished chunk(s) in {self.folder} are of "
                       "is unknown")
            if not manifest.is_file():             # a FIFO would block its reading for ever
                raise InputError(f"{manifest} is not a regular file (a folder, a FIFO), {unknown}; move it away, "
                                 "then restore it or pass --fresh to discard those chunks")
            try:
                have = json.loads(manifest.read_text())
            except (OSError, ValueError):
                have = None
            if not isinstance(have, dict):
                raise InputError(f"{manifest} cannot be read as a JSON table, {unknown}; restore it, or pass "
                                 "--fresh to discard those chunks")
            if have != want:
                raise InputError(f"{self.folder} holds finished chunks of other work "
                                 f"({_first_difference(have, want)}); rerun the same command to finish "
                                 f"that work, or pass --fresh to discard its chunks")
        else:
            parts = self.part_files()
            if parts and not fresh:                # parts of unknown work: never mixed in, never deleted unasked
                raise InputError(f"{self.folder} holds {len(parts)} finished chunk(s) but no manifest.json "
                                 "saying what work they are of; restore it, or pass --fresh to discard those chunks")
            for p in parts:
                p[2].unlink()
            self._write_text(manifest, json.dumps(want, indent=1))
        for tmp in self.folder.glob(".*.tmp"):       # a write killed half-way
            tmp.unlink(missing_ok=True)

    def _lock(self) -> None:
        path = self.folder / "lock"
        if path.exists() and not path.is_file():
            raise InputError(f"{path} is not a regular file (a folder, a FIFO); delete it and rerun the same command")
        fh = open(path, "a+")
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            fh.seek(0)
            pid = fh.read().strip() or "?"
            fh.close()
            raise InputError(f"{self.folder} is being written by another process (pid {pid}); "
                             "wait for it to finish or write to another output") from None
        fh.seek(0)
        fh.truncate()
        fh.write(str(os.getpid()))
        fh.flush()
        self._lock_fh = fh

    def close(self) -> None:
        if self._lock_fh is not None:
            with contextlib.suppress(OSError):
                fcntl.flock(self._lock_fh, fcntl.LOCK_UN)
            self._lock_fh.close()
            self._lock_fh = None

    def remove(self) -> None:
        """Delete the store (after its parts were assembled into the final outputs)."""
        for p in self.part_files():
            p[2].unlink(missing_ok=True)
        for name in ("manifest.json", "lock"):
            (self.folder / name).unlink(missing_ok=True)
        for tmp in self.folder.glob(".*.tmp"):
            tmp.unlink(missing_ok=True)
        self.close()
        with contextlib.suppress(OSError):
            self.folder.rmdir()

    # ---------------------------------------------------------------- parts
    def part_files(self) -> list[tuple[int, int, Path]]:
        """(first, stop, path) of every finished part, by first item (stop exclusive)."""
        out = []
        for p in self.folder.iterdir():
            m = _PART_RE.match(p.name)
            if m:
                out.append((int(m.group(1)), int(m.group(2)) + 1, p))
        return sorted(out)

    def done_ranges(self) -> list[tuple[int, int]]:
        return [(a, b) for a, b, _ in self.part_files()]

    def missing(self, n_items: int) -> list[tuple[int, int]]:
        """The ranges [start, stop) of items 0..n_items-1 that no part holds."""
        out, pos = [], 0
        for a, b in self.done_ranges():
            if a > pos:
                out.append((pos, min(a, n_items)))
            pos = max(pos, b)
        if pos < n_items:
            out.append((pos, n_items))
        return [(a, b) for a, b in out if b > a]

    def write(self, start: int, stop: int, rows) -> Path:
        """Write the rows of items [start, stop) as one part (atomically): ``rows`` a sequence of
        dicts, column -> value (a column a row lacks, None or NaN: an empty cell; floats with 17
        significant digits), or a DataFrame."""
        if hasattr(rows, "to_dict"):                         # a DataFrame, without importing pandas
            rows = rows.to_dict("records")
        if len(rows) != stop - start:
            raise ValueError(f"part {start}..{stop}: {len(rows)} rows")
        path = self.folder / f"items-{start:09d}-{stop - 1:09d}.csv"
        out = io.StringIO()
        # lines end in CRLF: the csv module quotes a field holding a character of the line ending,
        # and with "\n" alone a lone "\r" in an error message would go unquoted and split its row
        writer = csv.writer(out, lineterminator="\r\n")
        writer.writerow(self.columns)
        writer.writerows([_cell(row.get(c)) for c in self.columns] for row in rows)
        self._write_text(path, out.getvalue())
        return path

    def read(self, path: Path) -> dict[str, list[str]]:
        """A part's cells as text, column -> one cell per row (empty: no value); InputError when
        its header is not the store's columns or a row has another number of cells."""
        try:
            with open(path, newline="") as fh:
                table = list(csv.reader(fh))
        except UnicodeDecodeError:
            table = []                   # bytes the encoding it was written in cannot give: damaged
        if not table or table[0] != self.columns or any(len(r) != len(self.columns) for r in table[1:]):
            raise InputError(f"{path} is damaged (not a table of the columns {', '.join(self.columns)}); delete it "
                             "and rerun the same command to compute those runs again")
        return {c: [r[k] for r in table[1:]] for k, c in enumerate(self.columns)}

    def _write_text(self, path: Path, text: str) -> None:
        tmp = path.with_name(f".{path.name}.tmp")
        try:
            with open(tmp, "w", newline="") as fh:        # the text's line endings, unchanged
                fh.write(text)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, path)
        except BaseException as exc:     # an interruption too: no temporary is left behind
            tmp.unlink(missing_ok=True)
            if not isinstance(exc, OSError):
                raise
            if _is_disk_full(exc):
                raise DiskFull(f"{exc.strerror} writing {path}") from None
            raise InputError(f"cannot write {path} ({exc.strerror})") from None


def _cell(v) -> str:
    """A value as a part's CSV cell (what pandas' to_csv wrote with float_format "%.17g")."""
    t = type(v)                   # the exact types first: an ABC isinstance costs ~1 us, 13 a row
    if t is float:
        return "" if v != v else "%.17g" % v
    if t is str:
        return v
    if t is int:
        return str(v)
    if v is None:
        return ""
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, numbers.Integral):
        return str(int(v))
    if isinstance(v, numbers.Real):
        return "" if v != v else "%.17g" % v
    return str(v)


def float_cells(cells: list[str]) -> list[float]:
    """Numeric cells of ``PartStore.read`` as floats (an empty cell: NaN)."""
    return [float(c) if c else math.nan for c in cells]


def _first_difference(have: dict, want: dict) -> str:
    for key in ("format", "version", "columns"):
        if have.get(key) != want.get(key):
            return f"{key} {have.get(key)!r}, not {want.get(key)!r}"
    hw, ww = have.get("work") or {}, want["work"]
    if not isinstance(hw, dict):
        return f"its work is {_short(hw)}, not a table"
    for key in sorted(set(hw) | set(ww)):
        if hw.get(key) != ww.get(key):
            return f"its {key} is {_short(hw.get(key))}, this run's is {_short(ww.get(key))}"
    return "a different manifest"


def _short(v) -> str:
    text = json.dumps(v, default=str)
    return text if len(text) <= 80 else text[:77] + "..."
