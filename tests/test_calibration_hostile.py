"""Calibration's hostile inputs and its checks.

Each case failed on main (commit e271890): a clipped or integer reference was fitted (exit 0, Ka
wrong by 9x or 1000x), a calibration file's ``true`` or ``1e300`` was used as a Ka, a channel
name injected a Ka through the hand-formatted TOML, a newline in a file name made the TOML
unparseable, rich markup in a channel name crashed after the file was written, a truncated
reference gave a traceback, a second --calibration silently replaced the first, and the paper's
Ka was used without a word.
"""
import math
import tomllib

import h5py
import numpy as np
import pytest
import xarray as xr

from labtool.cli import main
from labtool.processing.calibration_file import read_calibration
from stand_data import stand_recording, write_v1

FS = 10000.0
SAMPLE_CAL = __import__("pathlib").Path(__file__).resolve().parents[1] / "sample_data" / "calibration_79p6Hz.h5"


def sine_recording(path, volts_peak=0.1135, names=("aE_t", "aE_n", "tacho"), on=0, seconds=1.0, dtype="float32",
                   clip_v=None, noise_v=3e-4, seed=0, attrs=None):
    """A reference recording (format v1) with a 79.6 Hz sine of ``volts_peak`` on column ``on``."""
    t = np.arange(int(seconds * FS)) / FS
    rng = np.random.default_rng(seed)
    v = noise_v * rng.standard_normal((t.size, len(names)))
    v[:, on] += volts_peak * np.sin(2 * np.pi * 79.6 * t + 0.3)
    if clip_v is not None:
        v = np.clip(v, -clip_v, clip_v)
    if np.dtype(dtype).kind == "i":
        v = np.round(v)
    write_v1(path, v, names, FS, dtype=dtype, cam_speed_rpm=None)
    if attrs:
        with h5py.File(path, "a") as f:
            f.attrs.update(attrs)
    return path


def one_error_line(capsys) -> str:
    err = [x for x in capsys.readouterr().err.strip().splitlines() if not x.startswith("labtool: warning:")]
    assert len(err) == 1 and err[0].startswith("labtool: error: "), err
    return err[0]


@pytest.mark.hostile("silent_wrong")
def test_a_clipped_reference_sine_is_refused(tmp_path, capsys):
    # the chain's true Ka is 0.086 m/s^2/V: 9.81 m/s^2 gives 114 V, clipped at the ADC's 10 V;
    # main fitted the square wave and wrote Ka = 0.771
    rec = sine_recording(tmp_path / "ref.h5", volts_peak=9.81 / 0.086, clip_v=10.0, noise_v=0.0)
    out = tmp_path / "cal.toml"
    assert main(["calibrate", str(rec), "-o", str(out)]) == 2
    line = one_error_line(capsys)
    assert "clipped" in line and "aE_t" in line
    assert not out.exists()


@pytest.mark.hostile("silent_wrong")
def test_a_mildly_clipped_sine_and_the_adc_range_are_seen_too(tmp_path, capsys):
    # clipped at 95 % of its amplitude (a flat top of ~10 % of each period), with noise
    rec = sine_recording(tmp_path / "ref.h5", volts_peak=1.0, clip_v=0.95, noise_v=1e-4)
    assert main(["calibrate", str(rec), "-o", str(tmp_path / "a.toml")]) == 2
    assert "clipped" in one_error_line(capsys)
    # samples at the stated ADC rails (the file says +-1 V) are clipped even without a flat top
    rec2 = sine_recording(tmp_path / "ref2.h5", volts_peak=0.999, noise_v=1e-3, attrs={"adc_range_v": 1.0})
    assert main(["calibrate", str(rec2), "-o", str(tmp_path / "b.toml")]) == 2
    assert "ADC" in one_error_line(capsys)


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("adc, said", [("1", "ADC"), ("ten volts", "adc_range_v")])
def test_an_adc_range_stated_as_text_is_read_or_refused(tmp_path, capsys, adc, said):
    """adc_range_v = "1" (text, which process reads as 1 V) or "ten volts" was passed over: a sine at
    the rails of a +-1 V ADC was calibrated, exit 0."""
    rec = sine_recording(tmp_path / "ref.h5", volts_peak=0.999, noise_v=1e-3, attrs={"adc_range_v": adc})
    assert main(["calibrate", str(rec), "-o", str(tmp_path / "a.toml")]) == 2
    assert said in one_error_line(capsys)
    assert not (tmp_path / "a.toml").exists()


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("dtype", ["int16", "int32"])
def test_integer_adc_counts_are_not_fitted_as_volts(tmp_path, capsys, dtype):
    # 0.1135 V peak on a +-10 V 16-bit ADC is 372 counts: main fitted the counts, Ka 3277x too small
    rec = sine_recording(tmp_path / "ref.h5", volts_peak=0.1135 * 32768 / 10, noise_v=1.0, dtype=dtype)
    out = tmp_path / "cal.toml"
    assert main(["calibrate", str(rec), "-o", str(out)]) == 2
    one_error_line(capsys)
    assert not out.exists()


