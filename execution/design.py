"""A factorial design (``labtool.models.study.doe.Design``) run in chunks, streamed to disk, then assembled.

``run_design(design, csv_path, nc_path, backend)`` maps ``design.row`` over the runs with
:func:`labtool.execution.chunked.map_chunked`; the finished chunks go to ``<csv>.parts/``
(:class:`labtool.execution.parts.PartStore`, keyed by the design's fingerprint: a rerun of the same
design resumes, another design is refused). When every run is done the parts are assembled, one
part at a time, into

* the results CSV shaped like the paper's Tables 2/3 (run, level columns, responses; counts as
  integers, a failed run's cells empty), and
* the NetCDF with one dimension per factor (its level values as the coordinate, CF units and long
  names), one variable per response plus ``run`` and ``wall_s``, written hyperslab by hyperslab
  (a chunk of consecutive runs is a few rectangular blocks of the factor grid),

both written to temporary names and renamed together; then the parts folder is removed. Memory
stays that of the chunks in flight and of NC_FLUSH_ROWS runs' columns, whatever the number of runs.
"""
from __future__ import annotations

import csv
import dataclasses
import math
import shutil
from pathlib import Path

import numpy as np

from labtool.common.errors import InputError, OutputError
from labtool.common.files import OutputSet
from labtool.execution.chunked import map_chunked
from labtool.execution.parts import DiskFull, PartStore, _is_disk_full, float_cells

EXTRA_COLUMNS = ("wall_s", "error")
MAX_LISTED_FAILURES = 100
# disk needed per run at the least (bytes: its CSV row and NetCDF values), checked against the free
# space before anything runs; a disk that fills later is caught where it fills
BYTES_PER_RUN = 100
NC_FLUSH_ROWS = 1 << 18     # runs gathered from consecutive parts per NetCDF write (~2 MB a column)


@dataclasses.dataclass
class DesignOutcome:
    n_runs: int
    resumed: int
    failures: dict[int, str]         # run number -> reason (first MAX_LISTED_FAILURES)
    n_failed: int
    where: str
    wall_s: float
    cost_s: float | None


def parts_folder(csv_path: Path) -> Path:
    return Path(str(csv_path) + ".parts")


def run_design(design, csv_path: Path, nc_path: Path, backend=None, *, chunk_items=None, fresh=False,
               on_estimate=None, progress=None, history: str = "") -> DesignOutcome:
    """Run every run of ``design`` not finished yet and write the CSV and the NetCDF."""
    design.validate()
    csv_path, nc_path = Path(csv_path), Path(nc_path)
    check_free_space(csv_path.parent, len(design))
    store = None
    try:
        store = PartStore(parts_folder(csv_path), design.fingerprint(), design.columns + list(EXTRA_COLUMNS),
                          fresh=fresh)
        _check_parts(store, len(design))
        out = map_chunked(design.row, range(len(design)), store, backend, chunk_items=chunk_items,
                          on_estimate=on_estimate, progress=progress, unit="runs")
        if out.failed_chunks:
            a, b, msg = out.failed_chunks[0]
            runs = sum(y - x for x, y, _ in out.failed_chunks)
            raise InputError(f"{len(out.failed_chunks)} chunk(s) ({runs} runs, first runs {a + 1}-{b}) failed on the "
                             f"workers: {msg}; the finished runs are kept in {store.folder}, rerun to retry")
        failures, n_failed = assemble(design, store, csv_path, nc_path, history)
    except BaseException as exc:
        if store is None:                # PartStore cleans up what it made when it cannot open
            raise
        if not store.part_files():      # refused or failed before any run finished: leave nothing
            store.remove()
        elif isinstance(exc, KeyboardInterrupt) and not getattr(exc, "__notes__", None):
            # stopped before the runs (checking the parts) or while the results were assembled
            done = sum(b - a for a, b, _ in store.part_files())
            exc.add_note(f"all {done} runs are finished and kept in {store.folder}; the same command writes the "
                         "results without computing again" if done == len(design) else
                         f"{done} of {len(design)} runs are finished and kept in {store.folder}; the same command "
                         "resumes")
        raise
    finally:
        if store is not None:
            store.close()
    store.remove()
    return DesignOutcome(len(design), out.resumed, failures, n_failed, out.where, out.wall_s, out.cost_s)


