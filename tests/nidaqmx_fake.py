"""A fake NI board made of ``unittest.mock.create_autospec`` objects of the real nidaqmx classes.

Every call the driver makes is checked against the real signatures (a wrong keyword raises
TypeError), and every attribute it sets must be a real property of the class (``spec_set``): a
property that does not exist in nidaqmx raises AttributeError. Behind the mocks, the board coerces
ranges to its own gain ranges, the rate with ``coerce``, and serves a ramp (the sample number, plus
0.001 x the channel index) so tests see exactly which samples arrived.
"""
from unittest import mock

import numpy as np
from nidaqmx import Task
from nidaqmx.constants import Coupling, ExcitationSource, TerminalConfiguration, TriggerType, UsageTypeAI
from nidaqmx.errors import DaqError
from nidaqmx.stream_readers import AnalogMultiChannelReader
from nidaqmx.system import PhysicalChannel
from nidaqmx.task import InStream, Timing
from nidaqmx.task.channels import AIChannel
from nidaqmx.task.collections import AIChannelCollection
from nidaqmx.task.triggering import StartTrigger, Triggers

OVERRUN = -200279


def _spec(cls):
    return mock.create_autospec(cls, instance=True, spec_set=True)


class FakeBoard:
    """``board.task`` is the fake Task, ``board.reader(task)`` the fake stream reader.

    ranges       the board's input ranges (+-V): a channel gets the smallest that covers its limits
    coerce       requested rate -> the rate the board really runs at
    script       {read number: "overrun" | "unplug"}
    terminal     if set, the only terminal configuration the board has (a DSA board: PSEUDO_DIFF)
    teds_mv_per_g  sensitivity the TEDS chips report
    source       (first sample, n) -> (n, channels) volts the inputs see (e.g. the simulated stand's)
    """

    def __init__(self, coerce=lambda r: r, script=None, reject_rate=False, ranges=(0.316, 1.0, 3.16, 10.0),
                 terminal=None, teds_mv_per_g=9.87, source=None):
        self.coerce, self.script, self.reject_rate = coerce, dict(script or {}), reject_rate
        self.source = source  # (first sample, n) -> (n, channels) volts; None: the ramp
        self.ranges, self.terminal, self.teds_mv_per_g = ranges, terminal, teds_mv_per_g
        self.chans: dict[str, mock.NonCallableMagicMock] = {}
        self.order: list[str] = []
        self.kinds: dict[str, str] = {}
        self.calls: list = []
        self.produced = 0  # board sample counter, continues across restarts
        self.reads = 0
        self.started = self.stopped = 0
        self.closed = False
        t = self.task = _spec(Task)
        t.ai_channels = _spec(AIChannelCollection)
        t.timing = _spec(Timing)
        t.triggers = _spec(Triggers)
        t.triggers.start_trigger = _spec(StartTrigger)
        t.in_stream = _spec(InStream)
        t.ai_channels.add_ai_accel_chan.side_effect = self._add("accel")
        t.ai_channels.add_teds_ai_accel_chan.side_effect = self._add("teds")
        t.ai_channels.add_ai_voltage_chan.side_effect = self._add("voltage")
        t.ai_channels.__getitem__.side_effect = lambda name: self.chans[name]
        t.timing.cfg_samp_clk_timing.side_effect = self._timing
        st = t.triggers.start_trigger
        st.trig_type = TriggerType.NONE
        st.cfg_dig_edge_start_trig.side_effect = self._dig_trigger
        st.cfg_anlg_edge_start_trig.side_effect = self._anlg_trigger
        t.start.side_effect = self._start
        t.stop.side_effect = self._stop
        t.close.side_effect = self._close
        t.in_stream.total_samp_per_chan_acquired = 0
        t.in_stream.avail_samp_per_chan = 0
        t.in_stream.input_buf_size = 0
        self.physical = {}

    # -- channels
    def _add(self, kind):
        def add(physical_channel, name_to_assign_to_channel="", terminal_config=TerminalConfiguration.DEFAULT,
                min_val=-5.0, max_val=5.0, units=None, sensitivity=1000.0, sensitivity_units=None,
                current_excit_source=ExcitationSource.INTERNAL, current_excit_val=0.004, custom_scale_name=""):
            ch = _spec(AIChannel)
            ch.physical_channel = _spec(PhysicalChannel)
            ch.physical_channel.name = physical_channel
            ch.ai_term_cfg = TerminalConfiguration(self.terminal or (
                TerminalConfiguration.PSEUDO_DIFF if terminal_config == TerminalConfiguration.DEFAULT else terminal_config))
            ch.ai_coupling = Coupling.DC if kind == "voltage" else Coupling.AC
            if kind == "teds":
                ch.ai_accel_sensitivity = self.teds_mv_per_g
            elif kind == "accel":
                ch.ai_accel_sensitivity = sensitivity
            if kind != "voltage":
                ch.ai_meas_type = UsageTypeAI.ACCELERATION_ACCELEROMETER_CURRENT_INPUT
                ch.ai_excit_src, ch.ai_excit_val = current_excit_source, current_excit_val
                ch.ai_accel_sensitivity_units = sensitivity_units if kind == "accel" else mock.sentinel.teds_units
                ch.ai_accel_units = units
            else:
                ch.ai_meas_type = UsageTypeAI.VOLTAGE
            self._limits(ch, kind)
            ch.ai_min, ch.ai_max = min_val, max_val
            name = name_to_assign_to_channel or physical_channel
            self.chans[name] = ch
            self.order.append(name)
            self.kinds[name] = kind
            self.calls.append((kind, physical_channel, name, dict(terminal_config=terminal_config, min_val=min_val,
                               max_val=max_val, units=units, sensitivity=sensitivity, sensitivity_units=sensitivity_units,
                               current_excit_source=current_excit_source, current_excit_val=current_excit_val)))
        return add

    def _limits(self, ch, kind):
        """ai_min / ai_max as properties (of this mock's own class): setting them re-chooses the
        board range, as DAQmx does; a TEDS channel's limits are in g."""
        store = {}

        def prop(name):
            def set_(obj, value):
                store[name] = value
                scale = obj.ai_accel_sensitivity / 1000.0 if kind == "teds" else 1.0
                self._set_range(obj, max(abs(store.get("ai_min", 0.0)), abs(store.get("ai_max", 0.0))) * scale)
            return property(lambda obj: store[name], set_)

        type(ch).ai_min, type(ch).ai_max = prop("ai_min"), prop("ai_max")

    def _set_range(self, ch, volts):
        fit = [r for r in self.ranges if r >= volts * (1 - 1e-9)]
        r = fit[0] if fit else self.ranges[-1]
        ch.ai_rng_low, ch.ai_rng_high = -r, r

    # -- timing and triggers
    def _timing(self, rate, source="", active_edge=None, sample_mode=None, samps_per_chan=1000):
        if self.reject_rate:
            raise DaqError("Requested value is not a supported value for this property.", -200077)
        tm = self.task.timing
        tm.samp_clk_rate = self.coerce(rate)
        tm.samp_clk_src = source or "OnboardClock"
        tm.samp_quant_samp_mode = sample_mode
        tm.samp_quant_samp_per_chan = samps_per_chan
        self.task.in_stream.input_buf_size = samps_per_chan

    def _dig_trigger(self, trigger_source, trigger_edge=None):
        st = self.task.triggers.start_trigger
        st.trig_type, st.dig_edge_src, st.dig_edge_edge = TriggerType.DIGITAL_EDGE, trigger_source, trigger_edge

    def _anlg_trigger(self, trigger_source="", trigger_slope=None, trigger_level=0.0):
        st = self.task.triggers.start_trigger
        st.trig_type, st.anlg_edge_src, st.anlg_edge_slope, st.anlg_edge_lvl = (
            TriggerType.ANALOG_EDGE, trigger_source, trigger_slope, trigger_level)

    # -- run
    def _start(self):
        self.started += 1
        self.task.in_stream.total_samp_per_chan_acquired = 0

    def _stop(self):
        self.stopped += 1

    def _close(self):
        self.closed = True

    def reader(self, task):
        assert task is self.task
        r = _spec(AnalogMultiChannelReader)
        r.read_many_sample.side_effect = self._read
        self.stream_reader = r
        return r

    def _read(self, data, number_of_samples_per_channel=-1, timeout=10.0):
        self.reads += 1
        n = number_of_samples_per_channel
        s = self.task.in_stream
        if data.shape != (len(self.order), n):  # what the real reader's verify_array_shape checks
            raise DaqError(f"array shape {data.shape}, need {(len(self.order), n)}", -1)
        action = self.script.get(self.reads)
        if action == "overrun":  # the board went on acquiring 3 blocks nobody read
            self.produced += 3 * n
            s.total_samp_per_chan_acquired += 3 * n
            raise DaqError("Attempted to read samples that are no longer available.", OVERRUN)
        if action == "unplug":
            raise DaqError("Device has been removed.", -88709)
        ramp = np.arange(self.produced, self.produced + n, dtype=float)
        wired = None if self.source is None else self.source(self.produced, n)
        for c, name in enumerate(self.order):
            v = ramp + 0.001 * c if wired is None else wired[:, c]
            data[c, :] = v / (self.chans[name].ai_accel_sensitivity / 1000.0) if self.kinds[name] == "teds" else v
        self.produced += n
        s.total_samp_per_chan_acquired += n
        s.avail_samp_per_chan = n // 2
        return n

    def physical_channel(self, name):
        pc = _spec(PhysicalChannel)
        pc.name = name
        pc.teds_mfg_id, pc.teds_model_num, pc.teds_serial_num = 12, 352, 4711
        self.physical[name] = pc
        return pc


def stand_source(scene=None, seed=0):
    """Volts of the simulated stand as the board's inputs: the fake board wired to the stand."""
    from labtool.acquisition import signal_chain as sc
    from labtool.acquisition.sim_stand import SimStand

    dev = SimStand(scene or sc.StandScene(truth_model="kinematic"), seed=seed, realtime=False)
    dev.configure(10000)
    dev.start()
    buf = {"data": np.empty((0, 3)), "first": 0}

    def read(first, n):
        while buf["first"] + buf["data"].shape[0] < first + n:
            buf["data"] = np.concatenate([buf["data"], dev.read_block().data.astype(float)])
        lo = first - buf["first"]
        out = buf["data"][lo:lo + n]
        buf["data"], buf["first"] = buf["data"][lo + n:], first + n
        return out
    return read
