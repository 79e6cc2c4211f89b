"""labtool suggest: the next experiment's criterion on a stand-in whose backlash is most visible
at a known speed, the expected interval's parts against a joint fit's own, and its bad input.

The stand-in (tests/test_fit.py) shifts the kinematic cycle by 0.05 ln(j / 0.2 mm) rad; here the
shift is also weighted by w(n1) = exp(-((n1 - 300) / 120)^2): a recording at 300 rpm sees the
backlash best, so the suggestion must be 300 rpm, and a second recording at the measured speed
must be expected to narrow the measurement's part of a lone parameter's interval by 1 / sqrt(2)
(twice the information). The real models on the simulated stand are in benchmarks/suggest_loop.py.
"""
from __future__ import annotations

import json
import math

import pytest

from labtool.common.errors import InputError
from labtool.common.files import write_netcdf
from labtool.identification.design import SuggestRequest, information, suggest
from labtool.reports.synthetic import synthetic_measured
from tests.test_fit import stand_in


def weight(rpm: float) -> float:
    return math.exp(-((rpm - 300.0) / 120.0) ** 2)


def _stand_in(monkeypatch):
    stand_in(monkeypatch, shift=lambda op: 0.05 * math.log(op["backlash_mm"] / 0.2) * weight(op["cam_speed_rpm"])
             / weight(180.0))


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    path = tmp_path_factory.mktemp("suggest") / "measured.nc"
    write_netcdf(synthetic_measured(noise=0.01, revolutions=4.3), path)
    return path


@pytest.mark.slow
def test_the_measurement_part_narrows_most_where_the_backlash_shows_most(measured, monkeypatch, tmp_path):
    _stand_in(monkeypatch)
    # the restitution at the stand-in's own 0.5, so that the model explains the measurement
    out = suggest(SuggestRequest([measured], free="backlash", shared="backlash", rpm_range=(120.0, 480.0, 30.0),
                                 loads=(0.0,), fit={"overrides": {"restitution": 0.5}}))
    s = out.summary
    lin = out.fit.linear
    by_rpm = {c.rpm: c for c in out.candidates}
    # a second recording like the first: twice the information, the measurement's part / sqrt(2);
    # its objective's roughness R_c, foreseen from the model's departures at the fit's points at
    # 180 rpm, is the measured R's order (R is one draw, an rms over two departures): with R_c / R
    # within a factor 3 either way the roughness's part sqrt(hypot(R, R_c) g / 2) / sqrt(R g) lies
    # between sqrt(hypot(1, 1/3) / 2) = 0.72 and sqrt(hypot(1, 3) / 2) = 1.26 (none foreseen: 0.71)
    meas_now = lin.t * lin.sd_u[0]
    assert by_rpm[180.0].parts["measurement"][0] / meas_now == pytest.approx(1 / math.sqrt(2), rel=0.05)
    assert math.sqrt(math.hypot(1, 1 / 3) / 2) < by_rpm[180.0].parts["roughness"][0] / lin.rough_u[0] \
        < math.sqrt(math.hypot(1, 3) / 2)
    # at 300 rpm the shift per unit ln j is 1 / w(180) = 1.75 times larger: information x 3.1
    expected = 1 / math.sqrt(1 + (1 / weight(180.0)) ** 2)
    assert by_rpm[300.0].parts["measurement"][0] / meas_now == pytest.approx(expected, rel=0.05)
    best_measurement = min(out.candidates, key=lambda c: c.parts["measurement"][0])
    assert best_measurement.rpm == 300.0
    # the point is where the whole expected interval is narrowest (here the stand-in's curvature,
    # counted as the fit's roughness, is most of it: a recording as sensitive as 300 rpm brings
    # steps in its objective as large, so the point lies below 300 rpm, not at it)
    best = min(out.candidates, key=lambda c: c.shrink["backlash_mm"])
    assert s["point"] == {"cam_speed_rpm": best.rpm, "Fu_N": 0.0, "law": "sine", "jt_factor": 1.0}
    assert best.shrink["backlash_mm"] < 1.0
    assert f"[[points]]\nname = \"next_{best.rpm:g}rpm\"\nrpm = {best.rpm:g}\nFu_N = 0\n" == s["plan_points_toml"]
    json.dumps(s, allow_nan=False)