@pytest.mark.hostile("silent_wrong")
def test_integer_counts_in_a_float_file_are_refused_by_the_fit(tmp_path, capsys):
    rec = sine_recording(tmp_path / "ref.h5", volts_peak=372.0, noise_v=1.0, dtype="int16")
    with h5py.File(rec, "a") as f:   # the same counts, stored as float32
        counts = f["signals"][...].astype("float32")
        del f["signals"]
        d = f.create_dataset("signals", data=counts, chunks=(8192, 3), maxshape=(None, 3))
        d.attrs["channel_names"] = np.array(["aE_t", "aE_n", "tacho"], dtype=h5py.string_dtype())
        d.attrs["ka_m_s2_per_v"] = np.full(3, np.nan)
    assert main(["calibrate", str(rec), "-o", str(tmp_path / "c.toml")]) == 2
    line = one_error_line(capsys)
    assert "ADC counts" in line and "aE_t" in line


def _cal_file(path, value: str):
    path.write_text('format = "labtool.calibration"\nformat_version = 1\n'
                    f"[channels.aE_t]\nka_m_s2_per_v = {value}\n[channels.aE_n]\nka_m_s2_per_v = 86.43\n")
    return path


@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("value", ["true", "1e300", '"86.43"', "nan", "inf", "0", "-86.43", "[86.43]"])
def test_a_ka_that_is_not_a_usable_number_is_refused(tmp_path, capsys, value):
    rec = tmp_path / "run.h5"
    stand_recording(rec, duration_s=1.0, ka=[np.nan, np.nan, np.nan])
    cal = _cal_file(tmp_path / "cal.toml", value)
    out = tmp_path / "m.nc"
    assert main(["process", str(rec), "--calibration", str(cal), "-o", str(out)]) == 2
    line = one_error_line(capsys)
    assert "[channels.aE_t] ka_m_s2_per_v = " in line and "cal.toml" in line
    assert not out.exists()


@pytest.mark.hostile("silent_wrong")
def test_unknown_keys_in_a_calibration_file_are_named(tmp_path, capsys):
    cal = tmp_path / "cal.toml"
    cal.write_text("[channels.aE_t]\nka_m_s2_per_v = 86.4\nka_uncertainty = 0.2\n")   # a misspelt key
    rec = tmp_path / "run.h5"
    stand_recording(rec, duration_s=1.0, ka=[np.nan, np.nan, np.nan])
    assert main(["process", str(rec), "--calibration", str(cal), "-o", str(tmp_path / "m.nc")]) == 2
    line = one_error_line(capsys)
    assert "unknown key [channels.aE_t] ka_uncertainty" in line and "uncertainty_m_s2_per_v" in line


INJECT = "aE_n]\nka_m_s2_per_v = 1.0\n[x"


@pytest.mark.hostile("injection")
def test_a_channel_name_cannot_inject_a_ka(tmp_path, capsys):
    # the recording's second channel is named with a TOML payload; main wrote it unquoted and
    # 'process' then applied Ka = 1.0 to aE_n
    rec = sine_recording(tmp_path / "ref.h5", names=("aE_t", INJECT, "aE_n"), on=1)
    cal = tmp_path / "cal.toml"
    code = main(["calibrate", str(rec), "--channel", INJECT, "-o", str(cal)])
    if code == 0:   # written, then quoted: the name round-trips and no aE_n entry appears
        doc = tomllib.loads(cal.read_text())
        assert list(doc["channels"]) == [INJECT]
    else:
        assert code == 2
        line = one_error_line(capsys)
        assert "\n" not in line and "control characters" in line
        assert not cal.exists()
    # a calibration file with that table header quoted by hand is read as that (odd) channel only
    hand = tmp_path / "hand.toml"
    hand.write_text('[channels."aE_t"]\nka_m_s2_per_v = 90.0\n')
    assert set(read_calibration(hand)) == {"aE_t"}


