"""labtool report: the pipeline on synthetic measurements with a known answer, the outputs, bad input."""
import json
import math

import numpy as np
import pytest

from labtool.cli import main
from labtool.common.files import write_netcdf
from labtool.common.errors import InputError
from labtool.common.units import RPM
from labtool.reports import align, pipeline
from labtool.reports.synthetic import synthetic_measured

EVIL_CHANNEL = "<img src=x onerror=alert(1)>"
EVIL_ATTR = "aE_t,<script>alert('x')</script>"


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("report")
    exact = synthetic_measured(noise=0.0, gain=1.0, revolutions=3.4)
    scaled = synthetic_measured(noise=0.0, gain=1.3, revolutions=3.4)
    late = synthetic_measured(noise=0.0, gain=1.0, lag_deg=3.0, revolutions=3.4)
    noisy = synthetic_measured(noise=0.03, gain=1.05, revolutions=3.4, seed=3)
    noisy[EVIL_CHANNEL] = ("time", np.zeros(noisy.sizes["time"]), {"units": "V", "long_name": "<b>bold</b> channel"})
    noisy.attrs["channel_names"] = EVIL_ATTR
    noisy.attrs["law"] = "sine"
    # '$' in a file's strings must not reach matplotlib's mathtext (an unbalanced one fails the drawing)
    noisy["aE_t_amplitude"].attrs["long_name"] = "amplitude $\\frac{ x$ of aE_t"   # mathtext would raise
    noisy["aE_n"].attrs["units"] = "$\\undefinedcmd$"
    paths = {}
    for name, ds in (("exact", exact), ("scaled", scaled), ("late", late), ("noisy", noisy)):
        paths[name] = d / f"{name}.nc"
        write_netcdf(ds, paths[name])
    no_omega = exact.drop_vars("omega2")
    paths["no_omega2"] = d / "no_omega2.nc"
    write_netcdf(no_omega, paths["no_omega2"])
    paths["dir"] = d
    return paths


def _kin_report(path, **kw):
    return pipeline.build_report(path, models=("kinematic",), modes=("const",), **kw)


@pytest.mark.slow
def test_measured_identical_to_the_model_gives_perfect_scores(files):
    """The synthetic measurement is the kinematics itself: after alignment on the cam angle every
    error is ~0 and every ISO score ~1 (checks the alignment, grid and filter end to end)."""
    rep = _kin_report(files["exact"])
    assert len(rep.cycles.revolutions) == 3 and rep.cycles.partial == 2
    assert rep.cycles.cam_speed_rpm == pytest.approx(180.0, rel=1e-6)
    for c in rep.comparisons:
        o = c["overall"]
        assert o["iso_rating"] == pytest.approx(1.0, abs=2e-3), c["signal"]
        assert o["sg_comprehensive"] == pytest.approx(0.0, abs=2e-3)
        assert o["nrmse"] == pytest.approx(0.0, abs=2e-3)
        for r in c["per_revolution"]:
            assert r["iso_rating"] == pytest.approx(1.0, abs=2e-3)


def test_scaled_measurement_gives_the_sprague_geers_magnitude(files):
    """measured = 1.3 x model: M = sqrt(psi_cc/psi_mm) - 1 = 1/1.3 - 1, P = 0, on both signals."""
    rep = _kin_report(files["scaled"])
    for c in rep.comparisons:
        assert c["overall"]["sg_magnitude"] == pytest.approx(1 / 1.3 - 1, abs=1e-3)
        assert c["overall"]["sg_phase"] == pytest.approx(0.0, abs=2e-3)
        assert c["overall"]["peak_max_error"] == pytest.approx(1 / 1.3 - 1, abs=5e-3)


def test_late_measurement_shows_as_a_negative_lag(files):
    """The measurement lags the model by 3 deg of cam angle: the model is early, lag = -3 deg."""
    rep = _kin_report(files["late"])
    for c in rep.comparisons:
        assert c["overall"]["lag_deg"] == pytest.approx(-3.0, abs=0.5)
        assert c["overall"]["peak_max_shift_deg"] == pytest.approx(-3.0, abs=1.0)


