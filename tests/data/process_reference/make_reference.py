"""Make the processing reference: a fixed recording and what ``labtool process`` made of it.

    # the recording (once; it is kept, so later changes of the simulated stand do not move it)
    .venv/bin/python tests/data/process_reference/make_reference.py --recording
    # the references, with the version to freeze first on the path (here: main at 93b2959,
    # before the processing speed work: git archive 93b2959 | tar -x -C /tmp/base)
    PYTHONPATH=/tmp/base .venv/bin/python tests/data/process_reference/make_reference.py
    # the attributes, history steps and fields the frozen version did not record (NEW_ATTRS, ...),
    # written into the references from the current code (their variables and the rest stay)
    .venv/bin/python tests/data/process_reference/make_reference.py --new-metadata

The recording: 3 s of the simulated stand at 300 rpm (kinematic truth, the paper's x10 chain,
tests/stand_data.py, seed 7), with a gap (250 samples lost) and an overrun at sample 12000, a
recorder clip event at 21000, three impact bursts (spikes), and 4 samples of aE_t held at a new
extreme value from 25000 (a saturated ADC of unknown range). The references: its measured.nc
with the tacho, and with the cam angle by correlation (the tacho ignored), stored compressed by
tests/measured_compare.store_reference; their attributes carry the current names (the nominal speed
as cam_speed_rpm, the measured one as cam_speed_rpm_measured). tests/test_proc_reference.py compares
the current output.
"""
from __future__ import annotations

import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
RECORDING = HERE / "recording_300rpm.h5"
CASES = {"tacho": {}, "correlation": {"tacho_channel": "no-tacho"}}


def make_recording() -> None:
    import h5py

    sys.path.insert(0, str(HERE.parents[1]))
    from stand_data import impact_bursts, stand_recording

    events = [(12000, "gap", "missing_samples=250 (0.025 s) lost before this row"), (12000, "overrun", "250 samples lost"),
              (21000, "clip", "aE_t")]
    stand_recording(RECORDING, duration_s=3.0, rpm=300.0, seed=7, events=events,
                    extra_m_s2=impact_bursts([0.4137, 1.5021, 2.6533]))
    with h5py.File(RECORDING, "r+") as f:
        s = f["signals"]
        top = float(s[:, 0].max()) + 0.01
        block = s[25000:25004]
        block[:, 0] = top
        s[25000:25004] = block


def make_references() -> None:
    sys.path.insert(0, str(HERE.parents[1]))
    from measured_compare import store_reference
    from labtool.processing.pipeline import ProcessOptions, process_recording
    from labtool.processing.readers import open_recording

    for name, opts in CASES.items():
        with tempfile.TemporaryDirectory() as tmp, open_recording(RECORDING) as rec:
            out = Path(tmp) / "measured.nc"
            process_recording(rec, out, ProcessOptions(**opts), warn=lambda m: None)
            store_reference(out, HERE / f"measured_{name}.h5")


# what processing records that the frozen version did not: written into the references from the
# current code's output (everything else in them stays the frozen version's)
NEW_ATTRS = ("cam_speed_rpm_min", "cam_speed_rpm_max", "cam_speed_drift", "channel_check", "channel_check_finding",
             "channels_inverted")
NEW_STEPS = ("check_channels",)
NEW_FIELDS = {"cam_angle": ("search_rpm", "search_reason", "search_averaged_samples", "cam_speed_rpm_min",
                            "cam_speed_rpm_max", "cam_speed_trend", "assumption")}


def add_new_metadata() -> None:
    import json

    import h5py

    sys.path.insert(0, str(HERE.parents[1]))
    from labtool.processing.pipeline import ProcessOptions, process_recording
    from labtool.processing.readers import open_recording

    for name, opts in CASES.items():
        with tempfile.TemporaryDirectory() as tmp, open_recording(RECORDING) as rec:
            out = Path(tmp) / "measured.nc"
            process_recording(rec, out, ProcessOptions(**opts), warn=lambda m: None)
            with h5py.File(out, "r") as new, h5py.File(HERE / f"measured_{name}.h5", "r+") as ref:
                for key in NEW_ATTRS:
                    if key in ref.attrs:
                        del ref.attrs[key]
                    if key in new.attrs:
                        ref.attrs[key] = new.attrs[key]
                kept = {s["step"]: s for s in json.loads(ref.attrs["processing_history"])}
                steps = []
                for step in json.loads(new.attrs["processing_history"]):
                    if step["step"] in NEW_STEPS:
                        steps.append(step)
                        continue
                    mine = kept[step["step"]]
                    fresh = NEW_FIELDS.get(step["step"], ())
                    mine["parameters"] = {k: v for k, v in mine["parameters"].items() if k not in fresh}
                    mine["parameters"].update({k: v for k, v in step["parameters"].items() if k in fresh})
                    steps.append(mine)
                ref.attrs["processing_history"] = json.dumps(steps)


if __name__ == "__main__":
    if "--recording" in sys.argv:
        make_recording()
    elif "--new-metadata" in sys.argv:
        add_new_metadata()
    else:
        make_references()
