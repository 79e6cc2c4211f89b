"""Factorial designs and ``labtool doe run``: factor files, run order, Scene mapping, local and Dask runs."""
from __future__ import annotations

import importlib.util
import math

import numpy as np
import pandas as pd
import pytest
import xarray as xr
from hypothesis import given, settings
from hypothesis import strategies as st

from labtool.cli import main
from labtool.models.study import doe
from labtool.common.errors import FileFormatError, InputError
from labtool.models.study.paper import read_reference, table1_runs
from labtool.models.dynamics.scene import Scene
from labtool.models.study.paper import paper_scene
from labtool.common.units import RPM

TOML_2x3 = """
[[factor]]
name = "A"
symbol = "Fu"
unit = "N"
levels = [0, 30, 65]

[[factor]]
name = "B"
symbol = "n1"
unit = "rpm"
levels = [180, 300]
"""


def test_table1_full_factorial_is_the_papers_run_order():
    design = doe.full_factorial(doe.table1_factors())
    t2 = read_reference("table2_rigid")
    for col in ("A_Fu_level", "B_j_level", "C_n1_level", "D_Jt_level"):
        assert (design[col].to_numpy() == t2[col].to_numpy()).all()
    runs = table1_runs()
    for sym, col in (("Fu", "Fu_N"), ("j", "j_mm"), ("n1", "n1_rpm"), ("Jt", "Jt_factor")):
        assert design[sym].to_numpy() == pytest.approx(runs[col].to_numpy())


def test_scene_for_run_converts_edge_units_to_si_once():
    f = doe.table1_factors()
    sc = doe.scene_for_run(paper_scene(), f, {"Fu": 65.0, "j": 0.128, "n1": 300.0, "Jt": 4.0})
    assert (sc.Fu, sc.backlash, sc.cam_speed_rpm, sc.jt_factor) == pytest.approx((65.0, 0.128e-3, 300.0, 4.0))
    lw = doe.Factor("E", "lw", "mm", (5.0, 10.0))
    assert doe.scene_for_run(paper_scene(), [lw], {"lw": 5.0}).contact_length == pytest.approx(5e-3)


def test_factor_files_csv_and_toml_agree(tmp_path):
    toml = tmp_path / "f.toml"
    toml.write_text(TOML_2x3)
    csv = tmp_path / "f.csv"
    csv.write_text("factor,symbol,unit,level_1,level_2,level_3\nA,Fu,N,0,30,65\nB,n1,rpm,180,300,\n")
    assert doe.read_factors(toml) == doe.read_factors(csv)
    design = doe.full_factorial(doe.read_factors(toml))
    assert len(design) == 6 and list(design["A_Fu_level"]) == [1, 1, 2, 2, 3, 3]


