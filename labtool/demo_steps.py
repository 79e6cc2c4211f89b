"""The steps of ``labtool demo``, each writing into one output folder."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from labtool.output import write_netcdf


def run_demo(out: Path) -> None:
    console = Console()
    kin_path = step_kinematics(out, console)
    table_path = step_table1_kinematic(out, console)
    console.print(f"[bold]demo done[/bold]: kinematics {kin_path}, Table 1 comparison {table_path}")


def step_kinematics(out: Path, console: Console) -> Path:
    import matplotlib.pyplot as plt

    from models.kinematics import analyze, rise_summary

    ds = analyze(rpm=180.0)
    s = rise_summary(ds)
    path = out / "kinematics_180rpm.nc"
    write_netcdf(ds, path)
    phi = np.degrees(ds["phi1"].values)
    fig, axes = plt.subplots(4, 1, figsize=(8, 9), sharex=True)
    for ax, name, scale, unit in [(axes[0], "psi", 180 / math.pi, "deg"), (axes[1], "omega2", 1, "rad/s"),
                                  (axes[2], "epsilon2", 1, "rad/s²"), (axes[3], "MR13D", 1, "N·m")]:
        ax.plot(phi, ds[name].values * scale)
        ax.set_ylabel(f"{name} [{unit}]")
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("cam angle φ1 [deg]")
    fig.suptitle("Kinematics of the STB-216 yarn-catcher cam, sine law, 180 rpm")
    fig.tight_layout()
    fig.savefig(out / "kinematics_180rpm.png", dpi=110)
    plt.close(fig)
    console.print(f"kinematics at 180 rpm: MR13D {s['MR13D_min_Nm']:.3f} .. {s['MR13D_max_Nm']:.3f} N m, "
                  f"omega2 max {s['omega2_max_rad_s']:.3f} rad/s, pressure angle max {s['pressure_angle_max_deg']:.1f} deg")
    return path


def step_table1_kinematic(out: Path, console: Console) -> Path:
    from models.paper import kinematic_vs_table3

    df = kinematic_vs_table3()
    path = out / "table1_kinematic_vs_table3.csv"
    df.to_csv(path, index=False)
    t = Table(title="Kinematic MR13D over the rise vs the paper's Table 3 (cam at the drive's no-load speed)")
    for col in ["run", "MR13D_max_Nm", "paper_max", "max_diff_pct", "MR13D_min_Nm", "paper_min", "min_diff_pct", "sign_change_matches"]:
        t.add_column(col, justify="right")
    for _, r in df.iterrows():
        t.add_row(str(int(r.run)), f"{r.MR13D_max_Nm:.3f}", f"{r.paper_max:.3f}", f"{r.max_diff_pct:+.1f}",
                  f"{r.MR13D_min_Nm:.3f}", f"{r.paper_min:.3f}", f"{r.min_diff_pct:+.1f}", str(bool(r.sign_change_matches)))
    console.print(t)
    return path
