"""First call against the hundredth: compile times with an empty numba cache, per kernel and per command.

1. **Commands** (whole CLI commands in fresh processes, as a user runs them): for each of
   ``simulate --model elastic``, ``simulate --model rigid``, ``process`` (a 3 s recording of the
   simulated stand, the demo's) and ``report`` (its measured file), interleaved ``--repeats`` times:
   the command with an empty cache (a fresh ``NUMBA_CACHE_DIR``, as on a new user's machine), then
   the same command again with the cache it left (warm). Wall and CPU time (user + system of the
   child) of each, the ratio cold / warm (the goal: at most 5), and how long after the start the
   compile notice reached stderr (labtool.models.dynamics.compiling; the goal: within 1 s).
2. **warmup**: ``labtool warmup`` from an empty cache, its wall and CPU time; then each command
   again in that cache, to show that none compiles (the notice absent).
3. **Kernels**: per command, every labtool function numba compiled at the top level (a callee it
   compiles inside is part of its caller's time) with its seconds, from numba's compile events in
   a probe process with an empty cache.

Ratios are measured side by side in the same run (the machine is shared: ``uptime`` is recorded
before and after); medians over the repeats. Results: benchmarks/results/compile_times.json and a
Markdown table on stdout (docs/performance.md, "First call and compile time").

    .venv/bin/python benchmarks/compile_times.py [--repeats 3] [--skip-kernels] [--compare /path/to/main/.venv/bin/python]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
PYTHON = [sys.executable]           # --python: another checkout's interpreter (its editable install)
LABTOOL = PYTHON + ["-m", "labtool"]
NOTICE = "labtool: compiling "

COMMANDS = {
    "simulate elastic": ["simulate", "--model", "elastic", "--json"],
    "simulate rigid": ["simulate", "--model", "rigid", "--json"],
    "process": ["process", "{rec}", "-o", "{tmp}/m.nc", "--force"],
    "report": ["report", "{measured}", "-o", "{tmp}/r.html", "--force"],
}

PROBE = r"""
import json, sys, time
from numba.core import event
recs, stack = [], []
class Listener(event.Listener):
    def on_start(self, ev):
        stack.append(time.perf_counter())
    def on_end(self, ev):
        t0 = stack.pop()
        if stack:
            return
        fn = getattr(ev.data["dispatcher"], "py_func", None)
        name = f"{fn.__module__}.{fn.__qualname__}" if fn is not None else str(ev.data["dispatcher"])
        recs.append((name, time.perf_counter() - t0))
