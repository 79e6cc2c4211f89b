"""The execution layer: chunked maps streamed to disk, resume, backends, bounded work (issues 17, 20).

The hostile cases run the real command in real processes: a SIGKILL in the middle of a design, a
second writer, a full tmpfs, a design of 10^6 runs, a scheduler address that is not one.
"""
from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import xarray as xr
from hypothesis import given, settings
from hypothesis import strategies as st

from labtool.common.errors import InputError
from labtool.execution import backends, chunked
from labtool.execution.design import hyperslabs, parts_folder
from labtool.execution.parts import PartStore
from labtool.execution.progress import LineProgress
from labtool.cli import main

LABTOOL = [sys.executable, "-m", "labtool.cli"]


def square(x):
    """A pure function of one item (top level: worker processes import it by name)."""
    return {"x": x, "y": x * x, "error": ""}


CALLS = []


def counted(x):
    CALLS.append(x)
    return square(x)


# ------------------------------------------------------------------------------------ pure parts

@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(shape=st.lists(st.integers(1, 6), min_size=1, max_size=4), data=st.data())
def test_hyperslabs_tile_a_flat_range_in_order(shape, data):
    n = math.prod(shape)
    a = data.draw(st.integers(0, n - 1))
    b = data.draw(st.integers(a + 1, n))
    grid = np.arange(n).reshape(shape)
    pos = a
    for index, offset, size in hyperslabs(a, b, tuple(shape)):
        block = grid[index]
        assert offset == pos and block.size == size
        assert np.array_equal(block.ravel(), np.arange(offset, offset + size))
        pos += size
    assert pos == b


def test_plan_tiles_the_missing_ranges_and_shrinks_at_the_end():
    cost = chunked.Cost()
    chunks = list(chunked.plan([(0, 10), (20, 25)], cost, 2, 1.0, None))
    assert chunks[0] == (0, 4)                       # probes before a cost is known
    assert sum(b - a for a, b in chunks) == 15 and all(b > a for a, b in chunks)
    cost.weighted, cost.n = 1e-3 * 10, 10            # 1 ms per item: 1 s tasks would be 1000 items
    sizes = [b - a for a, b in chunked.plan([(0, 100_000)], cost, 2, 1.0, None)]
    assert sizes[0] == 1000 and sizes[-1] < 1000 and sum(sizes) == 100_000
    assert max(sizes) <= chunked.MAX_CHUNK
    # the shrinking tail stops at MIN_TASK_S of work (50 items of 1 ms), except the very last chunk
    floor = round(chunked.MIN_TASK_S / 1e-3)
    assert min(sizes[:-1]) == floor and sizes[-1] <= floor


def test_cost_skips_the_first_item_of_each_worker():
    cost = chunked.Cost()
    cost.add(chunked.ChunkResult(0, 4, None, np.array([2.0, 1e-3, 1e-3, 1e-3]), pid=1))
    assert cost.per_item == pytest.approx(1e-3)
    cost.add(chunked.ChunkResult(4, 6, None, np.array([1e-3, 3e-3]), pid=1))    # same worker: all count
    assert cost.per_item == pytest.approx((3e-3 + 2 * 2e-3) / 5)


def test_line_progress_prints_every_interval_with_an_eta():
    lines, now = [], [0.0]
    p = LineProgress("job", lines.append, interval_s=10, clock=lambda: now[0])
    p(100, 1000)                 # start (100 resumed: not in the rate)
    now[0] = 5.0
    p(200, 1000)
    assert lines == []
    now[0] = 10.0
    p(300, 1000)                 # 200 items in 10 s: 700 left -> 35 s
    assert lines == ["job: 300/1000 (30.0 %), 10 s elapsed, ETA 35 s"]


@pytest.mark.parametrize("address,ok", [
    ("tcp://127.0.0.1:8786", "tcp://127.0.0.1:8786"), ("127.0.0.1:8786", "tcp://127.0.0.1:8786"),
    ("tls://scheduler.lab:8786", "tls://scheduler.lab:8786"), ("tcp://[::1]:8786", "tcp://[::1]:8786"),
    ("not a url", None), ("tcp://host", None), ("http://host:8786", None), ("tcp://host:99999", None),
    ("", None), ("tcp://:8786", None), ("tcp://h:87;rm -rf /", None),
])
def test_scheduler_addresses_are_checked_before_connecting(address, ok):
    if ok:
        assert backends.check_scheduler_address(address) == ok
    else:
        with pytest.raises(InputError, match="--scheduler"):
            backends.check_scheduler_address(address)


