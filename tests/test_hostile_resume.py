"""Hostile inputs to a resumed `doe run`: a `results.csv.parts/` folder tampered with by hand.

Every case builds the finished parts of a small design (3 x 3 runs, made-up values: nothing is
simulated), tampers with them, and runs the real command: it must end with one
`labtool: error:` line and exit 2, or give the right table, never exit 0 with a wrong one or
lose the finished parts.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from labtool.execution.design import parts_folder
from labtool.execution.parts import PartStore
from labtool.cli import main

FACTORS_9 = "factor,symbol,unit,level_1,level_2,level_3\nA,Fu,N,0,5,10\nB,n1,rpm,150,165,180\n"


def _design(tmp_path: Path, model: str):
    from labtool.models.study.paper import paper_scene
    from labtool.models.study.doe import Design, read_factors
    (tmp_path / "f.csv").write_text(FACTORS_9)
    return Design(tuple(read_factors(tmp_path / "f.csv")), paper_scene(accuracy="fast"), model)


def _finished(tmp_path: Path, model: str = "rigid", ranges=((0, 3), (3, 6), (6, 9))) -> Path:
    """The parts folder of the design with ``ranges`` finished (made-up responses); returns it."""
    design = _design(tmp_path, model)
    store = PartStore(parts_folder(tmp_path / "r.csv"), design.fingerprint(), design.columns + ["wall_s", "error"])

    def row(i):
        r = {"run": i + 1, **dict(zip(design.level_columns, design.level_indices(i)))}
        for k, c in enumerate(design.responses):
            r[c] = i % 3 if c in ("jumps", "impacts") else float(10 * i + k)
        return {**r, "wall_s": 0.01, "error": ""}
    for a, b in ranges:
        store.write(a, b, [row(i) for i in range(a, b)])
    store.close()
    return store.folder


def _run(tmp_path: Path, capsys, model: str = "rigid", *extra) -> tuple[int, list[str]]:
    rc = main(["doe", "run", "--model", model, "--accuracy", "fast", "--factors", str(tmp_path / "f.csv"),
               "-o", str(tmp_path / "r.csv"), *extra])
    return rc, capsys.readouterr().err.strip().splitlines()


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_bytes().decode()
    assert old in text
    path.write_bytes(text.replace(old, new, 1).encode())


def _refused(rc, err, *words) -> None:
    assert rc == 2 and err and err[-1].startswith("labtool: error:"), err
    for w in words:
        assert w in err[-1], err[-1]


@pytest.mark.hostile("silent_wrong")
def test_a_part_whose_level_columns_were_edited_is_refused(tmp_path, capsys):
    """Run 2 is levels (1, 2) of this design; a part saying (3, 2) was copied into the table as is."""
    folder = _finished(tmp_path)
    part = folder / "items-000000000-000000002.csv"
    _edit(part, "\r\n2,1,2,", "\r\n2,3,2,")
    rc, err = _run(tmp_path, capsys)
    _refused(rc, err, "items-000000000-000000002.csv", "is damaged", "levels")
    assert not (tmp_path / "r.csv").exists() and part.exists()


@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("cell", ["nan", "inf", "-inf", "1.5"])
def test_a_part_whose_count_is_not_a_whole_number_is_refused(tmp_path, capsys, cell):
    """jumps is a count, written as an integer: 'nan' or 'inf' there ended in exit 70 (int(round(nan)))."""
    folder = _finished(tmp_path)
    part = folder / "items-000000003-000000005.csv"
    _edit(part, ",44,1,0.01,", f",44,{cell},0.01,")               # run 5's jumps
    rc, err = _run(tmp_path, capsys)
    _refused(rc, err, "items-000000003-000000005.csv", "is damaged", "jumps")
    assert not (tmp_path / "r.csv").exists() and part.exists()


@pytest.mark.hostile("silent_wrong")
def test_parts_without_their_manifest_are_kept_and_refused(tmp_path, capsys):
    """A deleted manifest.json: the finished parts were deleted without a word and every run computed again."""
    folder = _finished(tmp_path, "kinematic", ranges=((0, 3), (3, 6)))
    (folder / "manifest.json").unlink()
    rc, err = _run(tmp_path, capsys, "kinematic")
    _refused(rc, err, "manifest.json", "--fresh")
    assert (folder / "items-000000000-000000002.csv").exists() and (folder / "items-000000003-000000005.csv").exists()
    assert not (tmp_path / "r.csv").exists()


@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("work", [[1], "x", 3, None])
def test_a_manifest_whose_work_is_not_a_table_is_refused(tmp_path, capsys, work):
    folder = _finished(tmp_path)
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["work"] = work
    (folder / "manifest.json").write_text(json.dumps(manifest))
    rc, err = _run(tmp_path, capsys)
    _refused(rc, err, "holds finished chunks of other work", "--fresh")
    assert len(list(folder.glob("items-*.csv"))) == 3


def _rename(folder: Path, old: str, new: str) -> None:
    (folder / old).rename(folder / new)


def _copy(folder: Path, old: str, new: str) -> None:
    (folder / new).write_bytes((folder / old).read_bytes())


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("tamper,named", [
    (lambda f: _rename(f, "items-000000000-000000002.csv", "items-000000000-000000003.csv"), "items-000000003-000000005.csv"),
    (lambda f: _copy(f, "items-000000003-000000005.csv", "items-0000000003-000000005.csv"), "items-000000003-000000005.csv"),
    (lambda f: _copy(f, "items-000000003-000000005.csv", "items-000000002-000000004.csv"), "items-000000002-000000004.csv"),
    (lambda f: _rename(f, "items-000000006-000000008.csv", "items-000000008-000000006.csv"), "items-000000008-000000006.csv"),
    (lambda f: _copy(f, "items-000000006-000000008.csv", "items-000000009-000000011.csv"), "items-000000009-000000011.csv"),
], ids=["longer-name", "same-range", "overlap", "backwards", "past-the-end"])
def test_parts_that_overlap_or_lie_outside_the_design_are_refused_before_any_run(tmp_path, capsys, tamper, named):
    """Before: 'runs 5-3 are missing, or ... overlaps another part; rerun the same command', and the
    same refusal at every rerun (a backwards name even had runs computed again first)."""
    folder = _finished(tmp_path, "kinematic")
    tamper(folder)
    before = sorted(p.name for p in folder.iterdir())
    rc, err = _run(tmp_path, capsys, "kinematic")
    _refused(rc, err, named, "delete")
    assert "rerun the same command" not in err[-1] or "delete" in err[-1].split("rerun")[0]
    assert sorted(p.name for p in folder.iterdir()) == before and not (tmp_path / "r.csv").exists()


@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("workers", ["99999999999999999999", "100000"])
def test_more_workers_than_the_machine_can_run_is_refused_at_once(tmp_path, capsys, workers):
    """--workers 99999999999999999999 ended in exit 70 (OverflowError in the process pool); 100000
    was taken, and with runs left to do it would have started a process per queued chunk."""
    folder = _finished(tmp_path, "kinematic")
    rc, err = _run(tmp_path, capsys, "kinematic", "--workers", workers)
    _refused(rc, err, "--workers", "cores")
    assert len(list(folder.glob("items-*.csv"))) == 3 and not (tmp_path / "r.csv").exists()


@pytest.mark.hostile("silent_wrong")
def test_a_netcdf_named_as_the_parts_folder_is_refused_before_any_run(tmp_path, capsys, monkeypatch):
    """--netcdf r.csv.parts: every run was computed, then 'Is a directory while writing r.csv and
    r.csv.parts: neither was written; ... rerun the same command' - with r.csv written, and every
    rerun the same."""
    _design(tmp_path, "kinematic")
    monkeypatch.chdir(tmp_path)
    rc, err = _run(tmp_path, capsys, "kinematic", "--netcdf", "r.csv.parts")
    _refused(rc, err, "--netcdf", "r.csv.parts")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.csv"]


@pytest.mark.hostile("traceback")
def test_a_part_with_bytes_that_are_not_utf8_is_refused(tmp_path, capsys):
    """A byte 0xff in a part ended in exit 70 (UnicodeDecodeError)."""
    folder = _finished(tmp_path)
    part = folder / "items-000000003-000000005.csv"
    part.write_bytes(part.read_bytes().replace(b",44,", b",4\xff4,"))
    rc, err = _run(tmp_path, capsys)
    _refused(rc, err, "items-000000003-000000005.csv", "is damaged")
    assert part.exists() and not (tmp_path / "r.csv").exists()


@pytest.mark.hostile("silent_wrong")
def test_a_part_that_is_a_folder_is_named_so(tmp_path, capsys):
    """Before: 'Is a directory while writing r.csv and r.nc: ... free space and rerun the same command'."""
    folder = _finished(tmp_path)
    part = folder / "items-000000003-000000005.csv"
    part.unlink()
    part.mkdir()
    rc, err = _run(tmp_path, capsys)
    _refused(rc, err, "items-000000003-000000005.csv", "not a regular file", "delete it")
    assert "free space" not in err[-1] and not (tmp_path / "r.csv").exists()


@pytest.mark.slow
@pytest.mark.hostile("hang")
def test_a_part_that_is_a_fifo_is_refused_without_waiting(tmp_path):
    """A FIFO named as a part: 'doe run' waited for ever for a writer, opening it."""
    folder = _finished(tmp_path)
    part = folder / "items-000000003-000000005.csv"
    part.unlink()
    os.mkfifo(part)
    out = subprocess.run([sys.executable, "-m", "labtool.cli", "doe", "run", "--model", "rigid", "--accuracy", "fast",
                          "--factors", str(tmp_path / "f.csv"), "-o", str(tmp_path / "r.csv")],
                         capture_output=True, text=True, timeout=120, cwd=Path(__file__).resolve().parents[1])
    err = out.stderr.strip().splitlines()
    _refused(out.returncode, err, "items-000000003-000000005.csv", "not a regular file")


# ------------------------------------------------------------------------------------ campaign run

def _campaign_point(tmp_path: Path, steps) -> tuple[Path, Path]:
    """A plan (test_campaign_run.quick_plan) and its first point's folder holding a recording and a
    point.json with ``steps`` (a function of the acquire step's true inputs digest); returns (plan,
    campaign folder)."""
    from labtool.campaign.plan import load_plan
    from labtool.campaign.runner import _inputs, point_folder
    from labtool.campaign.state import PointState, sha256_file
    from test_campaign_run import quick_plan
    plan_path = quick_plan(tmp_path)           # its first point is the one made here
    plan = load_plan(plan_path)
    out = tmp_path / "camp"
    folder = point_folder(out, plan.points[0])
    folder.mkdir(parents=True)
    (folder / "recording.h5").write_bytes(b"a finished recording")
    state = PointState(folder, plan.points[0].name, plan.points[0].spec())
    doc = {"format": "labtool.campaign.point", "format_version": 1, "name": plan.points[0].name,
           "spec": plan.points[0].spec(),
           "steps": steps(_inputs(plan, plan.points[0], state, "acquire"), sha256_file(folder / "recording.h5"))}
    (folder / "point.json").write_text(json.dumps(doc))
    return plan_path, out


@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("record", [
    lambda inputs, sha: {"inputs": inputs, "outputs": ["recording.h5"]},
    lambda inputs, sha: {"inputs": inputs, "outputs": {"recording.h5": 5}},
    lambda inputs, sha: {"inputs": [inputs], "outputs": {"recording.h5": sha}},
], ids=["outputs-list", "digest-number", "inputs-list"])
def test_a_point_record_whose_step_is_malformed_is_refused(tmp_path, capsys, record):
    """point.json's acquire step with its outputs a list ended in exit 70 (AttributeError: 'list'
    object has no attribute 'items')."""
    plan, out = _campaign_point(tmp_path, lambda inputs, sha: {"acquire": record(inputs, sha)})
    rc = main(["campaign", "run", str(plan), "-o", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    _refused(rc, err, "point.json", "acquire")
    assert (out / "points" / "01_180rpm" / "recording.h5").read_bytes() == b"a finished recording"


def _complete_recording(path: Path, complete: bool) -> bytes:
    import h5py
    with h5py.File(path, "w") as h:
        h.attrs["complete"] = complete
        h["signals"] = [[1.0, 2.0, 3.0]]
    return path.read_bytes()


@pytest.mark.hostile("silent_wrong")
def test_a_finished_recording_that_point_json_does_not_record_is_kept(tmp_path, capsys):
    """point.json deleted beside a finished recording: 'its acquisition did not finish (killed or
    stopped); recording it again' - the measurement was replaced, exit 0."""
    plan, out = _campaign_point(tmp_path, lambda inputs, sha: {})
    folder = out / "points" / "01_180rpm"
    (folder / "point.json").unlink()
    before = _complete_recording(folder / "recording.h5", True)
    rc = main(["campaign", "run", str(plan), "-o", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    _refused(rc, err, "01_180rpm", "recording.h5", "--redo 01_180rpm")
    assert (folder / "recording.h5").read_bytes() == before


@pytest.mark.slow
@pytest.mark.hostile("hang")
def test_a_point_record_that_is_a_fifo_is_refused_without_waiting(tmp_path):
    """A FIFO named point.json: 'campaign run' waited for ever for a writer, reading it."""
    plan, out = _campaign_point(tmp_path, lambda inputs, sha: {})
    record = out / "points" / "01_180rpm" / "point.json"
    record.unlink()
    os.mkfifo(record)
    proc = subprocess.run([sys.executable, "-m", "labtool.cli", "campaign", "run", str(plan), "-o", str(out)],
                          capture_output=True, text=True, timeout=120, cwd=Path(__file__).resolve().parents[1])
    _refused(proc.returncode, proc.stderr.strip().splitlines(), "point.json", "not a regular file")


@pytest.mark.slow
@pytest.mark.hostile("hang")
def test_a_manifest_that_is_a_fifo_is_refused_without_waiting(tmp_path):
    """A FIFO named manifest.json: 'doe run' waited for ever for a writer, reading it."""
    folder = _finished(tmp_path, "kinematic")
    (folder / "manifest.json").unlink()
    os.mkfifo(folder / "manifest.json")
    out = subprocess.run([sys.executable, "-m", "labtool.cli", "doe", "run", "--model", "kinematic", "--accuracy", "fast",
                          "--factors", str(tmp_path / "f.csv"), "-o", str(tmp_path / "r.csv")],
                         capture_output=True, text=True, timeout=120, cwd=Path(__file__).resolve().parents[1])
    _refused(out.returncode, out.stderr.strip().splitlines(), "manifest.json", "--fresh")
    assert len(list(folder.glob("items-*.csv"))) == 3


@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("kind", ["fifo", "folder"])
def test_a_lock_that_is_not_a_regular_file_is_named(tmp_path, capsys, kind):
    """A FIFO named lock: 'labtool: error: File or stream is not seekable.', naming nothing."""
    folder = _finished(tmp_path, "kinematic")
    (folder / "lock").unlink()
    os.mkfifo(folder / "lock") if kind == "fifo" else (folder / "lock").mkdir()
    rc, err = _run(tmp_path, capsys, "kinematic")
    _refused(rc, err, str(folder / "lock"), "not a regular file")
    assert len(list(folder.glob("items-*.csv"))) == 3