@pytest.mark.parametrize("text,suffix,fragment", [
    ("factor,symbol,unit,level_1,level_2\nA,Fu,N,0,\n", ".csv", "has 1 level"),
    ("factor,symbol,unit,level_1,level_2\nA,Fu,N,0,0\n", ".csv", "repeat a value"),
    ("factor,symbol,unit,level_1,level_2\nA,Fu,N,0,x\n", ".csv", "is not a number"),
    ("factor,symbol,unit,level_1,level_2,colour\nA,Fu,N,0,1,red\n", ".csv", "unknown column(s) colour"),
    ("factor,symbol,unit,level_1,level_2\nA,Fu,N,0,1\nA,j,mm,0,1\n", ".csv", "factor name repeated: A"),
    ("factor,symbol,level_1,level_2\nA,Fu,0,1\n", ".csv", "missing unit"),
    ('[[factor]]\nname = "A"\nsymbol = "Fu"\nunit = "N"\nlevels = [1]\n', ".toml", "has 1 level"),
    ('[[factor]]\nname = "A"\nsymbol = "Fu"\nlevels = "0, 65"\n', ".toml", "levels must be a list of numbers"),
    ('[[factor]]\nname = "A"\nsymbol = "Fu"\nunit = "N"\nlevels = [0, 65]\ncolor = 1\n', ".toml", "unknown key(s) color"),
    ("[[factor]\n", ".toml", "not a valid TOML file"),
    ('[[factor]]\nname = "AA"\nsymbol = "Fu"\nunit = "N"\nlevels = [0, 65]\n', ".toml", "one capital letter"),
    ("factor,symbol,unit,level_1,level_2\nA,Fu,N,0,NA\n", ".csv", "level 'NA' is not a number"),   # pandas dropped it
    ("factor,symbol,unit,level_1,level_2\nA,Fu,N,0,nan\n", ".csv", "level 'nan' is not a number"),
    ("factor,symbol,unit,level_1,level_2\nA,Fu,N,0,1,2\n", ".csv", "row 2 has 6 cells"),
    ("factor,symbol,unit,level_1,level_1\nA,Fu,N,0,1\n", ".csv", "level_1 repeated"),
    ("factor,symbol,unit,level_1,level_2,\nA,Fu,N,0,1,\n", ".csv", "unknown column(s) (unnamed)"),
    ("", ".csv", "not a readable CSV file"),
    ("\n\n", ".csv", "not a readable CSV file"),
])
def test_bad_factor_files_are_user_errors(tmp_path, text, suffix, fragment, capsys):
    p = tmp_path / f"f{suffix}"
    p.write_text(text)
    with pytest.raises((InputError, FileFormatError)) as exc:
        doe.read_factors(p)
    assert fragment in str(exc.value)
    assert main(["doe", "run", "--model", "kinematic", "--factors", str(p), "-o", str(tmp_path / "r.csv")]) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_factor_csv_from_a_spreadsheet_reads_as_pandas_reads_it(tmp_path):
    """A byte-order mark, quoted cells, CRLF line ends, blank lines and rows short of cells: the
    factors pandas (what read them before) finds."""
    text = ('\ufefffactor,symbol,unit,level_1,level_2,level_3\r\n"A","Fu","N",0,"32.5",65\r\n\r\n'
            'B,n1,rpm,180,300\r\n,,,,,\r\nC,j,mm, 0.016 ,0.128,\r\n')
    p = tmp_path / "f.csv"
    p.write_text(text, encoding="utf-8", newline="")
    got = doe.read_factors(p)
    frame = pd.read_csv(p, dtype={"unit": str}).dropna(how="all")
    want = [doe.Factor(str(r.factor), str(r.symbol), str(r.unit),
                       tuple(float(v) for v in (r.level_1, r.level_2, r.level_3) if not pd.isna(v)))
            for r in frame.itertuples()]
    assert got == want and [f.levels for f in got] == [(0.0, 32.5, 65.0), (180.0, 300.0), (0.016, 0.128)]


@settings(max_examples=40, deadline=None)
@given(levels=st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=0, max_size=4))
def test_factor_levels_accepted_iff_two_or_more_distinct(levels):
    ok = len(levels) >= 2 and len(set(levels)) == len(levels)
    if ok:
        assert doe.Factor("A", "Fu", "N", tuple(levels)).levels == tuple(levels)
    else:
        with pytest.raises(InputError):
            doe.Factor("A", "Fu", "N", tuple(levels))


def test_unknown_symbol_or_unit_is_refused_before_running():
    base = paper_scene()
    with pytest.raises(InputError, match="no simulation parameter 'colour'"):
        doe.Design([doe.Factor("A", "colour", "", (1.0, 2.0))], base, "kinematic").validate()
    with pytest.raises(InputError, match="unit 'km' not understood"):
        doe.Design([doe.Factor("A", "j", "km", (1.0, 2.0))], base, "kinematic").validate()
    with pytest.raises(InputError, match=r"load Fu must be in \[0, "):  # the owner's bounds, per level
        doe.Design([doe.Factor("A", "Fu", "N", (-5.0, 2.0))], base, "kinematic").validate()


def test_lazy_design_rows_are_the_full_factorial():
    """Design (lazy, any size) gives the same run order, levels and scenes as full_factorial."""
    f = doe.table1_factors()
    design, table = doe.Design(f, paper_scene(), "kinematic"), doe.full_factorial(f)
    assert len(design) == len(table) == 16
    for i in (0, 5, 15):
        assert design.level_indices(i) == tuple(table.loc[i, [x.column for x in f]])
        assert design.scene(i) == doe.scene_for_run(paper_scene(), f, {x.symbol: table.loc[i, x.symbol] for x in f})
    big = doe.Design([doe.Factor(chr(65 + k), s, u, tuple(range(1, 11)))
                      for k, (s, u) in enumerate([("Fu", "N"), ("n1", "rpm"), ("Jt", "-"), ("Kc", "-"),
                                                  ("lw", "mm"), ("k", "-")])], paper_scene(), "elastic")
    assert len(big) == 10**6 and big.level_indices(10**6 - 1) == (10,) * 6
    assert big.level_indices(123456) == (2, 3, 4, 5, 6, 7)


