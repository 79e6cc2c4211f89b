"""One-line errors whose advice must be true: what was kept, where, and what the user can do.

Each case here was a message that named the wrong thing or advised what cannot help (free space on
a disk that is not full, rerun when a rerun ends the same way).
"""
from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest

from labtool.execution.design import parts_folder
from labtool.execution.parts import PartStore
from labtool.cli import main

FACTORS_9 = "factor,symbol,unit,level_1,level_2,level_3\nA,Fu,N,0,5,10\nB,n1,rpm,150,165,180\n"


def _refused(rc, err, *words) -> None:
    assert rc == 2 and err and err[-1].startswith("labtool: error:"), err
    for w in words:
        assert w in err[-1], err[-1]


# ------------------------------------------------------------------------------------ doe run

def _finished_design(tmp_path: Path) -> Path:
    """The parts folder of a 3 x 3 kinematic design with every run finished (made-up values)."""
    from labtool.models.study.paper import paper_scene
    from labtool.models.study.doe import Design, read_factors
    (tmp_path / "f.csv").write_text(FACTORS_9)
    design = Design(tuple(read_factors(tmp_path / "f.csv")), paper_scene(accuracy="fast"), "kinematic")
    store = PartStore(parts_folder(tmp_path / "r.csv"), design.fingerprint(), design.columns + ["wall_s", "error"])
    rows = [{"run": i + 1, **dict(zip(design.level_columns, design.level_indices(i))),
             **{c: float(10 * i + k) for k, c in enumerate(design.responses)}, "wall_s": 0.01, "error": ""}
            for i in range(9)]
    store.write(0, 9, rows)
    store.close()
    return store.folder


def _doe(tmp_path: Path, capsys, *extra) -> tuple[int, list[str]]:
    rc = main(["doe", "run", "--model", "kinematic", "--accuracy", "fast", "--factors", str(tmp_path / "f.csv"),
               "-o", str(tmp_path / "r.csv"), *extra])
    return rc, capsys.readouterr().err.strip().splitlines()


@pytest.mark.hostile("silent_wrong")
def test_a_netcdf_that_cannot_be_renamed_leaves_neither_output_and_says_why(tmp_path, capsys, monkeypatch):
    """The CSV was renamed into place, the NetCDF's rename failed (EACCES): 'Permission denied while
    writing r.csv and r.nc: neither was written; ... free space and rerun' - with r.csv written and
    a disk that was not full."""
    folder = _finished_design(tmp_path)
    real_replace = os.replace

    def replace(src, dst, *a, **k):
        if Path(dst) == tmp_path / "r.nc":
            raise PermissionError(errno.EACCES, "Permission denied", str(dst))
        return real_replace(src, dst, *a, **k)
    monkeypatch.setattr(os, "replace", replace)
    rc, err = _doe(tmp_path, capsys)
    _refused(rc, err, "r.nc", "Permission denied", "none of r.csv, r.nc was written", str(folder), "rerun")
    assert "free space" not in err[-1]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.csv", "r.csv.parts"]
    assert len(list(folder.glob("items-*.csv"))) == 1


# ------------------------------------------------------------------------------------ campaign run

ROOT = Path(__file__).resolve().parents[1]


def _one_point_plan(tmp_path: Path) -> Path:
    plan = tmp_path / "plan.toml"
    plan.write_text(f"""[campaign]
name = "quick"
[device]
seed = 3
pacing = "fast"
[calibration]
files = ["{ROOT / 'sample_data' / 'calibration.toml'}"]
[defaults]
revolutions = 3
[[points]]
rpm = 180.0
[compare]
models = ["kinematic"]
omega1 = ["const"]
""")
    return plan


def _campaign(tmp_path: Path, capsys, *extra) -> tuple[int, list[str]]:
    rc = main(["campaign", "run", str(_one_point_plan(tmp_path)), "-o", str(tmp_path / "c"), *extra])
    return rc, capsys.readouterr().err.strip().splitlines()


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("name", ["recording.h5", "measured.nc"])
def test_a_point_output_that_is_a_folder_is_named_with_what_to_do(tmp_path, capsys, name):
    """recording.h5 made a folder: 'point 01_180rpm (acquire): cannot write in .../01_180rpm: Is a
    directory; the finished points and steps are kept, rerun to resume', and every rerun the same."""
    point = tmp_path / "c" / "points" / "01_180rpm"
    (point / name).mkdir(parents=True)
    (point / name / "mine.txt").write_text("kept")
    for _ in range(2):
        rc, err = _campaign(tmp_path, capsys)
        _refused(rc, err, "01_180rpm", name, "is a folder", "move it away")
        assert "rerun to resume" not in err[-1]
    assert (point / name / "mine.txt").read_text() == "kept"


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("redo", [False, True])
def test_a_point_folder_that_is_a_file_is_named_with_what_to_do(tmp_path, capsys, redo):
    """The point's folder made a plain file: '.../points/01_180rpm: File exists' (and with --redo
    'Not a directory'), with nothing to do."""
    point = tmp_path / "c" / "points" / "01_180rpm"
    point.parent.mkdir(parents=True)
    point.write_text("mine")
    rc, err = _campaign(tmp_path, capsys, *(["--redo", "01_180rpm"] if redo else []))
    _refused(rc, err, "01_180rpm", "is a file", "move it away")
    assert point.read_text() == "mine"


