"""Recordings from stands nobody simulated: processed correctly where the data allow it, refused in
one line where they do not, and the output says which.

The recordings come from the one sensor chain (tests/stand_data.py) with the stand's own truth,
edited where the simulated stand cannot make them: channels swapped or a sign inverted (numpy), the
cam speed drifting by 5 % (stand_data.drifting_speed), a cam at 5 rpm with a DC-coupled chain. Every
processed result is checked against that truth (omega2, epsilon2, phi1), not against itself.
"""
from __future__ import annotations

import json
import re

import h5py
import numpy as np
import pytest
import xarray as xr

from hostile import one_error_line
from labtool.cli import main
from stand_data import stand_recording


def _cli(args, capsys):
    """labtool in-process: (exit code, stdout, stderr)."""
    capsys.readouterr()
    code = main([str(a) for a in args])
    got = capsys.readouterr()
    return code, got.out, got.err


def _open(path):
    return xr.open_dataset(path, engine="h5netcdf", decode_times=False).load()


def _errors(ds, tr):
    """(omega2, epsilon2) RMS error over the rises, relative to the truth's peak, per sample."""
    om, ep = ds["omega2"].values, ds["epsilon2"].values
    rise = (np.mod(tr["phi1"], 2 * np.pi) < tr["program"].rise_angle) & np.isfinite(om)
    assert rise.sum() > 1000
    e_o = np.sqrt(np.mean((om[rise] - tr["omega2"][rise]) ** 2)) / np.abs(tr["omega2"][rise]).max()
    e_e = np.sqrt(np.mean((ep[rise] - tr["epsilon2"][rise]) ** 2)) / np.abs(tr["epsilon2"][rise]).max()
    return e_o, e_e


def _phi1_error(ds, tr) -> float:
    """RMS of the cam angle's error against the truth (rad), over the samples with a cam angle."""
    d = np.angle(np.exp(1j * (ds["phi1"].values - np.mod(tr["phi1"], 2 * np.pi))))
    return float(np.sqrt(np.nanmean(d**2)))


def _edit(path, swap=False, invert=()):
    """Swap the aE_t and aE_n columns and/or invert columns (by the names they end up with)."""
    with h5py.File(path, "r+") as f:
        s = f["signals"][()]
        if swap:
            s[:, [0, 1]] = s[:, [1, 0]]
        for name in invert:
            s[:, {"aE_t": 0, "aE_n": 1}[name]] *= -1
        f["signals"][...] = s


def _step(ds, name):
    return next(s["parameters"] for s in json.loads(ds.attrs["processing_history"]) if s["step"] == name)


# --------------------------------------------------------------------- swapped or inverted channels

