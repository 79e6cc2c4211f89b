"""The NI-DAQmx driver against a fake board made of autospecs of the real nidaqmx classes.

Configuration round trip: set (CLI / device file) -> task (checked signatures, real property names)
-> read back from the task -> stored in the recording.
"""
import json

import numpy as np
import pytest
from nidaqmx.constants import AccelSensitivityUnits, AccelUnits, AcquisitionType, Edge, ExcitationSource, Slope
from nidaqmx.constants import TerminalConfiguration

from labtool.acquisition import nidaqmx_config as nc
from labtool.acquisition import session
from labtool.acquisition.device import DeviceDisconnected
from labtool.acquisition.nidaqmx_driver import NIDAQmxDevice, check_readback, expand_channels
from labtool.common import recording_format
from labtool.common.errors import InputError
from nidaqmx_fake import FakeBoard


def make(board, spec="Dev1/ai0:2", overrides=(), doc=None, **kw):
    cfg = nc.build(expand_channels(spec) if spec else None, doc=doc, overrides=overrides)
    return NIDAQmxDevice(cfg, task_factory=lambda: board.task, reader_factory=board.reader,
                         physical_channel_factory=board.physical_channel, block_s=0.01, read_timeout_s=1.0, **kw)


def test_channels_are_iepe_accelerometers_with_excitation_off_and_volts_out():
    board = FakeBoard()
    dev = make(board)
    assert dev.configure(10000) == 10000
    assert [(k, p, n) for k, p, n, _ in board.calls] == [
        ("accel", "Dev1/ai0", "aE_t"), ("accel", "Dev1/ai1", "aE_n"), ("voltage", "Dev1/ai2", "tacho")]
    for _, _, _, kw in board.calls[:2]:
        assert kw["current_excit_source"] == ExcitationSource.NONE  # the 480C02 powers the sensor
        # 1000 mV/g read in g: the numbers are the input volts
        assert kw["sensitivity"] == 1000.0 and kw["sensitivity_units"] == AccelSensitivityUnits.MILLIVOLTS_PER_G
        assert kw["units"] == AccelUnits.G
    assert board.task.timing.samp_quant_samp_mode == AcquisitionType.CONTINUOUS
    board.task.read.assert_not_called()  # reads go through the stream reader into a preallocated array


DEVICE_FILE = """
[device]
sample_clock_source = "/Dev1/PFI2"
buffer_s = 5.0

[trigger]
type = "digital"
source = "/Dev1/PFI0"
edge = "falling"

[channels.aE_t]
physical = "Dev1/ai0"
range_v = 3.0
terminal = "pseudodiff"
coupling = "ac"
iepe_excitation_a = 0.004
sensitivity_mv_per_g = 10.2
conditioner_gain = 1.0
sensor_model = "PCB 352A76"
sensor_serial = "LW001"

[channels.aE_n]
physical = "Dev1/ai1"
range_v = 1.0
terminal = "pseudodiff"
coupling = "ac"
teds = true
iepe_excitation_a = 0.002

[channels.tacho]
physical = "Dev1/ai2"
range_v = 10.0
coupling = "dc"

[channels.strain]
physical = "Dev1/ai5"
kind = "voltage"
range_v = 0.3

[metadata]
operator = "M. Ionescu"
"""


