"""The report's comparison method: steady cycle or cycle statistics, band statistics,
bounded reading of a long recording, the robustness rows."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from labtool.common.files import write_netcdf
from labtool.reports import align, pipeline
from labtool.reports.synthetic import synthetic_measured

GRID = align.Conditioning().grid


def test_a_periodic_model_is_compared_on_its_last_revolution():
    rev = np.sin(GRID)
    revs = {"omega2": np.array([0.5 * rev, rev, rev * (1 + 1e-4)]), "epsilon2": np.array([rev, rev, rev])}
    cyc = align.steady_cycles(revs, GRID)
    assert cyc.periodic and cyc.n_used == 1 and cyc.change == pytest.approx(1e-4, rel=1e-3)
    assert np.array_equal(cyc.signals["omega2"], revs["omega2"][-1]) and not cyc.std["omega2"].any()


def test_a_model_that_varies_is_compared_by_its_cycle_statistics():
    rng = np.random.default_rng(0)
    rows = np.sin(GRID) + 0.3 * rng.standard_normal((6, GRID.size))
    cyc = align.steady_cycles({"omega2": rows, "epsilon2": rows}, GRID)
    assert not cyc.periodic and cyc.n_used == 5 and "NOT periodic" in cyc.note
    assert np.allclose(cyc.signals["omega2"], rows[1:].mean(axis=0))
    assert np.allclose(cyc.std["omega2"], rows[1:].std(axis=0))
    # the first k revolutions of the same simulation
    assert np.allclose(cyc.upto(3).signals["omega2"], rows[1:3].mean(axis=0))
    assert np.allclose(cyc.upto(2).signals["omega2"], rows[1])       # too few for statistics: the last one


def test_band_statistics_known_answers():
    m, s = np.zeros(100), np.ones(100)
    sim = np.where(np.arange(100) < 25, 5.0, 1.0)           # 25 % of the points 5 sigma away, the rest 1
    out = pipeline.band_statistics(m, s, sim, np.zeros(100))
    assert out["band_overlap"] == pytest.approx(0.75) and out["scatter_ratio"] == 0.0
    assert pipeline.band_statistics(m, s, sim, 2 * s)["scatter_ratio"] == pytest.approx(2.0)


@pytest.mark.slow
def test_energy_loss_makes_the_models_periodic_and_k_1_does_not():
    """At 180 rpm with j = 0.128 mm: the rigid model with k = 0.7 repeats its revolution (< 5 % rms),
    the paper's k = 1 bounces differently every revolution; the report says which is which."""
    op = {"law": "sine", "cam_speed_rpm": 180.0, "Fu": 0.0, "backlash_mm": 0.128, "jt_factor": 1.0}
    cond = align.Conditioning()
    damped = pipeline.run_simulation({**op, "restitution": 0.7}, "rigid", "const", "fast", 4, cond)
    paper = pipeline.run_simulation({**op, "restitution": 1.0}, "rigid", "const", "fast", 4, cond)
    print(f"rms change between the last two revolutions: k = 0.7 {damped.cycle.change:.3f}, k = 1 {paper.cycle.change:.3f}")
    assert damped.cycle.periodic and damped.cycle.change < align.PERIODIC_TOL
    assert not paper.cycle.periodic and paper.cycle.change > 2 * align.PERIODIC_TOL and paper.cycle.n_used >= 2


def test_a_long_recording_is_read_in_bounded_blocks(tmp_path):
    ds = synthetic_measured(noise=0.01, revolutions=60.3, fs=2000.0)
    period = 60.0 / 180.0
    start = (360.0 - 250.0) / 360.0 * period            # synthetic_measured starts at 250 deg
    ds["revolution_start_time"] = ("revolution_mark", start + period * np.arange(60))
    path = tmp_path / "long.nc"
    write_netcdf(ds, path)
    opened = pipeline.load_measured(path)
    cyc = align.read_measured(opened, ("omega2", "epsilon2"), align.Conditioning(), max_revolutions=20)
    assert cyc.in_file == 60 and len(cyc.blocks) == 1 and 18 <= len(cyc.revolutions) <= 20
    cyc = align.read_measured(opened, ("omega2",), align.Conditioning(), max_revolutions=40)
    assert len(cyc.blocks) == 2 and len(set(cyc.revolutions.tolist())) == len(cyc.revolutions)
    # the whole file when it is short enough, as before
    full = align.read_measured(opened, ("omega2",), align.Conditioning())
    assert full.in_file is None and len(full.revolutions) == 59
    # the same cycle average from the sample as from everything (the stand repeats itself)
    assert np.allclose(cyc.mean("omega2"), full.mean("omega2"), atol=0.01 * np.abs(full.mean("omega2")).max())


@settings(max_examples=150, deadline=None)
@given(n=st.integers(1, 5000), gaps=st.lists(st.tuples(st.floats(0, 1), st.floats(0, 0.5)), max_size=3),
       probes=st.lists(st.floats(-0.1, 1.1), min_size=1, max_size=20), window=st.sampled_from([4, 16, 512]))
@pytest.mark.slow
def test_lazy_searchsorted_equals_numpys_on_a_time_axis_with_gaps(n, gaps, probes, window):
    """The long file's time axis is never read whole (a 1-hour recording's is 288 MB): the interpolation
    search finds numpy's answer, gaps (lost samples counted in time) or not, inside or outside."""
    import xarray as xr
    t = np.arange(n) * 1e-4
    for at, jump in gaps:
        t[int(at * (n - 1)):] += jump
    values = [t[0] + p * (t[-1] - t[0] + 1e-4) for p in probes] + [t[int(p * (n - 1))] for p in probes if 0 <= p <= 1]
    assert align.lazy_searchsorted(xr.DataArray(t, dims="time"), values, window) == \
        list(np.searchsorted(t, values, side="left"))


def test_a_long_file_is_opened_without_its_time_index(tmp_path):
    ds = synthetic_measured(noise=0.01, revolutions=4.3)
    path = tmp_path / "m.nc"
    write_netcdf(ds, path)
    opened = pipeline.load_measured(path)
    assert "time" not in opened.indexes and "time" in opened.coords


@pytest.mark.slow
def test_the_robustness_rows_name_the_closest_model_at_both_presets_and_lengths(tmp_path):
    path = tmp_path / "m.nc"
    write_netcdf(synthetic_measured(noise=0.01, revolutions=4.3), path)
    rep = pipeline.build_report(path, models=("rigid", "kinematic"), modes=("const",), accuracy="fast",
                                overrides={"restitution": 0.5}, revolutions=4)
    assert [(r["accuracy"], r["revolutions"]) for r in rep.robustness] == [("fast", 4.0), ("fast", 2.0),
                                                                            ("standard", 4.0), ("standard", 2.0)]
    # the kinematic truth: the kinematic level is the closest everywhere, so the verdict is robust
    assert all(r["closest"] == "kinematic, w1 = ct." for r in rep.robustness)
    assert pipeline.robust_verdict(rep.robustness)["robust"]
    assert not pipeline.robust_verdict([{"closest": "a"}, {"closest": "b"}])["robust"]
