"""A (fake) NI-DAQmx run's operating point and metadata reach the report, each value with its source."""
import json
import sys

import numpy as np
import pytest

import labtool.acquisition.nidaqmx_driver as drv
from labtool.common import recording_format
from labtool.cli import main
from nidaqmx_fake import FakeBoard, stand_source


@pytest.mark.slow
@pytest.mark.hostile("silent_wrong")
def test_operating_point_and_metadata_from_an_nidaqmx_run_reach_the_report(tmp_path, monkeypatch, capsys):
    import nidaqmx

    board = FakeBoard(source=stand_source(seed=4))  # the fake board's inputs wired to the simulated stand
    monkeypatch.setattr(nidaqmx, "Task", lambda: board.task)
    monkeypatch.setattr(drv, "_reader", board.reader)
    rec_path, nc, js = tmp_path / "ni.h5", tmp_path / "ni.nc", tmp_path / "ni.json"
    sens = ["--ni", "aE_t.sensitivity_mv_per_g=11.346", "--ni", "aE_t.conditioner_gain=1",
            "--ni", "aE_n.sensitivity_mv_per_g=11.346", "--ni", "aE_n.conditioner_gain=1"]
    assert main(["acquire", "--device", "nidaqmx:Dev1/ai0:2", "--duration", "4", "--rpm", "180", "--law", "sine",
                 "--fu", "5", "--backlash-mm", "0.1", "--jt-factor", "1.2", "--motor-setting", "variator 3.5",
                 "--test-id", "T-042", "--operator", "M. Ionescu", "--sensor-model", "PCB 352A76",
                 "--sensor-serial", "LW001", "--conditioner-gain", "1", "--notes", "after greasing",
                 *sens, "-o", str(rec_path)]) == 0
    a = recording_format.load(rec_path)["attrs"]
    assert a["device"] == "nidaqmx" and a["Fu_N"] == 5.0 and a["Fu_N_source"] == "stated by the operator (--fu)"
    ka = recording_format.load(rec_path)["ka_m_s2_per_v"]
    np.testing.assert_allclose(ka[:2], 9806.65 / 11.346, rtol=1e-9)  # nominal: sensitivity x gain (x1, as the stand)
    assert main(["process", str(rec_path), "-o", str(nc)]) == 0
    capsys.readouterr()
    assert main(["report", str(nc), "--models", "rigid", "--omega1", "const", "-o", str(tmp_path / "r.html"),
                 "--json", str(js)]) in (0, 1)
    doc = json.loads(js.read_text())
    op = doc["operating_point"]
    assert (op["Fu_N"], op["backlash_mm"], op["jt_factor"], op["law"]) == (5.0, 0.1, 1.2, "sine")
    assert op["Fu_N_source"] == "file attribute Fu_N, stated by the operator (--fu)"
    assert op["backlash_mm_source"] == "file attribute backlash_mm, stated by the operator (--backlash-mm)"
    run = doc["measured"]["run"]
    assert run["test_id"] == "T-042" and run["operator"] == "M. Ionescu" and run["sensor_serial"] == "LW001"
    assert run["conditioner_gain"] == 1.0 and run["motor_setting"] == "variator 3.5"
    assert "aE_t" in run["headroom_summary"] and "% of +-10 V" in run["headroom_summary"]
    html = (tmp_path / "r.html").read_text()
    assert "T-042" in html and "stated by the operator (--fu)" in html


@pytest.mark.hostile("silent_wrong")
def test_a_value_not_in_the_file_is_said_to_be_a_default():
    import xarray as xr

    from labtool.reports.pipeline import operating_point

    op = operating_point(xr.Dataset(attrs={"cam_speed_rpm": 180.0, "Fu_N": 5.0}), 180.0, {})
    assert op["Fu_N"] == 5.0 and op["Fu_N_source"] == "file attribute Fu_N"
    assert op["backlash_mm"] == 0.128 and op["backlash_mm_source"].startswith("default (")
    assert op["assumed"] == ["law", "backlash", "jt_factor"]
    given = operating_point(xr.Dataset(attrs={"cam_speed_rpm": 180.0}), 180.0, {"Fu": 2.0})
    assert given["Fu_N_source"] == "option --fu"