@pytest.mark.hostile("injection")
def test_quotes_and_brackets_in_names_stay_inside_their_keys(tmp_path):
    name = 'aE_t" = 1\n#'
    rec = sine_recording(tmp_path / 'ref "quoted" [x].h5', names=("aE]t", name.replace("\n", " "), "tacho"))
    cal = tmp_path / "cal.toml"
    assert main(["calibrate", str(rec), "--channel", "aE]t", "-o", str(cal)]) == 0
    doc = tomllib.loads(cal.read_text())
    assert list(doc["channels"]) == ["aE]t"] and doc["source"] == str(rec)
    assert read_calibration(cal)["aE]t"].ka_m_s2_per_v == pytest.approx(9.81 / 0.1135, rel=0.01)


@pytest.mark.hostile("injection")
def test_a_newline_in_the_file_name_keeps_the_toml_and_the_error_on_one_line(tmp_path, capsys):
    rec = sine_recording(tmp_path / "ref\nka_m_s2_per_v = 1.0.h5")
    cal = tmp_path / "cal.toml"
    assert main(["calibrate", str(rec), "-o", str(cal)]) == 0
    doc = tomllib.loads(cal.read_text())     # main wrote a raw newline inside a TOML string
    assert doc["source"] == str(rec) and doc["channels"]["aE_t"]["source"] == str(rec)
    capsys.readouterr()
    missing = tmp_path / "gone\nlabtool: error: fake.h5"
    assert main(["calibrate", str(missing), "-o", str(tmp_path / "x.toml")]) == 2
    line = one_error_line(capsys)
    assert "\\n" in line


@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("name", ["aE_t[/x]", "[bold]aE_t", "aE_t[/]", "[link=http://x]aE_t"])
def test_rich_markup_in_a_channel_name_is_shown_as_text(tmp_path, capsys, name):
    rec = sine_recording(tmp_path / "ref.h5", names=(name, "aE_n", "tacho"))
    cal = tmp_path / "cal.toml"
    assert main(["calibrate", str(rec), "--channel", name, "-o", str(cal)]) == 0
    assert list(tomllib.loads(cal.read_text())["channels"]) == [name]
    assert name in capsys.readouterr().out


@pytest.mark.hostile("traceback")
@pytest.mark.parametrize("keep", [0.45, 0.6, 0.9])
def test_a_truncated_reference_recording_is_one_line(tmp_path, capsys, keep):
    # a reference recorded by the recorder (SWMR, libver latest), cut as a full disk or a copy would;
    # main raised RuntimeError "Can't decode global heap prefix" with a traceback
    data = SAMPLE_CAL.read_bytes()
    cut = tmp_path / "cut.h5"
    cut.write_bytes(data[: int(keep * len(data))])
    out = tmp_path / "cal.toml"
    assert main(["calibrate", str(cut), "-o", str(out)]) == 2
    one_error_line(capsys)
    assert not out.exists()


def test_every_calibration_error_names_its_channel(tmp_path, capsys):
    # the sine is on aE_t only: aE_n holds noise. main said "calibration: no sine near 79.6 Hz ..."
    rec = sine_recording(tmp_path / "ref.h5")
    assert main(["calibrate", str(rec), "--channel", "aE_t", "--channel", "aE_n", "-o", str(tmp_path / "c.toml")]) == 2
    line = one_error_line(capsys)
    assert "channel aE_n of" in line and "aE_t" not in line.split("channel aE_n")[0]
    assert main(["calibrate", str(rec), "--channel", "aE_x", "-o", str(tmp_path / "d.toml")]) == 2
    assert "channel aE_x is not in" in one_error_line(capsys)


def test_two_channels_from_one_call_make_one_file_with_both_uncertainties(tmp_path, capsys):
    # a triaxial (or back-to-back) mount: both channels on the exciter in one recording
    t = np.arange(int(2 * FS)) / FS
    rng = np.random.default_rng(5)
    ka = {"aE_t": 86.43, "aE_n": 91.2}
    v = np.column_stack([9.81 / ka["aE_t"] * np.sin(2 * np.pi * 79.6 * t), 9.81 / ka["aE_n"] * np.sin(2 * np.pi * 79.6 * t + 1),
                         np.zeros_like(t)]) + 2e-4 * rng.standard_normal((t.size, 3))
    rec = tmp_path / "ref.h5"
    write_v1(rec, v, ["aE_t", "aE_n", "tacho"], FS, cam_speed_rpm=None)
    cal = tmp_path / "cal.toml"
    assert main(["calibrate", str(rec), "--channel", "aE_t", "--channel", "aE_n", "--reference-uncertainty", "0.01",
                 "-o", str(cal)]) == 0
    got = read_calibration(cal)
    for ch, k in ka.items():
        assert got[ch].ka_m_s2_per_v == pytest.approx(k, rel=1e-3)
        # the exciter's 1 % dominates the combined standard uncertainty
        assert got[ch].uncertainty_m_s2_per_v == pytest.approx(0.01 * k, rel=0.02)
    out = capsys.readouterr().out
    assert "aE_t" in out and "aE_n" in out


