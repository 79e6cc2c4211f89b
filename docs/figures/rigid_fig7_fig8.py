"""Figures 7-8 of the paper with the rigid model (run 10 and run 13). Run from the repo root:
.venv/bin/python docs/figures/rigid_fig7_fig8.py  ->  docs/figures/rigid_fig7_fig8.png"""
import matplotlib; matplotlib.use("Agg")
import matplotlib.pyplot as plt, numpy as np
from labtool.models.study.paper import paper_scene
from labtool.models.dynamics.rigid import simulate
from labtool.common.units import RPM
r10 = simulate(paper_scene(cam_speed=180 * RPM, Fu=65, backlash=0.016e-3, jt_factor=4)).dataset
r13 = simulate(paper_scene(cam_speed=180 * RPM, Fu=65, backlash=0.128e-3, jt_factor=1)).dataset
fig, ax = plt.subplots(3, 2, figsize=(11, 9))
t = r10.time.values * 1e3
ax[0,0].plot(t, r10.MR13D, label="with backlash (rcj)"); ax[0,0].plot(t[:-1], r10.MR13D_rfj[:-1], "--", label="j = 0 (rfj)")
ax[0,0].set(title="Fig. 7a: MR13D, run 10", xlabel="t [ms]", ylabel="N m"); ax[0,0].legend()
ax[0,1].plot(r13.time.values*1e3, r13.MR13D); ax[0,1].set(title="Fig. 7b: MR13D, run 13 (no jump)", xlabel="t [ms]", ylabel="N m")
ax[1,0].plot(t, np.degrees(r10.dphi2)); ax[1,0].set(title="Fig. 8a: phi2rcj - phi2rfj, run 10", xlabel="t [ms]", ylabel="deg")
ax[1,1].plot(t, r10.domega2); ax[1,1].set(title="Fig. 8b: omega2rcj - omega2rfj", xlabel="t [ms]", ylabel="rad/s")
ax[2,0].plot(t, r10.domega1); ax[2,0].set(title="Fig. 8c: omega1rcj - omega1rfj", xlabel="t [ms]", ylabel="rad/s")
ax[2,1].stem(r10.event_time.values*1e3, np.abs(r10.event_percussion.values)); ax[2,1].set(title="Fig. 8d: percussion at each impact", xlabel="t [ms]", ylabel="N s")
for a in ax.flat: a.grid(alpha=.3)
fig.tight_layout(); fig.savefig("docs/figures/rigid_fig7_fig8.png", dpi=90)