@pytest.mark.slow
def test_the_cli_prints_the_point_and_writes_the_json_and_the_figure(measured, monkeypatch, tmp_path, capsys):
    from labtool.cli import main
    _stand_in(monkeypatch)
    out = tmp_path / "next.json"
    rc = main(["suggest", str(measured), "--free", "backlash", "--shared", "backlash", "--rpm-range", "180:420:60",
               "--loads", "0", "-o", str(out)])
    text = capsys.readouterr().out
    s = json.loads(out.read_text())
    assert rc == 0 and f"next point: {s['point']['cam_speed_rpm']:g} rpm, Fu = 0 N" in text and "[[points]]" in text
    assert s["format"] == "labtool.suggest" and 180.0 <= s["point"]["cam_speed_rpm"] <= 420.0
    assert (tmp_path / "next.png").stat().st_size > 10_000


def test_information_ignores_a_parameter_the_fit_does_not_see():
    import numpy as np
    cov = np.array([[0.04, 0.0], [0.0, np.inf]])
    M = information(cov)
    assert M[0, 0] == pytest.approx(25.0) and M[1, 1] == 0.0


@pytest.mark.parametrize("args, fragment", [
    (["--goal", "discriminate", "--models", "rigid"], "--goal discriminate needs two or more of rigid, elastic"),
    (["--goal", "guess"], "--goal must be one of identify, discriminate"),
    (["--rpm-range", "300:200:10"], "--rpm-range must be lo:hi:step with 0 < lo <= hi"),
    (["--rpm-range", "a:b:c"], "--rpm-range must be lo:hi:step in rpm"),
    (["--rpm-range", "100:600:1"], "at most 201"),
    (["--loads", "x"], "--loads must be numbers in N"),
    (["--loads", "-5"], "a load must be a finite force >= 0 N"),
    (["--free", "contact_damping"], "not a parameter of the rigid model"),
    (["--shared", "restitution"], "'restitution' is not among the free parameters"),
])
def test_bad_options_end_in_one_line_and_exit_2(measured, capsys, args, fragment):
    from labtool.cli import main
    rc = main(["suggest", str(measured), "--free", "backlash", *args])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith("labtool: error:") and fragment in err[0], err


def test_speeds_the_models_do_not_take_are_refused(measured):
    with pytest.raises(InputError, match="holds no speed the models take"):
        suggest(SuggestRequest([measured], free="backlash", rpm_range=(0.1, 0.5, 0.1)))


@pytest.mark.slow
def test_discriminate_picks_a_speed_where_the_models_differ_more_than_at_180_rpm(tmp_path, capsys):
    # the simulated stand's twin at 180 rpm; rigid and elastic with their default options: where
    # does a recording tell them apart best? (the report's discrimination, at every candidate)
    from labtool.cli import main
    h5, nc = tmp_path / "twin.h5", tmp_path / "twin.nc"
    assert main(["acquire", "--device", "sim", "--rpm", "180", "--duration", "3", "--fast", "-o", str(h5)]) == 0
    assert main(["process", str(h5), "-o", str(nc)]) == 0
    capsys.readouterr()
    out = tmp_path / "next.json"
    assert main(["suggest", str(nc), "--goal", "discriminate", "--rpm-range", "120:600:120", "--loads", "0",
                 "-o", str(out)]) == 0
    assert "next point:" in capsys.readouterr().out
    s = json.loads(out.read_text())
    at = {c["cam_speed_rpm"]: c["epsilon2_distance"] for c in s["candidates"]}
    print(s["expected"]["sentence"])
    # the measured speed (179.99... rpm) is among the candidates; the point is another, where the
    # models' epsilon2 differ by more (twin, 3 s: 73 measured scatters at 600 rpm, 12 at 180)
    assert abs(s["point"]["cam_speed_rpm"] - 180.0) > 1.0
    assert s["expected"]["epsilon2_distance"] > 1.5 * s["expected"]["at_measured"]
    assert s["expected"]["epsilon2_distance"] == max(v for v in at.values() if v is not None)
    assert (tmp_path / "next.png").stat().st_size > 10_000


