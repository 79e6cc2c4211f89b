"""Does following ``labtool suggest`` pay? A simulated campaign loop on the simulated stand.

For each seed (a stand with its own backlash j and energy loss: the twin, docs/twin.md, with its
contact damping, or ``--truth rigid``, the rigid model's own physics through the stand's chain,
with its restitution):

* **suggested**: a first recording at 180 rpm, no load; ``labtool suggest --goal identify``
  on it (120-600 rpm by 40, at the measured load, its default; ``--loads`` adds others) gives the
  second point; ``labtool suggest`` on the two gives the third;
* **fixed**: the same first recording, then 300 and 500 rpm, no load (the paper's speeds);

* ``--arm A:B`` (any number): the same first recording, then A and B rpm, no load (their own
  recordings, tagged ``_b1`` and ``_b2``): what a given rule would have got, the bound on what any
  choice of the two points could; ``--table --arms`` tables them against the fixed arm (and writes
  ``benchmarks/results/suggest_loop_arms_<truth>.json``);

each arm's three recordings are fitted jointly (``labtool fit a b c --model rigid --free
backlash,restitution --shared backlash``) and the backlash's 95 % interval compared: its width
(on the log scale, ln(hi / lo), as the fit searches it) and whether it holds the truth.

Everything is kept under ``--dir`` (resumable). ``--table`` prints the table and writes
``benchmarks/results/suggest_loop_<truth>.json`` (``suggest_loop_<truth>_from<first seed>.json`` for
a directory of seeds from ``--first-seed``). ``--headroom`` (``--dir`` given once per directory)
prints how the recordings' peak over the input range grows with the cam speed, against each
stand's 180 rpm recording (labtool.identification.design.HEADROOM_EXPONENT).

    nice -n 10 .venv/bin/python benchmarks/suggest_loop.py --dir /tmp/loop --seeds 6 [--truth rigid]
    .venv/bin/python benchmarks/suggest_loop.py --dir /tmp/loop --table
    nice -n 10 .venv/bin/python benchmarks/suggest_loop.py --dir /tmp/loop --seeds 2 --arm 180:180 --arm 300:420
    .venv/bin/python benchmarks/suggest_loop.py --dir /tmp/loop --table --arms
    .venv/bin/python benchmarks/suggest_loop.py --headroom --dir /tmp/loop --dir /tmp/loop_rigid
"""
from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
LABTOOL = str(ROOT / ".venv" / "bin" / "labtool")
DURATION_S = 4.0
FIRST = (180.0, 0.0)
FIXED = ((300.0, 0.0), (500.0, 0.0))
RESULTS = ROOT / "benchmarks" / "results" / "suggest_loop_{truth}.json"
FIT = ["--model", "rigid", "--free", "backlash,restitution", "--shared", "backlash", "--accuracy", "fast"]
SUGGEST = ["--model", "rigid", "--free", "backlash,restitution", "--shared", "backlash", "--rpm-range", "120:600:40",
           "--accuracy", "fast"]


TRUTH = {"model": "twin"}     # the stand's truth: twin or rigid (--truth)


def truth(seed: int) -> dict:
    rng = np.random.default_rng([2026, seed])
    out = {"backlash_mm": round(float(np.exp(rng.uniform(math.log(0.06), math.log(0.2)))), 4),
           "contact_damping": round(float(rng.uniform(20.0, 60.0)), 1)}
    if TRUTH["model"] == "rigid":
        out = {"backlash_mm": out["backlash_mm"], "restitution": round(float(rng.uniform(0.2, 0.6)), 3)}
    return out


def _run(args: list[str]) -> subprocess.CompletedProcess:
    r = subprocess.run([LABTOOL, *args], capture_output=True, text=True)
    if r.returncode not in (0, 1):
        raise RuntimeError(f"labtool {' '.join(args[:2])}: {r.stderr.strip().splitlines()[-1]}")
    return r


def record(folder: Path, seed: int, rpm: float, Fu: float, tag: str = "") -> Path:
    """measured.nc of the seed's stand at (rpm, Fu), made once (the stated backlash removed);
    ``tag`` tells apart a second recording at the same point (its own noise)."""
    from benchmarks.fit_recovery import _forget_stated_backlash

    t = truth(seed)
    nc = folder / f"{rpm:g}rpm_{Fu:g}N{tag}.nc"
    if not nc.exists():
        h5 = nc.with_suffix(".h5")
        loss = (["--truth", "rigid", "--restitution", str(t["restitution"])] if "restitution" in t
                else ["--contact-damping", str(t["contact_damping"])])
        _run(["acquire", "--device", "sim", "--fast", "--duration", str(DURATION_S), "--rpm", f"{rpm:g}", "--fu",
              f"{Fu:g}", "--backlash-mm", str(t["backlash_mm"]), *loss,
              "--seed", str(seed * 100_000 + int(rpm) * 100 + int(Fu) + (11 * int(tag[-1]) if tag else 0)),
              "-o", str(h5), "--force"])
        _run(["process", str(h5), "-o", str(nc), "--force"])
        _forget_stated_backlash(nc)
    return nc