@pytest.mark.slow
def test_several_reference_recordings_merge_per_channel_with_their_uncertainties(tmp_path):
    # aE_t on the exciter twice (two mounts), aE_n once, from its own recording
    r1 = sine_recording(tmp_path / "t1.h5", volts_peak=9.81 / 86.0, seed=1, noise_v=2e-3)
    r2 = sine_recording(tmp_path / "t2.h5", volts_peak=9.81 / 86.0, seed=2, noise_v=2e-3)
    rn = sine_recording(tmp_path / "n.h5", volts_peak=9.81 / 90.0, on=1, seed=3)
    cal = tmp_path / "cal.toml"
    assert main(["calibrate", str(r1), str(r2), str(rn), "--channel", f"aE_t={r1}", "--channel", f"aE_t={r2}",
                 "--channel", f"aE_n={rn}", "-o", str(cal)]) == 0
    doc = tomllib.loads(cal.read_text())["channels"]
    t, n = doc["aE_t"], doc["aE_n"]
    assert t["n_references"] == 2 and n["n_references"] == 1 and "birge_ratio" in t
    singles = []
    for r in (r1, r2):
        one = tmp_path / f"one_{r.stem}.toml"
        assert main(["calibrate", str(r), "-o", str(one)]) == 0
        singles.append(tomllib.loads(one.read_text())["channels"]["aE_t"])
    w = [1 / s["ka_std_fit_m_s2_per_v"] ** 2 for s in singles]
    mean = sum(wi * s["ka_m_s2_per_v"] for wi, s in zip(w, singles)) / sum(w)
    assert t["ka_m_s2_per_v"] == pytest.approx(mean, rel=1e-12)
    assert t["ka_std_fit_m_s2_per_v"] == pytest.approx(max(1.0, t["birge_ratio"]) / math.sqrt(sum(w)), rel=1e-9)
    assert t["ka_std_fit_m_s2_per_v"] < min(s["ka_std_fit_m_s2_per_v"] for s in singles)
    assert n["ka_m_s2_per_v"] == pytest.approx(90.0, rel=2e-3)


def test_a_recording_name_that_is_not_a_given_reference_is_refused(tmp_path, capsys):
    r1 = sine_recording(tmp_path / "t1.h5")
    assert main(["calibrate", str(r1), "--channel", "aE_t=other.h5", "-o", str(tmp_path / "c.toml")]) == 2
    assert "other.h5 is not one of the reference recordings" in one_error_line(capsys)


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_a_second_calibration_is_merged_or_refused_never_silently_replacing(tmp_path, capsys):
    rec = tmp_path / "run.h5"
    stand_recording(rec, duration_s=1.5, ka=[np.nan, np.nan, np.nan])
    t = tmp_path / "t.toml"
    t.write_text("[channels.aE_t]\nka_m_s2_per_v = 100.0\nuncertainty_m_s2_per_v = 0.3\n")
    n = tmp_path / "n.toml"
    n.write_text("[channels.aE_n]\nka_m_s2_per_v = 99.0\nuncertainty_m_s2_per_v = 0.4\n")
    out = tmp_path / "m.nc"
    assert main(["process", str(rec), "--calibration", str(t), "--calibration", str(n), "-o", str(out)]) == 0
    ds = xr.open_dataset(out, engine="h5netcdf")
    assert ds.attrs["ka_aE_t_m_s2_per_v"] == 100.0 and ds.attrs["ka_aE_n_m_s2_per_v"] == 99.0
    assert "t.toml" in ds.attrs["ka_source_aE_t"] and "n.toml" in ds.attrs["ka_source_aE_n"]
    ds.close()
    capsys.readouterr()
    both = tmp_path / "both.toml"
    both.write_text("[channels.aE_t]\nka_m_s2_per_v = 80.0\n")
    assert main(["process", str(rec), "--calibration", str(t), "--calibration", str(both),
                 "-o", str(tmp_path / "m2.nc")]) == 2
    line = one_error_line(capsys)
    assert "aE_t" in line and "t.toml" in line and "both.toml" in line
    assert not (tmp_path / "m2.nc").exists()


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_the_papers_default_ka_is_never_used_silently(tmp_path, capsys):
    rec = tmp_path / "run.h5"
    stand_recording(rec, duration_s=1.5, ka=[np.nan, np.nan, np.nan])   # no Ka in the file, no calibration given
    assert main(["process", str(rec), "-o", str(tmp_path / "m.nc")]) == 0
    warn = [x for x in capsys.readouterr().err.splitlines() if "paper" in x]
    assert len(warn) == 2 and all(w.startswith("labtool: warning:") and "86.43" in w for w in warn)
    assert "channel aE_t" in warn[0] and "channel aE_n" in warn[1]
    # with a Ka in the recording, or a calibration for both channels, nothing is said
    rec2 = tmp_path / "run2.h5"
    stand_recording(rec2, duration_s=1.5, ka=[864.3, 864.3, np.nan])
    assert main(["process", str(rec2), "-o", str(tmp_path / "m2.nc")]) == 0
    assert "paper" not in capsys.readouterr().err