def disk_bytes(design) -> float:
    """About the most disk a run of ``design`` uses (bytes): its parts (up to 17 digits a number,
    ~19 bytes a cell) while it runs, and the results CSV (~8 bytes a cell) and the NetCDF (8 bytes a
    response, run number and wall time) they are assembled into before the parts are removed."""
    cells = len(design.columns) + len(EXTRA_COLUMNS)
    return len(design) * (19.0 * cells + 8.0 * len(design.columns) + 8.0 * (len(design.responses) + 2))


def check_free_space(folder: Path, n_runs: int) -> None:
    need = n_runs * BYTES_PER_RUN
    free = shutil.disk_usage(folder if str(folder) else ".").free
    if need > free:
        raise InputError(f"a design of {n_runs} runs needs about {need / 1e6:.3g} MB in {folder or '.'}, "
                         f"{free / 1e6:.3g} MB are free; free space or write elsewhere")


def assemble(design, store: PartStore, csv_path: Path, nc_path: Path, history: str):
    """Parts -> CSV + NetCDF (temporary names, renamed together). Returns (failures, n_failed)."""
    import h5netcdf
    from labtool.models.study.doe import COUNT_RESPONSES

    parts = store.part_files()
    _check_tiling(parts, len(design), store)
    # HDF5 does not fail cleanly on a full disk: refuse before writing when the outputs cannot fit
    need = sum(p.stat().st_size for _, _, p in parts) + 8 * len(design) * (len(design.responses) + 2) + 65536
    free = shutil.disk_usage(csv_path.parent if str(csv_path.parent) else ".").free
    if need > free:
        raise DiskFull(f"{csv_path} and {nc_path} need about {need / 1e6:.3g} MB, {free / 1e6:.3g} MB are free: "
                       f"nothing written; all {len(design)} runs are finished and kept in {store.folder}; free "
                       "space and rerun the same command to write the results without computing again")
    failures, n_failed = {}, 0
    pending = []                  # consecutive parts' columns not yet in the NetCDF
    out = OutputSet()             # both renamed, or neither (a failed rename puts the first back)
    try:
        tmp_csv, tmp_nc = out.add(csv_path), out.add(nc_path)
        with open(tmp_csv, "w") as fh, h5netcdf.File(tmp_nc, "w") as nc:
            variables = _netcdf_layout(nc, design)
            writer = csv.writer(fh, lineterminator="\n")
            for k, (a, b, path) in enumerate(parts):
                cells = store.read(path)
                try:
                    runs = np.array(float_cells(cells["run"]))
                    columns = {name: runs.astype(np.int64) if name == "run" else np.array(float_cells(cells[name]))
                               for name in variables}
                    for name in design.level_columns:        # copied as text into the results CSV
                        float_cells(cells[name])
                except ValueError:
                    raise InputError(f"{path} is damaged (a cell that holds a number holds text); delete it and "
                                     "rerun the same command to compute those runs again") from None
                if runs.size != b - a or not np.array_equal(runs, np.arange(a + 1, b + 1)):
                    raise InputError(f"{path} is damaged (its rows are not runs {a + 1}-{b}); delete it and "
                                     "rerun the same command to compute those runs again")
                for name, idx in zip(design.level_columns, np.unravel_index(columns["run"] - 1, design.shape)):
                    if cells[name] != [str(k + 1) for k in idx.tolist()]:   # copied as text into the CSV
                        raise InputError(f"{path} is damaged (its {name} column is not the levels of runs "
                                         f"{a + 1}-{b} of this design); delete it and rerun the same command "
                                         "to compute those runs again")
                for name in COUNT_RESPONSES:              # written as integers into the CSV
                    if name in columns:
                        v = columns[name][[c != "" for c in cells[name]]]
                        if not (np.isfinite(v).all() and (v == np.round(v)).all()):
                            raise InputError(f"{path} is damaged (its {name} column holds a count that is not "
                                             "a whole number); delete it and rerun the same command to compute "
                                             "those runs again")
                for run, msg in zip(runs, cells["error"]):
                    if msg:
                        n_failed += 1
                        if len(failures) < MAX_LISTED_FAILURES:
                            failures[int(run)] = msg
                _write_csv_part(writer, cells, design, header=(k == 0))
                pending.append((a, b, columns))
                if sum(y - x for x, y, _ in pending) >= NC_FLUSH_ROWS or k == len(parts) - 1:
                    _write_nc_block(variables, pending, design.shape)
                    pending.clear()
            nc.attrs["failed_runs"] = _failed_text(failures, n_failed)
            nc.attrs["history"] = history
        out.commit()
    except (OSError, OutputError) as exc:
        out.rollback()
        kept = f"all {len(design)} runs are finished and kept in {store.folder}"
        again = "the same command to write the results without computing again"
        if isinstance(exc, OutputError) and exc.errno is None:     # a file of the set not created or renamed
            raise DiskFull(f"{exc}; {kept}; once that is fixed, rerun {again}") from None
        full = exc.errno is not None if isinstance(exc, OutputError) else _is_disk_full(exc)
        reason = "disk full" if full else exc.strerror or str(exc)
        advice = "free space and rerun" if full else "once that is fixed, rerun"
        raise DiskFull(f"{reason} while writing {csv_path} and {nc_path}: neither was written; {kept}; "
                       f"{advice} {again}") from None
    except BaseException:
        out.rollback()
        raise
    return failures, n_failed