def suggested_point(folder: Path, files: list[Path], step: int) -> tuple[float, float]:
    out = folder / f"suggest_{step}.json"
    if not out.exists():
        _run(["suggest", *map(str, files), *SUGGEST, "-o", str(out), "--force"])
    p = json.loads(out.read_text())["point"]
    return float(p["cam_speed_rpm"]), float(p["Fu_N"])


def joint(folder: Path, name: str, files: list[Path]) -> dict:
    out = folder / f"joint_{name}.json"
    if not out.exists():
        _run(["fit", *map(str, files), *FIT, "-o", str(out), "--force"])
    return json.loads(out.read_text())


def interval(s: dict, seed: int, files: list[Path]) -> dict:
    """The joint fit's backlash interval: its log width and whether it holds the truth."""
    j = s["parameters"]["backlash_mm"]
    lo, hi = j["ci95"]
    t = truth(seed)["backlash_mm"]
    return {"points": [f.stem for f in files], "value": j["value"], "ci95": [lo, hi],
            "ci95_joint": j["ci95_joint"], "log_width": math.log(hi / lo) if lo and hi and lo > 0 else None,
            "holds": lo is not None and hi is not None and lo <= t <= hi, "consistent": s["consistent"]}


def arms_seed(root: Path, seed: int, arms: list[tuple[float, float]]) -> dict:
    """The fixed arm and each given pair of second and third speeds (no load) after the first recording."""
    folder = root / f"seed_{seed:02d}"
    folder.mkdir(parents=True, exist_ok=True)
    first = record(folder, seed, *FIRST)
    fixed = [first] + [record(folder, seed, *p) for p in FIXED]
    path = folder / "arms.json"
    out = json.loads(path.read_text()) if path.exists() else {"seed": seed, "truth": truth(seed), "arms": {}}
    out["fixed"] = interval(joint(folder, "fixed", fixed), seed, fixed)
    for a, b in arms:
        name = f"{a:g}_{b:g}"
        try:
            files = [first, record(folder, seed, a, 0.0, tag="_b1"), record(folder, seed, b, 0.0, tag="_b2")]
            out["arms"][name] = interval(joint(folder, f"arm_{name}", files), seed, files)
        except RuntimeError as exc:     # a recording the processing cannot use: said, not hidden
            out["arms"][name] = {"error": str(exc), "log_width": None}
        path.write_text(json.dumps(out, indent=1))
    return out


def arms_table(root: Path) -> list[dict]:
    """Per seed and arm: the width ratio arm / fixed; per arm: the median and how often narrower."""
    rows = [json.loads(p.read_text()) for p in sorted(root.glob("seed_*/arms.json"))]
    names = sorted({n for r in rows for n in r["arms"]}, key=lambda n: tuple(float(v) for v in n.split("_")))
    print("| second, third [rpm] | " + " | ".join(f"seed {r['seed']}" for r in rows) + " | median | narrower |")
    print("|---|" + "---|" * (len(rows) + 2))
    for n in names:
        ratios = []
        for r in rows:
            a, f = r["arms"].get(n) or {}, r["fixed"]
            ratios.append(a["log_width"] / f["log_width"] if a.get("log_width") and f["log_width"] else math.nan)
        ok = [x for x in ratios if math.isfinite(x)]
        med = float(np.median(ok)) if ok else math.nan
        print(f"| {n.replace('_', ', ')} | " + " | ".join(f"{x:.2f}" for x in ratios)
              + f" | {med:.2f} | {sum(x < 1 for x in ok)} of {len(ok)} |")
    return rows


def one_seed(root: Path, seed: int) -> dict:
    folder = root / f"seed_{seed:02d}"
    folder.mkdir(parents=True, exist_ok=True)
    first = record(folder, seed, *FIRST)
    files = [first]
    for step in (1, 2):
        files.append(record(folder, seed, *suggested_point(folder, files, step), tag=f"_s{step}"))
    fixed = [first] + [record(folder, seed, *p) for p in FIXED]
    out = {"seed": seed, "truth": truth(seed)}
    for name, fs in (("suggested", files), ("fixed", fixed)):
        out[name] = interval(joint(folder, name, fs), seed, fs)
    (folder / "result.json").write_text(json.dumps(out, indent=1))
    return out