def _misfit_problem(rng, n=400, p=2, size=6.0):
    """A linear problem whose misfit (a few smooth bumps, ``size`` x the unit noise) the model
    cannot follow: its Jacobian and residuals."""
    import numpy as np
    x = np.linspace(0.0, 1.0, n)
    J = np.column_stack([np.sin(2 * np.pi * (k + 1) * x) for k in range(p)]) * 3.0
    bumps = sum(np.exp(-0.5 * ((x - c) / 0.01) ** 2) for c in (0.13, 0.41, 0.58, 0.77, 0.9))
    return J, size * bumps + rng.standard_normal(n)


@pytest.mark.parametrize("grow", [1.0, 3.0])
def test_the_expected_discrepancy_is_the_joint_fits_own(grow):
    # one recording with a misfit; a second whose misfit has the same shape, ``grow`` x as large:
    # the discrepancy half-width combine() expects must be what uncertainty.discrepancy finds on
    # the two recordings stacked (an independent computation from the residuals themselves)
    import numpy as np
    from labtool.identification import expected, uncertainty
    rng = np.random.default_rng(7)
    J0, r0 = _misfit_problem(rng)
    J1, r1 = _misfit_problem(rng, size=6.0 * grow)
    u = np.full(2, 0.5)
    lin = uncertainty.linear(J0, r0, u)
    lin.disc_u, lin.disc_rise, lin.disc_info = uncertainty.discrepancy(J0, r0, lin)
    infl = lin.inflation
    today = expected.Today(M=information(lin.cov_u), A=information(lin.gn_inv), t=lin.t, half=lin.half_u(),
                           other=np.zeros(2), excess=lin.disc_info["objective_beyond_noise"], objective=float(r0 @ r0),
                           features=lin.disc_info["features"], inflation=max(float(np.mean(infl)), 1.0), rough=0.0,
                           n_files=1, ns=2)
    excess_c = float(r1 @ r1) - r1.size
    got = expected.combine(today, np.arange(2), J1.T @ J1 / lin.s2, J1.T @ J1, excess_c, r1.size)
    J, r = np.vstack([J0, J1]), np.r_[r0, r1]
    both = uncertainty.linear(J, r, u, [(0, r0.size), (r0.size, r.size)])
    want, _, _ = uncertainty.discrepancy(J, r, both)
    assert got["discrepancy"] == pytest.approx(want, rel=0.2)
    if grow > 1.0:
        # a recording where the model misses 3 x as much: the interval widens despite its information
        assert np.all(got["discrepancy"] > lin.disc_u)


@pytest.mark.slow
def test_the_secant_is_the_tangent_where_the_residuals_are_linear_and_shorter_where_not(measured, monkeypatch):
    # the stand-in's gain is linear in k (1 + 0.8 (k - 0.5)), so a secant across any interval of k
    # is its derivative; its backlash shifts the cycle by a phase linear in ln j, so a secant across
    # a wide interval of ln j sees a harmonic of order n shortened by sin(n d) / (n d) < 1
    import numpy as np
    from labtool.identification import design
    from labtool.identification.search import FD_STEP
    _stand_in(monkeypatch)
    req = SuggestRequest([measured], free="backlash,restitution", rpm_range=(300.0, 300.0, 30.0), loads=(0.0,))
    fit = suggest(req).fit
    target, space = fit.target, fit.space
    noise = design.noise_model([target])
    u = np.asarray(fit.linear.u, float)
    free = space.params
    args = (req, space, free, u, dict(fit.evaluator.fixed), target, noise, 300.0, 0.0)
    narrow = design._candidate_runs(*args, np.full(2, FD_STEP), None)[0]
    wide = design._candidate_runs(*args, np.full(2, 0.3), None)[0]
    k = [p.key for p in free].index("restitution")
    j = 1 - k
    assert np.allclose(wide[:, k], narrow[:, k], rtol=1e-6, atol=1e-9 * np.abs(narrow[:, k]).max())
    assert np.linalg.norm(wide[:, j]) < 0.9 * np.linalg.norm(narrow[:, j])