# ------------------------------------------------------------------------------------ stores, maps

def _store(tmp_path, fingerprint=None, **kw):
    return PartStore(tmp_path / "out.parts", fingerprint or {"work": "squares", "n": 50}, ["x", "y", "error"], **kw)


@pytest.mark.parametrize("backend", ["in-process", pytest.param("processes", marks=pytest.mark.slow)])
def test_map_chunked_computes_every_item_once_into_parts(tmp_path, backend):
    store = _store(tmp_path)
    be = backends.InProcess() if backend == "in-process" else backends.LocalProcesses(2)
    out = chunked.map_chunked(square, list(range(50)), store, be, chunk_items=7)
    be.close()
    assert out.done_now == 50 and out.resumed == 0 and not out.failed_chunks
    frame = pd.concat([pd.read_csv(p) for _, _, p in store.part_files()], ignore_index=True)   # pandas reads them
    assert list(frame.x) == list(range(50)) and list(frame.y) == [x * x for x in range(50)]
    cells = [store.read(p) for _, _, p in store.part_files()]                                  # and so does the store
    assert sum((c["y"] for c in cells), []) == [str(x * x) for x in range(50)]
    assert [b - a for a, b in store.done_ranges()] == [7] * 7 + [1]
    store.close()


def test_a_reopened_store_resumes_and_another_work_is_refused(tmp_path):
    store = _store(tmp_path)
    store.write(0, 10, pd.DataFrame([square(i) for i in range(10)]))
    store.write(30, 35, pd.DataFrame([square(i) for i in range(30, 35)]))
    (store.folder / ".items-000000010-000000019.csv.tmp").write_text("x,y\n1,")   # killed mid-write
    store.close()
    again = _store(tmp_path)
    assert not list(again.folder.glob(".*.tmp"))
    assert again.missing(50) == [(10, 30), (35, 50)]
    CALLS.clear()
    out = chunked.map_chunked(counted, list(range(50)), again, backends.InProcess())
    assert out.resumed == 15 and sorted(CALLS) == list(range(10, 30)) + list(range(35, 50))
    assert again.missing(50) == []
    again.close()
    with pytest.raises(InputError, match=r"holds finished chunks of other work \(its n is 50, this run's is 60\)"):
        _store(tmp_path, {"work": "squares", "n": 60})
    fresh = _store(tmp_path, {"work": "squares", "n": 60}, fresh=True)
    assert fresh.part_files() == []
    fresh.close()


def _stopped_in_compiled_code(i):
    """Item 20 meets a Ctrl-C inside a numba function: a SystemError chained to the KeyboardInterrupt."""
    if i == 20:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise SystemError("CPUDispatcher(<function run>) returned a result with an exception set") from exc
    return square(i)


@pytest.mark.hostile("interrupted")
def test_a_ctrl_c_in_compiled_code_stops_the_map_instead_of_failing_a_run(tmp_path):
    """doe run interrupted in a model's compiled loop went on, with 'run 529: SystemError:
    CPUDispatcher(...) returned a result with an exception set' left empty in the results."""
    store = _store(tmp_path)
    with pytest.raises(KeyboardInterrupt) as caught:
        chunked.map_chunked(_stopped_in_compiled_code, list(range(50)), store, backends.InProcess(), chunk_items=7)
    assert "14 of 50 items are finished and kept in" in caught.value.__notes__[0]
    assert store.done_ranges() == [(0, 7), (7, 14)]
    cells = [store.read(p) for _, _, p in store.part_files()]
    assert all(e == "" for c in cells for e in c["error"])
    store.close()


@pytest.mark.slow
def test_a_store_has_one_writer_across_processes(tmp_path):
    store = _store(tmp_path)
    code = ("import sys; from labtool.execution.parts import PartStore\n"
            f"PartStore({str(tmp_path / 'out.parts')!r}, {{'work': 'squares', 'n': 50}}, ['x', 'y', 'error'])")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode != 0 and f"being written by another process (pid {os.getpid()})" in proc.stderr
    store.close()
    assert subprocess.run([sys.executable, "-c", code], capture_output=True).returncode == 0


