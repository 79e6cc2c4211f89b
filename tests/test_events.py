"""The one event record (labtool.models.dynamics.events): its layout in both models' datasets, one
definition of each count, a file round trip."""
import numpy as np
import pytest
import xarray as xr
from hypothesis import given, settings
from hypothesis import strategies as st

from labtool.common.errors import FileFormatError
from labtool.models.dynamics import events
from labtool.models.study.paper import paper_scene
from labtool.models.dynamics.simulate import simulate


def _record():
    # lift-off, rebound on the exterior flank (contact + separation at one instant), settle inside
    return events.record([0.1, 0.2, 0.2, 0.3], [1.0, 2.0, 2.0, 7.0], ["separation", "contact", "separation", "contact"],
                         ["interior", "exterior", "exterior", "interior"], [0.0, -0.05, 0.05, 0.01],
                         [0.0, -1.5, 0.0, -0.3], [np.nan, 0.02, np.nan, 0.004], [True, False, False, True])


def test_counts_have_one_definition_each():
    ev = xr.Dataset(_record())
    assert events.flights(ev) == 2 and events.impacts(ev) == 2
    assert events.lift_offs(ev) == 1 and events.settles(ev) == 1
    assert events.flights(ev, side=events.INTERIOR) == 1 and events.impacts(ev, side=events.EXTERIOR) == 1
    assert np.all(ev["event_v_rel"].values >= 0)            # speeds are stored as magnitudes
    cols = events.columns(_record())                         # the same counts from plain arrays
    assert (events.flights(cols), events.impacts(cols), events.lift_offs(cols)) == (2, 2, 1)
    rise = events.within_rise(ev, 6.0)                       # phi1 = 7 rad lies in the next revolution's rise
    assert rise.sizes["event"] == 4 and events.within_rise(ev, 0.5).sizes["event"] == 0
    with pytest.raises(ValueError, match="side"):
        events.flights(ev, side="left")


def test_the_row_counts_equal_the_named_counts():
    # the rows the compiled loops write (integer codes), in every order of kinds and sides
    rng = np.random.default_rng(7)
    for n in (0, 1, 5, 40):
        rows = np.full((n, events.N_SHARED + 2), np.nan)
        rows[:, events.COL_KIND] = rng.integers(0, 2, n)
        rows[:, events.COL_SIDE] = rng.integers(0, 2, n)
        rows[:, events.COL_PERSISTENT] = rng.integers(0, 2, n)
        ev = events.columns(events.from_rows(rows))
        for side in (None, events.INTERIOR, events.EXTERIOR):
            assert events.flights_in_rows(rows, side) == events.flights(ev, side)
            assert events.impacts_in_rows(rows, side) == events.impacts(ev, side)
    with pytest.raises(ValueError, match="side"):
        events.flights_in_rows(rows, side="left")


def test_integer_codes_and_names_agree_and_bad_values_are_refused():
    by_code = events.record([0.0], [0.0], [events.KIND_CONTACT], [events.SIDE_EXTERIOR], [0.1], [0.0], [0.0], [False])
    assert by_code["event_kind"][1][0] == "contact" and by_code["event_side"][1][0] == "exterior"
    with pytest.raises(ValueError, match="unknown"):
        events.record([0.0], [0.0], ["bounce"], ["interior"], [0.1], [0.0], [0.0], [False])
    with pytest.raises(ValueError, match="rows"):
        events.record([0.0, 1.0], [0.0], ["contact"], ["interior"], [0.1], [0.0], [0.0], [False])


@pytest.mark.hostile("real_file")
def test_the_record_survives_a_netcdf_file_and_a_file_without_one_is_refused(tmp_path):
    path = tmp_path / "ev.nc"
    xr.Dataset(_record()).to_netcdf(path, engine="h5netcdf")
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        ev = events.read(ds)
        assert list(ev["event_kind"].values) == ["separation", "contact", "separation", "contact"]
        assert ev["event_persistent"].dtype == bool and events.lift_offs(ev) == 1
        assert ev["event_percussion"].attrs["units"] == "N s"
    with pytest.raises(FileFormatError, match="no event record"):
        events.read(xr.Dataset({"phi1": ("time", [0.0, 1.0])}))


