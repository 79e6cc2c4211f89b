"""labtool report's progress when stderr is piped: periodic lines on a long report, none on a quick one."""
import io

from labtool.output import ProgressLines


def test_progress_lines_are_periodic_and_quiet_at_first(monkeypatch):
    clock = iter([0.0, 0.5, 2.5, 3.0, 8.0, 9.0])
    monkeypatch.setattr("labtool.output.time.perf_counter", lambda: next(clock))
    out = io.StringIO()
    lines = ProgressLines(out, "report", quiet=2.0, period=5.0)             # t0 = 0
    for msg in ("reading", "simulating rigid", "simulating elastic", "metrics", "figures"):
        lines.update(msg)                                  # at 0.5, 2.5, 3.0, 8.0, 9.0 s
    assert out.getvalue().splitlines() == ["report: simulating rigid (2 s)", "report: metrics (8 s)"]