@pytest.mark.slow
def test_configuration_round_trip_set_task_read_back_stored(tmp_path):
    (tmp_path / "dev.toml").write_text(DEVICE_FILE)
    doc = nc.load_device_file(tmp_path / "dev.toml")
    board = FakeBoard()
    # the CLI's --ni overrides win over the file
    dev = make(board, spec=None, doc=doc, overrides=["aE_t.range_v=0.9", "tacho.terminal=rse"])
    res = session.run(dev, tmp_path / "n.h5", 10000, 0.05)
    assert res.outcome == "done" and board.closed
    # set -> task: what the driver asked for, through the real signatures
    kinds = {n: (k, p, kw) for k, p, n, kw in board.calls}
    assert list(kinds) == ["aE_t", "aE_n", "tacho", "strain"]
    k, p, kw = kinds["aE_t"]
    assert (k, p, kw["min_val"], kw["max_val"]) == ("accel", "Dev1/ai0", -0.9, 0.9)
    assert kw["terminal_config"] == TerminalConfiguration.PSEUDO_DIFF
    assert kw["current_excit_source"] == ExcitationSource.INTERNAL and kw["current_excit_val"] == 0.004
    assert kinds["aE_n"][0] == "teds" and board.physical["Dev1/ai1"].configure_teds.called
    assert kinds["tacho"][2]["terminal_config"] == TerminalConfiguration.RSE
    board.task.timing.cfg_samp_clk_timing.assert_called_once_with(
        10000, source="/Dev1/PFI2", sample_mode=AcquisitionType.CONTINUOUS, samps_per_chan=50000)
    board.task.triggers.start_trigger.cfg_dig_edge_start_trig.assert_called_once_with(
        trigger_source="/Dev1/PFI0", trigger_edge=Edge.FALLING)
    assert str(board.chans["aE_t"].ai_coupling) == "Coupling.AC" and str(board.chans["tacho"].ai_coupling) == "Coupling.DC"
    # task -> read back -> stored in the recording
    rec = recording_format.load(tmp_path / "n.h5")
    a = rec["attrs"]
    rb = json.loads(a["ni_readback_json"])
    assert rb["channels"]["aE_t"]["ai_rng_high"] == 1.0  # the board's range covering +-0.9 V
    assert rb["channels"]["aE_n"]["ai_rng_high"] == 1.0 and rb["channels"]["strain"]["ai_rng_high"] == 0.316
    assert rb["channels"]["tacho"]["ai_term_cfg"] == "RSE" and rb["channels"]["aE_t"]["ai_term_cfg"] == "PSEUDO_DIFF"
    assert rb["channels"]["aE_t"]["ai_coupling"] == "AC" and rb["channels"]["tacho"]["ai_coupling"] == "DC"
    assert rb["channels"]["aE_n"]["ai_excit_src"] == "INTERNAL" and rb["channels"]["aE_n"]["ai_excit_val"] == 0.002
    assert rb["timing"] == {"samp_clk_rate": 10000.0, "samp_clk_src": "/Dev1/PFI2",
                            "samp_quant_samp_mode": "CONTINUOUS", "samp_quant_samp_per_chan": 50000}
    assert rb["trigger"] == {"trig_type": "DIGITAL_EDGE", "dig_edge_src": "/Dev1/PFI0", "dig_edge_edge": "FALLING"}
    assert list(a["ni_ai_term_cfg"]) == ["PSEUDO_DIFF", "PSEUDO_DIFF", "RSE", "PSEUDO_DIFF"]
    np.testing.assert_array_equal(a["ni_ai_rng_high"], [1.0, 1.0, 10.0, 0.316])
    assert a["ni_timing_samp_clk_src"] == "/Dev1/PFI2" and a["ni_trigger_trig_type"] == "DIGITAL_EDGE"
    assert a["trigger"].startswith("digital falling on /Dev1/PFI0")
    # the recording's ranges are the board's (headroom is measured against them)
    sig = __import__("h5py").File(tmp_path / "n.h5", "r")["signals"]
    np.testing.assert_array_equal(sig.attrs["input_range_v"], [1.0, 1.0, 10.0, 0.316])
    # sensors: the stated one and the TEDS one (its sensitivity read from the chip)
    assert list(a["channel_sensor_serial"])[:2] == ["LW001", "4711"]
    np.testing.assert_allclose(a["channel_sensitivity_mv_per_g"][:2], [10.2, 9.87])
    assert a["ni_config_source"] == "command line"
    # TEDS readings (g) came back to volts: every channel holds the ramp
    np.testing.assert_allclose(rec["signals"][:, 1] - rec["signals"][:, 0], 0.001, atol=2e-3)


def test_nominal_ka_from_sensitivity_and_gain():
    cfg = nc.build(["Dev1/ai0", "Dev1/ai1"], overrides=["aE_t.sensitivity_mv_per_g=10", "aE_t.conditioner_gain=10"])
    assert cfg.channel("aE_t").nominal_ka == pytest.approx(98.0665)  # 9.80665 m/s^2 per 100 mV
    assert np.isnan(cfg.channel("aE_n").nominal_ka)