def _write_nc_block(variables: dict, pending: list, shape: tuple[int, ...]) -> None:
    """The columns of consecutive parts [(a, b, {name: column}), ...] into the NetCDF variables as
    one range of runs: a few hyperslabs per variable instead of a few per part (each write costs
    HDF5 ~0.5 ms, as much as an elastic run)."""
    a, b = pending[0][0], pending[-1][1]
    for name, var in variables.items():
        column = np.concatenate([cols[name] for _, _, cols in pending])
        for index, offset, size in hyperslabs(a, b, shape):
            var[index] = column[offset - a: offset - a + size].reshape(_block_shape(index))


def _check_parts(store: PartStore, n: int) -> None:
    """Before any run: every part's runs lie in the design and no two parts hold the same run (a part
    renamed or copied by hand; the missing runs are then computed, but the table could not be made)."""
    prev = None
    for a, b, path in store.part_files():
        if not path.is_file():                 # a FIFO would block its reading for ever
            raise InputError(f"{path} is not a regular file (a folder, a FIFO or a broken link); delete it and "
                             "rerun the same command")
        if not a < b <= n:
            raise InputError(f"{path} is not a part of this design (its name says runs {a + 1}-{b}, the design has "
                             f"runs 1-{n}); delete it and rerun the same command")
        if prev is not None and a < prev[1]:
            last = min(b, prev[1])
            runs = f"run {last}" if last == a + 1 else f"runs {a + 1}-{last}"
            raise InputError(f"{path} and {prev[2].name} both hold {runs}; delete one of "
                             "them and rerun the same command")
        if prev is None or b > prev[1]:
            prev = (a, b, path)


def _check_tiling(parts, n: int, store) -> None:
    pos = 0
    for a, b, path in parts:
        if a != pos:
            raise InputError(f"{store.folder}: runs {pos + 1}-{a} are missing, or {path.name} overlaps "
                             "another part; rerun the same command")
        pos = b
    if pos != n:
        raise InputError(f"{store.folder}: runs {pos + 1}-{n} are missing; rerun the same command")