@pytest.mark.parametrize("change", [0.0, 0.5, 2.0])
def test_the_new_recordings_revolutions_part_is_the_joint_fits_own(change):
    # today's recording repeats itself exactly; the new one's model revolutions differ by
    # ``change`` x a fixed pattern: the model-revolutions part combine() expects must be the one
    # uncertainty.numerical finds on the two stacked (2 x the spread of the Gauss-Newton steps each
    # revolution asks for), zero for a model that repeats itself and growing with its change
    import numpy as np
    from labtool.identification import expected, uncertainty
    rng = np.random.default_rng(3)
    J0, r0 = _misfit_problem(rng, size=0.0)
    J1, r1 = _misfit_problem(rng, size=0.0)
    x = np.linspace(0.0, 1.0, r1.size)
    pattern = np.sin(2 * np.pi * x) + 0.3 * np.cos(6 * np.pi * x)
    revs1 = [r1 + change * k * pattern for k in (-1.0, 0.4, 1.0)]
    u = np.full(2, 0.5)
    lin = uncertainty.linear(J0, r0, u)
    today = expected.Today(M=information(lin.cov_u), A=information(lin.gn_inv), t=lin.t, half=lin.half_u(),
                           other=np.zeros(2), excess=0.0, objective=float(r0 @ r0), features=float(r0.size),
                           inflation=1.0, rough=0.0, n_files=1, ns=2)
    rev_c = J1.T @ (np.array(revs1) - r1).T
    got = expected.combine(today, np.arange(2), J1.T @ J1 / lin.s2, J1.T @ J1, 0.0, r1.size, None, rev_c)
    J, r = np.vstack([J0, J1]), np.r_[r0, r1]
    want, _, _ = uncertainty.numerical(J, r, [np.r_[r0, rk] for rk in revs1], None)
    assert got["numerical"] == pytest.approx(want, rel=1e-6, abs=1e-12)
    if change == 0.0:
        assert np.all(got["numerical"] == 0.0)
    else:
        assert np.all(got["numerical"] > 0.0)
        assert got["numerical"] == pytest.approx(change * _revolutions_part_per_change(J0, J1, r1, pattern), rel=1e-6)


def _revolutions_part_per_change(J0, J1, r1, pattern):
    import numpy as np
    G = np.linalg.inv(J0.T @ J0 + J1.T @ J1)
    steps = np.array([G @ J1.T @ (k * pattern) for k in (-1.0, 0.4, 1.0)])
    return 2.0 * steps.std(axis=0, ddof=1)


