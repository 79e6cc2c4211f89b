"""Waiting for a steady cam speed: the criterion, a drive that spins up, one that never settles,
the prompt, and the simulated stand through a whole campaign point."""
import math

import h5py
import numpy as np
import pytest

from labtool.acquisition.device import Block, Device
from labtool.campaign.settle import steady, wait_for_operator, wait_for_tacho
from labtool.common.errors import InputError
from labtool.cli import main


class SpinningUp(Device):
    """A tacho (5 V, 1 ms pulses) on a drive whose speed approaches ``final_rpm`` as
    final * (1 - 0.3 exp(-t / tau)); 0.1 s blocks; a fake clock advanced by the samples read."""

    channel_names = ("aE_t", "aE_n", "tacho")
    metadata: dict = {}

    def __init__(self, final_rpm=180.0, tau_s=2.0, rate=10000.0):
        self.final, self.tau, self.rate = final_rpm, tau_s, rate
        self.n = 0
        self.t = 0.0
        self.started = self.stopped = 0

    def configure(self, rate_hz):
        return self.rate

    def start(self):
        self.started += 1

    def stop(self):
        self.stopped += 1

    @property
    def actual_rate_hz(self):
        return self.rate

    def clock(self):
        return self.n / self.rate

    def read_block(self):
        k = int(0.1 * self.rate)
        t = (self.n + np.arange(k)) / self.rate
        # cam angle: integral of omega(t) = W (1 - 0.3 exp(-t/tau))
        W = self.final * math.pi / 30
        phi = W * (t - 0.3 * self.tau * (1 - np.exp(-t / self.tau)))
        frac = np.mod(phi, 2 * math.pi) / (W * (1 - 0.3 * np.exp(-t / self.tau)))   # s since the last pulse
        tacho = np.where(frac < 1e-3, 5.0, 0.0)
        data = np.column_stack([np.zeros(k), np.zeros(k), tacho])
        b = Block(data, self.n)
        self.n += k
        return b


def test_the_criterion_needs_every_recent_revolution_within_the_tolerance():
    rate = 10000.0
    period = 60 / 180 * rate
    edges = np.arange(8) * period
    ok, rpm, dev = steady(edges, rate, 180.0, 0.01, 5)
    assert ok and rpm == pytest.approx(180.0) and dev == pytest.approx(0.0, abs=1e-12)
    slow = edges.copy()
    slow[-1] += 0.02 * period       # the last revolution 2 % slow
    assert not steady(slow, rate, 180.0, 0.01, 5)[0]
    assert steady(slow, rate, 180.0, 0.03, 5)[0]
    assert not steady(edges[:5], rate, 180.0, 0.01, 5)[0]   # 4 periods known, 5 asked


def test_a_drive_spinning_up_is_waited_for():
    dev = SpinningUp(final_rpm=180.0, tau_s=2.0)
    res = wait_for_tacho(dev, 10000.0, 180.0, 0.01, 5, timeout_s=60.0, clock=dev.clock)
    # 30 % low at t = 0: within 1 % needs exp(-t/2) < 1/30, t > 6.8 s, and 5 revolutions in it
    assert 6.8 < res.waited_s < 10.0
    assert res.rpm == pytest.approx(180.0, rel=0.01) and res.spread <= 0.01
    assert dev.started == dev.stopped == 1


def test_a_drive_that_never_settles_is_one_line_saying_what_it_saw():
    dev = SpinningUp(final_rpm=150.0, tau_s=0.5)
    with pytest.raises(InputError, match=r"did not settle at 180 rpm.*\(150\.\d rpm, 16\.\d % off\)"):
        wait_for_tacho(dev, 10000.0, 180.0, 0.01, 5, timeout_s=10.0, clock=dev.clock)
    assert dev.stopped == 1

    class NoTacho(SpinningUp):
        channel_names = ("aE_t", "aE_n")
    with pytest.raises(InputError, match="needs a 'tacho' channel"):
        wait_for_tacho(NoTacho(), 10000.0, 180.0, 0.01, 5, timeout_s=1.0)


def test_the_prompt_waits_for_the_operator():
    asked = []
    res = wait_for_operator(asked.append, "set 180 rpm")
    assert asked == ["set 180 rpm"] and res.how.startswith("prompt")


@pytest.mark.slow
def test_a_campaign_point_waits_on_the_simulated_stands_tacho(tmp_path, capsys):
    plan = tmp_path / "plan.toml"
    plan.write_text('[device]\nsettle = "tacho"\nsettle_revolutions = 3\n[defaults]\nrevolutions = 3\n'
                    '[[points]]\nrpm = 300.0\n[compare]\nmodels = ["kinematic"]\nomega1 = ["const"]\n')
    out = tmp_path / "camp"
    assert main(["campaign", "run", str(plan), "-o", str(out), "--no-report"]) == 0
    with h5py.File(out / "points" / "01_300rpm" / "recording.h5") as h:
        assert h.attrs["settle_rpm_measured"] == pytest.approx(300.0, rel=0.01)   # the stand's 0.5 % ripple
        assert h.attrs["settle_method"].startswith("tacho")
    # settle = "prompt" without a terminal: one line, nothing recorded
    plan.write_text(plan.read_text().replace('"tacho"', '"prompt"'))
    capsys.readouterr()
    assert main(["campaign", "run", str(plan), "-o", str(tmp_path / "p")]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("labtool: error: point 01_300rpm (acquire):") and "no terminal" in err