def test_excitation_from_the_daq_when_asked():
    board = FakeBoard()
    cfg = nc.build(expand_channels("Dev1/ai0:2"), iepe_excitation_a=0.002)
    NIDAQmxDevice(cfg, task_factory=lambda: board.task, reader_factory=board.reader).configure(10000)
    kw = board.calls[0][3]
    assert kw["current_excit_source"] == ExcitationSource.INTERNAL and kw["current_excit_val"] == 0.002
    assert board.calls[2][0] == "voltage"  # the tacho gets no excitation


@pytest.mark.slow
def test_real_rate_is_read_back_and_stored(tmp_path):
    board = FakeBoard(coerce=lambda r: 12.8e6 / 1279)  # 10007.8 Hz
    res = session.run(make(board), tmp_path / "n.h5", 10000, 0.05)
    rec = recording_format.load(tmp_path / "n.h5")
    assert rec["attrs"]["sample_rate_hz"] == pytest.approx(12.8e6 / 1279)
    assert rec["attrs"]["requested_rate_hz"] == 10000
    assert res.outcome == "done" and board.closed
    # samples arrive in order, channels in columns, as volts
    np.testing.assert_allclose(rec["signals"][:, 0], np.arange(rec["signals"].shape[0]), atol=1e-3)
    np.testing.assert_allclose(rec["signals"][:, 2] - rec["signals"][:, 0], 0.002, atol=1e-3)


@pytest.mark.parametrize("board,overrides,said", [
    (FakeBoard(coerce=lambda r: r * 0.5), (), "cannot sample at 10000 Hz"),
    (FakeBoard(reject_rate=True), (), "refused the configuration"),
    (FakeBoard(ranges=(1.0, 5.0)), ["aE_t.range_v=10"], "does not cover +-10 V"),
    (FakeBoard(terminal=TerminalConfiguration.PSEUDO_DIFF), ["aE_t.terminal=diff"], "terminal configuration is PSEUDO_DIFF"),
])
def test_what_the_board_does_not_take_is_refused(board, overrides, said):
    with pytest.raises(InputError, match=said.replace("+", r"\+")):
        make(board, overrides=overrides).configure(10000)
    assert board.closed


def test_analog_start_trigger_on_the_tacho():
    board = FakeBoard()
    make(board, overrides=["trigger.type=analog", "trigger.source=tacho", "trigger.level_v=2.5"]).configure(10000)
    board.task.triggers.start_trigger.cfg_anlg_edge_start_trig.assert_called_once_with(
        trigger_source="Dev1/ai2", trigger_slope=Slope.RISING, trigger_level=2.5)


def test_pretrigger_samples_mean_a_software_trigger_not_a_hardware_one():
    board = FakeBoard()
    dev = make(board, overrides=["trigger.type=analog", "trigger.source=tacho", "trigger.level_v=2.5",
                                 "trigger.pretrigger_samples=50"])
    dev.configure(10000)
    assert dev.config.trigger.software
    assert not board.task.triggers.start_trigger.cfg_anlg_edge_start_trig.called


@pytest.mark.slow
def test_overrun_becomes_an_event_and_a_gap(tmp_path):
    board = FakeBoard(script={3: "overrun"})
    res = session.run(make(board), tmp_path / "o.h5", 10000, 0.1)
    assert res.overruns == 1 and res.gaps == 1 and res.samples_lost >= 300
    rec = recording_format.load(tmp_path / "o.h5")
    kinds = [(i, k) for i, k, _ in rec["events"] if k in ("overrun", "gap")]
    assert kinds == [(200, "overrun"), (200, "gap")]
    assert board.started == 2  # restarted after the overrun
    x = rec["signals"][:, 0]
    assert np.all(np.diff(x[:200]) == 1) and x[200] > x[199] + 1  # the ramp jumps: samples were lost, not joined silently