@pytest.mark.slow
def test_cli_writes_html_pdf_json_and_escapes_file_strings(files, capsys):
    d = files["dir"]
    html, pdf, js = d / "r.html", d / "r.pdf", d / "s.json"
    rc = main(["report", str(files["noisy"]), "--models", "kinematic", "-o", str(html), "--pdf", str(pdf),
               "--json", str(js)])
    assert rc == 0, capsys.readouterr().err
    text = html.read_text(encoding="utf-8")
    # markup from the file shows as text
    assert EVIL_CHANNEL not in text and "<script>alert" not in text and "<b>bold</b>" not in text
    assert "&lt;img src=x onerror=alert(1)&gt;" in text
    assert "&lt;script&gt;alert(" in text
    assert "&lt;b&gt;bold&lt;/b&gt; channel" in text
    # self-contained: figures embedded, nothing fetched from the network
    assert text.count('src="data:image/png;base64,') >= 5
    assert "http://" not in text and "https://" not in text
    assert pdf.read_bytes().startswith(b"%PDF")
    summary = json.loads(js.read_text())
    assert summary["format"] == "labtool.report.summary" and summary["passed"] is True
    assert {(c["requested_model"], c["omega1"], c["signal"]) for c in summary["comparisons"]} == {
        ("kinematic", "const", "omega2"), ("kinematic", "const", "epsilon2"), ("kinematic", "var", "omega2"),
        ("kinematic", "var", "epsilon2")}
    assert summary["measured"]["whole_revolutions"] == 3
    assert "kinematic, w1 = ct." in capsys.readouterr().out


@pytest.mark.slow
def test_thresholds_pass_and_fail_set_the_exit_code(files, capsys):
    d = files["dir"]
    good = d / "good.toml"
    good.write_text('[omega2]\niso_rating = 0.5\nnrmse = { max = 0.2 }\n[epsilon2]\nsg_comprehensive = 1.0\n')
    bad = d / "bad.toml"
    bad.write_text('[omega2]\niso_rating = 0.999\n[apply]\nomega1 = ["const"]\n')
    args = ["report", str(files["noisy"]), "--models", "kinematic", "--force"]
    assert main(args + ["--thresholds", str(good), "-o", str(d / "g.html"), "--json", str(d / "g.json")]) == 0
    assert all(r["passed"] for r in json.loads((d / "g.json").read_text())["thresholds"]["rows"])
    assert main(args + ["--thresholds", str(bad), "-o", str(d / "b.html"), "--json", str(d / "b.json")]) == 1
    s = json.loads((d / "b.json").read_text())
    assert s["passed"] is False and len(s["thresholds"]["rows"]) == 1 and s["thresholds"]["rows"][0]["omega1"] == "const"
    assert "FAILED" in (d / "b.html").read_text()
    assert "threshold checks failed" in capsys.readouterr().err


def _one_line_exit_2(capsys, args, fragment):
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("labtool: error:"), err
    assert fragment in err[0]


def test_measured_file_without_omega2_is_one_line_exit_2(files, capsys):
    out = files["dir"] / "x.html"
    _one_line_exit_2(capsys, ["report", str(files["no_omega2"]), "-o", str(out)], "no omega2")
    assert not out.exists()


def test_cam_speed_the_models_cannot_do_is_one_line_exit_2(files, capsys):
    out = files["dir"] / "x.html"
    _one_line_exit_2(capsys, ["report", str(files["exact"]), "--rpm", "5000", "-o", str(out)], "5000 rpm")
    _one_line_exit_2(capsys, ["report", str(files["exact"]), "--rpm", "-10", "-o", str(out)], "-10 rpm")
    assert not out.exists()


