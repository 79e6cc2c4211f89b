"""Count the hostile-input suite per kind, and with ``--run`` run it and count outcomes.

    python tests/hostile_counts.py            # tests per kind (collection only, seconds)
    python tests/hostile_counts.py --run      # run them: passed / failed / skipped per kind
    python tests/hostile_counts.py --run -x   # any further arguments go to pytest

Every test of the suite carries ``@pytest.mark.hostile("<kind>")`` (tests/conftest.py lists the
kinds and refuses others); a parametrized test counts once per case, a hypothesis test once.
"""
from __future__ import annotations

import collections
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))   # tests that import benchmarks/, as pytest run from the root finds it
from conftest import HOSTILE_KINDS  # noqa: E402


class _Tally:
    def __init__(self):
        self.kind = {}
        self.outcome = {}

    def pytest_collection_finish(self, session):
        for item in session.items:
            mark = item.get_closest_marker("hostile")
            if mark is not None:
                self.kind[item.nodeid] = mark.args[0]

    def pytest_runtest_logreport(self, report):
        if report.nodeid not in self.kind:
            return
        if report.failed:
            self.outcome[report.nodeid] = "failed"
        elif report.skipped and self.outcome.get(report.nodeid) != "failed":
            self.outcome[report.nodeid] = "skipped"
        elif report.when == "call" and report.passed and report.nodeid not in self.outcome:
            self.outcome[report.nodeid] = "passed"


def main(argv: list[str]) -> int:
    run = "--run" in argv
    extra = [a for a in argv if a != "--run"]
    tally = _Tally()
    args = [str(HERE), "-m", "hostile", "-q", "-p", "no:cacheprovider", *([] if run else ["--collect-only"]), *extra]
    code = pytest.main(args, plugins=[tally])
    per_kind = collections.Counter(tally.kind.values())
    outcomes = collections.defaultdict(collections.Counter)
    for nodeid, kind in tally.kind.items():
        outcomes[kind][tally.outcome.get(nodeid, "not run")] += 1
    print()
    header = f"{'kind':14s} {'tests':>6s}" + ("".join(f" {c:>8s}" for c in ("passed", "failed", "skipped")) if run else "")
    print(header)
    for kind in HOSTILE_KINDS:
        line = f"{kind:14s} {per_kind.get(kind, 0):6d}"
        if run:
            line += "".join(f" {outcomes[kind].get(c, 0):8d}" for c in ("passed", "failed", "skipped"))
        print(line)
    total = sum(per_kind.values())
    line = f"{'total':14s} {total:6d}"
    if run:
        line += "".join(f" {sum(o.get(c, 0) for o in outcomes.values()):8d}" for c in ("passed", "failed", "skipped"))
    print(line)
    missing = [k for k in HOSTILE_KINDS if not per_kind.get(k)]
    if missing:
        print(f"kinds without a test: {', '.join(missing)}")
    return int(code) if run else (1 if missing else 0)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
