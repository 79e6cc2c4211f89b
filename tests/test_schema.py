"""labtool.common.schema: TOML inputs checked for type, range and unknown keys; every failure one line."""
import math
import tomllib

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from labtool.common.errors import InputError
from labtool.common.names import shown
from labtool.common.schema import (Bool, Integer, ListOf, MapOf, Number, OneOf, SchemaError, String, Table,
                           load_toml, parse_toml)

SCHEMA = Table({
    "name": String(default="unnamed"),
    "frame": Table({"xD_mm": Number(unit="mm", ge=-1e4, le=1e4), "n": Integer(ge=1, le=10)}),
    "flags": Table({"on": Bool(default=False), "law": String(choices=("sine", "cosine"), required=False)},
                   default={}),
    "levels": ListOf(Number(gt=0), min_len=1, max_len=3, required=False),
    "channels": MapOf(Table({"ka": Number(gt=0)}), required=False),
    "limit": OneOf(Number(ge=0), Table({"min": Number(required=False), "max": Number(required=False)}),
                   required=False),
})
GOOD = {"frame": {"xD_mm": -34.073, "n": 3}}


def _error(doc) -> str:
    with pytest.raises(SchemaError) as info:
        SCHEMA.check(doc, where="test file t.toml")
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith("test file t.toml: ")
    return msg


def test_a_good_document_gets_its_defaults_and_floats():
    out = SCHEMA.check({"frame": {"xD_mm": -34, "n": 3}})
    assert out == {"name": "unnamed", "frame": {"xD_mm": -34.0, "n": 3}, "flags": {"on": False}}
    assert isinstance(out["frame"]["xD_mm"], float) and isinstance(out["frame"]["n"], int)


@pytest.mark.parametrize("frame, expected", [
    ({"xD_mm": "fast", "n": 3}, '[frame] xD_mm = "fast": expected a number [mm], got a string'),
    ({"xD_mm": [1, 2], "n": 3}, "[frame] xD_mm = [1, 2]: expected a number [mm], got a list"),
    ({"xD_mm": True, "n": 3}, "[frame] xD_mm = true: expected a number [mm], got a boolean"),
    ({"xD_mm": 1e300, "n": 3}, "[frame] xD_mm = 1e+300: must be <= 10000 [mm]"),
    ({"xD_mm": math.inf, "n": 3}, "must be a finite number"),
    ({"xD_mm": math.nan, "n": 3}, "must be a finite number"),
    ({"xD_mm": 1.0, "n": 1.5}, "[frame] n = 1.5: expected an integer, got a number"),
    ({"xD_mm": 1.0, "n": 2.0}, "expected an integer"),
    ({"xD_mm": 1.0, "n": 0}, "[frame] n = 0: must be >= 1"),
    ({"xD_mm": 1.0}, "missing parameter [frame] n (an integer)"),
    ({"xD_mm": 1.0, "n": 3, "xd_mm": 2}, "unknown key [frame] xd_mm (did you mean xD_mm?); known: xD_mm, n"),
])
def test_bad_values_name_the_key_and_what_it_takes(frame, expected):
    assert expected in _error({"frame": frame})


def test_a_whole_number_may_be_written_as_a_float_but_not_with_a_fraction():
    """``whole=True`` (a count of revolutions): 10 and 10.0 are 10.0; 8.5 is refused naming the key."""
    field = Table({"revolutions": Number(ge=2, whole=True)})
    assert field.check({"revolutions": 10}, "plan") == {"revolutions": 10.0}
    assert field.check({"revolutions": 10.0}, "plan") == {"revolutions": 10.0}
    with pytest.raises(SchemaError, match=r"revolutions = 8\.5: must be a whole number"):
        field.check({"revolutions": 8.5}, "plan")
    endless = Table({"revolutions": Number(ge=2, whole=True, allow_inf=True)})      # "until stopped"
    assert endless.check({"revolutions": math.inf}, "plan") == {"revolutions": math.inf}


def test_unknown_tables_and_keys_are_named():
    assert "unknown table [framE] (did you mean frame?)" in _error({**GOOD, "framE": {}})
    assert "unknown key colour" in _error({**GOOD, "colour": 1})


