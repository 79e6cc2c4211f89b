"""The acquisition monitor on screen: a rich panel on a terminal, one status line in a log.

Figures come from ``labtool.acquisition.monitor.Snapshot``; this module only lays them out. The live trace
of the last revolution is drawn with plotext (braille-free ASCII-safe markers), turned into rich
text; headroom is coloured: above 80 % of the input range yellow, clipping red.
"""
from __future__ import annotations

import math

from rich.console import Group
from rich.table import Table
from rich.text import Text

STATE_STYLE = {"ok": "green", "warn": "bold yellow", "clip": "bold red"}
STATE_WORD = {"ok": "", "warn": "LOW HEADROOM", "clip": "CLIPPING"}


def _t(seconds) -> str:
    if seconds is None or not math.isfinite(seconds):
        return "-"
    seconds = max(0.0, seconds)
    if seconds >= 3600:
        return f"{int(seconds // 3600)}h{int(seconds % 3600 // 60):02d}m"
    if seconds >= 60:
        return f"{int(seconds // 60)}m{int(seconds % 60):02d}s"
    return f"{seconds:.1f} s"


def _num(v, fmt=".3g") -> str:
    return "-" if v is None or not math.isfinite(v) else format(v, fmt)


def _pct(fraction: float) -> str:
    """A percentage with two significant figures below 10 % (0.2 %, not 0 %)."""
    p = 100 * fraction
    return f"{p:.1f}" if p < 10 else f"{p:.0f}"


def speed_text(s) -> str:
    if s.rpm is None:
        return "no tacho pulse yet" if s.revolutions == 0 else "-"
    drift = "" if s.rpm_drift is None else f", drift {s.rpm_drift:+.2f} rpm since start"
    return f"{s.rpm:.2f} rpm{drift} ({s.revolutions} revolutions)"


def progress_text(s) -> str:
    if s.progress is None:
        return f"{_t(s.data_s)} of data (until stopped), {_t(s.elapsed_wall_s)} wall"
    return f"{100 * s.progress:5.1f} % of {_t(s.duration_s)}, ETA {_t(s.eta_s)}"


def status_line(s) -> str:
    """Everything on one line, for a log or a pipe."""
    parts = [f"acquire {progress_text(s)}", f"cam {speed_text(s)}"]
    for c in s.channels:
        flag = f" {STATE_WORD[c.state]}" if c.state != "ok" else ""
        rng = f" = {_pct(c.fraction)} % of +-{c.range_v:g} V" if math.isfinite(c.fraction) else ""
        parts.append(f"{c.name} peak {_num(c.peak)} {c.unit}{rng}, 1 s rms {_num(c.rms_recent)} {c.unit}{flag}")
    parts.append(f"overruns {s.overruns}, gaps {s.gaps} ({s.samples_lost} samples lost)")
    if s.buffer_fill is not None:
        parts.append(f"buffer {100 * s.buffer_fill:.0f} %")
    return "labtool: " + " | ".join(parts)


def render(s, title: str, width: int = 100):
    """The terminal panel: speed, progress, a headroom table, losses, and the last revolution."""
    head = Table(show_header=False, box=None, pad_edge=False)
    head.add_column(style="bold")
    head.add_column()
    head.add_row("cam speed", speed_text(s))
    head.add_row("progress", progress_text(s))
    fill = "-" if s.buffer_fill is None else f"{100 * s.buffer_fill:.0f} %"
    losses = Text(f"{s.overruns} overruns, {s.gaps} gaps ({s.samples_lost} samples lost), buffer {fill}",
                  style="bold red" if s.overruns or s.gaps else "")
    head.add_row("losses", losses)
    tab = Table(title=None, expand=False)
    for col, just in (("channel", "left"), ("peak", "right"), ("peak 1 s", "right"), ("rms 1 s", "right"),
                      ("unit", "left"), ("of range", "right"), ("", "left")):
        tab.add_column(col, justify=just)
    for c in s.channels:
        style = STATE_STYLE[c.state]
        rng = f"{100 * c.fraction:.1f} % of +-{c.range_v:g} V" if math.isfinite(c.fraction) else f"{c.peak_v:.3f} V"
        tab.add_row(c.name, _num(c.peak, ".4g"), _num(c.peak_recent, ".4g"), _num(c.rms_recent, ".4g"), c.unit,
                    Text(rng, style=style), Text(STATE_WORD[c.state], style=style))
    parts = [Text(title, style="bold"), head, tab]
    if s.trace is not None:
        parts.append(trace_text(s.trace, width=min(width, 100), height=12))
    return Group(*parts)


def trace_text(trace: dict, width: int = 80, height: int = 12) -> Text:
    """aE_t and aE_n over the last revolution, side by side, each on its own scale (plotext), as rich Text."""
    import plotext as plt

    names = [n for n in ("aE_t", "aE_n") if n in trace]
    panels = []
    for name in names:
        plt.clf()
        plt.plotsize(width // len(names), height)
        plt.theme("clear")
        plt.plot(list(map(float, trace["x"])), list(map(float, trace[name])), marker="dot")
        plt.title(f"{name} [{trace['unit']}], {trace['what']}")
        plt.xlabel(trace["x_unit"])
        panels.append(plt.build().splitlines())
    rows = max(len(p) for p in panels)
    lines = ["".join(p[i] if i < len(p) else "" for p in panels) for i in range(rows)]
    return Text.from_ansi("\n".join(lines))