@pytest.mark.hostile("silent_wrong")
# 1e308 and 1e-300 (acquire --ka took them) were used: omega2 "265.6 % rms of peak" off, exit 0
@pytest.mark.parametrize("bad", [0.0, np.inf, -50.0, 1e308, 1e-300])
def test_an_unusable_ka_in_the_recording_does_not_fall_back_to_the_papers(tmp_path, capsys, bad):
    rec = tmp_path / "run.h5"
    stand_recording(rec, duration_s=1.5, ka=[bad, 864.3, np.nan])
    assert main(["process", str(rec), "-o", str(tmp_path / "m.nc")]) == 2
    line = one_error_line(capsys)
    assert "aE_t" in line and "--calibration" in line


def test_a_clean_coarsely_quantised_reference_is_accepted(tmp_path):
    # the 480C02 at gain x1: 9.81 m/s^2 is 0.01135 V, 37 steps of a 16-bit +-10 V ADC; the sine
    # then sits on its extreme step for ~7 % of the samples without being clipped
    lsb = 20.0 / 65536
    t = np.arange(int(2 * FS)) / FS
    v = np.zeros((t.size, 3))
    rng = np.random.default_rng(2)
    v[:, 0] = np.round((9.81 / 864.3 * np.sin(2 * np.pi * 79.6 * t) + 5e-5 * rng.standard_normal(t.size)) / lsb) * lsb
    rec = tmp_path / "ref.h5"
    write_v1(rec, v, ["aE_t", "aE_n", "tacho"], FS, dtype="float64", cam_speed_rpm=None)
    cal = tmp_path / "cal.toml"
    assert main(["calibrate", str(rec), "-o", str(cal)]) == 0
    assert read_calibration(cal)["aE_t"].ka_m_s2_per_v == pytest.approx(864.3, rel=0.005)


@pytest.mark.hostile("silent_wrong")
def test_a_calibration_ten_times_the_recordings_ka_is_said(tmp_path, capsys):
    # a calibration made at conditioner gain x1 (864.3) applied to a run recorded at x10 (86.43)
    rec = tmp_path / "run.h5"
    stand_recording(rec, duration_s=1.5, ka=[86.43, 86.43, np.nan])
    cal = tmp_path / "cal.toml"
    cal.write_text("[channels.aE_t]\nka_m_s2_per_v = 864.3\n[channels.aE_n]\nka_m_s2_per_v = 86.5\n")
    assert main(["process", str(rec), "--calibration", str(cal), "-o", str(tmp_path / "m.nc")]) == 0
    warn = [x for x in capsys.readouterr().err.splitlines() if "same conditioner gain" in x]
    assert len(warn) == 1 and "aE_t" in warn[0] and "10 x" in warn[0]


@pytest.mark.slow
@pytest.mark.hostile("hang")
@pytest.mark.parametrize("keep_bytes", [100, 512, 2048, 4096])
def test_a_reference_cut_to_its_first_bytes_does_not_hang_calibrate(tmp_path, keep_bytes):
    # main hung for ever (SWMR open of a truncated file); calibrate now reads through
    # labtool.processing.readers and its superblock check. Run in a child with a bound, as a user would.
    import subprocess
    import sys
    cut = tmp_path / "cut.h5"
    cut.write_bytes(SAMPLE_CAL.read_bytes()[:keep_bytes])
    res = subprocess.run([sys.executable, "-m", "labtool", "calibrate", str(cut), "-o", str(tmp_path / "c.toml")],
                         capture_output=True, text=True, timeout=120)
    err = res.stderr.strip().splitlines()
    assert res.returncode == 2 and len(err) == 1 and "truncated" in err[0]
