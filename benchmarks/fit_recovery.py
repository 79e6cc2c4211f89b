"""Recovery of known parameters by ``labtool fit`` on recordings of the simulated stand.

Each case records the stand with a model truth whose parameters the fit is not told
(``labtool acquire --device sim --truth rigid|elastic --backlash-mm J --restitution K |
--contact-damping C``), processes it (the j the recording states, which on the simulated stand is
the truth, removed from the processed file: it carries no truth), fits the same model
with ``--free backlash,restitution`` (rigid) or ``backlash,contact_damping`` (elastic), and prints
the true and fitted values, the 95 % interval and whether it holds the truth. The ``twin`` cases
fit both models to the stand's default, richer truth and print the grades before and after.
Prints, no asserts (the table goes into docs/identification.md).

    .venv/bin/python benchmarks/fit_recovery.py [--dir DIR] [--accuracy fast|standard] [--cases rA,rB,...]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LABTOOL = str(ROOT / ".venv" / "bin" / "labtool")
DURATION_S = 4.0

# name: (truth model, truth options, rpm, fitted model, free, the truths by JSON key)
CASES = {
    "rA": ("rigid", ["--backlash-mm", "0.2", "--restitution", "0.5"], 180, "rigid", "backlash,restitution",
           {"backlash_mm": 0.2, "restitution": 0.5}),
    "rC": ("rigid", ["--backlash-mm", "0.3", "--restitution", "0.6"], 180, "rigid", "backlash,restitution",
           {"backlash_mm": 0.3, "restitution": 0.6}),
    "rE": ("rigid", ["--backlash-mm", "0.1", "--restitution", "0.3"], 180, "rigid", "backlash,restitution",
           {"backlash_mm": 0.1, "restitution": 0.3}),
    "rD": ("rigid", ["--backlash-mm", "0.15", "--restitution", "0.3"], 500, "rigid", "backlash,restitution",
           {"backlash_mm": 0.15, "restitution": 0.3}),
    "rB": ("rigid", ["--backlash-mm", "0.08", "--restitution", "0.3"], 500, "rigid", "backlash,restitution",
           {"backlash_mm": 0.08, "restitution": 0.3}),
    "eB": ("elastic", ["--backlash-mm", "0.25", "--contact-damping", "120"], 180, "elastic", "backlash,contact_damping",
           {"backlash_mm": 0.25, "contact_damping_s_per_m": 120.0}),
    "eA": ("elastic", ["--backlash-mm", "0.128", "--contact-damping", "40"], 500, "elastic", "backlash,contact_damping",
           {"backlash_mm": 0.128, "contact_damping_s_per_m": 40.0}),
    "t180r": ("twin", [], 180, "rigid", "backlash,restitution", {}),
    "t180e": ("twin", [], 180, "elastic", "backlash,contact_damping", {}),
    "t500r": ("twin", [], 500, "rigid", "backlash,restitution", {}),
    "t500e": ("twin", [], 500, "elastic", "backlash,contact_damping", {}),
}


def run(args: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run([LABTOOL, *args], capture_output=True, text=True)


def recording(folder: Path, truth: str, options: list[str], rpm: int) -> Path:
    """The processed recording of one truth (made once per folder)."""
    stem = folder / f"{truth}_{rpm}_{'_'.join(o.strip('-').replace('.', 'p') for o in options) or 'default'}"
    measured = stem.with_suffix(".nc")
    if not measured.exists():
        acq = run(["acquire", "--device", "sim", "--fast", "--duration", str(DURATION_S), "--rpm", str(rpm),
                   "--truth", truth, *options, "-o", str(stem.with_suffix(".h5")), "--force"])
        if acq.returncode:
            raise SystemExit(acq.stderr)
        proc = run(["process", str(stem.with_suffix(".h5")), "-o", str(measured), "--force"])
        if proc.returncode:
            raise SystemExit(proc.stderr)
        _forget_stated_backlash(measured)
    return measured


def _forget_stated_backlash(path: Path) -> None:
    """labtool process keeps the j a recording states; a worn groove's true j is what nobody states."""
    import xarray as xr

    from labtool.common.files import write_netcdf
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        ds = ds.load()
    for k in [k for k in ds.attrs if "backlash" in k]:
        del ds.attrs[k]
    write_netcdf(ds, path)


def fit_case(folder: Path, name: str, accuracy: str) -> dict:
    truth, options, rpm, model, free, truths = CASES[name]
    measured = recording(folder, truth, options, rpm)
    t0 = time.perf_counter()
    res = run(["fit", str(measured), "--model", model, "--free", free, "--accuracy", accuracy, "--json"])
    wall = time.perf_counter() - t0
    if res.returncode:
        return {"name": name, "error": res.stderr.strip().splitlines()[-1]}
    return {"name": name, "truth": truth, "rpm": rpm, "model": model, "truths": truths, "fit": json.loads(res.stdout),
            "command_s": wall}


def print_case(c: dict) -> None:
    if "error" in c:
        print(f"{c['name']}: {c['error']}")
        return
    s = c["fit"]
    head = f"{c['name']}: {c['truth']} truth at {c['rpm']} rpm, {c['model']} fitted ({s['accuracy']}): " \
           f"{s['evaluations']} model runs, fit {s['wall_s']:.1f} s (command {c['command_s']:.1f} s)"
    print(head)
    for key, p in s["parameters"].items():
        lo, hi = p["ci95"]
        lo_s = "-inf" if lo is None else f"{lo:.4g}"
        hi_s = "+inf" if hi is None else f"{hi:.4g}"
        t = c["truths"].get(key)
        if t is None:
            inside = ""
        else:
            held = (lo is None or lo <= t) and (hi is None or t <= hi)
            err = (p["value"] / t - 1) * 100 if key != "restitution" else p["value"] - t
            unit = "%" if key != "restitution" else ""
            inside = f"  true {t:g}, error {err:+.3g}{unit}, interval {'holds' if held else 'MISSES'} it"
        verdict = "identified" if p["identifiable"] else "NOT identifiable (" + "; ".join(p["notes"]) + ")"
        print(f"   {key:24s} {p['value']:.4g} [{lo_s}, {hi_s}]{inside}; {verdict}")
    for when in ("metrics_before", "metrics_after"):
        m = s[when]
        if m is None:
            print(f"   {when}: the model failed")
            continue
        ev = m["events"]
        print(f"   {when[8:]:6s}: omega2 ISO {m['omega2']['iso_rating']:.3f} ({m['omega2']['iso_grade']}), "
              f"epsilon2 ISO {m['epsilon2']['iso_rating']:.3f} ({m['epsilon2']['iso_grade']}); visible impacts/rev "
              f"{ev['impacts_per_rev']} (measured {ev['measured_impacts_per_rev']}), first {ev['first_impact_deg']} "
              f"(measured {ev['measured_first_impact_deg']}) deg")
    print(f"   objective {s['objective_before']:.4g} -> {s['objective_after']:.4g}, per residual "
          f"{s['objective_per_residual']:.3g}")
    for n in s["notes"]:
        print(f"   note: {n}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dir", type=Path, default=None, help="keep the recordings here (default: a temporary folder)")
    ap.add_argument("--accuracy", default="fast", choices=("fast", "standard"))
    ap.add_argument("--cases", default=",".join(CASES), help="comma-separated: " + ",".join(CASES))
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.dir or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        for name in args.cases.split(","):
            print_case(fit_case(folder, name, args.accuracy))
            sys.stdout.flush()


if __name__ == "__main__":
    main()