def test_threshold_file_with_an_unknown_metric_is_one_line_exit_2(files, capsys):
    th = files["dir"] / "unknown.toml"
    th.write_text("[omega2]\niso_ratin = 0.5\n")
    out = files["dir"] / "x.html"
    _one_line_exit_2(capsys, ["report", str(files["exact"]), "--thresholds", str(th), "-o", str(out)],
                     "unknown metric [omega2] iso_ratin (did you mean iso_rating?)")
    assert not out.exists()


@pytest.mark.parametrize("content,fragment", [
    ("[omega3]\nnrmse = 0.1\n", "unknown table [omega3] (did you mean omega2?)"),
    ("[omega2]\nnrmse = 'small'\n", "expected a number or a table"),
    ("[omega2]\nnrmse = { below = 0.1 }\n", "unknown key [omega2.nrmse] below; known: min, max"),
    ("[omega2]\nnrmse = { min = 0.5, max = 0.1 }\n", "above max"),
    ("[apply]\nmodels = ['stiff']\n", '"stiff": expected one of'),
    ("[apply]\nscope = 'sometimes'\n", "scope"),
    ("[omega2\n", "not valid TOML"),
])
def test_bad_threshold_files(files, capsys, content, fragment):
    th = files["dir"] / "bad_th.toml"
    th.write_text(content)
    _one_line_exit_2(capsys, ["report", str(files["exact"]), "--thresholds", str(th), "-o",
                              str(files["dir"] / "x.html")], fragment)


def test_other_bad_inputs(files, capsys, tmp_path):
    junk = tmp_path / "junk.nc"
    junk.write_bytes(b"this is not netcdf")
    _one_line_exit_2(capsys, ["report", str(junk), "-o", str(tmp_path / "a.html")], "not a NetCDF4 file")
    _one_line_exit_2(capsys, ["report", str(tmp_path / "missing.nc"), "-o", str(tmp_path / "a.html")], "not found")
    _one_line_exit_2(capsys, ["report", str(files["exact"]), "--models", "stiff", "-o", str(tmp_path / "a.html")],
                     "unknown model 'stiff'")
    _one_line_exit_2(capsys, ["report", str(files["exact"]), "--omega1", "fast", "-o", str(tmp_path / "a.html")],
                     "unknown omega1 mode 'fast'")
    existing = tmp_path / "exists.html"
    existing.write_text("keep me")
    _one_line_exit_2(capsys, ["report", str(files["exact"]), "-o", str(existing)], "already exists")
    assert existing.read_text() == "keep me"


def test_a_gap_makes_its_revolution_partial():
    ds = synthetic_measured(noise=0.0, revolutions=4.3)
    t = ds["time"].values
    keep = (t < 0.5) | (t > 0.52)           # 20 ms lost inside the second whole revolution
    ds = ds.isel(time=keep)
    cyc = align.measured_cycles(ds, ("omega2", "epsilon2"), align.Conditioning())
    full = align.measured_cycles(synthetic_measured(noise=0.0, revolutions=4.3), ("omega2",), align.Conditioning())
    assert len(cyc.revolutions) == len(full.revolutions) - 1
    assert cyc.partial == full.partial + 1


def test_no_whole_revolution_is_input_error():
    ds = synthetic_measured(noise=0.0, revolutions=0.8)
    with pytest.raises(InputError, match="no whole cam revolution"):
        align.measured_cycles(ds, ("omega2",), align.Conditioning())


def test_time_derivative_on_the_cam_angle_grid():
    """omega2 = sin(3 phi1) at omega1 = 20 rad/s: d omega2/dt = 3 * 20 * cos(3 phi1) exactly
    (a band-limited signal, below the filter's harmonic limit)."""
    cond = align.Conditioning(n_grid=360, n_harmonics=20)
    phi = cond.fine_grid
    d = align.derivative_in_time(np.sin(3 * phi), np.full(phi.size, 20.0), cond)
    assert np.allclose(d, 60.0 * np.cos(3 * phi), atol=1e-9)