# (swap, columns inverted after the swap, what the warning must name)
MOUNTINGS = {
    "swapped": (True, (), "aE_t and aE_n swapped"),
    "aE_t inverted": (False, ("aE_t",), "aE_t inverted"),
    "aE_n inverted": (False, ("aE_n",), "aE_n inverted"),
    "swapped, the tangential inverted": (True, ("aE_n",), "aE_t and aE_n swapped, aE_t inverted"),
}


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("case", sorted(MOUNTINGS))
def test_swapped_or_inverted_channels_with_a_tacho_are_corrected_and_said(tmp_path, capsys, case):
    """With the cam angle from the tacho, each channel's reading per cam angle against an ideal
    sensor's tells which channel is which and its sign: corrected, said in a warning with the
    evidence, in the attributes and the history; the option the warning names gives the same result
    with nothing left to correct."""
    swap, invert, named = MOUNTINGS[case]
    rec = tmp_path / "rec.h5"
    tr = stand_recording(rec, duration_s=3.0, rpm=180.0)
    _edit(rec, swap, invert)
    code, out, err = _cli(["process", rec, "-o", tmp_path / "m.nc"], capsys)
    assert code == 0, err
    warning = next(ln for ln in err.splitlines() if f"{named}: corrected" in ln)
    assert "cam angle by tacho" in warning and re.search(r"aE_[tn]~[TN] [+-]1\.00", warning), warning
    assert "channels: corrected" in out
    ds = _open(tmp_path / "m.nc")
    assert ds.attrs["channel_check"] == "corrected" and named in ds.attrs["channel_check_finding"]
    step = _step(ds, "check_channels")
    assert step["swapped"] == swap and step["marks"] == "tacho"
    e_o, e_e = _errors(ds, tr)
    assert e_o < 0.02 and e_e < 0.05, (e_o, e_e)
    # the advice, followed: the same omega2, and the channels then read as labelled
    advised = re.search(r"to state it yourself: (.*)\)$", warning).group(1)
    opts = re.findall(r"(--\S+) (\S+)", advised)
    code, out, err = _cli(["process", rec, "-o", tmp_path / "stated.nc", *[x for o in opts for x in o]], capsys)
    assert code == 0, err
    assert "corrected" not in err and "channels: aE_t and aE_n read as labelled" in out, (out, err)
    stated = _open(tmp_path / "stated.nc")
    assert stated.attrs["channel_check"] == "as labelled"
    np.testing.assert_allclose(stated["omega2"].values, ds["omega2"].values, rtol=0, atol=1e-6, equal_nan=True)


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
@pytest.mark.parametrize("case", ["as recorded", "swapped", "aE_n inverted"])
def test_without_a_tacho_a_swap_and_an_inverted_normal_channel_are_corrected(tmp_path, capsys, case):
    """The cam angle by correlation is tried on each channel as the tangential one: a swap is found
    (as recorded, the normal channel repeats twice a revolution and matches no tangential
    reading); aE_n's sign shows in its mean, omega2^2 DE >= 0."""
    rec = tmp_path / "rec.h5"
    tr = stand_recording(rec, duration_s=3.0, rpm=180.0, tacho=False)
    _edit(rec, swap=case == "swapped", invert=("aE_n",) if case == "aE_n inverted" else ())
    code, out, err = _cli(["process", rec, "-o", tmp_path / "m.nc"], capsys)
    assert code == 0, err
    ds = _open(tmp_path / "m.nc")
    assert ds.attrs["phi1_method"] == "correlation"
    if case == "as recorded":
        assert ds.attrs["channel_check"] == "as labelled" and "corrected" not in err
    else:
        assert ds.attrs["channel_check"] == "corrected" and f"{case.replace('swapped', 'aE_t and aE_n swapped')}: " \
            "corrected" in err, err
        assert "cam angle by correlation" in ds.attrs["channel_check_finding"]
    e_o, e_e = _errors(ds, tr)
    assert e_o < 0.02 and e_e < 0.05, (e_o, e_e)
    assert _phi1_error(ds, tr) < 0.01


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_without_a_tacho_an_inverted_tangential_channel_is_said_and_invert_settles_it(tmp_path, capsys):
    """On this cam the return mirrors the rise half a turn later, so without a tacho an inverted aE_t
    reads as the right one half a turn on: the data cannot tell. The run says what phi1 assumes and
    names --invert aE_t; given, omega2 and phi1 match the truth."""
    rec = tmp_path / "rec.h5"
    tr = stand_recording(rec, duration_s=3.0, rpm=180.0, tacho=False)
    _edit(rec, invert=("aE_t",))
    code, out, err = _cli(["process", rec, "-o", tmp_path / "m.nc"], capsys)
    assert code == 0, err
    assert "assume aE_t reads positive along the rise" in err and "give --invert aE_t" in err, err
    ds = _open(tmp_path / "m.nc")
    assert "assume aE_t reads positive along the rise" in _step(ds, "cam_angle")["assumption"]
    # as the warning says: half a turn off, omega2 of the other sign
    assert abs(_phi1_error(ds, tr) - np.pi) < 0.05 and _errors(ds, tr)[0] > 1.0
    code, out, err = _cli(["process", rec, "-o", tmp_path / "inverted.nc", "--invert", "aE_t"], capsys)
    assert code == 0, err
    assert "processed with aE_t inverted" in out
    inv = _open(tmp_path / "inverted.nc")
    assert inv.attrs["channels_inverted"] == "aE_t" and _step(inv, "check_channels")["inverted_by_option"] == ["aE_t"]
    e_o, e_e = _errors(inv, tr)
    assert e_o < 0.02 and e_e < 0.05 and _phi1_error(inv, tr) < 0.01, (e_o, e_e)


@pytest.mark.hostile("silent_wrong")
def test_the_check_can_fail_and_wrong_options_are_refused(tmp_path, capsys):
    """The check's verdict follows the evidence (an ideal reading and its negative, arrangement by
    arrangement), and --invert takes only aE_t and aE_n."""
    from labtool.models.mechanism import Mechanism
    from labtool.models.mechanism.motion_laws import CamProgram
    from labtool.processing import orientation

    mech = Mechanism.default()
    prog = CamProgram.for_mechanism(mech)
    fs, period = 10000.0, 3000
    n = 4 * period
    phi = 2 * np.pi * np.arange(n) / period
    T, N = orientation.templates(mech, prog, 2 * np.pi * fs / period, n)
    T, N = (np.interp(np.mod(phi, 2 * np.pi), 2 * np.pi * (np.arange(n) + 0.5) / n, x, period=2 * np.pi) for x in (T, N))
    marks = np.arange(0, n, period, dtype=float)
    assert orientation.check(T, N, 0, fs, mech, prog, marks).verdict == "as labelled"
    found = orientation.check(N, -T, 0, fs, mech, prog, marks)
    assert (found.verdict, found.swap, found.signs) == ("corrected", True, (-1, 1))
    rng = np.random.default_rng(1)
    found = orientation.check(rng.normal(size=n), rng.normal(size=n), 0, fs, mech, prog, marks)
    assert found.verdict == "inconclusive" and not found.changes
    assert orientation.mirror_symmetric(prog)
    rec = tmp_path / "rec.h5"
    stand_recording(rec, duration_s=1.0, rpm=300.0)
    line = one_error_line(*_cli(["process", rec, "-o", tmp_path / "m.nc", "--invert", "tacho"], capsys)[::2])
    assert "--invert" in line and "aE_t or aE_n" in line, line


