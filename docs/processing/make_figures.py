"""Figures and accuracy table of docs/processing.md (run: .venv/bin/python docs/processing/make_figures.py)."""
from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")
HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))
sys.path.insert(0, str(HERE.parents[1] / "tests"))

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

from labtool.processing.pipeline import ProcessOptions, process_recording  # noqa: E402
from labtool.processing.readers import open_recording  # noqa: E402
from stand_data import stand_recording  # noqa: E402  (the simulated stand's chain, tests/stand_data.py)
from labtool.common.units import RPM


def run_synth(tmp, opts=None, **kw):
    p = Path(tmp) / "r.h5"
    out = Path(tmp) / "m.nc"
    for f in (p, out):
        f.unlink(missing_ok=True)
    tr = stand_recording(p, **kw)
    with open_recording(p) as rec:
        process_recording(rec, out, opts or ProcessOptions(), warn=lambda m: None)
    return xr.open_dataset(out, engine="h5netcdf", decode_times=False).load(), tr


def errors(ds, tr):
    om, ep = ds["omega2"].values, ds["epsilon2"].values
    rise = (np.mod(tr["phi1"], 2 * np.pi) < tr["program"].rise_angle) & np.isfinite(om)
    e_o = np.sqrt(np.mean((om[rise] - tr["omega2"][rise]) ** 2)) / np.abs(tr["omega2"][rise]).max()
    e_e = np.sqrt(np.mean((ep[rise] - tr["epsilon2"][rise]) ** 2)) / np.abs(tr["epsilon2"][rise]).max()
    return 100 * e_o, 100 * e_e


def sim_stand(tmp, rpm):
    from labtool.acquisition import signal_chain as sc
    from labtool.cli import main

    rec, out = Path(tmp) / "s.h5", Path(tmp) / "s.nc"
    for f in (rec, out):
        f.unlink(missing_ok=True)
    main(["acquire", "--device", "sim", "--rpm", str(rpm), "--duration", "5", "--fast", "--seed", "7", "-o", str(rec)])
    main(["process", str(rec), "-o", str(out)])
    ds = xr.open_dataset(out, engine="h5netcdf", decode_times=False).load()
    scene = sc.StandScene(cam_speed=rpm * RPM)
    t = sc.truth(scene, np.arange(ds.sizes["time"]) / ds.attrs["sample_rate_hz"])
    t["program"] = scene.program
    return ds, t


