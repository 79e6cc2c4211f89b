"""The operating point has one owner (labtool.common.operating_point): one set of defaults, bounds
and names in every command, the simulated stand, the campaign plan, the DOE and the files."""
from __future__ import annotations

import dataclasses

import pytest

from labtool.common.errors import InputError
from labtool.common.operating_point import (DEFAULT, FIELD, FIELDS, PAPER_EXPERIMENT, STATED, OperatingPoint,
                                            from_attrs, from_edge, resolve)
from labtool.common.units import MM, RPM


def _help(*args) -> str:
    from typer.testing import CliRunner

    from labtool.cli import app
    out = CliRunner().invoke(app, [*args, "--help"], terminal_width=400, env={"COLUMNS": "400"}).output
    return " ".join(out.split())


ACQUIRE_FIELDS = STATED + ("restitution", "contact_damping")


@pytest.mark.parametrize("command", ["simulate", "acquire", "report", "fit"])
def test_every_command_shows_the_owners_defaults(command):
    """Each command's --help states each operating-point value's default and reason as the owner
    has it (report and fit take the measured file's value first, and the measured speed)."""
    text = _help(command)
    for f in FIELDS:
        if command == "acquire" and f.name not in ACQUIRE_FIELDS:
            continue
        if (command, f.name) in (("report", "cam_speed"), ("fit", "cam_speed"), ("simulate", "law")):
            continue                      # the measured speed; a mechanism file's [program] law
        if command in ("report", "fit") and f.name in ("omega1_mode", "accuracy"):
            continue                      # which modes to compare (both by default), the fit's presets
        default = f.default if f.text else f"{f.default_edge:g}"
        assert f.option in text, (command, f.name)
        assert f"{default}: {f.reason}" in text, (command, f.name)


def test_the_stand_the_plan_and_acquire_default_to_the_owners_point():
    from labtool.acquisition.signal_chain import StandScene
    from labtool.campaign.plan import BASE_POINT, POINT_KEYS
    from labtool.api.acquisition import DEFAULTS, POINT_OPTIONS
    from labtool.models.dynamics.scene import Scene

    stand, scene = StandScene(), Scene()
    for f in FIELDS:
        if f.name != "accuracy":          # the stand's truth runs at its own preset (fast)
            assert getattr(stand, f.name) == getattr(DEFAULT, f.name) == getattr(scene, f.name), f.name
    for key, name in POINT_KEYS.items():
        if key != "rpm":
            assert BASE_POINT[key] == FIELD[name].default_edge
    for option, name in POINT_OPTIONS.items():
        assert DEFAULTS[option] == FIELD[name].default_edge


def test_a_default_recording_is_compared_with_the_defaults_it_was_made_with(tmp_path):
    """What the simulated stand records by default and what a report assumes for what the file
    does not state are one set: the report's model options are the stand's truth's."""
    from labtool.acquisition.signal_chain import StandScene
    attrs = StandScene().attrs()
    assert attrs["truth_restitution"] == DEFAULT.restitution
    assert attrs["truth_contact_damping_s_per_m"] == DEFAULT.contact_damping
    assert from_attrs(attrs, base=PAPER_EXPERIMENT).backlash == DEFAULT.backlash   # stated, so not the paper's


def test_attributes_round_trip_in_edge_units():
    p = OperatingPoint(law="cosine", cam_speed=250 * RPM, Fu=65.0, backlash=0.05 * MM, jt_factor=4.0,
                       omega1_mode="var", restitution=0.7, contact_damping=12.0, contact_length=7 * MM,
                       kc_factor=2.0, elastic_gap="closed", accuracy="fast")
    a = p.attrs()
    assert (a["cam_speed_rpm"], a["backlash_mm"], a["contact_length_mm"]) == pytest.approx((250.0, 0.05, 7.0))
    back = from_attrs(a)
    for f in FIELDS:
        v = getattr(p, f.name)
        assert getattr(back, f.name) == (v if f.text else pytest.approx(v, rel=1e-14)), f.name


def test_resolve_says_where_each_value_came_from():
    s = resolve({"Fu": 65.0}, {"backlash_mm": 0.1, "backlash_mm_source": "stated by the operator (--backlash-mm)",
                               "cam_speed_rpm": 0.0}, where="m.nc")
    assert s.sources["Fu"] == "option --fu"
    assert s.sources["backlash"] == "file attribute backlash_mm, stated by the operator (--backlash-mm)"
    assert s.sources["cam_speed"].startswith("default (")      # a stated 0 rpm is no speed
    assert any("0.0 rpm" in n and "not stated" in n for n in s.notes)
    assert s.assumed() == ["law", "cam_speed", "jt_factor"]
    assert resolve(None, {}, base=PAPER_EXPERIMENT).point == PAPER_EXPERIMENT


@pytest.mark.parametrize("name, bad", [("Fu", -1.0), ("backlash", 11 * MM), ("jt_factor", 0.0), ("restitution", 1.5),
                                       ("contact_damping", float("nan")), ("omega1_mode", "fast"),
                                       ("cam_speed", -1.0), ("elastic_gap", "ajar")])
def test_every_bound_is_the_owners_in_every_place(name, bad):
    """The same value is refused the same way by the type, a file attribute and a plan point."""
    f = FIELD[name]
    with pytest.raises(InputError) as direct:
        OperatingPoint(**{name: bad})
    assert direct.value.args[0].startswith(f.named) and f.option in direct.value.args[0]
    with pytest.raises(InputError, match=f"attribute {f.attr}: {f.named}"):
        from_attrs({f.attr: bad if f.text else f.to_edge(bad)}, where="m.nc")
    from labtool.campaign.plan import POINT_KEYS, check_plan, expand_points
    if name in POINT_KEYS.values():
        key = next(k for k, n in POINT_KEYS.items() if n == name)
        with pytest.raises(InputError):
            expand_points(check_plan({"points": [{"rpm": 180, key: bad if f.text else f.to_edge(bad)}]}, "plan"))


def test_a_plan_is_checked_completely_before_anything_runs():
    """A backlash that leaves the groove undercut on the second point is refused when the plan is
    read, not after the first point was recorded."""
    from labtool.campaign.plan import check_plan, expand_points
    with pytest.raises(InputError, match="point 2: the groove is undercut"):
        expand_points(check_plan({"points": [{"rpm": 180}, {"rpm": 300, "backlash_mm": 8.0}]}, "plan"))


def test_edge_values_are_converted_once():
    assert from_edge({"cam_speed_rpm": 300, "backlash_mm": 0.1}) == {"cam_speed": 300 * RPM, "backlash": 0.1 * MM}
    with pytest.raises(InputError, match="unknown operating-point key 'rpm'"):
        from_edge({"rpm": 300})


def test_the_paper_experiment_is_table_1s_first_run_with_the_papers_idealisations():
    assert (PAPER_EXPERIMENT.cam_speed_rpm, PAPER_EXPERIMENT.Fu, PAPER_EXPERIMENT.backlash / MM,
            PAPER_EXPERIMENT.jt_factor) == pytest.approx((180.0, 0.0, 0.016, 1.0))
    assert (PAPER_EXPERIMENT.omega1_mode, PAPER_EXPERIMENT.restitution, PAPER_EXPERIMENT.contact_damping) == \
        ("var", 1.0, 0.0)
    changed = {f.name for f in dataclasses.fields(OperatingPoint)
               if getattr(PAPER_EXPERIMENT, f.name) != getattr(DEFAULT, f.name)}
    assert changed == {"backlash", "omega1_mode", "restitution", "contact_damping"}