event.register("numba:compile", Listener())
from labtool.cli import main
rc = main(sys.argv[1:])
json.dump(dict(rc=rc, kernels=recs), open(OUT, "w"))
"""


def _env(cache: Path) -> dict:
    return dict(os.environ, NUMBA_CACHE_DIR=str(cache), MPLBACKEND="Agg")


def timed(args: list[str], cache: Path, cwd: Path) -> dict:
    """A command in a fresh process: wall s, cpu s (the child's user + system), exit code, the
    seconds from its start to the first compile notice on stderr (None if none), stderr."""
    t0 = time.perf_counter()
    p = subprocess.Popen(args, cwd=cwd, env=_env(cache), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                         text=True)
    first, lines = [None], []

    def read():
        for line in p.stderr:
            if first[0] is None and line.startswith(NOTICE):
                first[0] = time.perf_counter() - t0
            lines.append(line)
    reader = threading.Thread(target=read)
    reader.start()
    _, status, usage = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t0
    reader.join()
    p.returncode = os.waitstatus_to_exitcode(status)
    return dict(wall_s=wall, cpu_s=usage.ru_utime + usage.ru_stime, rc=p.returncode, notice_s=first[0],
                stderr="".join(lines)[-3000:])


def _args(name: str, files: dict, python: str | None = None) -> list[str]:
    return ([python, "-m", "labtool"] if python else LABTOOL) + [a.format(**files) for a in COMMANDS[name]]


def inputs(work: Path) -> dict:
    """The 3 s recording of the simulated stand (the demo's) and its measured file, made with a
    cache of their own (not measured)."""
    cache = work / "inputs_cache"
    rec, measured = work / "rec.h5", work / "measured.nc"
    for args in (["acquire", "--device", "sim", "--rpm", "180", "--duration", "3", "--fast", "--seed", "1",
                  "--backlash-mm", "0.128", "-o", str(rec)], ["process", str(rec), "-o", str(measured)]):
        r = timed(LABTOOL + args, cache, work)
        if r["rc"] != 0:
            raise SystemExit(f"making the inputs failed: {r['stderr']}")
    return dict(rec=str(rec), measured=str(measured))


def commands(work: Path, files: dict, repeats: int, other: str | None = None) -> tuple[dict, dict]:
    """Each command cold then warm, ``repeats`` times; with ``other`` (another checkout's python)
    that checkout's too, interleaved command by command (the same load for both)."""
    out = {name: [] for name in COMMANDS}
    out_other = {name: [] for name in COMMANDS}
    for k in range(repeats):
        for name in COMMANDS:
            for python, into, label in ((None, out, "this"), (other, out_other, "other")):
                if label == "other" and other is None:
                    continue
                cache = work / f"cache_{label}_{name.replace(' ', '_')}_{k}"
                tmp = work / f"out_{k}"
                tmp.mkdir(exist_ok=True)
                args = _args(name, dict(files, tmp=str(tmp)), python)
                cold = timed(args, cache, work)
                warm = timed(args, cache, work)
                for r in (cold, warm):
                    if r["rc"] not in (0, 1):
                        raise SystemExit(f"{name} ({label}) failed: {r['stderr']}")
                into[name].append(dict(cold=cold, warm=warm, warm_compiled=NOTICE in warm["stderr"]))
                shutil.rmtree(cache, ignore_errors=True)
                print(f"  {label:5s} {name} #{k + 1}: cold {cold['wall_s']:.2f} s, warm {warm['wall_s']:.2f} s, "
                      f"ratio {cold['wall_s'] / warm['wall_s']:.1f}, notice at {cold['notice_s']} s", flush=True)
    return out, out_other


def warmup(work: Path, files: dict) -> dict:
    cache = work / "cache_warmup"
    r = timed(LABTOOL + ["warmup"], cache, work)
    if r["rc"] != 0:
        raise SystemExit(f"warmup failed: {r['stderr']}")
    after = {}
    tmp = work / "out_warmup"
    tmp.mkdir(exist_ok=True)
    for name in COMMANDS:
        a = timed(_args(name, dict(files, tmp=str(tmp))), cache, work)
        after[name] = dict(wall_s=a["wall_s"], compiled=NOTICE in a["stderr"])
    shutil.rmtree(cache, ignore_errors=True)
    return dict(wall_s=r["wall_s"], cpu_s=r["cpu_s"], then=after)


def kernels(work: Path, files: dict) -> dict:
    out = {}
    for name in COMMANDS:
        cache, tmp = work / f"cache_kernels_{name.replace(' ', '_')}", work / "out_kernels"
        tmp.mkdir(exist_ok=True)
        path = work / "kernels.json"
        args = [PYTHON[0], "-c", f"OUT = {str(path)!r}\n" + PROBE] + _args(name, dict(files, tmp=str(tmp)))[3:]
        r = timed(args, cache, work)
        if r["rc"] != 0:
            raise SystemExit(f"kernel probe of {name} failed: {r['stderr']}")
        recs = json.loads(path.read_text())["kernels"]
        out[name] = dict(total_s=sum(s for _, s in recs),
                         kernels=sorted(([n.replace("labtool.", ""), s] for n, s in recs), key=lambda x: -x[1]))
        shutil.rmtree(cache, ignore_errors=True)
    return out


def _median(runs, key, sub):
    return statistics.median(r[key][sub] for r in runs)


def table(result: dict) -> str:
    rows = ["| command | empty cache (s) | warm (s) | ratio | CPU ratio | notice after (s) |",
            "|---|---|---|---|---|---|"]
    for name, runs in result["commands"].items():
        ratios = [r["cold"]["wall_s"] / r["warm"]["wall_s"] for r in runs]
        cpu = [r["cold"]["cpu_s"] / r["warm"]["cpu_s"] for r in runs]
        notices = [r["cold"]["notice_s"] for r in runs if r["cold"]["notice_s"] is not None]
        notice = f"{max(notices):.2f}" if notices else "none"
        words = name.split()
        command = f"labtool {words[0]}" + (f" --model {words[1]}" if len(words) > 1 else "")
        rows.append(f"| `{command}` | {_median(runs, 'cold', 'wall_s'):.2f} | {_median(runs, 'warm', 'wall_s'):.2f} | "
                    f"{statistics.median(ratios):.1f} ({min(ratios):.1f}-{max(ratios):.1f}) | "
                    f"{statistics.median(cpu):.1f} | {notice} |")
    w = result.get("warmup")
    if w:
        rows.append(f"| `labtool warmup` | {w['wall_s']:.1f} (CPU {w['cpu_s']:.1f}) | | | | |")
    return "\n".join(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--skip-kernels", action="store_true")
    ap.add_argument("--no-warmup", action="store_true", help="a checkout without labtool warmup")
    ap.add_argument("--python", default=sys.executable, help="the interpreter whose labtool is measured")
    ap.add_argument("--only", default=None, help="comma-separated commands of COMMANDS to measure")
    ap.add_argument("--compare", default=None, help="another checkout's python (its editable install, e.g. main's): "
                                                    "its commands run interleaved with these, the same way")
    ap.add_argument("-o", "--output", type=Path, default=RESULTS / "compile_times.json")
    args = ap.parse_args()
    PYTHON[0] = LABTOOL[0] = args.python
    if args.only:
        for name in set(COMMANDS) - set(args.only.split(",")):
            del COMMANDS[name]
    load = [os.getloadavg()]
    with tempfile.TemporaryDirectory(prefix="labtool-compile-") as tmp:
        work = Path(tmp)
        files = inputs(work)
        result = {"machine": dict(nproc=os.cpu_count(), python=sys.version.split()[0])}
        result["commands"], other = commands(work, files, args.repeats, args.compare)
        if args.compare:
            result["compare"] = {"python": args.compare, "commands": other}
        if not args.no_warmup:
            result["warmup"] = warmup(work, files)
        if not args.skip_kernels:
            result["kernels"] = kernels(work, files)
    load.append(os.getloadavg())
    result["machine"]["loadavg_before_after"] = load
    for block in (result["commands"], result.get("compare", {}).get("commands", {})):
        for runs in block.values():
            for r in runs:
                for side in ("cold", "warm"):
                    r[side].pop("stderr", None)
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(result, indent=1) + "\n")
    print(table(result))
    if "compare" in result:
        print(f"\nthe same commands, interleaved, with {args.compare}:")
        print(table({"commands": result["compare"]["commands"]}))
    w = result.get("warmup") or dict(wall_s=float("nan"), then={})
    print(f"\nafter warmup ({w['wall_s']:.1f} s): " + ", ".join(
        f"{name} {a['wall_s']:.2f} s{' (compiled!)' if a['compiled'] else ''}" for name, a in w["then"].items()))
    for name, k in result.get("kernels", {}).items():
        top = ", ".join(f"{n} {s:.2f}" for n, s in k["kernels"][:6])
        print(f"{name}: {k['total_s']:.1f} s compiling; {top}")
    print(f"load average before/after: {load}; wrote {args.output}")


if __name__ == "__main__":
    main()