def test_the_estimate_is_asked_before_any_part_is_written(tmp_path):
    store = _store(tmp_path)
    seen = []

    def refuse(cost_s, n_left, workers):
        seen.append((n_left, workers, len(store.part_files())))
        raise InputError("too long")

    with pytest.raises(InputError, match="too long"):
        chunked.map_chunked(square, list(range(50)), store, backends.InProcess(), on_estimate=refuse)
    assert seen == [(50, 1, 0)] and store.part_files() == []
    store.close()


# ------------------------------------------------------------------------------------ doe run, real processes

FACTORS_100 = "factor,symbol,unit," + ",".join(f"level_{k}" for k in range(1, 11)) + "\n" + \
    "A,Fu,N," + ",".join(str(5 * k) for k in range(10)) + "\n" + \
    "B,n1,rpm," + ",".join(str(150 + 15 * k) for k in range(10)) + "\n"


FACTORS_400 = "factor,symbol,unit," + ",".join(f"level_{k}" for k in range(1, 21)) + "\n" + \
    "A,Fu,N," + ",".join(str(5 * k) for k in range(20)) + "\n" + \
    "B,n1,rpm," + ",".join(str(150 + 5 * k) for k in range(20)) + "\n"


def _doe(tmp_path, out="r.csv", *extra, model="rigid", accuracy="fast"):
    return LABTOOL + ["doe", "run", "--model", model, "--accuracy", accuracy, "--factors", str(tmp_path / "f.csv"),
                      "-o", str(tmp_path / out), *extra]


