"""How fast can labtool's elastic whole call be against the best compiled peer? A bound, measured.

a goal asked the elastic whole call (scene -> Dataset) to be >= 3x the best compiled peer
(numbalsoda DOP853 or LSODA, ``benchmarks/peers/``) at equal achieved accuracy. The peer's whole
call is its loop plus the problem's tables and omega2, MR13D, x_el at the uniform output instants
(``peers.elastic_problem.outputs``); labtool's is its loop plus a 24-variable Dataset on the
uniform instants *and* the solver's step instants, the landings' impulses, Table 3's indicators and
the energy-balance check. This script times, in one interleaved run, warm (``--calls``; the first
call of a round is not timed):

* ``full``: ``simulate(scene, "elastic")``, what a user gets;
* ``indicators``: the Dataset-free indicator path;
* ``peer-outputs``: a prototype (this file only, not a labtool API) that makes exactly the peer's
  outputs from labtool's loop: the tables and the loop, the event record, x and x' at the uniform
  output instants, omega2 = omega2_kin + x'/arm (eq. 19) and MR13D = F arm there, one small Dataset.
  Its omega2 is checked against ``full``'s at the same instants;
* ``loop``: the tables and the loop alone (``elastic._solve``); it or ``indicators`` (the same
  tables and loop in one compiled pass, with the extremes) is the floor of any call;
* the peers' tolerance ladders, read at labtool's achieved errors (``work_precision.cost_at_error``).

It prints each labtool variant's ratio and the budget the 3x goal leaves for everything beyond
that floor: peer / 3 - floor. Run: ``.venv/bin/python benchmarks/whole_call_bound.py [--runs 1,16]
[--repeats 5] [--calls 4]``; writes ``benchmarks/results/whole_call_bound.json``.
"""
from __future__ import annotations

import argparse
import json
import pathlib
import statistics
import sys
import time
import warnings

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from benchmarks.work_precision import RESULTS, cost_at_error, pin_one_core, scenes  # noqa: E402

PEERS = {"numbalsoda-DOP853": [1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12],
         "numbalsoda-LSODA": [1e-7, 1e-8, 1e-9, 1e-10, 1e-11]}


def peer_outputs_call(scene):
    """The peer's outputs from labtool's loop (module doc): a Dataset of omega2, MR13D, x_el on the
    uniform output instants and the event record."""
    from labtool.common.datasets import dataset
    from labtool.models.dynamics import elastic as E
    from labtool.models.dynamics import events
    from labtool.models.dynamics.kernels import dopri5 as dp
    from labtool.models.dynamics.kernels import elastic_nb as eq
    run = E._solve(scene, "consistent", None, None, {}, raw=True)
    E.complete_events(run.rows, E.phase_table(run.segments, run.raw), run.model, run.tab)
    record = events.from_rows(run.rows)
    t, y, seg, grid_index = dp.merge_run(E.output_grid(run.tab), run.raw, 2)
    on_grid = grid_index >= 0
    t, x, v = t[on_grid], y[0][on_grid], y[1][on_grid]
    phase = run.raw[11][:run.raw[4], 0].astype(np.int64)[seg[on_grid]]
    block = E._grid_block(scene, run.tab.omega1, float(run.tab.t[-1]))      # the cached kinematics
    arm = block[len(E._TERMS)]                                   # _FACTOR_ROWS[0]
    omega2 = block[E._TERMS.index("dpsi")] * run.tab.omega1 + v / arm
    F = np.empty(t.size)
    eq.forces(run.model, phase, x, v, F)
    return dataset({"omega2": ("time", omega2, {"units": "rad/s"}), "MR13D": ("time", F * arm, {"units": "N m"}),
                    "x_el": ("time", x, {"units": "m"}), **record}, {"time": ("time", t, {"units": "s"})}, {})