def table(root: Path) -> list[dict]:
    rows = [json.loads(p.read_text()) for p in sorted(root.glob("seed_*/result.json"))]
    for p in sorted(root.glob("seed_*/error.txt")):
        print(f"{p.parent.name}: left out: {p.read_text().strip()}")
    print("| seed | true j [mm] | suggested points | j (95 %), suggested | fixed 180/300/500 | j (95 %), fixed "
          "| width ratio suggested / fixed |")
    print("|---|---|---|---|---|---|---|")
    ratios = []
    for r in rows:
        s, f = r["suggested"], r["fixed"]

        def cell(x):
            return (f"{x['value']:.4g} [{x['ci95'][0]:.4g}, {x['ci95'][1]:.4g}]" + ("" if x["holds"] else " misses")
                    + ("" if x["consistent"] else ", files disagree"))
        ratio = s["log_width"] / f["log_width"] if s["log_width"] and f["log_width"] else float("nan")
        print(f"| {r['seed']} | {r['truth']['backlash_mm']:.4g} | {', '.join(s['points'][1:])} | {cell(s)} | "
              f"{', '.join(f['points'][1:])} | {cell(f)} | {ratio:.2f} |")
        ratios.append(ratio)
    ok = [x for x in ratios if math.isfinite(x)]
    if ok:
        print(f"median width ratio {float(np.median(ok)):.2f}; suggested narrower in {sum(x < 1 for x in ok)} of {len(ok)}; "
              f"intervals holding the truth: suggested {sum(r['suggested']['holds'] for r in rows)}, "
              f"fixed {sum(r['fixed']['holds'] for r in rows)} of {len(rows)}")
    return rows


def headroom_table(roots: list[Path]) -> dict:
    """How each stand's peak over the input range grows with the cam speed: for every recording
    that did not clip, the exponent a in peak(n) = peak(180 rpm) (n / 180)^a against the same
    stand's 180 rpm recording (labtool.identification.design.HEADROOM_EXPONENT)."""
    import re

    import h5py

    def peak(h5: Path) -> tuple[float, bool]:
        with h5py.File(h5, "r") as f:
            a = f["signals"].attrs
            return float(a["peak_fraction_of_range"][0]), bool(a["clipped"][0])

    above, below = [], []
    stands = 0
    for root in roots:
        for folder in sorted(root.glob("seed_*")):
            first = folder / f"{FIRST[0]:g}rpm_{FIRST[1]:g}N.h5"
            if not first.exists():
                continue
            stands += 1
            p0, _ = peak(first)
            for h5 in folder.glob("*rpm_*.h5"):
                n = float(re.match(r"([0-9.]+)rpm", h5.name).group(1))
                p, clipped = peak(h5)
                if n == FIRST[0] or clipped or p >= 1.0:
                    continue
                (above if n > FIRST[0] else below).append(math.log(p / p0) / math.log(n / FIRST[0]))
    out = {"stands": stands, "recordings": len(above) + len(below)}
    for name, v in (("above", above), ("below", below)):
        if v:
            out[name] = {"n": len(v), "median": float(np.median(v)), "p90": float(np.percentile(v, 90)),
                         "max": float(np.max(v))}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dir", type=Path, required=True, action="append")
    ap.add_argument("--seeds", type=int, default=4, help="how many seeds")
    ap.add_argument("--first-seed", type=int, default=0, help="the first seed (fresh stands: one not tuned on)")
    ap.add_argument("--arm", action="append", default=[], metavar="A:B",
                    help="instead of following suggest: the second and third speeds A and B [rpm], no load")
    ap.add_argument("--arms", action="store_true", help="with --table: table the --arm runs")
    ap.add_argument("--headroom", action="store_true",
                    help="how the recordings' peak over the input range grows with speed (every --dir given)")
    ap.add_argument("--table", action="store_true")
    ap.add_argument("--truth", default="twin", choices=("twin", "rigid"), help="the simulated stand's truth")
    args = ap.parse_args()
    TRUTH["model"] = args.truth
    if args.headroom:
        print(json.dumps(headroom_table(args.dir), indent=1))
        return
    args.dir = args.dir[0]
    if args.table and args.arms:
        rows = arms_table(args.dir)
        out = Path(str(RESULTS).format(truth=f"arms_{args.truth}"))
        out.write_text(json.dumps(rows, indent=1) + "\n")
        print(f"wrote {out}")
        return
    if args.table:
        rows = table(args.dir)
        first = min((r["seed"] for r in rows), default=0)
        # fresh stands (seeds from --first-seed) get their own file beside the first five's
        out = Path(str(RESULTS).format(truth=args.truth + (f"_from{first}" if first else "")))
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(rows, indent=1) + "\n")
        print(f"wrote {out}")
        return
    arms = [tuple(float(v) for v in a.split(":")) for a in args.arm]
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        try:
            if arms:
                arms_seed(args.dir, seed, arms)
                print(f"seed {seed}: {len(arms)} arms", flush=True)
                continue
            r = one_seed(args.dir, seed)
        except RuntimeError as exc:       # a recording the processing cannot use: said, not hidden
            (args.dir / f"seed_{seed:02d}" / "error.txt").write_text(str(exc) + "\n")
            print(f"seed {seed}: {exc}", flush=True)
            continue
        print(json.dumps({k: r[k] for k in ("seed", "truth")}), "suggested", r["suggested"]["points"],
              r["suggested"]["ci95"], "fixed", r["fixed"]["ci95"], flush=True)


if __name__ == "__main__":
    main()
