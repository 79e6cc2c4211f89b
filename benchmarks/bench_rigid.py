"""Cost and error of the rigid model's accuracy presets on the 16 runs of Table 1 (sine, omega1 var).

Error: each indicator of each run against the 'reference' preset (relative, max over the runs; jump
and impact counts: number of runs whose count differs). Cost: wall time of the 16 runs.
Run: .venv/bin/python benchmarks/bench_rigid.py   (about 1-2 minutes; not part of the tests)
"""
from __future__ import annotations

import time

import numpy as np

from labtool.models.study.paper import TABLE2_KEYS, rigid_vs_table2


def main() -> None:
    results, cost = {}, {}
    for preset in ("reference", "standard", "fast"):
        t0 = time.perf_counter()
        results[preset] = rigid_vs_table2(preset)
        cost[preset] = time.perf_counter() - t0
    ref = results["reference"]
    print(f"{'preset':<10} {'16 runs [s]':>11}  " + "  ".join(f"{k:>18}" for k in TABLE2_KEYS))
    for preset in ("fast", "standard", "reference"):
        df = results[preset]
        cells = []
        for key in TABLE2_KEYS:
            if key == "jumps":
                cells.append(f"{int((df[key] != ref[key]).sum()):>12d} differ")
            else:
                r = ref[key].to_numpy(float)
                o = df[key].to_numpy(float)
                rel = np.abs(o - r) / np.where(r == 0, 1.0, np.abs(r))
                cells.append(f"{rel.max():>18.2e}")
        print(f"{preset:<10} {cost[preset]:>11.1f}  " + "  ".join(cells))


if __name__ == "__main__":
    main()