@pytest.fixture(scope="module")
def kinematic_2x3(tmp_path_factory):
    d = tmp_path_factory.mktemp("doe")
    (d / "f.toml").write_text(TOML_2x3)
    rc = main(["doe", "run", "--model", "kinematic", "--factors", str(d / "f.toml"), "--workers", "2",
               "-o", str(d / "r.csv")])
    return rc, d


@pytest.mark.slow
def test_doe_run_local_processes_writes_table_and_netcdf(kinematic_2x3, capsys):
    rc, d = kinematic_2x3
    assert rc == 0
    table = pd.read_csv(d / "r.csv")
    assert list(table.columns) == ["run", "A_Fu_level", "B_n1_level", "MR13D_max_Nm", "MR13D_min_Nm"]
    assert list(table.run) == [1, 2, 3, 4, 5, 6]
    # each row equals a direct simulation of that operating point (independent of the runner)
    from labtool.models.dynamics.simulate import simulate
    direct = simulate(paper_scene(Fu=30.0, cam_speed=300.0 * RPM), "kinematic").indicators
    row = table[(table.A_Fu_level == 2) & (table.B_n1_level == 2)].iloc[0]
    assert row.MR13D_max_Nm == pytest.approx(direct["MR13D_max_Nm"], rel=1e-9)
    ds = xr.open_dataset(d / "r.nc", engine="h5netcdf")
    assert ds["MR13D_max_Nm"].dims == ("Fu", "n1")
    assert list(ds.Fu.values) == [0, 30, 65] and ds.Fu.attrs["units"] == "N" and ds.n1.attrs["units"] == "rpm"
    assert float(ds.MR13D_max_Nm.sel(Fu=30, n1=300)) == pytest.approx(row.MR13D_max_Nm)
    for v in ds.variables.values():
        assert "units" in v.attrs and "long_name" in v.attrs
    ds.close()
    # more than two levels: the analysis reads it back and prints per-level effects
    assert main(["doe", "analyze", str(d / "r.csv"), "--json"]) == 0


def _in_process(d, name="one.csv"):
    assert main(["doe", "run", "--model", "kinematic", "--factors", str(d / "f.toml"), "--workers", "1",
                 "-o", str(d / name)]) == 0
    return pd.read_csv(d / name)


@pytest.mark.slow
def test_doe_run_in_process_equals_process_pool(kinematic_2x3, capsys):
    _, d = kinematic_2x3
    one = _in_process(d)
    assert "(in-process," in capsys.readouterr().out
    pooled = pd.read_csv(d / "r.csv")
    pd.testing.assert_frame_equal(one, pooled)


@pytest.mark.slow
def test_doe_run_on_a_local_dask_cluster(tmp_path):
    """A Dask distributed cluster on loopback (one in-process worker thread), closed by the test."""
    distributed = pytest.importorskip("distributed")
    (tmp_path / "f.toml").write_text(TOML_2x3)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp",
                                  host="127.0.0.1", dashboard_address=None) as cluster:
        rc = main(["doe", "run", "--model", "kinematic", "--factors", str(tmp_path / "f.toml"),
                   "--scheduler", cluster.scheduler_address, "--scheduler-always", "-o", str(tmp_path / "d.csv")])
    assert rc == 0
    local = _in_process(tmp_path)
    remote = pd.read_csv(tmp_path / "d.csv")
    assert remote.MR13D_max_Nm.to_numpy() == pytest.approx(local.MR13D_max_Nm.to_numpy(), rel=1e-9)


def test_a_small_design_given_a_scheduler_runs_here_and_says_why(tmp_path, capsys):
    """Its measured work is far under what a cluster's start costs: the scheduler is never
    contacted (this address has nothing behind it) and the summary says where the runs went."""
    (tmp_path / "f.toml").write_text(TOML_2x3)
    rc = main(["doe", "run", "--model", "kinematic", "--factors", str(tmp_path / "f.toml"),
               "--scheduler", "tcp://127.0.0.1:1", "-o", str(tmp_path / "d.csv")])
    out = capsys.readouterr().out
    assert rc == 0
    assert "(in-process, not the Dask cluster at tcp://127.0.0.1:1: 6 runs x " in out
    assert " ms measured = about 0." in out and " s of work, under the 10 s a cluster needs to pay for its start" in out
    assert pd.read_csv(tmp_path / "d.csv").MR13D_max_Nm.to_numpy() == pytest.approx(
        _in_process(tmp_path).MR13D_max_Nm.to_numpy(), rel=1e-12)