@pytest.mark.parametrize("curvature", [0.0, 0.7])
def test_the_roughness_at_a_candidate_is_what_the_fit_would_measure(curvature):
    # residuals r(u) = e + a (u - u0) + curvature x b (u - u0)^2 / h^2 per parameter, e a misfit:
    # the departures _rough_gaps foresees (with r0 = e, no noise) must give the R that
    # uncertainty.roughness measures on the objective itself; zero where the residuals are linear
    import numpy as np
    from types import SimpleNamespace
    from labtool.identification import design, uncertainty
    from labtool.identification.search import FD_STEP as h
    rng = np.random.default_rng(5)
    n, p = 300, 2
    a, b, e = rng.standard_normal((n, p)), rng.standard_normal((n, p)), 2.0 * rng.standard_normal(n)
    u0 = np.array([0.4, 0.6])

    def model(u):
        d = np.asarray(u, float) - u0
        return a @ d + curvature * (b @ (d / h) ** 2)

    class Problem:
        def at(self, v):
            r = e + model(v)
            return SimpleNamespace(ok=True, objective=float(r @ r))

    J = np.column_stack([(model(u0 + h * np.eye(p)[i]) - model(u0 - h * np.eye(p)[i])) / (2 * h) for i in range(p)])
    lin = uncertainty.linear(J, e, u0)
    _, want = uncertainty.roughness(Problem(), lin, J, u0, e + model(u0), h)
    gaps = []
    for i in range(p):
        up, dn = u0 + h * np.eye(p)[i], u0 - h * np.eye(p)[i]
        gaps += design._rough_gaps(model, lambda x, y: x - y, model(u0), u0, i, h, model(up), model(dn), np.zeros(n))
    got = design.roughness_at(gaps, e)
    assert got == pytest.approx(want, rel=1e-9, abs=1e-9)
    assert (got > 1.0) == (curvature > 0.0)


def test_the_expected_peak_scales_with_speed_and_names_what_clips():
    from labtool.identification.design import HEADROOM_EXPONENT, clips, expected_peak
    measured = [(180.0, 0.39)]
    assert expected_peak(measured, 180.0) == pytest.approx(0.39)
    assert expected_peak(measured, 90.0) == pytest.approx(0.195)                    # below: as the speed
    assert expected_peak(measured, 360.0) == pytest.approx(0.39 * 2 ** HEADROOM_EXPONENT)
    assert clips(measured, 300.0) is None
    why = clips(measured, 440.0)
    assert "expected to clip" in why and "114 %" in why and "39 % at the measured 180 rpm" in why
    # the largest of several measurements decides; no stated headroom: nothing is left out
    assert expected_peak([(180.0, 0.1), (300.0, 0.6)], 400.0) == pytest.approx(0.6 * (4 / 3) ** HEADROOM_EXPONENT)
    assert clips([], 600.0) is None and math.isnan(expected_peak([], 600.0))


@pytest.mark.slow
def test_the_headroom_law_foresees_the_clipping_of_a_faster_recording(tmp_path):
    """On the simulated stand (the rigid truth, j 0.187 mm, k 0.5): the peak over the input range
    the 180 rpm recording states, scaled by HEADROOM_EXPONENT, is at least what the 300 and 440 rpm
    recordings reach, and not far above it; at 520 rpm the recording clips and the law says so."""
    import h5py

    from labtool.cli import main
    from labtool.identification.design import clips, expected_peak, headroom
    from labtool.identification.objective import load_target

    peaks, clipped = {}, {}
    for rpm in (180, 300, 440, 520):
        h5 = tmp_path / f"r{rpm}.h5"
        assert main(["acquire", "--device", "sim", "--truth", "rigid", "--backlash-mm", "0.187", "--restitution",
                     "0.5", "--rpm", str(rpm), "--duration", "2", "--fast", "--seed", "4", "-o", str(h5)]) == 0
        with h5py.File(h5, "r") as f:
            peaks[rpm] = float(f["signals"].attrs["peak_fraction_of_range"][0])
            clipped[rpm] = bool(f["signals"].attrs["clipped"][0])
    nc = tmp_path / "r180.nc"
    assert main(["process", str(tmp_path / "r180.h5"), "-o", str(nc)]) == 0
    measured = headroom([load_target(nc, None, {})])         # carried through measured.nc
    assert measured and measured[0][1] == pytest.approx(peaks[180])
    print(peaks, clipped, {r: expected_peak(measured, r) for r in (300, 440, 520)})
    for rpm in (300, 440):
        assert not clipped[rpm] and peaks[rpm] <= expected_peak(measured, rpm) <= 1.3 * peaks[rpm]
    assert clips(measured, 300) is None
    assert clipped[520] and clips(measured, 520) is not None