def measure(run_ids, repeats, calls, log):
    from benchmarks.peers_bench import peer_call
    from labtool.models.dynamics import accuracy
    from labtool.models.dynamics import elastic as E
    from labtool.models.dynamics.simulate import indicators
    out = {}
    for run, scene in scenes(run_ids):
        ref = accuracy.reference_run(scene, "elastic")
        full = accuracy.run_model(scene, "elastic")
        lab_err = accuracy.compare(full, ref)
        lean = peer_outputs_call(scene)
        at = np.isin(full.dataset["time"].values, lean["time"].values)
        check = float(np.max(np.abs(full.dataset["omega2"].values[at] - lean["omega2"].values))
                      / np.max(np.abs(lean["omega2"].values)))
        variants = {
            "full": lambda: accuracy.run_model(scene, "elastic").dataset,      # the Dataset built too
            "indicators": lambda: indicators(scene, "elastic"),
            "peer-outputs": lambda: peer_outputs_call(scene),
            "loop": lambda: E._solve(scene, "consistent", None, None, {}, raw=True),
        }
        configs = [(k, None) for k in variants] + [(p, r) for p, ladder in PEERS.items() for r in ladder]
        errors = {}
        for solver, rtol in configs:
            if rtol is not None:
                res, _, _ = peer_call(scene, "elastic", solver, rtol, ref)
                errors[(solver, rtol)] = accuracy.compare(res, ref)
            else:
                variants[solver]()
        times = {c: [] for c in configs}
        for _ in range(repeats):
            for c in configs:
                for k in range(calls):
                    t0 = time.perf_counter()
                    if c[1] is None:
                        variants[c[0]]()
                        wall = time.perf_counter() - t0
                    else:
                        wall = peer_call(scene, "elastic", c[0], c[1], ref)[2]
                    if calls == 1 or k > 0:
                        times[c].append(wall)
        med = {c: statistics.median(v) for c, v in times.items()}
        best = {}
        for peer, ladder in PEERS.items():
            pts = [(errors[(peer, r)], med[(peer, r)]) for r in ladder if errors[(peer, r)]["d_events"] == 0]
            need = [cost_at_error([(e[key], w) for e, w in pts], max(lab_err[key], least))
                    for key, least in (("err_omega2", 1e-12), ("err_event_time", 1e-15))]
            if all(n is not None for n in need):
                best[peer] = max(need)
        peer = min(best, key=best.get)
        floor = min(med[("loop", None)], med[("indicators", None)])   # the cheapest call that runs the loop
        entry = {"labtool_errors": {k: lab_err[k] for k in ("err_omega2", "err_event_time")},
                 "peer_outputs_omega2_vs_full": check, "best_compiled_peer": peer,
                 "peer_whole_call_s": best[peer], "peers_at_labtool_errors_s": best,
                 "labtool_s": {k: med[(k, None)] for k in variants},
                 "ratio": {k: best[peer] / med[(k, None)] for k in variants},
                 "beyond_floor_budget_for_3x_s": best[peer] / 3.0 - floor,
                 "beyond_floor_s": {k: med[(k, None)] - floor for k in ("full", "peer-outputs")}}
        out[f"run_{run}"] = entry
        log(f"run {run}: peer {peer} {best[peer] * 1e3:.3f} ms at labtool's errors "
            f"(omega2 {lab_err['err_omega2']:.2g}, event times {lab_err['err_event_time']:.2g} s)")
        for k in variants:
            log(f"  {k:13s} {med[(k, None)] * 1e3:7.3f} ms  peer / labtool {entry['ratio'][k]:5.2f}"
                + (f"  (beyond the floor {entry['beyond_floor_s'][k] * 1e3:.3f} ms)" if k in entry["beyond_floor_s"] else ""))
        log(f"  3x leaves {entry['beyond_floor_budget_for_3x_s'] * 1e3:.3f} ms beyond the floor; "
            f"peer-outputs omega2 against full's: {check:.1e} relative")
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", default="1,16")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--calls", type=int, default=4, help="calls in a row per round; calls 2..N are timed (warm)")
    ap.add_argument("--out", default=str(RESULTS))
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)
    from benchmarks.peers.elastic_solvers import HAVE_NUMBALSODA
    if not HAVE_NUMBALSODA:
        print("numbalsoda is not installed (pip install -e '.[bench]'; needs gfortran and cmake): no peer to "
              "measure against")
        return None
    cpu = pin_one_core()
    out = measure({int(x) for x in args.runs.split(",")}, args.repeats, max(1, args.calls), lambda s: print(s, flush=True))
    out["machine"] = {"cpu_pinned": cpu, "repeats": args.repeats, "calls": args.calls}
    path = pathlib.Path(args.out)
    path.mkdir(parents=True, exist_ok=True)
    (path / "whole_call_bound.json").write_text(json.dumps(out, indent=1, default=float))
    return out


if __name__ == "__main__":
    main()