def test_harmonic_lowpass_keeps_low_and_removes_high_harmonics():
    x = np.linspace(0, 2 * math.pi, 400, endpoint=False)
    y = np.sin(2 * x) + 0.5 * np.cos(50 * x)
    assert np.allclose(align.harmonic_lowpass(y, 10), np.sin(2 * x), atol=1e-12)


@pytest.mark.slow
def test_json_to_stdout_is_one_object(files, capsys, tmp_path):
    rc = main(["report", str(files["exact"]), "--models", "kinematic", "--omega1", "const", "-o",
               str(tmp_path / "r.html"), "--json", "-"])
    assert rc == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["passed"] is True and summary["headline"][0]["omega2_iso_grade"] == "excellent"


@pytest.mark.slow
@pytest.mark.parametrize("drop", ["epsilon2", "phi1"])
def test_measured_file_without_epsilon2_or_phi1_is_one_line_exit_2(files, capsys, tmp_path, drop):
    import xarray as xr
    ds = xr.open_dataset(files["exact"], engine="h5netcdf").load().drop_vars(drop)
    path = tmp_path / f"no_{drop}.nc"
    write_netcdf(ds, path)
    _one_line_exit_2(capsys, ["report", str(path), "-o", str(tmp_path / "r.html")], f"no {drop}" if drop == "epsilon2" else "no cam angle phi1")


@pytest.mark.slow
def test_the_processing_lowpass_is_reapplied_to_the_simulations(tmp_path, monkeypatch):
    """A measurement low-passed in time by processing's Butterworth (here a strong 30 Hz, 10 cam
    harmonics): with the same filter re-applied to the model the two agree (the filters are the
    same); without it epsilon2 clearly disagrees."""
    import json as _json

    from labtool.processing.filters import lowpass_sos, zero_phase
    ds = synthetic_measured(noise=0.0, revolutions=4.3)
    sos = lowpass_sos(10_000.0, 30.0, 4)
    for name in ("omega2", "epsilon2"):
        ds[name].values[:] = zero_phase(sos, ds[name].values)
    ds.attrs["processing_history"] = _json.dumps([{"step": "lowpass", "parameters": {
        "kind": "butterworth", "order": 4, "cutoff_hz": 30.0, "zero_phase": True}}])
    path = tmp_path / "lp.nc"
    write_netcdf(ds, path)
    rep = _kin_report(path)
    assert rep.time_filter == align.TimeFilter(10_000.0, 30.0, 4)
    same = {c["signal"]: c["overall"] for c in rep.comparisons}
    # the middle revolutions agree; the recording's first/last revolutions carry filter end effects
    assert same["epsilon2"]["sg_comprehensive"] < 0.01 and same["omega2"]["sg_comprehensive"] < 0.01
    monkeypatch.setattr(align, "processing_filter", lambda ds: None)
    rep2 = _kin_report(path)
    assert any("no processing low-pass" in n for n in rep2.notes)
    other = {c["signal"]: c["overall"] for c in rep2.comparisons}
    assert other["epsilon2"]["sg_comprehensive"] > 5 * same["epsilon2"]["sg_comprehensive"]
    assert other["epsilon2"]["sg_comprehensive"] > 0.03


from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

_BASE = synthetic_measured(noise=0.01, revolutions=2.6, fs=2000.0)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(kind=st.sampled_from(["nan_block", "phi_const", "phi_reversed", "time_reversed", "inf", "short", "huge_phi",
                             "time_dup"]),
       start=st.floats(0.0, 0.9), frac=st.floats(0.0, 1.0))
