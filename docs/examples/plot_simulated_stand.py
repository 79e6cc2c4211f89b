"""
A measurement against the models, from Python
=============================================

The same chain as the tutorial's commands, through the Python API: record a few revolutions on
the simulated stand, process them into the follower's angular velocity, simulate the rigid model
at the measured operating point, and compare the two on the cam angle. This script runs on every
build of these pages.
"""

# %%
# Record on the simulated stand
# -----------------------------
# There is no ``labtool.acquire`` function: recording is a command (it drives a device, shows a
# live monitor and handles Ctrl-C), so a script runs it as one. Two seconds at 180 rpm is six
# cam revolutions.
import subprocess
import sys
import tempfile
from pathlib import Path

work = Path(tempfile.mkdtemp(prefix="labtool-example-"))
recording = work / "run.h5"
done = subprocess.run([sys.executable, "-m", "labtool", "acquire", "--device", "sim", "--rpm", "180",
                       "--duration", "2", "--fast", "--seed", "1", "-o", str(recording)],
                      check=True, capture_output=True, text=True)
print(done.stdout.strip())

# %%
# Process: volts to the follower's motion
# ---------------------------------------
# ``labtool.process`` returns the processed measurement as an xarray Dataset (and writes it when
# given a file). Every variable carries its unit; the operating point the recording states comes
# with it, each value with its source. Without a calibration file the Ka the recording states is
# used (the simulated chain's true one), and the processing history says where each Ka came from.
import labtool

measured = labtool.process(recording, work / "measured.nc")
print(measured["omega2"].attrs["units"], measured.attrs["cam_speed_rpm"])

# %%
# Simulate the rigid model at the same point
# ------------------------------------------
# The operating point is one type, in SI. ``labtool.DEFAULT`` is the simulated stand's;
# ``labtool.units`` converts from the units people type.
from labtool.units import RPM

point = labtool.DEFAULT.replace(cam_speed=180 * RPM)
sim = labtool.simulate(point, model="rigid", revolutions=3, rise_only=False)
print(sim.model, "model:", sim.reason)
print({k: v for k, v in sim.indicators.items() if k in ("MR13D_max_Nm", "jumps", "impacts")})

# %%
# Both on the cam angle
# ---------------------
# The simulation's ``cycles`` are on the same cam-angle grid as the measurement's cycle
# statistics, so they plot against each other directly.
import matplotlib.pyplot as plt
import numpy as np

phi_deg = np.degrees(sim.cycles["phi1"])
fig, ax = plt.subplots(figsize=(8, 4))
mean = measured["omega2_mean"]
ax.plot(np.degrees(mean["phi1_grid"]), mean, label="measured, mean of the revolutions")
ax.plot(phi_deg, sim.cycles["omega2"].sel(revolution=2), label="rigid model, third revolution")
ax.set_xlabel("cam angle φ1 from the start of the rise [deg]")
ax.set_ylabel("follower ω2 [rad/s]")
ax.set_xlim(0, 120)
ax.legend()
fig.tight_layout()

# %%
# The report: metrics and a verdict
# ---------------------------------
# ``labtool.report`` compares on the cam angle with the rigid and elastic models (here the fast
# preset and the cam at constant speed, to keep the build short) and returns the comparison; the
# verdict names the closest model.
from labtool.reports.pipeline import verdict_lines

rep = labtool.report(work / "measured.nc", models=("rigid", "elastic"), omega1=("const",),
                     accuracy="fast", revolutions=3, robustness=False)
for line in verdict_lines(rep):
    print(line)
