"""The acquisition monitor: cam speed from the tacho, engineering units, headroom, the last turn,
and a piped run that tells its progress while it runs."""
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from labtool.acquisition import signal_chain as sc
from labtool.acquisition.device import Block
from labtool.acquisition.monitor import Monitor
from labtool.acquisition.sim_stand import SimStand
from labtool import monitor_view
from labtool.common.units import RPM

ROOT = Path(__file__).resolve().parents[1]
PAPER_CHAIN = sc.ChainParams(ka_m_s2_per_v=(86.43, 86.43))  # the paper's gain x10: aE_t at 96 % of +-10 V at 500 rpm


def blocks_of(dev, seconds):
    dev.configure(10000)
    dev.start()
    out = []
    while (b := dev.read_block()) is not None and b.first_index < seconds * 10000:
        out.append(b)
    return out


@pytest.mark.parametrize("rpm", [180.0, 500.0])
def test_cam_speed_peak_rms_and_headroom_from_the_simulated_stand(rpm):
    dev = SimStand(sc.StandScene(cam_speed=rpm * RPM, truth_model="kinematic"), PAPER_CHAIN, seed=2, duration_s=3.0,
                   realtime=False)
    blocks = blocks_of(dev, 3.0)
    ka = [86.43, 86.43, np.nan]
    mon = Monitor(dev.channel_names, 10000.0, ka, dev.input_range_v, duration_s=3.0)
    for b in blocks:
        mon.update(b)
    snap = mon.snapshot(3.0)
    res = rpm / (60 / rpm * 10000)  # one sample per revolution: the simulated pulse starts on the internal grid
    assert snap.rpm == pytest.approx(rpm, abs=res) and abs(snap.rpm_drift) <= 2 * res
    assert 3.0 * rpm / 60 - 2 <= snap.revolutions <= 3.0 * rpm / 60
    data = np.concatenate([b.data for b in blocks]).astype(float)
    t, n, tach = snap.channels
    assert t.unit == "m/s^2" and tach.unit == "V"
    assert t.peak == pytest.approx(np.abs(data[:, 0]).max() * 86.43)
    assert t.rms_recent == pytest.approx(np.sqrt(np.mean(data[-10000:, 0] ** 2)) * 86.43, rel=1e-6)
    assert t.fraction == pytest.approx(np.abs(data[:, 0]).max() / 10.0)
    # at 500 rpm aE_t peaks at 96 % of +-10 V: flagged; at 180 rpm it is at 13 %
    assert t.state == ("warn" if rpm == 500 else "ok") and n.state == "ok"
    assert snap.progress == pytest.approx(1.0) and snap.eta_s == pytest.approx(0.0, abs=1e-9)
    # the trace is the last revolution, between the last two tacho edges, in m/s^2
    tr = snap.trace
    assert tr["what"] == "last revolution" and tr["unit"] == "m/s^2"
    assert tr["x"][0] >= 0 and tr["x"][-1] <= 360
    assert np.max(tr["aE_t"]) == pytest.approx(t.peak, rel=0.1)


def test_drift_and_a_gap_between_edges():
    """A cam slowing from 180 to 171 rpm; a 0.2 s overrun in the middle does not distort the speed."""
    rate = 10000.0
    mon = Monitor(("aE_t", "aE_n", "tacho"), rate, [86.43, 86.43, np.nan], [10.0] * 3)
    t = np.arange(int(10 * rate)) / rate
    rpm = 180.0 - 0.9 * t  # rpm(t)
    phi = np.cumsum(rpm / 60.0 * 2 * np.pi) / rate
    tach = np.where(np.mod(phi, 2 * np.pi) < 0.02, 5.0, 0.0)
    x = np.column_stack([np.sin(phi), np.cos(phi), tach])
    for k in range(0, x.shape[0], 1000):
        if 50_000 <= k < 52_000:
            continue  # lost: the next block starts 2000 samples later
        mon.update(Block(x[k:k + 1000], k))
    snap = mon.snapshot(10.0)
    edges = np.flatnonzero(np.diff(tach) > 0)
    expected = 60 * rate / np.diff(edges)[-1]
    assert snap.rpm == pytest.approx(expected, abs=0.1)
    assert snap.rpm_drift == pytest.approx(expected - 60 * rate / np.diff(edges)[0], abs=0.1)
    assert snap.rpm_drift < -8