def test_damaged_measurements_give_a_report_or_an_input_error(kind, start, frac):
    """Whatever is wrong with the measured signals, the alignment either finds whole revolutions or
    raises InputError (one line, exit 2), never another exception."""
    ds = _BASE.copy(deep=True)
    n = ds.sizes["time"]
    i0, i1 = int(start * n), int(start * n + frac * (n - start * n))
    if kind == "nan_block":
        ds["omega2"].values[i0:i1] = np.nan
    elif kind == "inf":
        ds["epsilon2"].values[i0:i1] = np.inf
    elif kind == "phi_const":
        ds["phi1"].values[i0:i1] = 1.0
    elif kind == "phi_reversed":
        ds["phi1"].values[:] = ds["phi1"].values[::-1]
    elif kind == "time_reversed":
        ds = ds.assign_coords(time=ds["time"].values[::-1].copy())
    elif kind == "short":
        ds = ds.isel(time=slice(0, max(int(frac * 50), 1)))
    elif kind == "huge_phi":
        ds["phi1"].values[i0:i1] *= 1e6
    elif kind == "time_dup":
        t = ds["time"].values.copy()
        t[i0:i1] = t[i0]
        ds = ds.assign_coords(time=t)
    try:
        cyc = align.measured_cycles(ds, ("omega2", "epsilon2"), align.Conditioning())
    except InputError:
        return
    assert len(cyc.revolutions) >= 1
    assert all(np.all(np.isfinite(v)) for v in cyc.signals.values())


def test_a_given_speed_that_contradicts_the_measured_one_is_refused(files):
    """--rpm 250 on a recording whose cam turned at 180 rpm: the models would not run where the
    stand did; refused before any simulation, naming the measured speed (5 rpm answered with the
    rigid model's 5000-event cap)."""
    for rpm in (250.0, 5.0):
        with pytest.raises(InputError, match=r"--rpm .* contradicts the measured cam speed 180\.0 rpm"):
            pipeline.build_report(files["exact"], models=("kinematic",), modes=("const",),
                                  overrides={"cam_speed": rpm * RPM})
    rep = pipeline.build_report(files["exact"], models=("kinematic",), modes=("const",), overrides={"cam_speed": 185 * RPM})
    assert rep.scene["cam_speed_rpm"] == 185.0 and rep.scene["cam_speed_rpm_source"] == "option --rpm"


@pytest.mark.slow
def test_the_models_run_at_the_measured_speed_not_the_stated_one(tmp_path):
    """A stand whose drive slips (or is set differently from the paper's) turns at another speed than
    it states: the models run at the measured mean speed; omega1 var has its drive set to that speed
    at no load, so its cam turns at it on average too (no load: the inertia moments average out)."""
    ds = synthetic_measured(noise=0.01, revolutions=4.3)
    ds.attrs["cam_speed_rpm"] = 200.0
    path = tmp_path / "m.nc"
    write_netcdf(ds, path)
    rep = pipeline.build_report(path, models=("rigid",), modes=("const", "var"), accuracy="fast", revolutions=3,
                                overrides={"restitution": 0.5}, robustness=False)
    op = rep.scene
    assert op["cam_speed_rpm"] == pytest.approx(180.0, rel=1e-5) and op["cam_speed_rpm_stated"] == 200.0
    assert op["omega1_var_n1_rpm"] == pytest.approx(180.0 * 920.0 / 1000.0, rel=1e-3)
    assert any("the file states 200 rpm" in n and "180.00 rpm" in n for n in rep.notes)
    for run in rep.sims:
        t, ph = run.dataset["time"].values, run.dataset["phi1"].values
        last = ph >= 2 * math.pi
        rpm = (ph[-1] - ph[last][0]) / (t[-1] - t[last][0]) * 30 / math.pi
        assert rpm == pytest.approx(180.0, rel=5e-3), run.omega1


def test_a_failing_model_ends_the_report_but_the_demo_lets_the_kinematic_level_stand_in(files, monkeypatch):
    import labtool.models.dynamics.simulate as ms
    real = ms.simulate

    def broken(scene, model="auto"):
        if model == "elastic":
            raise ValueError("step size too small")
        return real(scene, model)

    monkeypatch.setattr(ms, "simulate", broken)
    with pytest.raises(InputError, match="elastic model cannot simulate 180 rpm"):
        pipeline.build_report(files["exact"], models=("elastic",), modes=("const",))
    rep = pipeline.build_report(files["exact"], models=("elastic",), modes=("const",), stand_in_on_failure=True)
    assert rep.sims[0].model == "kinematic" and rep.sims[0].requested == "elastic"
    assert any("elastic model failed (ValueError: step size too small)" in n for n in rep.notes)


