"""Readers: labtool HDF5 v1, TDMS, CSV; dispatch by content; bad and malformed files."""
from __future__ import annotations

import math

import h5py
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from labtool.common.errors import FileFormatError, InputError, LabtoolError
from labtool.processing.readers import open_recording, sniff
from stand_data import write_v1

NAMES = ["aE_t", "aE_n", "tacho"]


def _volts(n=1000):
    t = np.arange(n) / 1000.0
    return np.column_stack([np.sin(2 * np.pi * 3 * t), np.cos(2 * np.pi * 3 * t), (t % 0.33 < 0.001) * 5.0])


def _v1(path, **kw):
    volts = kw.pop("volts", _volts())
    write_v1(path, volts, kw.pop("names", NAMES), kw.pop("fs", 1000.0), **kw)
    return volts


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_v1_roundtrip(tmp_path, dtype):
    p = tmp_path / "r.h5"
    volts = _v1(p, dtype=dtype, ka=[86.0, 87.0, np.nan], cam_speed_rpm=180.0,
                events=[(0, "start", ""), (400, "gap", "lost 12 samples"), (700, "clip", "aE_t")])
    rec = open_recording(p)
    assert rec.sample_rate_hz == 1000.0 and rec.channel_names == NAMES and rec.n_samples == 1000
    assert rec.cam_speed_rpm == 180.0 and rec.complete and not rec.warnings
    assert rec.ka_m_s2_per_v[:2].tolist() == [86.0, 87.0] and math.isnan(rec.ka_m_s2_per_v[2])
    got = np.vstack([b for _, b in rec.chunks(300)])
    np.testing.assert_allclose(got, volts.astype(dtype), rtol=0, atol=0)
    assert rec.segments() == [(0, 400), (400, 1000)]
    assert rec.clip_indices().tolist() == [700]
    assert [e.kind for e in rec.events] == ["start", "gap", "clip"]
    rec.close()


def test_v1_lenient_events_bytes_and_group(tmp_path):
    p = tmp_path / "r.h5"
    _v1(p)
    with h5py.File(p, "a") as f:
        del f["events"]
        dt = np.dtype([("INDEX", "<u4"), ("Kind", "S8"), ("detail", "S16")])
        f.create_dataset("events", data=np.array([(5, b"overrun", b"x"), (9, b"START", b"")], dtype=dt))
    with open_recording(p) as rec:
        assert [(e.index, e.kind) for e in rec.events] == [(5, "overrun"), (9, "start")]
    with h5py.File(p, "a") as f:
        del f["events"]
        g = f.create_group("events")
        g["index"] = [3]
        g["kind"] = np.array(["gap"], dtype=h5py.string_dtype())
    with open_recording(p) as rec:
        assert rec.segments() == [(0, 3), (3, 1000)]


def test_incomplete_recording_reads_with_warning(tmp_path):
    p = tmp_path / "r.h5"
    _v1(p, complete=False)
    rec = open_recording(p)
    assert not rec.complete and any("incomplete" in w for w in rec.warnings)


def test_dispatch_is_by_content_not_name(tmp_path):
    p = tmp_path / "looks_like.csv"
    _v1(p)
    assert sniff(p) == "hdf5"
    q = tmp_path / "data.h5"
    q.write_text("# sample_rate_hz = 100\naE_t,aE_n\n1,2\n3,4\n")
    assert sniff(q) == "csv" and open_recording(q).n_samples == 2


@pytest.mark.parametrize("mutate, exc, words", [
    (lambda f: f.attrs.__setitem__("format", "something.else"), FileFormatError, "not a labtool recording"),
    (lambda f: f.attrs.__setitem__("format_version", 2), FileFormatError, "format_version"),
    (lambda f: f.attrs.__delitem__("sample_rate_hz"), InputError, "sample_rate_hz"),
    (lambda f: f.attrs.__setitem__("sample_rate_hz", -5.0), InputError, "sample rate"),
    (lambda f: f.attrs.__setitem__("sample_rate_hz", float("nan")), InputError, "sample rate"),
    (lambda f: f.attrs.__setitem__("sample_rate_hz", "fast"), InputError, "sample rate"),
    (lambda f: f["signals"].attrs.__setitem__("channel_names", ["a", "b"]), FileFormatError, "channel names"),
    (lambda f: f.__delitem__("signals"), FileFormatError, "signals"),
])
def test_v1_bad_metadata(tmp_path, mutate, exc, words):
    p = tmp_path / "r.h5"
    _v1(p)
    with h5py.File(p, "a") as f:
        mutate(f)
    with pytest.raises(exc, match=words):
        open_recording(p)


