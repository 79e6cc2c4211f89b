"""Benchmark of ``labtool process``: end-to-end throughput and peak memory (prints, no asserts).

Writes a 3-channel 10 kHz float32 recording of ``--minutes`` (default 60) chunk-wise into /tmp
(10 s of the synthetic stand, 30 cam revolutions at 180 rpm, tiled: the phase stays continuous),
processes it in a single-threaded child process (OMP/MKL/OpenBLAS/numba threads = 1), reports samples/s (samples x channels / wall time) and the child's peak resident
memory, and deletes the files.

    .venv/bin/python benchmarks/bench_process.py [--minutes 60] [--keep]
"""
from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _rss_mb(pid: int) -> float:
    try:
        with open(f"/proc/{pid}/status") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return 0.0


def make_file(path: Path, minutes: float) -> int:
    import h5py
    import numpy as np

    from processing.synthetic import SynthSpec, make_signals

    spec = SynthSpec(rpm=180.0, duration_s=10.0, tacho=True)
    block, names, _ = make_signals(spec)  # 100000 x 3, exactly 30 revolutions
    block = block.astype(np.float32)
    n_blocks = int(round(minutes * 60 / 10.0))
    n = n_blocks * len(block)
    with h5py.File(path, "w") as f:
        f.attrs.update({"format": "labtool.recording", "format_version": 1, "sample_rate_hz": 10000.0,
                        "start_time_utc": "2026-11-22T00:00:00Z", "complete": True, "cam_speed_rpm": 180.0})
        d = f.create_dataset("signals", shape=(n, 3), dtype="f4", chunks=(65536, 3), maxshape=(None, 3))
        d.attrs["channel_names"] = np.array(names, dtype=h5py.string_dtype())
        d.attrs["ka_m_s2_per_v"] = np.full(3, np.nan)
        for k in range(n_blocks):
            d[k * len(block):(k + 1) * len(block)] = block
        ev = np.dtype([("index", "<i8"), ("kind", h5py.string_dtype()), ("detail", h5py.string_dtype())])
        f.create_dataset("events", data=np.array([(0, "start", ""), (n, "stop", "")], dtype=ev))
    return n


CHILD = r"""
import sys, time
sys.path.insert(0, {root!r})
from processing.readers import open_recording
from processing.pipeline import process_recording
t0 = time.perf_counter()
with open_recording({src!r}) as rec:
    s = process_recording(rec, {out!r}, warn=lambda m: None)
print("WALL", time.perf_counter() - t0)
print("INFO", s["cam_speed_rpm"], s["revolutions_averaged"], s["normal_check_rel_rms"])
"""


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--keep", action="store_true")
    args = ap.parse_args()
    tmpdir = Path(tempfile.mkdtemp(prefix="bench_process_", dir="/tmp"))
    src, out = tmpdir / "rec.h5", tmpdir / "measured.nc"
    try:
        t0 = time.perf_counter()
        n = make_file(src, args.minutes)
        print(f"recording: {n} samples x 3 channels ({args.minutes:g} min at 10 kHz), "
              f"{src.stat().st_size / 1e6:.0f} MB float32, written in {time.perf_counter() - t0:.1f} s")
        env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1",
                   NUMBA_NUM_THREADS="1", MPLBACKEND="Agg")
        cmd = [sys.executable, "-c", CHILD.format(root=str(ROOT), src=str(src), out=str(out))]
        # single-threaded (the env above); not pinned with taskset: on a shared machine a pinned
        # process waits for whatever else runs on that CPU
        t1 = time.perf_counter()
        proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        rss = []  # (s, MB) of the child while it runs: is memory bounded, or does it grow?
        while proc.poll() is None:
            rss.append((time.perf_counter() - t1, _rss_mb(proc.pid)))
            time.sleep(0.25)
        stdout, stderr = proc.communicate()
        wall_outer = time.perf_counter() - t1
        if proc.returncode != 0:
            print(stderr)
            raise SystemExit(1)
        wall = float(next(line.split()[1] for line in stdout.splitlines() if line.startswith("WALL")))
        info = next(line for line in stdout.splitlines() if line.startswith("INFO")).split()[1:]
        ru = resource.getrusage(resource.RUSAGE_CHILDREN)
        peak_mb = ru.ru_maxrss / 1024.0
        cpu = ru.ru_utime + ru.ru_stime  # the child's CPU time, less sensitive to a shared machine's load
        print(f"processing wall time: {wall:.1f} s (process incl. start-up {wall_outer:.1f} s)")
        print(f"throughput: {3 * n / wall / 1e6:.2f} M samples/s (samples x channels), "
              f"{n / wall / 1e6:.2f} M time steps/s, one core")
        print(f"CPU time of the processing process (incl. ~1.5 s start-up and imports): {cpu:.1f} s "
              f"-> {3 * n / cpu / 1e6:.2f} M samples/s of CPU")
        print(f"peak memory (max RSS of the processing process): {peak_mb:.0f} MB")
        rss = [(t, m) for t, m in rss if m > 0]
        if rss:
            marks = [rss[int(f * (len(rss) - 1))] for f in (0.2, 0.4, 0.6, 0.8, 1.0)]
            print("resident memory while running: " + ", ".join(f"{m:.0f} MB at {t:.0f} s" for t, m in marks))
        print(f"output: {out.stat().st_size / 1e6:.0f} MB; cam {float(info[0]):.2f} rpm, {info[1]} revolutions averaged, "
              f"normal check {100 * float(info[2]):.2f} %")
        print("goal: >= 10 M samples/s and < 500 MB peak memory")
    finally:
        if not args.keep:
            for p in (src, out):
                p.unlink(missing_ok=True)
            tmpdir.rmdir() if not any(tmpdir.iterdir()) else None


if __name__ == "__main__":
    main()