def _doe_parts(tmp_path: Path) -> Path:
    """A 3 x 3 kinematic design with its first 3 runs finished (made-up values), not yet assembled."""
    from labtool.models.study.paper import paper_scene
    from labtool.models.study.doe import Design, read_factors
    (tmp_path / "f.csv").write_text(FACTORS_9)
    design = Design(tuple(read_factors(tmp_path / "f.csv")), paper_scene(accuracy="fast"), "kinematic")
    store = PartStore(parts_folder(tmp_path / "r.csv"), design.fingerprint(), design.columns + ["wall_s", "error"])
    store.write(0, 3, [{"run": i + 1, **dict(zip(design.level_columns, design.level_indices(i))),
                        **{c: 1.0 for c in design.responses}, "wall_s": 0.01, "error": ""} for i in range(3)])
    store.close()
    return store.folder


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("damage", ["not-json", "a-list", "a-folder"])
def test_a_manifest_that_cannot_be_read_gets_advice_that_helps(tmp_path, capsys, damage):
    """'r.csv.parts holds finished chunks of other work (its manifest.json is not readable); rerun
    the same command to finish that work, or pass --fresh ...': the same command ends the same way,
    and for a folder --fresh ended 'cannot write .../manifest.json (Is a directory)'."""
    folder = _doe_parts(tmp_path)
    manifest = folder / "manifest.json"
    if damage == "a-folder":
        manifest.unlink()
        manifest.mkdir()
    else:
        manifest.write_text("{not json" if damage == "not-json" else "[1, 2]")
    rc, err = _doe(tmp_path, capsys)
    _refused(rc, err, "manifest.json", "1 finished chunk")
    assert "rerun the same command" not in err[-1]
    assert len(list(folder.glob("items-*.csv"))) == 1
    if damage == "a-folder":
        assert "move it away" in err[-1]
        manifest.rmdir()
        rc, err = _doe(tmp_path, capsys)
        _refused(rc, err, "manifest.json", "--fresh")
    rc, err = _doe(tmp_path, capsys, "--fresh")
    assert rc == 0, err
    assert (tmp_path / "r.csv").exists() and not folder.exists()


# ------------------------------------------------------------------------------------ acquire

@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("option", ["--test-id", "--operator", "--notes", "--motor-setting"])
def test_a_text_option_that_is_not_utf8_is_named(tmp_path, capsys, option):
    """--test-id $'T\\xff1' (a Latin-1 shell): 'a file name given is not valid UTF-8 and cannot be
    written into the outputs; rename the file (e.g. with convmv)' - no file name was at fault."""
    rc = main(["acquire", "--device", "sim", "--duration", "0.05", "--fast", option, "T\udcff1",
               "-o", str(tmp_path / "a.h5")])
    err = capsys.readouterr().err.strip().splitlines()
    _refused(rc, err, option, "not UTF-8", "T\\xff1")
    assert "file name" not in err[-1] and not list(tmp_path.iterdir())


# ------------------------------------------------------------------------------------ kinematics

@pytest.mark.hostile("silent_wrong")
def test_a_rise_that_does_not_fit_the_mechanisms_program_names_the_values_to_change(tmp_path, capsys):
    """--rise-deg 70 on the STB-216: 'cam program: rise + dwells + return = 372 deg, must be 360 deg',
    without saying that the dwells and the return are the mechanism file's, nor what would fit."""
    rc = main(["kinematics", "--rise-deg", "70", "-o", str(tmp_path / "k.nc")])
    err = capsys.readouterr().err.strip().splitlines()
    _refused(rc, err, "rise_deg 70 (given)", "upper_dwell_deg 122", "return_deg 58", "lower_dwell_deg 122",
             "= 372 deg", "stb216.toml", "rise of 58 deg")
    assert not list(tmp_path.iterdir())


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_a_last_block_lost_is_recorded_as_lost(tmp_path, capsys):
    """--fault drop@0.95 --duration 1: 9000 of 10000 samples, 'device finished', no gap event and
    samples_lost = 0: the loss was silent (a drop at 0.45 s is a gap of 1000 samples)."""
    import h5py
    rc = main(["acquire", "--device", "sim", "--fast", "--duration", "1", "--fault", "drop@0.95",
               "-o", str(tmp_path / "a.h5"), "--status-every", "0"])
    out = capsys.readouterr()
    assert rc == 0, out.err
    assert "1 gaps" in out.out + out.err
    with h5py.File(tmp_path / "a.h5", "r") as h:
        assert h.attrs["n_samples"] == 9000 and h.attrs["samples_lost"] == 1000
        assert "1000 samples short" in h.attrs["stop_reason"]
        gaps = [e for e in h["events"][:] if e["kind"] == b"gap"]
        assert len(gaps) == 1 and gaps[0]["index"] == 9000 and gaps[0]["detail"].startswith(b"missing_samples=1000 ")