def test_model_events_read_the_one_record():
    """The report reads a simulation's events from the one record (labtool.models.dynamics.events): contacts
    with the step of omega2 the model recorded, separations with none; no record, no events."""
    import xarray as xr
    from labtool.models.dynamics import events as model_events
    from labtool.reports import events
    two = 2 * math.pi
    phi = np.array([0.5, 1.0, 1.0, two + 0.3, two + 0.4, two + 0.4, two + 0.9])
    kind = ["separation", "contact", "separation", "separation", "contact", "separation", "contact"]
    side = ["interior", "exterior", "exterior", "interior", "exterior", "exterior", "interior"]
    n = phi.size
    d_omega2 = np.array([0.0, -0.8, 0.0, 0.0, -0.5, 0.0, -0.5])
    record = model_events.record(phi / two, phi, kind, side, np.zeros(n), d_omega2, np.zeros(n), np.zeros(n, dtype=bool))
    sim = xr.Dataset({"phi1": ("time", np.linspace(0, 2 * two, 50)), **record}, coords={"time": np.linspace(0, 2, 50)})
    rec = events.model_events(sim)
    assert list(rec.kind) == kind
    assert np.allclose(rec.d_omega2[rec.contacts], [-0.8, -0.5, -0.5]) and np.isnan(rec.d_omega2[~rec.contacts]).all()
    assert np.allclose(rec.phi1, phi)
    assert events.model_events(xr.Dataset({"phi1": ("phi1", [0.0, 1.0])})) is None


@pytest.mark.slow
def test_model_options_reach_the_simulations_and_the_page(files, capsys, tmp_path):
    """--restitution / --contact-damping / --contact-length-mm / --elastic-gap set the models' scene
    (not the paper's idealisations), are shown on the page and in the JSON; bad values exit 2."""
    op = pipeline.operating_point(pipeline.load_measured(files["exact"]), 180.0,
                                  {"restitution": 0.3, "contact_damping": 20.0, "elastic_gap": "closed"})
    assert (op["restitution"], op["contact_damping_s_per_m"], op["contact_length_mm"], op["elastic_gap"]) == \
        (0.3, 20.0, 6.0, "closed")
    cond = align.Conditioning()
    paper = pipeline.run_simulation({**op, "restitution": 1.0}, "rigid", "const", "fast", 1.0, cond)
    damped = pipeline.run_simulation(op, "rigid", "const", "fast", 1.0, cond)
    assert damped.indicators["impacts"] != paper.indicators["impacts"]
    el = pipeline.run_simulation(op, "elastic", "const", "fast", 1.0, cond)
    assert el.dataset.attrs["elastic_gap"] == "closed" and el.dataset.attrs["contact_damping_s_per_m"] == 20.0

    html, js = tmp_path / "r.html", tmp_path / "r.json"
    rc = main(["report", str(files["exact"]), "--models", "rigid", "--omega1", "const", "--accuracy", "fast",
               "--restitution", "0.5", "--revolutions", "1", "-o", str(html), "--json", str(js)])
    assert rc == 0
    assert json.loads(js.read_text())["operating_point"]["restitution"] == 0.5
    assert "restitution k" in html.read_text()
    for bad in (["--restitution", "2"], ["--elastic-gap", "ajar"], ["--contact-damping", "-1"],
                ["--contact-length-mm", "nan"]):
        capsys.readouterr()
        out = tmp_path / "bad.html"
        assert main(["report", str(files["exact"]), "--models", "rigid,elastic", "--omega1", "const",
                     "--accuracy", "fast", "--revolutions", "1", "-o", str(out), *bad]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("labtool: error:"), err
        assert not out.exists()
