"""The NI-DAQmx driver's contract, checked against a fake of nidaqmx.Task (no hardware, no NI runtime)."""
import numpy as np
import pytest
from nidaqmx.constants import AccelSensitivityUnits, AccelUnits, AcquisitionType, ExcitationSource
from nidaqmx.errors import DaqError

from acquisition import session
from acquisition.device import DeviceDisconnected
from acquisition.nidaqmx_driver import OVERRUN_ERROR, NIDAQmxDevice, expand_channels
from acquisition.recorder import read_recording
from common.errors import InputError


class FakeTask:
    """Enough of nidaqmx.Task: channels, timing, start/stop/close, read, in_stream counters.

    Produces a ramp (sample number) on every channel so tests can see exactly which samples arrived.
    ``coerce`` maps the requested rate to the one the 'board' really runs at; ``script`` lists, per
    read call, an exception to raise instead of data.
    """

    def __init__(self, coerce=lambda r: r, script=None, reject_rate=False):
        self.channels = []
        self.timing = self
        self.ai_channels = self
        self.in_stream = self
        self.started = 0
        self.stopped = 0
        self.closed = False
        self.coerce = coerce
        self.script = dict(script or {})
        self.reject_rate = reject_rate
        self.total_samp_per_chan_acquired = 0
        self.produced = 0  # board sample counter, continues across restarts
        self.reads = 0

    # ai_channels
    def add_ai_accel_chan(self, physical_channel, **kw):
        self.channels.append(("accel", physical_channel, kw))

    def add_ai_voltage_chan(self, physical_channel, **kw):
        self.channels.append(("voltage", physical_channel, kw))

    # timing
    def cfg_samp_clk_timing(self, rate, sample_mode=None, samps_per_chan=1000, **kw):
        if self.reject_rate:
            raise DaqError("Requested value is not a supported value for this property.", -200077)
        self.samp_clk_rate = self.coerce(rate)
        self.sample_mode = sample_mode
        self.samps_per_chan = samps_per_chan

    def start(self):
        self.started += 1
        self.total_samp_per_chan_acquired = 0

    def stop(self):
        self.stopped += 1

    def close(self):
        self.closed = True

    def read(self, number_of_samples_per_channel=1, timeout=10.0):
        self.reads += 1
        action = self.script.get(self.reads)
        if action == "overrun":
            # the board went on acquiring 3 blocks nobody read, then DAQmx reports -200279
            self.produced += 3 * number_of_samples_per_channel
            self.total_samp_per_chan_acquired += 3 * number_of_samples_per_channel
            raise DaqError("Attempted to read samples that are no longer available.", OVERRUN_ERROR)
        if action == "unplug":
            raise DaqError("Device has been removed.", -88709)
        n = number_of_samples_per_channel
        ramp = np.arange(self.produced, self.produced + n, dtype=float)
        self.produced += n
        self.total_samp_per_chan_acquired += n
        return [list(ramp + 0.001 * c) for c in range(len(self.channels))]


def make(task, spec="Dev1/ai0:2", **kw):
    return NIDAQmxDevice(spec, task_factory=lambda: task, block_s=0.01, read_timeout_s=1.0, **kw)


def test_channels_are_iepe_accelerometers_with_excitation_off_and_volts_out():
    task = FakeTask()
    dev = make(task)
    assert dev.configure(10000) == 10000
    kinds = [(k, p, kw.get("name_to_assign_to_channel")) for k, p, kw in task.channels]
    assert kinds == [("accel", "Dev1/ai0", "aE_t"), ("accel", "Dev1/ai1", "aE_n"), ("voltage", "Dev1/ai2", "tacho")]
    for _, _, kw in task.channels[:2]:
        assert kw["current_excit_source"] == ExcitationSource.NONE  # the 480C02 powers the sensor
        # 1000 mV/g read in g: the numbers are the input volts
        assert kw["sensitivity"] == 1000.0 and kw["sensitivity_units"] == AccelSensitivityUnits.MILLIVOLTS_PER_G
        assert kw["units"] == AccelUnits.G
    assert task.sample_mode == AcquisitionType.CONTINUOUS


def test_excitation_from_the_daq_when_asked():
    task = FakeTask()
    make(task, iepe_excitation=True, excitation_current_a=0.002).configure(10000)
    kw = task.channels[0][2]
    assert kw["current_excit_source"] == ExcitationSource.INTERNAL and kw["current_excit_val"] == 0.002


def test_real_rate_is_read_back_and_stored(tmp_path):
    task = FakeTask(coerce=lambda r: 12.8e6 / 1279)  # 10007.8 Hz
    dev = make(task)
    res = session.run(dev, tmp_path / "n.h5", 10000, 0.05)
    rec = read_recording(tmp_path / "n.h5")
    assert rec["attrs"]["sample_rate_hz"] == pytest.approx(12.8e6 / 1279)
    assert rec["attrs"]["requested_rate_hz"] == 10000
    assert res.outcome == "done" and task.closed
    # samples arrive in order, channels in columns, as volts
    np.testing.assert_allclose(rec["signals"][:, 0], np.arange(rec["signals"].shape[0]), atol=1e-3)
    np.testing.assert_allclose(rec["signals"][:, 2] - rec["signals"][:, 0], 0.002, atol=1e-3)


@pytest.mark.parametrize("task", [FakeTask(coerce=lambda r: r * 0.5), FakeTask(reject_rate=True)])
def test_a_rate_the_board_cannot_do_is_refused(task):
    with pytest.raises(InputError):
        make(task).configure(10000)
    assert task.closed


def test_overrun_becomes_an_event_and_a_gap(tmp_path):
    task = FakeTask(script={3: "overrun"})
    res = session.run(make(task), tmp_path / "o.h5", 10000, 0.1)
    assert res.overruns == 1 and res.gaps == 1 and res.samples_lost >= 300
    rec = read_recording(tmp_path / "o.h5")
    kinds = [(i, k) for i, k, _ in rec["events"] if k in ("overrun", "gap")]
    assert kinds == [(200, "overrun"), (200, "gap")]
    assert task.started == 2  # restarted after the overrun
    x = rec["signals"][:, 0]
    assert np.all(np.diff(x[:200]) == 1) and x[200] > x[199] + 1  # the ramp jumps: samples were lost, not joined silently


def test_a_vanished_device_ends_the_run_as_a_disconnect(tmp_path):
    task = FakeTask(script={2: "unplug"})
    dev = make(task)
    dev.configure(10000)
    dev.start()
    assert dev.read_block().n == 100
    with pytest.raises(DeviceDisconnected):
        dev.read_block()
    dev.stop()
    assert task.closed


def test_missing_package_or_runtime_is_one_line():
    def broken():
        raise RuntimeError("Could not find an installation of NI-DAQmx.")
    with pytest.raises(InputError, match="not available"):
        NIDAQmxDevice("Dev1/ai0:1", task_factory=broken).configure(10000)


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