def test_nan_samples_are_an_input_error(tmp_path):
    p = tmp_path / "r.h5"
    v = _volts()
    v[500, 1] = np.inf
    _v1(p, volts=v)
    rec = open_recording(p)
    with pytest.raises(InputError, match="sample 500 of channel 'aE_n'"):
        list(rec.chunks(256))


def test_missing_channel(tmp_path):
    p = tmp_path / "r.h5"
    _v1(p, names=["aE_t", "other", "tacho"])
    with pytest.raises(FileFormatError, match="channel 'aE_n' is missing"):
        open_recording(p).channel_index("aE_n")


def test_truncated_and_foreign_files(tmp_path):
    p = tmp_path / "r.h5"
    _v1(p, volts=np.tile(_volts(), (20, 1)))
    data = p.read_bytes()
    t = tmp_path / "trunc.h5"
    t.write_bytes(data[: len(data) // 2])
    with pytest.raises(FileFormatError):
        rec = open_recording(t)
        list(rec.chunks(4096))
    png = tmp_path / "img.h5"
    png.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 4)
    with pytest.raises(FileFormatError, match="not a recording"):
        open_recording(png)
    empty = tmp_path / "empty.h5"
    empty.write_bytes(b"")
    with pytest.raises(FileFormatError, match="empty"):
        open_recording(empty)
    with pytest.raises(InputError, match="does not exist"):
        open_recording(tmp_path / "nope.h5")


def test_tdms_reader(tmp_path):
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    v = _volts()
    p = tmp_path / "r.tdms"
    with TdmsWriter(p) as w:
        w.write_segment([RootObject({"cam_speed_rpm": 180.0}), GroupObject("Untitled")] + [
            ChannelObject("Untitled", n, v[:, j], properties={"wf_increment": 0.001, "ka_m_s2_per_v": 86.43})
            for j, n in enumerate(NAMES)])
    rec = open_recording(p)
    assert rec.format == "tdms (group 'Untitled')" and rec.sample_rate_hz == pytest.approx(1000.0) and rec.channel_names == NAMES
    assert rec.cam_speed_rpm == 180.0 and rec.ka_m_s2_per_v[0] == 86.43
    np.testing.assert_allclose(rec.read(100, 900), v[100:900])
    q = tmp_path / "norate.tdms"
    with TdmsWriter(q) as w:
        w.write_segment([ChannelObject("g", n, v[:, j]) for j, n in enumerate(NAMES)])
    with pytest.raises(InputError, match="sample rate"):
        open_recording(q)
    assert open_recording(q, sample_rate_hz=500.0).sample_rate_hz == 500.0


@pytest.mark.slow
def test_csv_reader(tmp_path):
    v = _volts(150000)
    p = tmp_path / "r.csv"
    with open(p, "w") as fh:
        fh.write("# sample_rate_hz = 1000\n# cam_speed_rpm = 180\n# ka_aE_t = 86.0\n")
        fh.write(",".join(NAMES) + "\n")
        np.savetxt(fh, v, delimiter=",", fmt="%.9g")
    rec = open_recording(p)
    assert rec.n_samples == 150000 and rec.sample_rate_hz == 1000.0 and rec.ka_m_s2_per_v[0] == 86.0
    np.testing.assert_allclose(rec.read(65530, 140000), v[65530:140000], rtol=1e-8)
    q = tmp_path / "t.csv"
    q.write_text("time,aE_t,aE_n\n0.0,1,2\n0.002,3,4\n0.004,5,6\n")
    r = open_recording(q)
    assert r.sample_rate_hz == pytest.approx(500.0) and r.channel_names == ["aE_t", "aE_n"]
    assert r.read(0, 3)[:, 0].tolist() == [1, 3, 5]
    n = tmp_path / "n.csv"
    n.write_text("aE_t,aE_n\n1,2\n")
    with pytest.raises(InputError, match="sample rate"):
        open_recording(n)
    bad = tmp_path / "b.csv"
    bad.write_text("# sample_rate_hz = 100\naE_t,aE_n\n1,2\n1,nan\n")
    with pytest.raises(InputError, match="NaN"):
        open_recording(bad).read(0, 2)


@pytest.fixture(scope="module")
def good_v1(tmp_path_factory):
    p = tmp_path_factory.mktemp("prop") / "good.h5"
    _v1(p, volts=np.tile(_volts(), (4, 1)), events=[(0, "start", ""), (10, "gap", "")])
    return p.read_bytes()


@pytest.fixture(scope="module")
def good_tdms(tmp_path_factory):
    from nptdms import ChannelObject, TdmsWriter

    p = tmp_path_factory.mktemp("prop") / "good.tdms"
    v = np.tile(_volts(), (3, 1))
    with TdmsWriter(p) as w:
        w.write_segment([ChannelObject("g", n, v[:, j], properties={"wf_increment": 1e-3})
                         for j, n in enumerate(NAMES)])
    return p.read_bytes()


@pytest.mark.slow
@settings(max_examples=int(__import__("os").environ.get("PROC_FUZZ_EXAMPLES", 60)), deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_property_malformed_files_raise_only_labtool_errors(tmp_path, good_v1, good_tdms, data, capsys):
    """Truncated, bit-flipped or random files: the readers either read them or raise a LabtoolError,
    and print nothing themselves (npTDMS's log lines are collected into one warning)."""
    kind = data.draw(st.sampled_from(["truncate", "flip", "random", "csvish"]))
    raw = bytearray(data.draw(st.sampled_from([good_v1, good_tdms])))
    if kind == "truncate":
        raw = raw[: data.draw(st.integers(0, len(raw) - 1))]
    elif kind == "flip":
        for _ in range(data.draw(st.integers(1, 40))):
            i = data.draw(st.integers(0, len(raw) - 1))
            raw[i] = data.draw(st.integers(0, 255))
    elif kind == "random":
        raw = bytearray(data.draw(st.binary(min_size=0, max_size=2000)))
    else:
        raw = bytearray(data.draw(st.text(alphabet="0123456789.,-e\n# =abcnatime_", max_size=400)).encode())
    p = tmp_path / "m.bin"
    p.write_bytes(bytes(raw))
    try:
        rec = open_recording(p, sample_rate_hz=data.draw(st.sampled_from([None, 100.0])))
        for _ in rec.chunks(1000):
            pass
        rec.segments()
        rec.close()
    except LabtoolError:
        pass
    out = capsys.readouterr()
    assert out.err == "" and out.out == ""


@pytest.mark.slow
def test_killed_swmr_writer_reads_with_warnings(tmp_path):
    """A recorder killed while writing in SWMR mode leaves the consistency flags set."""
    import subprocess
    import sys
    import textwrap

    p = tmp_path / "killed.h5"
    code = textwrap.dedent(f"""
        import os, h5py, numpy as np
        f = h5py.File({str(p)!r}, "w", libver="latest")
        f.attrs.update(dict(format="labtool.recording", format_version=1, sample_rate_hz=1000.0,
                            start_time_utc="2026-11-22T00:00:00Z", complete=False))
        d = f.create_dataset("signals", shape=(0, 2), maxshape=(None, 2), chunks=(256, 2), dtype="f4")
        d.attrs["channel_names"] = np.array(["aE_t", "aE_n"], dtype=h5py.string_dtype())
        f.swmr_mode = True
        d.resize((1000, 2)); d[:] = 1.0; d.flush(); f.flush()
        os._exit(0)  # killed: no close
    """)
    subprocess.run([sys.executable, "-c", code], check=True)
    with open_recording(p) as rec:
        assert rec.n_samples == 1000 and not rec.complete
        assert any("SWMR" in w for w in rec.warnings) and any("incomplete" in w for w in rec.warnings)
        assert rec.read(0, 1000).shape == (1000, 2)


@pytest.mark.slow
def test_unwritten_rows_are_not_read_as_zeros(tmp_path):
    p = tmp_path / "tail.h5"
    write_v1(p, np.random.default_rng(0).normal(size=(20000, 3)), NAMES, 1000.0)
    with h5py.File(p, "a") as f:
        f["signals"].resize((10**9, 3))  # resized, never written (or a damaged shape)
    with open_recording(p) as rec:
        assert rec.n_samples == 24576 and any("never written" in w for w in rec.warnings)  # 3 chunks of 8192
    q = tmp_path / "hole.h5"
    with h5py.File(q, "w") as f:
        f.attrs.update(dict(format="labtool.recording", format_version=1, sample_rate_hz=1000.0, complete=True))
        d = f.create_dataset("signals", shape=(30000, 3), chunks=(8192, 3), dtype="f4")
        d.attrs["channel_names"] = np.array(NAMES, dtype=h5py.string_dtype())
        d[:8192] = 1.0
        d[16384:] = 1.0
    with pytest.raises(FileFormatError, match="never written"):
        open_recording(q)