def test_clipping_is_red_and_the_status_line_says_everything():
    mon = Monitor(("aE_t", "tacho"), 1000.0, [86.43, np.nan], [10.0, 10.0], duration_s=None)
    mon.update(Block(np.array([[9.9997, 0.0], [1.0, 0.0]]), 0))
    snap = mon.snapshot(1.0, overruns=1, gaps=1, samples_lost=300, buffer_fill=0.25)
    assert snap.channels[0].state == "clip" and snap.progress is None
    line = monitor_view.status_line(snap)
    assert line.startswith("labtool: acquire") and "\n" not in line
    for part in ("aE_t peak 864 m/s^2 = 100 % of +-10 V", "CLIPPING", "overruns 1, gaps 1 (300 samples lost)",
                 "buffer 25 %", "until stopped", "no tacho pulse yet"):
        assert part in line, (part, line)


def test_tacho_peak_is_the_anti_alias_filters_step_overshoot():
    """6.033 V for a 5 V pulse: the order-8 Butterworth at 0.4 x rate overshoots a step by 20.7 %
    (its analog prototype by 16.3 %); the filter keeps the pulse's area (DC gain 1): 5 V x 1 ms."""
    p = sc.ChainParams()
    dev = SimStand(sc.StandScene(truth_model="kinematic"), seed=0, duration_s=1.0, realtime=False)
    x = np.concatenate([b.data for b in blocks_of(dev, 1.0)])[:, 2].astype(float)
    st = sc.new_chain_state(p, 10000.0)
    overshoot = signal.sosfilt(st.sos_aa, np.ones(400)).max()
    assert overshoot == pytest.approx(1.2067, abs=1e-3)
    assert x.max() == pytest.approx(p.tacho_v * overshoot, abs=2 * p.lsb_v)
    b, a = signal.butter(8, 2 * np.pi * 4000, analog=True)
    assert signal.step((b, a), T=np.linspace(0, 0.005, 20001))[1].max() == pytest.approx(1.163, abs=1e-3)
    rise = int(np.flatnonzero((x[1:] > 2.5) & (x[:-1] <= 2.5))[0]) + 1  # the pulse at t = 1/3 s
    area = x[rise - 20: rise + 30].sum() / 10000.0
    assert area == pytest.approx(p.tacho_v * p.tacho_width_s, rel=0.02)
    np.testing.assert_allclose(x[rise + 60: rise + 200], 0.0, atol=2 * p.lsb_v)  # and it settles to 0 V


@pytest.mark.slow
def test_a_piped_realtime_run_reports_while_it_runs(tmp_path):
    out = tmp_path / "p.h5"
    proc = subprocess.Popen([sys.executable, "-m", "labtool", "acquire", "--duration", "6", "--status-every", "1",
                             "-o", str(out)], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        first = proc.stderr.readline()
        running = proc.poll() is None
        rest_err = proc.stderr.read()
        rest_out = proc.stdout.read()
        proc.wait(60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert running, "the first status line came only after the run ended"
    lines = [first] + rest_err.splitlines()
    status = [ln for ln in lines if ln.startswith("labtool: acquire")]
    assert len(status) >= 4
    assert ("cam 179.9" in status[-1] or "cam 180.0" in status[-1]) and "aE_t peak" in status[-1] and "% of +-10 V" in status[-1]
    assert "wrote" in rest_out and proc.returncode == 0


def test_the_terminal_panel_shows_headroom_and_both_traces():
    from rich.console import Console

    dev = SimStand(sc.StandScene(cam_speed=500.0 * RPM, truth_model="kinematic"), PAPER_CHAIN, seed=2, duration_s=1.0,
                   realtime=False)
    mon = Monitor(dev.channel_names, 10000.0, [86.43, 86.43, np.nan], [10.0] * 3, duration_s=2.0)
    for b in blocks_of(dev, 1.0):
        mon.update(b)
    con = Console(record=True, width=100, force_terminal=True, color_system="truecolor")
    con.print(monitor_view.render(mon.snapshot(1.0), "simulated stand", width=100))
    text = con.export_text()
    assert "LOW HEADROOM" in text and "96." in text and "500.0" in text
    assert "aE_t [m/s^2], last revolution" in text and "aE_n [m/s^2], last revolution" in text
    assert "ETA" in text and "50.0 % of 2.0 s" in text
    assert max(len(line) for line in text.splitlines()) <= 100