def main():
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        base = dict(duration_s=5.0, params={"noise_m_s2": 0.5}, scene={"ripple": 0.01})
        hp03 = dict(duration_s=5.0, params={"noise_m_s2": 0.5, "highpass_hz": 1 / (2 * np.pi * 0.3)},
                    scene={"ripple": 0.01})
        for rpm in (180.0, 300.0, 500.0):
            for tacho in (True, False):
                ds, tr = run_synth(tmp, rpm=rpm, tacho=tacho, **base)
                rows.append((f"simulated stand chain, {rpm:g} rpm, phi1 by {'tacho' if tacho else 'correlation'}",
                             *errors(ds, tr), ds.attrs["omega2_normal_check_rel_rms"] * 100))
                if rpm == 180.0 and tacho:
                    keep = (ds, tr)
        ds, tr = run_synth(tmp, rpm=180.0, **hp03)
        rows.append(("simulated stand chain, 180 rpm, AC coupling tau = 0.3 s, not undone", *errors(ds, tr),
                     ds.attrs["omega2_normal_check_rel_rms"] * 100))
        ds, tr = run_synth(tmp, ProcessOptions(ac_tau_s=0.3), rpm=180.0, **hp03)
        rows.append(("simulated stand chain, 180 rpm, AC coupling tau = 0.3 s, undone (--ac-tau 0.3)", *errors(ds, tr),
                     ds.attrs["omega2_normal_check_rel_rms"] * 100))
        try:
            for rpm in (180.0, 500.0):
                sds, st = sim_stand(tmp, rpm)
                rows.append((f"acquisition's simulated stand, {rpm:g} rpm", *errors(sds, st),
                             sds.attrs["omega2_normal_check_rel_rms"] * 100))
        except ImportError:
            pass
        print("| recording | omega2 RMS error over the rise, % of peak | epsilon2 RMS error, % of peak | "
              "\\|omega2\\| vs sqrt(aE_n/DE), % |")
        print("|---|---|---|---|")
        for r in rows:
            print(f"| {r[0]} | {r[1]:.2f} | {r[2]:.2f} | {r[3]:.2f} |")

        ds, tr = keep
        t = ds["time"].values - ds["time"].values[0]
        sel = (t >= 1.0) & (t < 1.7)
        fig, ax = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
        ax[0].plot(t[sel], tr["omega2"][sel], "k", lw=2, label="truth (labtool.models.mechanism.kinematics)")
        ax[0].plot(t[sel], ds["omega2"].values[sel], "C1", lw=1, label="recovered omega2")
        ax[0].plot(t[sel], np.sqrt(np.maximum(ds["aE_n"].values[sel], 0) / ds.attrs["DE_m"]), "C2", lw=0.7,
                   label="sqrt(aE_n/DE) (check)")
        ax[0].set_ylabel("omega2 [rad/s]")
        ax[0].legend(fontsize=8)
        ax[1].plot(t[sel], tr["epsilon2"][sel], "k", lw=2, label="truth")
        ax[1].plot(t[sel], ds["epsilon2"].values[sel], "C1", lw=1, label="recovered epsilon2")
        ax[1].set_ylabel("epsilon2 [rad/s^2]")
        ax[1].legend(fontsize=8)
        ax[2].plot(t[sel], ds["omega2"].values[sel] - tr["omega2"][sel], "C1", lw=1, label="omega2 error [rad/s]")
        ax[2].plot(t[sel], (ds["epsilon2"].values[sel] - tr["epsilon2"][sel]) / 100, "C0", lw=0.7,
                   label="epsilon2 error / 100 [rad/s^2]")
        ax[2].set_xlabel("time [s]")
        ax[2].legend(fontsize=8)
        fig.suptitle("180 rpm, sine law, the simulated stand's chain: noise, gravity, AC coupling (0.1 Hz),\n"
                     "1.2 kHz follower mode, anti-alias filter, 16-bit ADC, 1 % speed ripple")
        fig.tight_layout()
        fig.savefig(HERE / "recovery_180rpm.png", dpi=110)

        fig, ax = plt.subplots(2, 2, figsize=(10, 7))
        f = ds["frequency"].values
        for j, ch in enumerate(("aE_n", "aE_t")):
            ax[0, j].semilogy(f, ds[f"{ch}_amplitude"].values, lw=0.7, label="amplitude spectrum [m/s^2]")
            ax[0, j].semilogy(f, ds[f"{ch}_psd"].values, lw=0.7, label="Welch PSD [(m/s^2)^2/Hz]")
            ax[0, j].axvline(ds.attrs["lowpass_hz"], color="k", ls=":", label="low-pass corner")
            ax[0, j].set_xlim(0, 2500)
            ax[0, j].set_xlabel("frequency [Hz]")
            ax[0, j].set_title(f"({'ab'[j]}) spectrum of {ch}")
            ax[0, j].legend(fontsize=7)
            ax[1, j].plot(t[sel], ds[ch].values[sel], lw=0.8)
            ax[1, j].set_xlabel("time [s]")
            ax[1, j].set_ylabel(f"{ch} [m/s^2]")
            ax[1, j].set_title(f"({'cd'[j]}) filtered and translated {ch}")
        fig.suptitle("After the paper's Figure 11 (simulated stand chain, 180 rpm)")
        fig.tight_layout()
        fig.savefig(HERE / "spectra_180rpm.png", dpi=110)

        fig, ax = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
        g = np.degrees(ds["phi1_grid"].values)
        for k, (v, unit) in enumerate((("omega2", "rad/s"), ("epsilon2", "rad/s^2"))):
            m, s = ds[f"{v}_mean"].values, ds[f"{v}_std"].values
            ax[k].fill_between(g, m - 2 * s, m + 2 * s, color="C1", alpha=0.3, label="mean +- 2 std over revolutions")
            ax[k].plot(g, m, "C1", label="cycle mean")
            ax[k].plot(g, ds[f"{v}_kinematic"].values, "k--", lw=1, label="kinematics at the mean speed")
            ax[k].set_ylabel(f"{v} [{unit}]")
            ax[k].legend(fontsize=8)
        ax[1].set_xlabel("cam angle phi1 [deg]")
        fig.suptitle(f"Cycle average over {ds.attrs['n_revolutions_averaged']} revolutions")
        fig.tight_layout()
        fig.savefig(HERE / "cycles_180rpm.png", dpi=110)


if __name__ == "__main__":
    main()
