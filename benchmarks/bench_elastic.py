"""Elastic model: cost and accuracy of the solver presets on Table 1's 16 runs, and the tables of
docs/models.md (Table 3 comparison, lw fit). Run: .venv/bin/python benchmarks/bench_elastic.py [--tables | --figure]

Not a test: it prints wall times (which depend on the machine) and markdown tables.
"""
from __future__ import annotations

import sys
import time

import numpy as np

from labtool.models.study.paper import compare_table3
from labtool.models.study.paper import read_reference, table1_runs
from labtool.models.study.paper import paper_scene
from labtool.models.dynamics.simulate import simulate
from labtool.common.units import RPM


def _runs(accuracy, backlash=None, **kw):
    out = []
    for r in table1_runs().itertuples():
        j = r.j_mm * 1e-3 if backlash is None else backlash
        s = paper_scene(cam_speed=r.n1_rpm * RPM, Fu=r.Fu_N, backlash=j, jt_factor=r.Jt_factor, accuracy=accuracy, **kw)
        t0 = time.perf_counter()
        res = simulate(s, "elastic")
        out.append((time.perf_counter() - t0, res.indicators, res.dataset.sizes["time"]))
    return out


def presets():
    ref = _runs("reference")
    print("| preset | wall, 16 runs (s) | events equal to reference | max xel error (um) | max contact-moment error (N m) |")
    print("|---|---|---|---|---|")
    for acc in ("fast", "standard", "reference"):
        res = ref if acc == "reference" else _runs(acc)
        same = sum((a[1]["jumps"], a[1]["impacts"], a[1]["separations"]) ==
                   (b[1]["jumps"], b[1]["impacts"], b[1]["separations"]) for a, b in zip(res, ref))
        dx = max(max(abs(a[1]["xel_max_mm"] - b[1]["xel_max_mm"]), abs(a[1]["xel_min_mm"] - b[1]["xel_min_mm"]))
                 for a, b in zip(res, ref)) * 1e3
        dm = max(abs(a[1]["MR13D_contact_min_Nm"] - b[1]["MR13D_contact_min_Nm"]) for a, b in zip(res, ref))
        print(f"| {acc} | {sum(r[0] for r in res):.2f} | {same}/16 | {dx:.4f} | {dm:.3f} |")


def lw_fit():
    """Contact length that best reproduces Table 3's interior-flank deformations (xel min), with
    Table 3's convention (gap closed: the interior minimum is the deformation under the largest push,
    not disturbed by a landing)."""
    t3 = read_reference("table3_elastic")
    print("| lw (mm) | geometric mean of xel_min(ours)/xel_min(paper), 16 runs | worst run ratio | run 9 xel_max ratio |")
    print("|---|---|---|---|")
    best = None
    for lw in (4.0, 5.0, 6.0, 7.0, 8.0, 10.0, 12.0):
        res = _runs("fast", contact_length=lw * 1e-3, elastic_gap="closed")
        ratios = np.array([ind["xel_min_mm"] / ref.xel_min_mm for (_, ind, _), ref in zip(res, t3.itertuples())])
        g = float(np.exp(np.mean(np.log(ratios))))
        worst = ratios[np.argmax(np.abs(np.log(ratios)))]
        r9 = res[8][1]["xel_max_mm"] / t3.xel_max_mm[8]
        print(f"| {lw:g} | {g:.3f} | {worst:.2f} | {r9:.2f} |")
        if best is None or abs(np.log(g)) < abs(np.log(best[1])):
            best = (lw, g)
    print(f"\nbest lw on the grid: {best[0]:g} mm (ratio {best[1]:.3f})")


def tables():
    d = compare_table3()          # Table 3's convention: gap closed
    print("| run | Fu | j | n1 | Jt | MR13D max (paper) | % | MR13D min (paper) | % | contact MR13D max / min | xel max mm (paper) | % | xel min mm (paper) | % | jumps (paper) | impacts (paper) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in d.itertuples():
        print(f"| {r.run} | {r.Fu_N:g} | {r.j_mm:g} | {r.n1_rpm:g} | {r.Jt:g} | {r.MR13D_max:.2f} ({r.paper_MR13D_max:g}) | {r.MR13D_max_pct:+.1f} "
              f"| {r.MR13D_min:.2f} ({r.paper_MR13D_min:g}) | {r.MR13D_min_pct:+.1f} | {r.contact_max:.2f} / {r.contact_min:.2f} "
              f"| {r.xel_max_mm:.4f} ({r.paper_xel_max_mm:g}) | {r.xel_max_pct:+.0f} "
              f"| {r.xel_min_mm:.4f} ({r.paper_xel_min_mm:g}) | {r.xel_min_pct:+.0f} "
              f"| {r.jumps} ({r.paper_jumps}) | {r.impacts} ({r.paper_impacts}) |")
    print()
    d = compare_table3(elastic_gap="physical")
    print("| run | j | xel max mm (paper) | exterior deformation mm | xel min mm (paper) | jumps (paper) | impacts (paper) | separations |")
    print("|---|---|---|---|---|---|---|---|")
    for r in d.itertuples():
        print(f"| {r.run} | {r.j_mm:g} | {r.xel_max_mm:.4f} ({r.paper_xel_max_mm:g}) | {max(r.xel_max_mm - r.j_mm, 0):.4f} "
              f"| {r.xel_min_mm:.4f} ({r.paper_xel_min_mm:g}) | {r.jumps} ({r.paper_jumps}) | {r.impacts} ({r.paper_impacts}) "
              f"| {r.separations} |")


def figure9(path="docs/figures/elastic_fig9_run1.png"):
    """The time series behind the paper's Figure 9 (run 1): MR13D and x_el over the rise, with the
    gap of Table 1 (j = 0.016 mm) and with the gap closed."""
    import os

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 2, figsize=(10, 5.5), sharex=True)
    for col, gap in enumerate(("physical", "closed")):
        j = 0.016e-3 if gap == "physical" else 0.0
        ds = simulate(paper_scene(backlash=0.016e-3, elastic_gap=gap), "elastic").dataset
        t = ds.time.values * 1e3
        ax[0, col].plot(t, ds["MR13D"], lw=0.8, label="contact force moment")
        ax[0, col].plot(t, ds["MR13D_static"], lw=1.2, ls="--", label="static reaction R31 moment")
        ax[1, col].plot(t, ds["x_el"] * 1e3, lw=0.8)
        if j > 0:
            ax[1, col].axhline(j * 1e3, color="grey", lw=0.6, ls=":")
        label = "j = 0.016 mm crossed" if gap == "physical" else "gap closed (Table 3's convention)"
        ax[0, col].set_title(f"run 1 (Fu = 0, n1 = 180 rpm, Jt = 1), {label}", fontsize=9)
        ax[1, col].set_xlabel("time from the start of the rise (ms)")
    ax[0, 0].set_ylabel("MR13D (N m)")
    ax[1, 0].set_ylabel("x_el (mm)")
    ax[0, 0].legend(fontsize=7)
    fig.tight_layout()
    os.makedirs(os.path.dirname(path), exist_ok=True)
    fig.savefig(path, dpi=80)
    print("wrote", path)


if __name__ == "__main__":
    if "--figure" in sys.argv:
        figure9()
        sys.exit(0)
    presets()
    if "--tables" in sys.argv:
        print()
        lw_fit()
        print()
        tables()