def test_a_vanished_device_ends_the_run_as_a_disconnect():
    board = FakeBoard(script={2: "unplug"})
    dev = make(board)
    dev.configure(10000)
    dev.start()
    assert dev.read_block().n == 100
    with pytest.raises(DeviceDisconnected):
        dev.read_block()
    dev.stop()
    assert board.closed


def test_missing_package_or_runtime_is_one_line():
    def broken():
        raise RuntimeError("Could not find an installation of NI-DAQmx.")
    with pytest.raises(InputError, match="not available"):
        NIDAQmxDevice("Dev1/ai0:1", task_factory=broken).configure(10000)


def test_the_fake_is_the_real_api():
    """The fake refuses what nidaqmx would: an unknown keyword, a property that does not exist."""
    board = FakeBoard()
    with pytest.raises(TypeError):
        board.task.ai_channels.add_ai_accel_chan("Dev1/ai0", sensitivity_mv=10)
    with pytest.raises(AttributeError):
        board.task.timing.sample_rate = 10000  # not a Timing property (samp_clk_rate is)
    make(board, spec="Dev1/ai0").configure(10000)
    with pytest.raises(AttributeError):
        board.chans["aE_t"].coupling = "AC"  # the property is ai_coupling


@pytest.mark.parametrize("overrides,said", [
    (["aE_t.range_v=0"], "range_v must lie in"),
    (["aE_t.range_v=nan"], "range_v must lie in"),
    (["aE_t.coupling=xx"], "coupling must be one of"),
    (["aE_t.bogus=1"], "unknown keys bogus"),
    (["tacho.iepe_excitation_a=0.004"], "accel channels only"),
    (["aE_t.teds=true", "aE_t.sensitivity_mv_per_g=10"], "not both"),
    (["trigger.type=analog", "trigger.source=nowhere", "trigger.level_v=1"], "among the channels"),
    (["trigger.type=analog", "trigger.source=tacho"], "needs its level"),
    (["trigger.type=analog", "trigger.source=tacho", "trigger.level_v=20"], "outside tacho's range"),
    (["trigger.pretrigger_samples=-3"], "pretrigger_samples must be"),
    (["x.physical=Dev1/ai0"], "given to two channels"),
    (["range_v"], "must look like"),
])
def test_bad_configuration_is_one_clear_error(overrides, said):
    with pytest.raises(InputError, match=said):
        nc.build(expand_channels("Dev1/ai0:2"), overrides=overrides)


def test_readback_check_names_every_difference():
    cfg = nc.build(["Dev1/ai0"], overrides=["aE_t.coupling=ac"])
    rb = {"channels": {"aE_t": {"ai_rng_low": -10.0, "ai_rng_high": 10.0, "ai_term_cfg": "PSEUDO_DIFF", "ai_coupling": "DC",
                                "ai_excit_src": "NONE", "ai_excit_val": 0.0, "ai_accel_sensitivity": 1000.0}},
          "timing": {"samp_clk_rate": 10000.0, "samp_clk_src": "OnboardClock"}, "trigger": {"trig_type": "NONE"}}
    assert check_readback(cfg, rb, 10000) == ["aE_t (Dev1/ai0) coupling is DC, not AC"]


@pytest.mark.parametrize("spec,expected", [
    ("Dev1/ai0:2", ["Dev1/ai0", "Dev1/ai1", "Dev1/ai2"]),
    ("Dev1/ai3,Dev1/ai1", ["Dev1/ai3", "Dev1/ai1"]),
    ("cDAQ1Mod1/ai0:1", ["cDAQ1Mod1/ai0", "cDAQ1Mod1/ai1"]),
])
def test_expand_channels(spec, expected):
    assert expand_channels(spec) == expected


@pytest.mark.parametrize("bad", ["ai0", "Dev1/ai", "Dev1/ai0,Dev1/ai0", "Dev1/ai0:40", ""])
def test_expand_channels_bad(bad):
    with pytest.raises(InputError):
        expand_channels(bad)


