"""Campaign plans: the schema (types, ranges, unknown keys named), points from a list and a grid."""
import pytest

from labtool.campaign.plan import expand_points, load_plan
from labtool.common.errors import InputError
from labtool.cli import main

SAMPLE = __import__("pathlib").Path(__file__).resolve().parents[1] / "sample_data" / "plans"


def write(tmp_path, text, name="plan.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_the_sample_plan_is_the_papers_three_speeds():
    plan = load_plan(SAMPLE / "paper_3_speeds.toml")
    assert [p.rpm for p in plan.points] == [180.0, 300.0, 500.0]
    assert [p.name for p in plan.points] == ["01_180rpm", "02_300rpm", "03_500rpm"]
    for p in plan.points:
        assert (p.law, p.Fu_N, p.backlash_mm, p.jt_factor) == ("sine", 0.0, 0.128, 1.0)
        assert p.duration_s == pytest.approx(9.5 * 60 / p.rpm)    # 8 whole revolutions + 1.5 periods
    assert [p.seed for p in plan.points] == [1, 2, 3]
    assert plan.calibration_files[0].name == "calibration.toml" and plan.calibration_files[0].is_file()
    assert plan.doc.compare.models == ["rigid", "elastic"]


def test_a_grid_varies_rpm_fastest_and_names_what_varies(tmp_path):
    p = write(tmp_path, "[grid]\nrpm = [180, 300]\nFu_N = [0, 65]\n[[points]]\nrpm = 500\nname = 'extra'\nduration_s = 2\n")
    pts = load_plan(p).points
    assert [(x.rpm, x.Fu_N) for x in pts] == [(500, 0), (180, 0), (300, 0), (180, 65), (300, 65)]
    assert pts[0].name == "extra" and pts[0].duration_s == 2.0
    assert pts[3].name == "04_180rpm_Fu65N"
    assert pts[1].duration_s == pytest.approx(11.5 * 60 / 180)   # the paper's default: 10 revolutions


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("text,expect", [
    ("[device]\nkind = 'sim'\nrate = 10000\n", "unknown key [device] rate (did you mean rate_hz?); known: kind, rate_hz"),
    ("[[points]]\nrpm = 180\nspeed = 3\n", "unknown key [points[0]] speed"),
    ("[defaults]\nFu = 65\n[[points]]\nrpm = 180\n", "unknown key [defaults] Fu (did you mean Fu_N?)"),
    ("[[points]]\nrpm = 'fast'\n", "[points[0]] rpm = \"fast\": expected a number [rpm], got a string"),
    ("[[points]]\nrpm = true\n", "rpm = true: expected a number [rpm], got a boolean"),
    ("[[points]]\nrpm = -180\n", "rpm = -180: must not be negative"),
    ("[[points]]\nrpm = 1e6\n", "point 1: cam speed 1000000 rpm is outside the range the models take"),
    ("[[points]]\nrpm = nan\n", "rpm = nan: must be a finite number"),
    # inside the schema's bound but past the models' range: refused before any point runs
    ("[grid]\nrpm = [180, 1500]\n", "grid point 2: cam speed 1500 rpm is outside the range the models take"),
    ("[[points]]\nrpm = 180\nrevolutions = 5\nduration_s = 3\n", "give revolutions or duration_s, not both"),
    # whole revolutions are recorded and averaged: 8.5 cannot be
    ("[defaults]\nrevolutions = 8.5\n[[points]]\nrpm = 180\n", "[defaults] revolutions = 8.5: must be a whole number"),
    ("[compare]\nmodels = ['rigid', 'fem']\n[[points]]\nrpm = 180\n", "[compare] models[1] = \"fem\": expected one of"),
    ("[device]\nkind = 'nidaqmx'\n[[points]]\nrpm = 180\n", "needs channels"),
    ("[device]\nchannels = 'Dev1/ai0:2'\n[[points]]\nrpm = 180\n", "describe a nidaqmx device"),
    ("[[points]]\nrpm = 180\nlaw = 'square'\n", "unknown motion law 'square'"),
    ("[[points]]\nrpm = 180\nname = 'a'\n[[points]]\nrpm = 300\nname = 'a'\n", "two points are named a"),
    ("[[points]]\nrpm = 180\nname = '../../etc'\n", "a point name is letters, digits"),
    ("[campaign]\nname = 'x'\n", "no operating points"),
    ("[[points]]\nlaw = 'sine'\n", "point 1: no rpm"),
    ("[grid]\nrpm = [100, 200, 300, 400, 500, 600, 700, 800, 900, 1000]\nFu_N = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9]\n"
     "backlash_mm = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6]\n", "at most 500"),
    ("[calibration]\nfiles = ['nope.toml']\n[[points]]\nrpm = 180\n", "calibration file"),
    ("[[points]\nrpm = 180\n", "not valid TOML"),
])
def test_a_bad_plan_is_one_line_naming_the_key(tmp_path, capsys, text, expect):
    p = write(tmp_path, text)
    out = tmp_path / "out"
    assert main(["campaign", "run", str(p), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("labtool: error: ") and expect in err[0], err
    assert not out.exists()


@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("content", [b"\xff\xfe not utf-8", b"", b"[[points]]\nrpm = 180\n" * 1 + b"\x00"])
def test_odd_plan_bytes_are_one_line(tmp_path, capsys, content):
    p = tmp_path / "plan.toml"
    p.write_bytes(content)
    assert main(["campaign", "run", str(p), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("labtool: error: ")


def test_a_plan_that_is_a_folder_or_missing(tmp_path, capsys):
    for target in (tmp_path, tmp_path / "none.toml"):
        assert main(["campaign", "run", str(target), "-o", str(tmp_path / "out")]) == 2
        assert "plan" in capsys.readouterr().err


def test_defaults_and_points_combine():
    from labtool.campaign.plan import check_plan
    doc = check_plan({"defaults": {"law": "cosine", "duration_s": 2.0, "backlash_mm": 0.016},
                      "points": [{"rpm": 180}, {"rpm": 300, "revolutions": 4, "jt_factor": 1.5}]}, "plan")
    a, b = expand_points(doc)
    assert (a.law, a.duration_s, a.backlash_mm) == ("cosine", 2.0, 0.016)
    assert b.duration_s == pytest.approx(5.5 * 60 / 300) and b.jt_factor == 1.5
    with pytest.raises(InputError, match="belong to a point"):
        expand_points(check_plan({"defaults": {"seed": 3}, "points": [{"rpm": 180}]}, "plan"))


def test_a_nidaqmx_plan_builds_its_device_without_touching_a_board(tmp_path):
    from labtool.campaign import steps
    p = write(tmp_path, '[device]\nkind = "nidaqmx"\nchannels = "Dev1/ai0:2"\n[[points]]\nrpm = 180\n')
    plan = load_plan(p)
    assert plan.doc.device.settle_mode == "tacho"          # real hardware waits for a steady speed
    dev, ka, attrs = steps.make_device(plan, plan.points[0])
    assert type(dev).__name__ == "NIDAQmxDevice" and dev.channel_names == ("aE_t", "aE_n", "tacho")
    assert len(ka) == 3 and "calibration files" in attrs["ka_source"]