@pytest.mark.parametrize("model", ["rigid", "elastic"])
def test_both_models_write_the_same_record_and_count_from_it(model):
    res = simulate(paper_scene(backlash=0.128e-3, accuracy="fast"), model)
    ds = res.dataset
    ev = events.read(ds)
    for name, (units, _) in events.VARIABLES.items():
        assert ds[name].attrs["units"] == units and ds[name].dims == ("event",)
    t = ev["event_time"].values
    assert t.size > 2 and np.all(np.diff(t) >= 0)                # time order
    landing = events.is_impact(ev)
    assert np.all(np.isfinite(ev["event_percussion"].values[landing]))
    assert np.all(ev["event_percussion"].values[landing] > 0)
    assert np.all(np.isnan(ev["event_percussion"].values[~landing]))
    jumps = events.flights(ev) if model == "rigid" else events.flights(ev, side=events.INTERIOR)
    assert res.indicators["jumps"] == jumps and res.indicators["impacts"] == events.impacts(ev)
    if model == "rigid":
        # a rebound: a contact and a separation at one instant; the impact's jump in omega2 and its
        # percussion on the contact row are the impact law's
        k = int(np.flatnonzero(landing & ~ev["event_persistent"].values)[0])
        assert t[k + 1] == t[k] and ev["event_kind"].values[k + 1] == "separation"
        jump = ds["event_omega2_after"].values[k] - ds["event_omega2_before"].values[k]
        assert ev["event_domega2"].values[k] == pytest.approx(jump, rel=1e-12)
        assert res.indicators["percussion_max_Ns"] == pytest.approx(np.max(ev["event_percussion"].values[landing]))
    else:
        # a bounce on the exterior flank returns near the speed it came with: its omega2 changes by
        # about 2 v / (l cos alpha), its percussion by about 2 M v
        k = int(np.flatnonzero(landing & (ev["event_side"].values == events.EXTERIOR))[0])
        v = ev["event_v_rel"].values[k]
        i = np.searchsorted(ds["time"].values, t[k])
        inv_arm = (ds["phi2"] - ds["phi2_kin"]).values[i] / ds["x_el"].values[i]      # 1 / (l cos alpha), eq. 19
        assert -ev["event_domega2"].values[k] == pytest.approx(2 * v * inv_arm, rel=0.3)
        assert ev["event_percussion"].values[k] == pytest.approx(2 * ds["reduced_mass"].values[i] * v, rel=0.3)


def test_an_elastic_landing_percussion_is_the_contact_force_impulse():
    # complete_events takes the impulse from the momentum balance, M dv + int drive dt; here the
    # contact force itself is integrated over each landing's window on the dense output
    from labtool.models.dynamics import elastic
    from labtool.models.dynamics.kernels import elastic_nb as eq
    s = paper_scene(backlash=0.016e-3, omega1_mode="var")                     # Table 1 run 1: a dozen landings
    run = elastic._solve(s, "consistent", None, None, None, raw=True)
    phases = elastic.phase_table(run.segments, run.raw)
    rows = elastic.complete_events(run.rows.copy(), phases, run.model, run.tab)
    tg, mass = run.model.tab[eq.TG], run.model.tab[eq.MASS]
    checked = 0
    for i in np.flatnonzero(rows[:, events.COL_KIND] == events.KIND_CONTACT):
        t_c = rows[i, events.COL_TIME]
        k = np.flatnonzero(phases.starts == t_c)
        if not k.size:
            continue
        tau = elastic.bounce_time(run.model.kc, float(np.interp(t_c, tg, mass)), rows[i, events.COL_V_REL])
        t_w = t_c + min(phases.ends[k[-1]] - t_c, tau)
        tt = np.linspace(t_c, t_w, 4001)
        x, v = phases.state_at(np.full(tt.size, k[-1]), tt)
        flank = eq.INTERIOR if rows[i, events.COL_SIDE] == events.SIDE_INTERIOR else eq.EXTERIOR
        F = np.empty(tt.size)
        eq.forces(run.model, np.full(tt.size, flank, dtype=np.int64), x, v, F)
        assert rows[i, events.COL_PERCUSSION] == pytest.approx(abs(np.trapezoid(F, tt)), rel=1e-3)   # M varies over a window
        arm = np.interp(t_c, run.tab.t, run.tab.arm)
        assert rows[i, events.COL_DOMEGA2] == pytest.approx((v[-1] - v[0]) / arm, rel=1e-9)
        checked += 1
    assert checked >= 5


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(xp=st.lists(st.floats(-1e3, 1e3), min_size=2, max_size=40, unique=True),
       fp=st.lists(st.floats(-1e6, 1e6), min_size=40, max_size=40),
       x=st.one_of(st.floats(-2e3, 2e3), st.sampled_from([np.nan, np.inf, -np.inf])),
       on_node=st.integers(0, 39))
def test_the_landings_scalar_interp_is_numpys(xp, fp, x, on_node):
    # complete_events' compiled passes read the drive, the mass and the arm with elastic._interp,
    # which promises np.interp's value bit for bit: between nodes, on a node, outside, NaN
    from labtool.models.dynamics import elastic
    xp = np.sort(np.array(xp))
    fp = np.array(fp[:xp.size])
    for at in (x, xp[on_node % xp.size]):
        want, got = np.interp(at, xp, fp), elastic._interp(at, xp, fp)
        assert got == want or (np.isnan(got) and np.isnan(want)), (at, got, want)