def _write_csv_part(writer, cells: dict, design, header: bool) -> None:
    """A part's rows in the results table: the run and level columns as integers, the counts
    rounded to integers, every other number with 10 significant digits, an empty cell for no value
    (a failed run's)."""
    from labtool.models.study.doe import COUNT_RESPONSES
    columns = design.columns
    as_text = set(["run"] + design.level_columns)

    def fmt(c):
        if c in as_text:
            return lambda v: v
        if c in COUNT_RESPONSES:
            return lambda v: str(int(round(float(v)))) if v else ""
        return lambda v: "%.10g" % float(v) if v else ""
    formats = [fmt(c) for c in columns]
    if header:
        writer.writerow(columns)
    writer.writerows([f(v) for f, v in zip(formats, row)] for row in zip(*(cells[c] for c in columns)))


def _failed_text(failures: dict, n_failed: int) -> str:
    if not n_failed:
        return "none"
    text = ",".join(map(str, sorted(failures)))
    return text if n_failed <= len(failures) else f"{text},... ({n_failed} in all)"


def _netcdf_layout(nc, design) -> dict:
    """Dimensions, coordinates and empty variables; returns {column: variable} to fill."""
    from labtool.models.study.doe import RESPONSE_ATTRS
    dims = tuple(f.symbol for f in design.factors)
    nc.dimensions = {f.symbol: len(f.levels) for f in design.factors}
    for f in design.factors:
        v = nc.create_variable(f.symbol, (f.symbol,), float)
        v[:] = np.asarray(f.levels, dtype=float)
        v.attrs.update(design.coordinate_attrs(f))
    chunks = _chunking(design.shape)
    out = {}
    for name in design.responses:
        units, long_name = RESPONSE_ATTRS.get(name, ("1", name))
        out[name] = nc.create_variable(name, dims, float, fillvalue=np.nan, chunks=chunks)
        out[name].attrs.update(units=units, long_name=long_name)
    out["run"] = nc.create_variable("run", dims, np.int64, chunks=chunks)
    out["run"].attrs.update(units="1", long_name="run number in the paper's order")
    out["wall_s"] = nc.create_variable("wall_s", dims, float, fillvalue=np.nan, chunks=chunks)
    out["wall_s"].attrs.update(units="s", long_name="wall time of the run's simulation")
    nc.attrs.update(model=design.model, title="labtool doe run: full factorial simulated experiment")
    return out


def _chunking(shape):
    """HDF5 chunks of at most ~64k values, whole trailing dimensions first (they are written together)."""
    chunks, size = [], 1
    for n in reversed(shape):
        c = max(1, min(n, 65536 // size))
        chunks.append(c)
        size *= c
    return tuple(reversed(chunks))


def hyperslabs(a: int, b: int, shape: tuple[int, ...]):
    """The flat C-order range [a, b) of an array of ``shape`` as rectangular blocks: yields
    (index tuple of ints and slices, flat offset of the block's first element, number of elements)."""
    if a >= b:
        return
    if len(shape) == 1:
        yield (slice(a, b),), a, b - a
        return
    inner = math.prod(shape[1:])
    i0, r0 = divmod(a, inner)
    i1, r1 = divmod(b, inner)
    if i0 == i1:
        for idx, off, size in hyperslabs(r0, r1, shape[1:]):
            yield (slice(i0, i0 + 1),) + idx, i0 * inner + off, size
        return
    if r0:
        for idx, off, size in hyperslabs(r0, inner, shape[1:]):
            yield (slice(i0, i0 + 1),) + idx, i0 * inner + off, size
        i0 += 1
    if i1 > i0:
        yield (slice(i0, i1),) + tuple(slice(0, n) for n in shape[1:]), i0 * inner, (i1 - i0) * inner
    if r1:
        for idx, off, size in hyperslabs(0, r1, shape[1:]):
            yield (slice(i1, i1 + 1),) + idx, i1 * inner + off, size


def _block_shape(index) -> tuple[int, ...]:
    return tuple(s.stop - s.start for s in index)


__all__ = ["run_design", "DesignOutcome", "hyperslabs", "parts_folder", "disk_bytes", "DiskFull"]