@pytest.mark.slow
def test_unreachable_scheduler_is_an_input_error(tmp_path):
    from labtool.execution.backends import DaskCluster
    with pytest.raises(InputError, match="cannot reach the Dask scheduler"):
        DaskCluster("tcp://127.0.0.1:1", connect_timeout_s=0.5)


def test_failed_runs_are_reported_and_left_empty(tmp_path, monkeypatch, capsys):
    """A run whose model raises keeps the other runs, leaves its row empty and ends in exit 2."""
    from labtool.models.dynamics import simulate as sim

    real = sim.simulate

    def flaky(scene, model="auto"):
        if scene.Fu > 50:
            raise sim.InputError("solver gave up (test)")
        return real(scene, model)

    monkeypatch.setattr(sim, "simulate", flaky)
    (tmp_path / "f.toml").write_text(TOML_2x3)
    rc = main(["doe", "run", "--model", "kinematic", "--factors", str(tmp_path / "f.toml"), "--workers", "1",
               "-o", str(tmp_path / "r.csv")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1
    assert "2 of 6 runs failed and are left empty" in err[0] and "run 5: solver gave up (test)" in err[0]
    table = pd.read_csv(tmp_path / "r.csv")
    assert table.MR13D_max_Nm.isna().sum() == 2 and table.MR13D_max_Nm.notna().sum() == 4
    # and the analysis refuses the incomplete table, naming the runs
    assert main(["doe", "analyze", str(tmp_path / "r.csv")]) == 2
    assert "missing or not a number in run(s) 5, 6" in capsys.readouterr().err


@pytest.mark.parametrize("argv,fragment", [
    (["--model", "quantum"], "doe run needs --model one of rigid, elastic, kinematic"),
    (["--model", "kinematic", "--law", "parabolic"], "unknown motion law 'parabolic'"),
    (["--model", "kinematic", "--omega1", "fast"], "omega1 mode must be one of const, var, got 'fast'"),
    (["--model", "kinematic", "--workers", "0"], "must be >= 1"),
    (["--model", "kinematic", "--factors", "nofile.toml"], "factor file nofile.toml does not exist"),
])
def test_doe_run_bad_options_are_one_line_exit_2(capsys, tmp_path, argv, fragment):
    assert main(["doe", "run", *argv, "-o", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("labtool: error:") and fragment in err[0], err
    assert not (tmp_path / "x.csv").exists()


def test_doe_run_refuses_to_overwrite(capsys, tmp_path):
    (tmp_path / "x.csv").write_text("keep me")
    assert main(["doe", "run", "--model", "kinematic", "-o", str(tmp_path / "x.csv")]) == 2
    assert "already exists" in capsys.readouterr().err
    assert (tmp_path / "x.csv").read_text() == "keep me"


# ---------------------------------------------------------------------------------------------
# the paper's 16-run tables from the dynamic models (issues 3 and 4 define their accuracy)

def _paper_end_to_end(model: str, table: str, tmp_path, extra=(), **scene_extra):
    if importlib.util.find_spec(f"labtool.models.dynamics.{model}") is None:
        pytest.skip(f"models/{model}.py does not exist yet (issue {3 if model == 'rigid' else 4})")
    out = tmp_path / f"{model}.csv"
    rc = main(["doe", "run", "--model", model, "--accuracy", "fast", "-o", str(out), *extra])
    assert rc == 0
    ours, paper = pd.read_csv(out), read_reference(table)
    assert list(ours.columns) == list(paper.columns)
    assert (ours[paper.columns[:5]].to_numpy() == paper[paper.columns[:5]].to_numpy()).all()
    # the runner adds nothing: run 10 (Fu 65 N, j 0.016 mm, 180 rpm, Jt x4) equals a direct simulation
    from labtool.models.dynamics.simulate import simulate
    direct = simulate(paper_scene(Fu=65.0, backlash=0.016e-3, cam_speed=180.0 * RPM, jt_factor=4.0,
                            accuracy="fast", **scene_extra), model).indicators
    for col in paper.columns[5:]:
        assert ours[col][9] == pytest.approx(direct[col], rel=1e-6, abs=1e-9), col
    return ours, paper


def _common_issue_accuracy(ours, paper):
    """What issues 3 and 4 both require: (MR13D)max within 10 % on every run; no jump in runs 9
    and 13 (Fu = 65 N, 180 rpm, Jt x1: MR13D keeps its sign), at least one in every other run."""
    assert np.max(np.abs(ours.MR13D_max_Nm / paper.MR13D_max_Nm - 1)) < 0.10
    assert (ours.jumps[[8, 12]] == 0).all() and (ours.jumps.drop([8, 12]) > 0).all()


@pytest.mark.slow
def test_doe_run_rigid_gives_table2(tmp_path):
    _common_issue_accuracy(*_paper_end_to_end("rigid", "table2_rigid", tmp_path))


@pytest.mark.slow
def test_doe_run_elastic_gives_table3(tmp_path):
    ours, paper = _paper_end_to_end("elastic", "table3_elastic", tmp_path)
    _common_issue_accuracy(ours, paper)
    # (MR13D)min within 10 % as well (exact jump and impact counts are tested in the
    # own tests; docs/doe.md records this table's counts against Table 3)
    assert np.max(np.abs(ours.MR13D_min_Nm / paper.MR13D_min_Nm - 1)) < 0.10


@pytest.mark.slow
def test_doe_run_elastic_closed_gap_reproduces_table3_counts(tmp_path, capsys):
    """Table 3 end to end: with Table 3's convention (--elastic-gap closed, docs/models.md) the
    DOE's jumps and impacts equal Table 3 in all 16 runs and j has no effect on any response."""
    ours, paper = _paper_end_to_end("elastic", "table3_elastic", tmp_path, ("--elastic-gap", "closed"),
                                    elastic_gap="closed")
    assert (ours.jumps == paper.jumps).all() and (ours.impacts == paper.impacts).all()
    assert np.max(np.abs(ours.MR13D_min_Nm / paper.MR13D_min_Nm - 1)) < 0.10
    lo, hi = ours[ours.B_j_level == 1].reset_index(drop=True), ours[ours.B_j_level == 2].reset_index(drop=True)
    pd.testing.assert_frame_equal(lo.drop(columns=["run", "B_j_level"]), hi.drop(columns=["run", "B_j_level"]))
    assert "gap closed" in capsys.readouterr().out


@pytest.mark.slow
def test_doe_run_to_a_pipe_loads_no_rich_and_a_forced_terminal_gets_the_bar(tmp_path):
    """Off a terminal the command's stderr gets plain lines (LineProgress, the resuming line) and
    rich is not imported (a shorter start); FORCE_COLOR makes rich take stderr for a terminal, and
    the command then uses rich's progress bar as before."""
    import os
    import subprocess
    import sys
    import textwrap
    from pathlib import Path

    f = tmp_path / "f.csv"      # 9 x 8 = 72 runs: over 64, so no results table (rich) is printed
    f.write_text("factor,symbol,unit," + ",".join(f"level_{k}" for k in range(1, 10)) + "\n"
                 "A,Fu,N,0,5,10,15,20,25,30,35,40\nB,n1,rpm,180,190,200,210,220,230,240,250,\n")
    code = textwrap.dedent(f"""
        import sys
        import labtool.cli as cli
        rc = cli.main(["doe", "run", "--model", "kinematic", "--factors", {str(f)!r}, "--workers", "1",
                       "-o", sys.argv[1]])
        print("rc", rc, "rich", "rich" in sys.modules, "bar", "rich.progress" in sys.modules)
        """)
    root = Path(__file__).resolve().parents[1]
    env = {k: v for k, v in os.environ.items() if k not in ("FORCE_COLOR", "TTY_COMPATIBLE")}
    plain = subprocess.run([sys.executable, "-c", code, str(tmp_path / "a.csv")], cwd=root, env=env,
                           capture_output=True, text=True, timeout=300)
    assert plain.stdout.strip().splitlines()[-1] == "rc 0 rich False bar False", plain.stderr
    forced = subprocess.run([sys.executable, "-c", code, str(tmp_path / "b.csv")], cwd=root,
                            env=dict(env, FORCE_COLOR="1"), capture_output=True, text=True, timeout=300)
    assert forced.stdout.strip().splitlines()[-1] == "rc 0 rich True bar True", forced.stderr
    assert (tmp_path / "a.csv").read_text() == (tmp_path / "b.csv").read_text()