def _children(pid: int) -> list[int]:
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                if int((d / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                    out.append(int(d.name))
            except (OSError, IndexError, ValueError):
                pass
    return out


def _wait_for_parts(folder: Path, n: int, proc, timeout=120.0):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if proc.poll() is not None:
            pytest.fail(f"doe run ended before {n} parts: {proc.communicate()}")
        if folder.is_dir() and len(list(folder.glob("items-*.csv"))) >= n:
            return
        time.sleep(0.01)
    pytest.fail("no parts appeared")


@pytest.mark.slow
@pytest.mark.hostile("interrupted")
def test_a_killed_doe_run_keeps_its_chunks_and_resumes(tmp_path):
    (tmp_path / "f.csv").write_text(FACTORS_100)
    proc = subprocess.Popen(_doe(tmp_path, "r.csv", "--workers", "2", "--chunk-runs", "4"),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    folder = parts_folder(tmp_path / "r.csv")
    _wait_for_parts(folder, 3, proc)
    workers = _children(proc.pid)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert workers
    t0 = time.monotonic()          # the worker processes end with their parent (no orphans computing)
    while any(Path(f"/proc/{w}").exists() for w in workers) and time.monotonic() - t0 < 10:
        time.sleep(0.1)
    assert not any(Path(f"/proc/{w}").exists() for w in workers)
    kept = sorted(folder.glob("items-*.csv"))
    assert len(kept) >= 3 and not (tmp_path / "r.csv").exists()
    kept_runs = sum(len(pd.read_csv(p)) for p in kept)
    assert 12 <= kept_runs < 100
    again = subprocess.run(_doe(tmp_path, "r.csv", "--workers", "1"), capture_output=True, text=True)
    assert again.returncode == 0, again.stderr
    assert "resuming from the finished chunks" in again.stderr
    assert f"{kept_runs} runs resumed" in again.stdout
    assert not folder.exists()
    whole = subprocess.run(_doe(tmp_path, "whole.csv", "--workers", "1"), capture_output=True, text=True)
    assert whole.returncode == 0, whole.stderr
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "r.csv"), pd.read_csv(tmp_path / "whole.csv"))
    a, b = xr.open_dataset(tmp_path / "r.nc", engine="h5netcdf"), xr.open_dataset(tmp_path / "whole.nc", engine="h5netcdf")
    assert a.MR13D_max_Nm.dims == ("Fu", "n1") and np.array_equal(a.MR13D_max_Nm, b.MR13D_max_Nm)
    assert np.array_equal(a.run.values.ravel(), np.arange(1, 101))
    a.close(), b.close()


@pytest.mark.slow
@pytest.mark.hostile("concurrency")
def test_a_second_doe_run_into_the_same_output_is_refused(tmp_path):
    (tmp_path / "f.csv").write_text(FACTORS_400)
    first = subprocess.Popen(_doe(tmp_path, "r.csv", "--workers", "1", "--chunk-runs", "2", accuracy="standard"),
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _wait_for_parts(parts_folder(tmp_path / "r.csv"), 1, first)
    second = subprocess.run(_doe(tmp_path, "r.csv", "--workers", "1", accuracy="standard"), capture_output=True,
                            text=True, timeout=120)
    out, err = first.communicate(timeout=300)
    assert first.returncode == 0, err
    lines = second.stderr.strip().splitlines()
    assert second.returncode == 2 and lines[-1].startswith("labtool: error:")
    assert f"being written by another process (pid {first.pid})" in lines[-1]
    assert len(pd.read_csv(tmp_path / "r.csv")) == 400


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_finished_chunks_of_another_design_are_not_mixed_in(tmp_path, capsys):
    (tmp_path / "f.csv").write_text(FACTORS_100)
    from labtool.models.study.paper import paper_scene
    from labtool.models.study.doe import Design, read_factors
    other = Design(tuple(read_factors(tmp_path / "f.csv")), paper_scene(accuracy="standard"), "kinematic")
    store = PartStore(parts_folder(tmp_path / "r.csv"), other.fingerprint(), other.columns + ["wall_s", "error"])
    store.write(0, 2, pd.DataFrame([other.row(0), other.row(1)]))
    store.close()
    rc = main(["doe", "run", "--model", "kinematic", "--accuracy", "fast", "--factors", str(tmp_path / "f.csv"),
               "-o", str(tmp_path / "r.csv")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and err[-1].startswith("labtool: error:") and "holds finished chunks of other work" in err[-1]
    assert "base_scene" in err[-1] and not (tmp_path / "r.csv").exists()


@pytest.mark.hostile("silent_wrong")
def test_chunks_finished_by_other_code_are_not_mixed_in(tmp_path, capsys, monkeypatch):
    """A run killed, labtool upgraded (the models' source changed), the run resumed: refused."""
    (tmp_path / "f.csv").write_text(FACTORS_100)
    from labtool.models.dynamics import provenance
    from labtool.models.study.paper import paper_scene
    from labtool.models.study.doe import Design, read_factors
    design = Design(tuple(read_factors(tmp_path / "f.csv")), paper_scene(accuracy="fast"), "kinematic")
    before = design.fingerprint()
    monkeypatch.setattr(provenance, "models_source_sha256", lambda: "0" * 64)
    after = design.fingerprint()
    assert before["labtool"] != after["labtool"] and {k: v for k, v in before.items() if k != "labtool"} == \
        {k: v for k, v in after.items() if k != "labtool"}
    store = PartStore(parts_folder(tmp_path / "r.csv"), after, design.columns + ["wall_s", "error"])
    store.write(0, 2, pd.DataFrame([design.row(0), design.row(1)]))
    store.close()
    monkeypatch.undo()
    rc = main(["doe", "run", "--model", "kinematic", "--accuracy", "fast", "--factors", str(tmp_path / "f.csv"),
               "-o", str(tmp_path / "r.csv")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and "holds finished chunks of other work" in err[-1] and "models source sha256" in err[-1]
    assert not (tmp_path / "r.csv").exists()


def test_the_models_source_hash_follows_the_files(tmp_path):
    """An edited constant changes the hash; a compiled cache beside the sources does not."""
    import shutil

    from labtool.models.dynamics import provenance
    src = Path(provenance.__file__).resolve().parents[1]
    copy = tmp_path / "models"
    shutil.copytree(src, copy, ignore=shutil.ignore_patterns("__pycache__"))
    h0 = provenance.tree_sha256(copy)
    assert h0 == provenance.models_source_sha256()
    (copy / "dynamics" / "__pycache__").mkdir(exist_ok=True)
    (copy / "dynamics" / "__pycache__" / "x.nbi").write_bytes(b"cache")
    assert provenance.tree_sha256(copy) == h0
    dopri = copy / "dynamics" / "kernels" / "dopri5.py"
    text = dopri.read_text()
    assert "SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9," in text
    dopri.write_text(text.replace("SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9,", "SAFETY, MIN_FACTOR, MAX_FACTOR = 0.5,"))
    assert provenance.tree_sha256(copy) != h0


@pytest.mark.slow
@pytest.mark.hostile("hang")
def test_a_design_of_ten_million_runs_gives_an_estimate_and_needs_yes(tmp_path):
    # 10^7 elastic runs: hours on any machine (10^6 at ~1 ms a run on 2 workers is under the 10 min
    # that needs --yes, and runs)
    levels = ",".join(f"level_{k}" for k in range(1, 11))
    rows = [f"{n},{s},{u}," + ",".join(str(v0 + dv * k) for k in range(10))
            for n, s, u, v0, dv in [("A", "Fu", "N", 0, 5), ("B", "n1", "rpm", 150, 10), ("C", "Jt", "-", 1, 0.5),
                                    ("D", "Kc", "-", 1, 0.1), ("E", "lw", "mm", 4, 0.5), ("F", "k", "-", 0.1, 0.1),
                                    ("G", "j", "mm", 0.016, 0.016)]]
    (tmp_path / "f.csv").write_text(f"factor,symbol,unit,{levels}\n" + "\n".join(rows) + "\n")
    t0 = time.monotonic()
    proc = subprocess.run(_doe(tmp_path, "r.csv", model="elastic"), capture_output=True, text=True,
                          timeout=120, stdin=subprocess.DEVNULL)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert lines[0].startswith("labtool: error: this design of 10000000 runs would take about ") and "pass --yes" in lines[0]
    assert "10000000 runs x " in lines[0] and "more than 10 min" in lines[0]
    assert time.monotonic() - t0 < 120
    assert not parts_folder(tmp_path / "r.csv").exists() and not (tmp_path / "r.csv").exists()


@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("address", ["not a url", "tcp://", "localhost"])
def test_a_scheduler_that_is_not_an_address_is_one_line_at_once(tmp_path, capsys, address):
    t0 = time.monotonic()
    rc = main(["doe", "run", "--model", "kinematic", "--scheduler", address, "-o", str(tmp_path / "r.csv")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith("labtool: error: --scheduler")
    assert time.monotonic() - t0 < 5.0


@pytest.mark.slow
@pytest.mark.hostile("full_disk")
def test_a_full_disk_keeps_the_finished_chunks_and_says_so(tmp_path, small_disk):
    disk = small_disk(64)
    (disk / "f.csv").write_text("factor,symbol,unit,level_1,level_2,level_3,level_4\n"
                                "A,Fu,N,0,10,20,30\nB,n1,rpm,150,200,250,300\nC,Jt,-,1,2,3,4\n")
    cmd = LABTOOL + ["doe", "run", "--model", "kinematic", "--factors", str(disk / "f.csv"), "--workers", "1",
                     "--chunk-runs", "1", "-o", str(disk / "r.csv")]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and lines[0].startswith("labtool: error: disk full"), proc.stderr
    folder = parts_folder(disk / "r.csv")
    kept = sum(len(pd.read_csv(p)) for p in folder.glob("items-*.csv"))
    assert 0 < kept < 64 and f"{kept} of 64 runs are finished and kept in {folder}" in lines[0]
    assert not (disk / "r.csv").exists() and not list(disk.glob(".*.tmp")) and not list(folder.glob(".*.tmp"))
    subprocess.run(["mount", "-o", "remount,size=4m", str(disk)], check=True)
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    assert f"{kept} runs resumed" in again.stdout and len(pd.read_csv(disk / "r.csv")) == 64


# ------------------------------------------------------------------------ the parts' CSV, against pandas

_cells = st.one_of(st.none(), st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**12, 10**12),
                   st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=12))


@settings(max_examples=60, deadline=None)
@given(rows=st.lists(st.fixed_dictionaries({"a": _cells, "b": st.floats(allow_nan=True), "error": st.text(max_size=20)}),
                     min_size=1, max_size=8))
@pytest.mark.slow
def test_a_part_reads_back_as_pandas_reads_it(tmp_path_factory, rows):
    """The parts are written with the csv module; pandas (what wrote and read them before) reads
    the same values: floats bit for bit, NaN and None as empty cells, any text (commas, quotes,
    line breaks) whole."""
    from labtool.execution.parts import float_cells
    store = PartStore(tmp_path_factory.mktemp("parts") / "p.parts", {"w": 1}, ["a", "b", "error"])
    path = store.write(0, len(rows), rows)
    cells = store.read(path)
    frame = pd.read_csv(path, keep_default_na=False, na_values=[""], dtype={"a": str, "error": str})
    b = np.array([math.nan if r["b"] is None else r["b"] for r in rows], dtype=float)
    assert np.array_equal(np.array(float_cells(cells["b"])), b, equal_nan=True)
    assert np.array_equal(frame["b"].to_numpy(dtype=float), b, equal_nan=True)
    assert cells["error"] == [r["error"] for r in rows]
    assert [("" if v != v else v) for v in frame["error"]] == [r["error"] for r in rows]
    for cell, v in zip(cells["a"], (r["a"] for r in rows)):
        if v is None or (isinstance(v, float) and v != v):
            assert cell == ""
        elif isinstance(v, (int, float)):
            assert float(cell) == v
        else:
            assert cell == v
    store.close()


def test_a_damaged_part_is_refused_in_one_line(tmp_path):
    store = _store(tmp_path)
    path = store.write(0, 2, [square(0), square(1)])
    path.write_text("x,y,error\n0,0,\n1,1\n")                  # a row short of a cell
    with pytest.raises(InputError, match="is damaged"):
        store.read(path)
    path.write_text("x,y\n0,0\n1,1\n")                         # another table
    with pytest.raises(InputError, match="is damaged"):
        store.read(path)
    store.close()


@pytest.mark.slow
def test_a_design_run_loads_no_pandas(tmp_path):
    """An elastic sweep's process reads its factor file, runs (the indicator path: no Dataset),
    writes its parts and assembles its outputs without pandas (0.3 s of a command's fixed cost)."""
    (tmp_path / "f.csv").write_text(FACTORS_100)
    code = f"""
import sys
from labtool.cli import main
rc = main(["doe", "run", "--model", "elastic", "--accuracy", "fast", "--factors", {str(tmp_path / 'f.csv')!r}, "-o", {str(tmp_path / 'r.csv')!r}])
print(rc, "pandas" in sys.modules)
"""
    out = subprocess.run([sys.executable, "-c", code], cwd=Path(__file__).resolve().parents[1], capture_output=True,
                         text=True, timeout=300)
    assert out.stdout.split()[-2:] == ["0", "False"], out.stdout + out.stderr
    assert len(pd.read_csv(tmp_path / "r.csv")) == 100


@pytest.mark.slow
def test_a_part_with_text_where_a_number_belongs_is_refused_in_one_line(tmp_path, capsys):
    (tmp_path / "f.csv").write_text(FACTORS_100)
    from labtool.models.study.paper import paper_scene
    from labtool.models.study.doe import Design, read_factors
    design = Design(tuple(read_factors(tmp_path / "f.csv")), paper_scene(accuracy="fast"), "kinematic")
    rows = [design.row(i) for i in range(100)]
    rows[7][design.responses[0]] = "12.5 N m"                  # a hand-edited or damaged cell
    store = PartStore(parts_folder(tmp_path / "r.csv"), design.fingerprint(), design.columns + ["wall_s", "error"])
    store.write(0, 100, rows)
    store.close()
    rc = main(["doe", "run", "--model", "kinematic", "--accuracy", "fast", "--factors", str(tmp_path / "f.csv"),
               "-o", str(tmp_path / "r.csv")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and err[-1].startswith("labtool: error:") and "is damaged" in err[-1]
    assert not (tmp_path / "r.csv").exists()


def test_a_part_cell_is_the_same_text_for_exact_and_derived_types():
    """The exact-type fast path of parts._cell writes what the generic path writes."""
    import numpy as np

    from labtool.execution.parts import _cell

    assert _cell(0.1) == _cell(np.float64(0.1)) == "0.10000000000000001"
    assert _cell(float("nan")) == _cell(np.float64("nan")) == _cell(None) == ""
    assert _cell(-0.0) == "-0"
    assert _cell(3) == _cell(np.int64(3)) == "3"
    assert _cell(True) == "True"
    assert _cell("a,\r\"b") == "a,\r\"b"