def test_strings_choices_and_one_line():
    assert 'expected one of "sine", "cosine" (did you mean sine?)' in _error({**GOOD, "flags": {"law": "sinus"}})
    assert "one line" in _error({**GOOD, "name": "a\nka = 1"})
    assert "true or false" in _error({**GOOD, "flags": {"on": 1}})


def test_lists_maps_and_alternatives():
    assert SCHEMA.check({**GOOD, "levels": [1, 2.5]})["levels"] == [1.0, 2.5]
    assert "levels[1] = -1: must be > " not in _error({**GOOD, "levels": [1, 0]})
    assert "levels[1] = 0: must be greater than zero" in _error({**GOOD, "levels": [1, 0]})
    assert "at most 3 item(s)" in _error({**GOOD, "levels": [1, 2, 3, 4]})
    assert SCHEMA.check({**GOOD, "channels": {"aE_t": {"ka": 86.43}}})["channels"]["aE_t"]["ka"] == 86.43
    assert "[channels.aE_t] ka = 0: must be greater than zero" in _error({**GOOD, "channels": {"aE_t": {"ka": 0}}})
    assert SCHEMA.check({**GOOD, "limit": 0.5})["limit"] == 0.5
    assert SCHEMA.check({**GOOD, "limit": {"max": 2}})["limit"] == {"max": 2.0}
    assert "limit = -1: must not be negative" in _error({**GOOD, "limit": -1})
    assert "unknown key [limit] mx (did you mean max?)" in _error({**GOOD, "limit": {"mx": 1}})
    assert 'expected a number or a table, got a string' in _error({**GOOD, "limit": "low"})


def test_load_toml_refuses_what_is_not_a_utf8_toml_file(tmp_path):
    with pytest.raises(InputError, match="is a folder"):
        load_toml(tmp_path, "scene file")
    with pytest.raises(InputError, match="not found"):
        load_toml(tmp_path / "none.toml", "scene file")
    bad = tmp_path / "b.toml"
    bad.write_bytes(b'a = 1\nname = "\xff\xfe"\n')
    with pytest.raises(InputError, match=r"not UTF-8 text \(byte 0xff on line 2\)"):
        load_toml(bad, "scene file")
    bad.write_bytes(b"a = 1\x00\n")
    with pytest.raises(InputError, match="NUL"):
        load_toml(bad, "scene file")
    bad.write_text("a = [1,\n")
    with pytest.raises(InputError, match="is not valid TOML"):
        load_toml(bad, "scene file")
    bad.write_text("[stand]\nrpm = 180\n")
    assert load_toml(bad, "scene file") == {"stand": {"rpm": 180}}


def test_shown_makes_any_file_name_printable():
    assert shown("r\udcff.h5") == "r\\xff.h5"
    assert shown("a\nb.toml") == "a\\nb.toml"
    assert shown("müller.toml") == "müller.toml"
    shown("r\udcff.h5").encode("utf-8")     # no surrogate left


_toml_values = st.recursive(
    st.one_of(st.booleans(), st.integers(), st.floats(), st.text(max_size=8), st.none()),
    lambda inner: st.one_of(st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=6), inner, max_size=3)),
    max_leaves=8)


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(doc=st.dictionaries(st.sampled_from(["name", "frame", "flags", "levels", "channels", "limit", "x"]),
                           _toml_values, max_size=5))
@example(doc={"frame": {"\n": None}})        # a quoted key with a newline (found by this test in CI)
@example(doc={"frame": {"a\rb": {}}})        # the same in a misnamed table's name
def test_any_document_is_accepted_or_refused_in_one_line(doc):
    try:
        out = SCHEMA.check(doc, where="t.toml")
    except SchemaError as exc:
        assert "\n" not in str(exc) and str(exc).startswith("t.toml: ")
        return
    assert -1e4 <= out["frame"]["xD_mm"] <= 1e4


@settings(max_examples=300, deadline=None)
@given(raw=st.binary(max_size=64))
def test_any_bytes_parse_or_are_refused_in_one_line(raw):
    try:
        doc = parse_toml(raw, "scene file s.toml")
    except InputError as exc:
        assert str(exc).startswith("scene file s.toml ") and "\n" not in str(exc).strip()
        return
    assert doc == tomllib.loads(raw.decode("utf-8-sig"))
