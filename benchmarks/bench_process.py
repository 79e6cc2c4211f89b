"""Benchmark of ``labtool process`` against a plain chunked numpy/scipy chain doing the same work.

Writes a 3-channel 10 kHz float32 recording of ``--minutes`` (default 60) into /tmp (10 s of the
simulated stand, acquisition/sim_stand.py, 30 cam revolutions at 180 rpm, tiled: the phase stays
continuous). Then, interleaved ``--repeats`` times, each in a fresh single-threaded child process
(OMP/MKL/OpenBLAS/numba threads = 1):

- **labtool**: ``python -m labtool process rec.h5 -o out.nc`` (the CLI: start-up and imports included);
- **plain**: the chain a skilled user writes with numpy/scipy (``plain_chain`` below), at its best
  chunk size (2^19 samples: 2^17 costs it 1.5x, 2^18 1.3x, 2^20 1.3x on this machine): the same two
  passes and chunk overlap, Ka, scipy.signal.sosfiltfilt, cam angle from the tacho, gravity and
  dwell reference, epsilon2, omega2 by a cumulative trapezoid with the same drift ramp, the normal
  check, spikes (median/MAD + find_peaks), clipping runs, Welch spectra, cycle averages, and the
  same seven per-sample outputs plus time written with h5py in the same HDF5 layout (2^17-sample chunks).

- **main** (with ``--main <checkout>``): main's ``labtool process`` from that checkout, and its
  output is compared with labtool's (tests/measured_compare.py: every variable within 1e-6 of its
  peak, NaN and integers identical, the same attributes and history).

Each peer first runs once on a 1-minute file (numba's on-disk cache of each checkout). Prints wall
(the parent's clock) and CPU time (user + system of the child) per run, the medians, the
throughput ratios labtool / plain and labtool / main in CPU and wall time, and each peer's peak
resident memory (ru_maxrss). No asserts: a benchmark reports. Under load (``uptime``), wall times
mostly measure the scheduler; CPU times are the comparable figure then.

    git archive main | tar -x -C /tmp/main-check       # main before the change, to compare with
    .venv/bin/python benchmarks/bench_process.py [--minutes 60] [--repeats 2] [--main /tmp/main-check]

Writes its figures to benchmarks/results/process_<minutes>min.json.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS_DIR = ROOT / "benchmarks" / "results"
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))


def make_file(path: Path, minutes: float) -> int:
    import h5py
    import numpy as np

    from stand_data import stand_volts

    block, _, _, fs = stand_volts(10.0, 180.0, seed=1)  # 100000 x 3, exactly 30 revolutions
    block = block.astype(np.float32)
    n_blocks = int(round(minutes * 60 / 10.0))
    n = n_blocks * len(block)
    with h5py.File(path, "w") as f:
        f.attrs.update({"format": "labtool.recording", "format_version": 1, "sample_rate_hz": fs,
                        "start_time_utc": "2026-11-22T00:00:00Z", "complete": True, "cam_speed_rpm": 180.0})
        d = f.create_dataset("signals", shape=(n, 3), dtype="f4", chunks=(65536, 3), maxshape=(None, 3))
        d.attrs["channel_names"] = np.array(["aE_t", "aE_n", "tacho"], dtype=h5py.string_dtype())
        d.attrs["ka_m_s2_per_v"] = np.full(3, 86.43)
        for k in range(n_blocks):
            d[k * len(block):(k + 1) * len(block)] = block
        ev = np.dtype([("index", "<i8"), ("kind", h5py.string_dtype()), ("detail", h5py.string_dtype())])
        f.create_dataset("events", data=np.array([(0, "start", ""), (n, "stop", "")], dtype=ev))
    return n


# labtool as a user runs it: the CLI in a fresh interpreter (start-up and imports included)
LABTOOL = ["-m", "labtool", "process", "{src}", "-o", "{out}", "--force"]

PLAIN = r"""
import sys
sys.path.insert(0, {bench!r})
from bench_process import plain_chain
s = plain_chain(sys.argv[1], sys.argv[2])
print("INFO", s["cam_speed_rpm"], s["revolutions_averaged"], s["normal_check_rel_rms"])
"""


def plain_chain(src: str, out: str, chunk: int = 1 << 19) -> dict:
    """The plain chunked numpy/scipy chain (the peer); same inputs, same work, same outputs."""
    import math

    import h5py
    import numpy as np
    from scipy import signal

    from labtool.models.mechanism import Mechanism, sensor_point
    from labtool.models.mechanism.motion_laws import CamProgram

    f = h5py.File(src, "r")
    sig = f["signals"]
    fs = float(f.attrs["sample_rate_hz"])
    ka = np.asarray(sig.attrs["ka_m_s2_per_v"])[:2]
    ka = np.where(np.isfinite(ka), ka, 86.43)
    n = sig.shape[0]
    mech = Mechanism.default()
    prog = CamProgram.for_mechanism(mech)
    # pass 1: tacho edges (sub-sample, at mid level) and channel extremes
    marks, vmin, vmax = [], np.full(3, np.inf), np.full(3, -np.inf)
    prev = None
    for a in range(0, n, chunk):
        x = sig[a:a + chunk].astype(np.float64)
        vmin, vmax = np.minimum(vmin, x.min(axis=0)), np.maximum(vmax, x.max(axis=0))
        t = x[:, 2] if prev is None else np.concatenate([[prev], x[:, 2]])
        i = np.flatnonzero((t[1:] >= 2.5) & (t[:-1] < 2.5))
        marks.extend((a - (prev is not None) + i + (2.5 - t[i]) / (t[i + 1] - t[i])).tolist())
        prev = x[-1, 2]
    marks = np.asarray(marks)
    period = float(np.median(np.diff(marks)))
    rpm = 60 * fs / float(np.mean(np.diff(marks)))
    sos = signal.butter(4, min(100 * rpm / 60, 0.4 * fs), fs=fs, output="sos")
    margin = int(1.3 * 1.25 * period) + 400
    N = 1 << 16
    grid = 2 * np.pi * np.arange(N) / N
    psi = prog(grid)[0]
    phi2 = mech.phiD + mech.psi0 + psi
    grav = np.column_stack(sensor_point.gravity_reading(phi2, mech.g))
    moving_tab = prog.direction(grid) != 0
    dm = max(1, int(round(10 / 360 * period)))
    g = h5py.File(out, "w")
    outs = {k: g.create_dataset(k, (n,), dt, chunks=(1 << 17,)) for k, dt in
            [("time", "f8"), ("aE_t", "f4"), ("aE_n", "f4"), ("epsilon2", "f4"), ("omega2", "f4"), ("phi1", "f4"),
             ("revolution", "i4"), ("clipped", "i1")]}
    nper = 32768
    psd_sum, nseg = 0.0, 0
    cyc_sum, cyc_n = np.zeros((5, 720)), 0
    chk_sq, chk_n, chk_pk = 0.0, 0, 0.0
    n_spikes = 0
    for a in range(0, n, chunk):
        b = min(a + chunk, n)
        wa, wb = max(0, a - margin), min(n, b + margin)
        v = sig[wa:wb, :2].astype(np.float64)
        c0, c1 = a - wa, b - wa
        at = (v == vmin[:2]) | (v == vmax[:2])
        clipped = np.zeros(len(v), bool)
        for j in range(2):
            d = np.diff(np.concatenate([[0], at[:, j].astype(np.int8), [0]]))
            s0, s1 = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
            for p, q in zip(s0[s1 - s0 >= 3], s1[s1 - s0 >= 3]):
                clipped[p:q] = True
        phys = v * ka
        lp = signal.sosfiltfilt(sos, phys, axis=0, padlen=27)
        idx = np.arange(wa, wb, dtype=float)
        k = np.clip(np.searchsorted(marks, idx, side="right") - 1, 0, len(marks) - 2)
        phi1 = np.mod(2 * np.pi * (idx - marks[k]) / (marks[k + 1] - marks[k]), 2 * np.pi)
        ti = (phi1 * (N / (2 * np.pi)) + 0.5).astype(np.int64) & (N - 1)
        acc = lp - grav[ti]
        moving = moving_tab[ti]
        # dwell reference: mean of the middle 60 % of each dwell, interpolated between dwells
        d = np.diff(np.concatenate([[0], (~moving).astype(np.int8), [0]]))
        s0, s1 = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
        full = (s0 > 0) & (s1 < len(v)) & (s1 - s0 >= 8)
        s0, s1 = s0[full], s1[full]
        cut = ((s1 - s0) * 0.2).astype(int)
        cs = np.vstack([np.zeros((1, 2)), np.cumsum(acc, axis=0)])
        lev = (cs[s1 - cut] - cs[s0 + cut]) / (s1 - s0 - 2 * cut)[:, None]
        cen = 0.5 * (s0 + s1 - 1)
        pos = np.arange(len(v))
        acc -= np.column_stack([np.interp(pos, cen, lev[:, 0]), np.interp(pos, cen, lev[:, 1])])
        acc[clipped] = np.nan
        eps = acc[:, 0] / mech.DE
        # omega2: trapezoid over each motion run widened by dm, linear ramp to 0 at its end
        d = np.diff(np.concatenate([[0], moving.astype(np.int8), [0]]))
        r0, r1 = np.flatnonzero(d == 1) - dm, np.flatnonzero(d == -1) + dm
        ok = (r0 > 0) & (r1 < len(v))
        c = np.concatenate([[0], np.cumsum(0.5 * (np.nan_to_num(eps)[1:] + np.nan_to_num(eps)[:-1]) / fs)])
        om = np.zeros(len(v))
        for p, q, good in zip(r0, r1, ok):
            p, q = max(p, 0), min(q, len(v))
            w = c[p:q] - c[p]
            om[p:q] = w - np.linspace(0, 1, q - p) * w[-1] if good else np.nan
        om[clipped] = np.nan
        absn = np.sqrt(np.maximum(np.nan_to_num(acc[:, 1]), 0) / mech.DE)
        mv = moving[c0:c1] & np.isfinite(om[c0:c1])
        dd = np.abs(om[c0:c1][mv]) - absn[c0:c1][mv]
        chk_sq, chk_n = chk_sq + float(dd @ dd), chk_n + int(mv.sum())
        chk_pk = max(chk_pk, float(np.abs(om[c0:c1][mv]).max()) if mv.any() else 0.0)
        for j in range(2):  # spikes: robust scale of the residual, peaks above k sigma
            r = phys[:, j] - lp[:, j]
            med = np.median(r[::8])
            thr = max(8 * 1.4826 * np.median(np.abs(r[::8] - med)), 0.05 * np.abs(lp[:, j]).max())
            if (np.abs(r - med) > thr).any():
                pk, _ = signal.find_peaks(np.abs(r - med), height=thr, distance=20)
                n_spikes += int(((pk >= c0) & (pk < c1)).sum())
        if c1 - c0 >= nper:
            fr, p = signal.welch(phys[c0:c1], fs, nperseg=nper, axis=0)
            psd_sum, nseg = psd_sum + p, nseg + 1
        rev = np.searchsorted(marks, idx, side="right") - 1
        gi = np.minimum((phi1 * (720 / (2 * np.pi))).astype(np.int64), 719)
        core = slice(c0, c1)
        full_rev = (rev[core] >= 0) & (rev[core] < len(marks) - 1) & np.isfinite(om[core])
        for q, y in enumerate((acc[core, 0], acc[core, 1], eps[core], om[core], absn[core])):
            cyc_sum[q] += np.bincount(gi[core][full_rev], weights=y[full_rev], minlength=720)
        cyc_n += int(full_rev.sum())
        outs["time"][a:b] = idx[core] / fs
        for name, y in (("aE_t", acc[core, 0]), ("aE_n", acc[core, 1]), ("epsilon2", eps[core]),
                        ("omega2", om[core]), ("phi1", phi1[core])):
            outs[name][a:b] = y.astype(np.float32)
        outs["revolution"][a:b] = rev[core].astype(np.int32)
        outs["clipped"][a:b] = clipped[core].astype(np.int8)
    g.create_dataset("psd", data=psd_sum / max(nseg, 1))
    g.create_dataset("cycle_sum", data=cyc_sum)
    g.close()
    f.close()
    return {"cam_speed_rpm": rpm, "revolutions_averaged": len(marks) - 1,
            "normal_check_rel_rms": math.sqrt(chk_sq / chk_n) / chk_pk, "spikes": n_spikes}


def _env(root: Path) -> dict:
    return dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1",
                NUMBA_NUM_THREADS="1", MPLBACKEND="Agg", PYTHONPATH=str(root))


def _argv(peer, src: Path, out: Path) -> list[str]:
    if isinstance(peer, list):
        return [sys.executable, *(a.format(src=src, out=out) for a in peer)]
    return [sys.executable, "-c", peer, str(src), str(out)]


def _child(peer, src: Path, out: Path, root: Path = ROOT) -> dict:
    """Run one peer in a fresh process: wall time (parent's clock), CPU time (user + system of the child)."""
    before, w0 = os.times(), time.perf_counter()
    # cwd = the checkout: ``python -m`` puts the working directory first on sys.path
    proc = subprocess.run(_argv(peer, src, out), env=_env(root), cwd=root, capture_output=True, text=True)
    wall, after = time.perf_counter() - w0, os.times()
    if proc.returncode != 0:
        print(proc.stdout, proc.stderr)
        raise SystemExit(1)
    cpu = (after.children_user - before.children_user) + (after.children_system - before.children_system)
    return {"wall": wall, "cpu": cpu}


def _peak_rss_mb(peer, src: Path, out: Path, root: Path = ROOT) -> float:
    """Peak resident memory (MB) of one more run of the peer: the ru_maxrss of that process, read by
    a small parent that waits for it (RUSAGE_CHILDREN holds the largest child's)."""
    code = ("import resource, subprocess, sys\n"
            "r = subprocess.run(sys.argv[1:])\n"
            "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\n")
    r = subprocess.run([sys.executable, "-c", code, *_argv(peer, src, out)], env=_env(root), cwd=root,
                       capture_output=True, text=True)
    out.unlink(missing_ok=True)
    return int(r.stdout.split()[-1]) / 1024.0


def _check_checkout(name: str, root: Path) -> None:
    """The peer imports the code of its own checkout (not an installed or editable copy)."""
    r = subprocess.run([sys.executable, "-c", "import labtool.processing.pipeline as p, labtool; print(p.__file__)"],
                       env=_env(root), cwd=root, capture_output=True, text=True)
    path = Path(r.stdout.strip()).resolve()
    if root.resolve() not in path.parents:
        raise SystemExit(f"{name}: imports {path}, not the checkout {root}")
    print(f"  {name}: {path.relative_to(root.resolve().parent)}")


def _compare(reference: Path, candidate: Path) -> None:
    sys.path.insert(0, str(ROOT / "tests"))
    from measured_compare import compare_measured

    problems, rel = compare_measured(reference, candidate)
    worst = max(rel, key=rel.get)
    print(f"output vs main's on this recording: {'EQUAL' if not problems else 'DIFFERENT'} "
          f"(tests/measured_compare.py: within 1e-6 of each variable's peak, NaN and integers identical); "
          f"{len(rel)} float variables, largest relative difference {rel[worst]:.2g} ({worst})")
    for p in problems[:20]:
        print("   ", p)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--keep", action="store_true")
    ap.add_argument("--main", type=Path, default=None,
                    help="a checkout of main (git archive main | tar -x -C /tmp/main-check): its labtool runs "
                         "too, and labtool's output is compared with its output")
    args = ap.parse_args()
    tmpdir = Path(tempfile.mkdtemp(prefix="bench_process_", dir="/tmp"))
    src, out, warm = tmpdir / "rec.h5", tmpdir / "out.nc", tmpdir / "warm.h5"
    plain = PLAIN.format(bench=str(ROOT / "benchmarks"))
    peers = [("labtool", LABTOOL, ROOT), ("plain", plain, ROOT)]
    if args.main is not None:
        peers.append(("main", LABTOOL, args.main.resolve()))
    kept = {name: tmpdir / f"out_{name}.nc" for name in ("labtool", "main")}
    try:
        t0 = time.perf_counter()
        n = make_file(src, args.minutes)
        make_file(warm, 1.0)
        print(f"recording: {n} samples x 3 channels ({args.minutes:g} min at 10 kHz), "
              f"{src.stat().st_size / 1e6:.0f} MB float32, written in {time.perf_counter() - t0:.1f} s; "
              f"load average {os.getloadavg()[0]:.1f}")
        for name, peer, root in peers:  # warm-up on 1 minute: numba's on-disk cache of each checkout
            _check_checkout(name, root)
            _child(peer, warm, out, root)
        runs = {name: [] for name, _, _ in peers}
        for k in range(args.repeats):  # interleaved
            for name, peer, root in peers:
                target = kept[name] if k == 0 and name in kept and args.main is not None else out
                r = _child(peer, src, target, root)
                runs[name].append(r)
                out.unlink(missing_ok=True)
                print(f"  run {k + 1} {name:8s} wall {r['wall']:6.1f} s  cpu {r['cpu']:6.1f} s  "
                      f"({3 * n / r['wall'] / 1e6:5.1f} M samples/s wall, {3 * n / r['cpu'] / 1e6:5.1f} per CPU s)")
        wall = {name: statistics.median(r["wall"] for r in rs) for name, rs in runs.items()}
        cpu = {name: statistics.median(r["cpu"] for r in rs) for name, rs in runs.items()}
        print(f"median: labtool wall {wall['labtool']:.1f} s cpu {cpu['labtool']:.1f} s; plain wall "
              f"{wall['plain']:.1f} s cpu {cpu['plain']:.1f} s")
        print(f"labtool / plain throughput: CPU {cpu['plain'] / cpu['labtool']:.2f}x, "
              f"wall {wall['plain'] / wall['labtool']:.2f}x   (goal >= 2x)")
        if "main" in wall:
            print(f"labtool / main (before) throughput: CPU {cpu['main'] / cpu['labtool']:.2f}x, "
                  f"wall {wall['main'] / wall['labtool']:.2f}x; main / plain CPU {cpu['plain'] / cpu['main']:.2f}x")
        rss = {}
        for name, peer, root in peers:
            rss[name] = _peak_rss_mb(peer, src, out, root)
            print(f"peak RSS {name}: {rss[name]:.0f} MB")
        RESULTS_DIR.mkdir(exist_ok=True)
        (RESULTS_DIR / f"process_{args.minutes:g}min.json").write_text(json.dumps({
            "minutes": args.minutes, "samples": n, "repeats": args.repeats, "runs": runs,
            "median_wall_s": wall, "median_cpu_s": cpu, "peak_rss_mb": rss,
            "labtool_over_plain_throughput": {"cpu": cpu["plain"] / cpu["labtool"], "wall": wall["plain"] / wall["labtool"]},
            "loadavg_end": os.getloadavg()}, indent=1) + "\n")
        print("goal: >= 2x the plain chain, peak RSS <= 300 MB; "
              f"load average now {os.getloadavg()[0]:.1f}")
        if args.main is not None:
            _compare(kept["main"], kept["labtool"])
    finally:
        if not args.keep:
            for p in (src, out, warm, *kept.values()):
                p.unlink(missing_ok=True)
            tmpdir.rmdir() if not any(tmpdir.iterdir()) else None


if __name__ == "__main__":
    main()
