"""The output of ``labtool process`` equals that of the version before the speed work (main at
93b2959) on a fixed recording with a gap, clip events, a saturated run and impacts, with the
cam angle from the tacho and by correlation (tests/data/process_reference/make_reference.py).

Equal: the same variables, integers and text identical, NaN at the same samples, floats within
1e-6 of each variable's peak (float32 output resolution is 6e-8), the same attributes and history.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from measured_compare import compare_measured
from labtool.processing.pipeline import ProcessOptions, process_recording
from labtool.processing.readers import open_recording

REF = Path(__file__).parent / "data" / "process_reference"


@pytest.mark.parametrize("case, opts", [("tacho", {}), ("correlation", {"tacho_channel": "no-tacho"})])
def test_output_equals_the_previous_version(tmp_path, case, opts):
    out = tmp_path / "measured.nc"
    with open_recording(REF / "recording_300rpm.h5") as rec:
        process_recording(rec, out, ProcessOptions(**opts), warn=lambda m: None)
    problems, rel = compare_measured(REF / f"measured_{case}.h5", out)
    assert not problems, "\n".join(problems)
    assert {"omega2", "epsilon2", "aE_t", "aE_n", "phi1", "omega2_mean", "aE_t_psd"} <= set(rel)


def test_the_comparison_sees_a_changed_sample(tmp_path):
    """The check can fail: one omega2 sample moved by 1e-4 of its peak, one NaN more, an attribute."""
    import h5py
    import shutil

    for change in ("sample", "nan", "attr"):
        p = tmp_path / f"{change}.h5"
        shutil.copy(REF / "measured_tacho.h5", p)
        with h5py.File(p, "r+") as f:
            om = f["omega2"]
            i = 20000
            if change == "sample":
                om[i] = om[i] + 1e-4 * abs(om[:]).max()
            elif change == "nan":
                om[i] = float("nan")
            else:
                f.attrs["cam_speed_rpm"] = f.attrs["cam_speed_rpm"] * (1 + 1e-5)
        problems, _ = compare_measured(REF / "measured_tacho.h5", p)
        assert problems, change
