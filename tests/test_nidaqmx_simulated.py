"""Opt-in tier: the NI-DAQmx driver against an NI MAX simulated device (as nidaqmx-python's own
tests run against simulated devices). Skipped, with the instructions, where there is none.

Set up (docs/acquisition.md, "Testing against a simulated NI device"): install NI-DAQmx, create a
simulated DSA device with IEPE inputs (e.g. a PCI-4462 or a USB-4431) named SimDev1 in NI MAX
(Windows) or by importing a configuration with ``nidaqmxconfig --import`` (Linux), then run

    LABTOOL_NIDAQMX_DEVICE=SimDev1 .venv/bin/python -m pytest -q tests/test_nidaqmx_simulated.py
"""
import json
import os

import numpy as np
import pytest

from labtool.acquisition import nidaqmx_config as nc
from labtool.acquisition import session
from labtool.acquisition.nidaqmx_driver import NIDAQmxDevice, list_devices
from labtool.common import recording_format
from labtool.common.errors import InputError

HOWTO = ("needs an NI-DAQmx simulated device: create one (e.g. a simulated PCI-4462 named SimDev1) in NI MAX or "
         "with nidaqmxconfig --import, then set LABTOOL_NIDAQMX_DEVICE=SimDev1 (docs/acquisition.md)")


@pytest.fixture(scope="module")
def sim_device():
    name = os.environ.get("LABTOOL_NIDAQMX_DEVICE")
    if not name:
        pytest.skip(f"LABTOOL_NIDAQMX_DEVICE is not set: {HOWTO}")
    try:
        found = {d["name"]: d for d in list_devices()}
    except InputError as exc:
        pytest.skip(f"{exc}: {HOWTO}")
    if name not in found:
        pytest.skip(f"NI-DAQmx has no device {name} (it has {', '.join(found) or 'none'}): {HOWTO}")
    dev = found[name]
    if dev.get("simulated") is not True:
        pytest.skip(f"{name} is a real device; this tier runs on simulated ones only")
    if len(dev["ai_channels"]) < 3:
        pytest.skip(f"{name} has {len(dev['ai_channels'])} AI channels; 3 needed (aE_t, aE_n, tacho)")
    return dev


def test_round_trip_on_the_simulated_device(sim_device, tmp_path):
    chans = sim_device["ai_channels"][:3]
    cfg = nc.build(chans, overrides=["aE_t.range_v=3", "aE_t.coupling=ac", "aE_n.coupling=ac", "tacho.coupling=dc",
                                     "aE_t.sensitivity_mv_per_g=10", "aE_t.conditioner_gain=10"])
    dev = NIDAQmxDevice(cfg)
    res = session.run(dev, tmp_path / "sim.h5", 10240, 1.0)
    assert res.outcome == "done" and res.complete
    rec = recording_format.load(tmp_path / "sim.h5")
    rb = json.loads(rec["attrs"]["ni_readback_json"])
    assert rb["channels"]["aE_t"]["ai_rng_high"] >= 3.0 and rb["channels"]["aE_t"]["ai_coupling"] == "AC"
    assert rb["timing"]["samp_quant_samp_mode"] == "CONTINUOUS"
    assert abs(rec["attrs"]["sample_rate_hz"] - 10240) <= 0.01 * 10240
    assert rec["signals"].shape == (res.n_samples, 3) and np.all(np.isfinite(rec["signals"]))


def test_a_setting_the_device_cannot_take_is_refused(sim_device):
    chans = sim_device["ai_channels"][:3]
    cfg = nc.build(chans, overrides=["aE_t.range_v=99"])
    with pytest.raises(InputError):
        NIDAQmxDevice(cfg).configure(10240)
