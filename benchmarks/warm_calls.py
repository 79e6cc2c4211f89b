"""Warm call cost of both models and of Table 1's 16 runs, in process time (robust to a loaded machine).

    .venv/bin/python benchmarks/warm_calls.py NAME
    # against another commit: git archive <commit> | tar -x -C /tmp/base, then
    # PYTHONPATH=/tmp/base .venv/bin/python benchmarks/warm_calls.py base   (alternate the two, 3 times)

Prints the best of 30 warm calls of each model at the standard preset (the default scene) and the
best of 3 passes over Table 1's 16 runs with both models; only ratios between runs made side by
side mean anything.
"""
import pathlib
import sys
import time

if "PYTHONPATH" not in __import__("os").environ:     # else: the tree PYTHONPATH names
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

from labtool.models.dynamics.scene import Scene  # noqa: E402
from labtool.models.dynamics.simulate import simulate  # noqa: E402
from labtool.models.study.paper import table1_runs  # noqa: E402
from labtool.common.units import RPM
from labtool.models.study.paper import paper_scene


def best(fn, repeat):
    out = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        out = min(out, time.process_time() - t0)
    return out


def main(name: str) -> None:
    s = paper_scene()
    warm = {}
    for m in ("rigid", "elastic"):
        simulate(s, m)
        warm[m] = best(lambda: simulate(s, m).dataset, 30) * 1e3     # the Dataset built (at its first read)
    scenes = [paper_scene(cam_speed=r.n1_rpm * RPM, Fu=r.Fu_N, backlash=r.j_mm * 1e-3, jt_factor=r.Jt_factor)
              for r in table1_runs().itertuples()]

    def table1():
        for sc in scenes:
            simulate(sc, "rigid").dataset
            simulate(sc, "elastic").dataset
    table1()
    print(f"{name}: rigid warm {warm['rigid']:.2f} ms, elastic warm {warm['elastic']:.2f} ms, "
          f"Table 1 both models {best(table1, 3):.3f} s (process time)")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "this tree")