# ------------------------------------------------------------------------------ a drifting speed

@pytest.mark.slow
@pytest.mark.parametrize("tacho", [True, False])
def test_a_speed_drifting_by_5_percent_is_followed_and_stated(tmp_path, capsys, tacho):
    """A drive warming up: 175.5 -> 184.5 rpm over 20 s. The tacho's marks follow it revolution by
    revolution; without a tacho the matched filter's template follows the latest revolutions and each
    mark is placed again with its own revolution's length (one template of the median length put
    the marks up to 3.3 degrees off at the ends: 31 mrad rms). The spread is stated."""
    rec = tmp_path / "rec.h5"
    tr = stand_recording(rec, duration_s=20.0, rpm=180.0, tacho=tacho, speed_drift=0.05)
    code, out, err = _cli(["process", rec, "-o", tmp_path / "m.nc"], capsys)
    assert code == 0, err
    ds = _open(tmp_path / "m.nc")
    e_o, e_e = _errors(ds, tr)
    assert e_o < 0.02 and e_e < 0.05, (e_o, e_e)
    # the tacho's phi1 is late by the anti-alias filter's delay (about 0.2 ms, 4 mrad at 180 rpm)
    assert _phi1_error(ds, tr) < 0.006, _phi1_error(ds, tr)
    # per revolution: the truth's speed at each revolution's middle
    t_mid = ds["revolution_start_time"].values[:-1] + 0.5 * np.diff(ds["revolution_start_time"].values)
    truth_rpm = 180.0 * (1 + 0.05 * (t_mid / 20.0 - 0.5))
    got = ds["revolution_omega1"].values[:-1] * 30 / np.pi
    np.testing.assert_allclose(got, truth_rpm, rtol=2e-3)
    assert ds.attrs["cam_speed_rpm_min"] == pytest.approx(truth_rpm.min(), rel=2e-3)
    assert ds.attrs["cam_speed_rpm_max"] == pytest.approx(truth_rpm.max(), rel=2e-3)
    span = (t_mid[-1] - t_mid[0]) / 20.0
    assert ds.attrs["cam_speed_drift"] == pytest.approx(0.05 * span, abs=0.003)
    assert "the cam speed varies over the recording" in err
    assert re.search(r"cam speed: 175\.\d\d to 184\.\d\d rpm per revolution \(drift \+4\.\d %", out), out


@pytest.mark.slow
def test_a_steady_speed_says_nothing_of_drift(tmp_path, capsys):
    rec = tmp_path / "rec.h5"
    stand_recording(rec, duration_s=3.0, rpm=180.0)
    code, out, err = _cli(["process", rec, "-o", tmp_path / "m.nc"], capsys)
    assert code == 0, err
    assert "varies over the recording" not in err and "per revolution" not in out
    ds = _open(tmp_path / "m.nc")
    assert ds.attrs["cam_speed_rpm_max"] - ds.attrs["cam_speed_rpm_min"] < 0.01 * 180.0


# ------------------------------------------------------------------- a slow cam, no tacho, a nominal speed