def test_software_trigger_keeps_the_pretrigger_samples(tmp_path):
    from labtool.acquisition import signal_chain as sc
    from labtool.acquisition.sim_stand import SimStand
    from labtool.acquisition.trigger import SoftwareTrigger, first_crossing

    assert first_crossing(np.array([0.0, 1.0, 3.0, 1.0]), 2.5, "rising", None) == 2
    assert first_crossing(np.array([3.0, 3.0]), 2.5, "rising", None) is None  # high from the start: no edge
    assert first_crossing(np.array([3.0, 0.0]), 2.5, "falling", None) == 1
    # the tacho rises at phi1 = 0: t = 0.333 s, 0.667 s, ... at 180 rpm; start 0.05 s past the first full turn
    dev = SimStand(sc.StandScene(truth_model="kinematic"), seed=3, duration_s=1.2, realtime=False, faults=[])
    trig = SoftwareTrigger(dev, channel=2, level_v=2.5, pretrigger=500)
    res = session.run(trig, tmp_path / "t.h5", 10000, 0.5)
    rec = recording_format.load(tmp_path / "t.h5")
    x = rec["signals"]
    assert res.n_samples == x.shape[0] == 5000
    starts = [(i, d) for i, k, d in rec["events"] if k == "start"]
    assert starts[1][0] == 500 and "software trigger" in starts[1][1]
    assert x[499, 2] < 2.5 <= x[500, 2]  # the trigger row is the first sample past the level
    ref = SimStand(sc.StandScene(truth_model="kinematic"), seed=3, duration_s=1.2, realtime=False)
    ref.configure(10000)
    ref.start()
    full = np.concatenate([b.data for b in iter(ref.read_block, None)])
    at = int(np.flatnonzero((full[1:, 2] >= 2.5) & (full[:-1, 2] < 2.5))[0]) + 1
    np.testing.assert_array_equal(x, full[at - 500: at - 500 + 5000])  # the same samples, re-based


def _fake_system(devices):
    from unittest import mock

    import nidaqmx.types
    from nidaqmx.system import Device as NIDevice
    from nidaqmx.system import PhysicalChannel, System

    system = mock.create_autospec(System, instance=True, spec_set=True)
    system.driver_version = nidaqmx.types.DriverVersion(2025, 3, 0)
    out = []
    for name, product, n in devices:
        d = mock.create_autospec(NIDevice, instance=True, spec_set=True)
        d.name, d.product_type, d.serial_num, d.is_simulated = name, product, 0, True
        d.ai_max_single_chan_rate = 102400.0
        d.ai_voltage_rngs = [-10.0, 10.0, -3.16, 3.16]
        chans = []
        for i in range(n):
            pc = mock.create_autospec(PhysicalChannel, instance=True, spec_set=True)
            pc.name = f"{name}/ai{i}"
            chans.append(pc)
        d.ai_physical_chans = chans
        out.append(d)
    system.devices = out
    return system


def test_devices_lists_what_nidaqmx_sees(monkeypatch, capsys):
    import nidaqmx.system
    from labtool.cli import main

    monkeypatch.setattr(nidaqmx.system.System, "local", staticmethod(lambda: _fake_system([("SimDev1", "PCI-4462", 4)])))
    assert main(["devices"]) == 0
    out = capsys.readouterr().out
    assert "NI-DAQmx driver 2025.3.0: 1 device(s)" in out
    assert "SimDev1: PCI-4462 (simulated), serial 0, 4 AI channels (SimDev1/ai0 .. SimDev1/ai3), max 102400.0 S/s" in out
    assert "ranges -10..10, -3.16..3.16 V" in out and "--device nidaqmx:SimDev1/ai0:2" in out
    assert main(["devices", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["nidaqmx"][0]["ai_channels"] == [f"SimDev1/ai{i}" for i in range(4)] and doc["nidaqmx_error"] is None


def test_devices_says_when_the_driver_is_absent(monkeypatch, capsys):
    import nidaqmx.system
    from nidaqmx.errors import DaqNotFoundError
    from labtool.cli import main

    def absent():
        raise DaqNotFoundError("Could not find an installation of NI-DAQmx.")
    monkeypatch.setattr(nidaqmx.system.System, "local", staticmethod(absent))
    assert main(["devices"]) == 0
    out = capsys.readouterr().out
    assert "sim: the simulated stand" in out and "NI-DAQmx: not available: NI-DAQmx driver not found" in out