@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_a_cam_at_5_rpm_without_tacho_is_found_around_its_stated_speed(tmp_path, capsys):
    """5 rpm, 40 s, a DC-coupled chain (the stand's 0.1 Hz AC coupling is above the cam's 0.083 Hz:
    nothing of a 5 rpm motion would survive it). The correlation searched 20-1500 rpm over 20 s on
    main and found no revolution; now it searches around the stated speed, averages 40 samples into
    one and holds gravity's reading in its template (2.5 m/s^2 over the stroke against a motion peak of
    0.08 m/s^2). The result equals the tacho's within the chain's noise. Without a stated speed: one
    line naming --rpm, which then works."""
    chain = {"params": {"highpass_hz": 1e-5}, "scene": {"ripple": 0.0}}
    with_tacho, without = tmp_path / "tacho.h5", tmp_path / "rec.h5"
    tr = stand_recording(with_tacho, duration_s=40.0, rpm=5.0, **chain)
    stand_recording(without, duration_s=40.0, rpm=5.0, tacho=False, **chain)
    code, out, err = _cli(["process", with_tacho, "-o", tmp_path / "tacho.nc"], capsys)
    assert code == 0, err
    code, out, err = _cli(["process", without, "-o", tmp_path / "m.nc"], capsys)
    assert code == 0, err
    by_tacho, ds = _open(tmp_path / "tacho.nc"), _open(tmp_path / "m.nc")
    assert ds.attrs["phi1_method"] == "correlation" and ds.attrs["cam_speed_rpm_measured"] == pytest.approx(5.0, rel=1e-3)
    step = _step(ds, "cam_angle")
    assert step["search_rpm"] == pytest.approx([5 / 1.5, 7.5]) and step["search_averaged_samples"] == 40
    assert _phi1_error(ds, tr) < 0.002            # the tacho's: 0.1 mrad
    (o_t, e_t), (o_c, e_c) = _errors(by_tacho, tr), _errors(ds, tr)
    assert o_c < 1.2 * o_t + 0.005 and e_c < 1.2 * e_t + 0.01, (o_t, e_t, o_c, e_c)
    assert o_c < 0.04 and e_c < 0.15, (o_c, e_c)      # noise against a 0.08 m/s^2 motion
    # gravity dominates both readings at 5 rpm: the channels cannot be checked, and that is said
    assert "channels not checked" in err and ds.attrs["channel_check"] == "not checked"
    with h5py.File(without, "r+") as f:
        del f.attrs["cam_speed_rpm"]
    line = one_error_line(*_cli(["process", without, "-o", tmp_path / "n.nc"], capsys)[::2])
    assert "searched 20 to 1500 rpm" in line and "--rpm" in line, line
    code, out, err = _cli(["process", without, "-o", tmp_path / "n.nc", "--rpm", "5"], capsys)
    assert code == 0, err
    np.testing.assert_allclose(_open(tmp_path / "n.nc")["omega2"].values, ds["omega2"].values, atol=1e-9,
                               equal_nan=True)


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_a_slow_cam_through_an_ac_coupled_chain_is_said_and_ac_tau_undoes_it(tmp_path, capsys):
    """30 rpm (0.5 Hz) through the stand's 0.1 Hz AC coupling: epsilon2 14 % off the truth with exit 0
    and no word on main. Now a warning names the --ac-tau that undoes the coupling; given, omega2 and
    epsilon2 meet 2 % and 5 %."""
    rec = tmp_path / "rec.h5"
    # the chain's corner as the recorder stores it (ChainParams.attrs)
    tr = stand_recording(rec, duration_s=10.0, rpm=30.0, attrs={"highpass_hz": 0.1})
    assert tr["params"].highpass_hz == 0.1
    code, out, err = _cli(["process", rec, "-o", tmp_path / "m.nc"], capsys)
    assert code == 0, err
    said = next(ln for ln in err.splitlines() if "AC coupling" in ln)
    assert "highpass_hz = 0.1 Hz" in said and "--ac-tau 1.59" in said, said
    e_o, e_e = _errors(_open(tmp_path / "m.nc"), tr)
    assert e_e > 0.05, e_e                   # what the warning is about
    tau = re.search(r"--ac-tau (\S+)", said).group(1)
    code, out, err = _cli(["process", rec, "-o", tmp_path / "undone.nc", "--ac-tau", tau], capsys)
    assert code == 0, err
    assert "AC coupling" not in err
    e_o, e_e = _errors(_open(tmp_path / "undone.nc"), tr)
    assert e_o < 0.02 and e_e < 0.05, (e_o, e_e)


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_the_check_reads_a_stand_with_impacts_and_a_bending_follower(tmp_path, capsys):
    """The simulated stand's default truth (the twin: impacts in a 0.4 mm backlash, the follower's
    bending mode) is no ideal sensor's reading: as recorded, the channels read as labelled (no
    warning); swapped with aE_t inverted, they are corrected to the very omega2 of the recording as
    it was."""
    import shutil

    rec = tmp_path / "rec.h5"
    code, out, err = _cli(["acquire", "--device", "sim", "--fast", "--duration", "3", "--backlash-mm", "0.4",
                           "--status-every", "0", "-o", rec], capsys)
    assert code == 0, err
    code, out, err = _cli(["process", rec, "-o", tmp_path / "ref.nc"], capsys)
    assert code == 0, err
    assert "channels: aE_t and aE_n read as labelled" in out and "channel" not in err, err
    edited = tmp_path / "edited.h5"
    shutil.copy(rec, edited)
    _edit(edited, swap=True, invert=("aE_n",))
    code, out, err = _cli(["process", edited, "-o", tmp_path / "m.nc"], capsys)
    assert code == 0, err
    assert "aE_t and aE_n swapped, aE_t inverted: corrected" in err, err
    np.testing.assert_allclose(_open(tmp_path / "m.nc")["omega2"].values, _open(tmp_path / "ref.nc")["omega2"].values,
                               rtol=0, atol=1e-6, equal_nan=True)
