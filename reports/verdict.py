"""What the measurement can tell: which model is closest, by how much, and which models it cannot
tell apart (docs/reports.md, "The verdict").

A model X is *ahead* of a model Y when its mean ISO rating (the mean of the omega2 and epsilon2
ratings) beats Y's by more than the measurement resolves for that pair, the larger of

- the revolution-to-revolution scatter: two standard errors of the per-revolution difference of
  the two models' mean ratings (each model rated against every measured revolution; paired, so
  what both models miss alike cancels), and
- the presets' spread: how much the same difference moves between the robustness rows (the other
  solver preset, half the simulated length).

Models whose ratings differ by less are reported as "this measurement cannot tell X and Y apart";
the verdict is *robust* only when the closest model is ahead of every other one. Runs that are the
same motion (the elastic model's omega1 var is its const, the report simulates it once) count once.

Pure functions on the report's plain data (headline, comparisons, robustness rows); ``sentence``
makes the one wording the terminal, the HTML, the PDF and the JSON all show.
"""
from __future__ import annotations

import itertools
import math

import numpy as np

SIGNALS = ("omega2", "epsilon2")
COVERAGE = 2.0          # standard errors: ~95 % for the per-revolution differences


def mean_rating(row: dict) -> float:
    """The mean of a headline or robustness entry's omega2 and epsilon2 ISO ratings [-]."""
    return 0.5 * (row["omega2_iso_rating"] + row["epsilon2_iso_rating"])


def per_revolution_ratings(comparisons: list[dict]) -> dict[str, np.ndarray]:
    """label -> the mean of the omega2 and epsilon2 ISO ratings against each measured revolution."""
    by = {}
    for c in comparisons:
        by.setdefault(c["label"], {})[c["signal"]] = np.array([r["iso_rating"] for r in c["per_revolution"]], float)
    return {lab: 0.5 * (s["omega2"] + s["epsilon2"]) for lab, s in by.items() if all(k in s for k in SIGNALS)
            and s["omega2"].size == s["epsilon2"].size}


def pair_resolution(a: str, b: str, per_rev: dict, rows: list[dict]) -> dict:
    """What the measurement resolves of the rating difference of runs ``a`` and ``b``: the
    revolution-to-revolution ``scatter`` (COVERAGE standard errors of the paired per-revolution
    difference; inf with fewer than two revolutions), the presets' ``spread`` (max - min of the
    difference over the robustness rows; 0 without rows) and ``resolution``, the larger."""
    scatter = math.inf
    if a in per_rev and b in per_rev and per_rev[a].size >= 2:
        d = per_rev[a] - per_rev[b]
        d = d[np.isfinite(d)]
        if d.size >= 2:
            scatter = COVERAGE * float(np.std(d, ddof=1)) / math.sqrt(d.size)
    margins = []
    for r in rows:
        got = {m["label"]: mean_rating(m) for m in r.get("models", ())}
        if a in got and b in got:
            margins.append(got[a] - got[b])
    spread = float(max(margins) - min(margins)) if len(margins) >= 2 else 0.0
    return {"scatter": scatter, "spread": spread, "resolution": max(scatter, spread)}


def judge(headline: list[dict], comparisons: list[dict], rows: list[dict], same_motion: dict[str, str]) -> dict | None:
    """The verdict of a report (None without a simulation).

    headline     rows with ``label`` and the two ISO ratings (labtool.reports.pipeline.headline)
    comparisons  per model, mode and signal, with ``per_revolution`` ISO ratings
    rows         the robustness rows (each with ``models``: label and ratings; or ``error``)
    same_motion  label -> the label of the run it repeats (the same motion, simulated once)

    Returns a dict: ``closest``, ``ranking`` [(label, mean rating)], ``runner_up``, ``margin``,
    ``scatter``, ``spread``, ``resolution`` (of closest vs runner-up), ``cannot_tell_apart`` (groups
    of labels, the closest's group first), ``pairs`` (every pair's margin and resolution),
    ``robust`` (True/False; None when the presets were not checked), ``failed_rows`` and
    ``same_motion``; ``discrimination`` is added by the report when it looked for a better speed."""
    if not headline:
        return None
    ranking = sorted(((h["label"], mean_rating(h)) for h in headline if h["label"] not in same_motion),
                     key=lambda e: -e[1] if math.isfinite(e[1]) else math.inf)
    per_rev = per_revolution_ratings(comparisons)
    ok_rows = [r for r in rows if r.get("closest") is not None]
    failed = [r for r in rows if r.get("closest") is None]
    pairs, tied = [], {}
    for (a, ra), (b, rb) in itertools.combinations(ranking, 2):
        res = pair_resolution(a, b, per_rev, ok_rows)
        margin = ra - rb
        apart = bool(math.isfinite(margin) and margin > res["resolution"])
        pairs.append({"ahead": a, "behind": b, "margin": margin, **res, "told_apart": apart})
        if not apart:
            tied.setdefault(a, set()).add(b)
            tied.setdefault(b, set()).add(a)
    groups = _groups([lab for lab, _ in ranking], tied)
    best = ranking[0][0]
    first = next((p for p in pairs if p["ahead"] == best), None)
    out = {"closest": best, "ranking": ranking, "runner_up": first["behind"] if first else None,
           "margin": first["margin"] if first else None, "scatter": first["scatter"] if first else None,
           "spread": first["spread"] if first else None, "resolution": first["resolution"] if first else None,
           "cannot_tell_apart": groups, "pairs": pairs, "failed_rows": [r.get("error", "") for r in failed],
           "same_motion": dict(same_motion), "discrimination": None}
    ahead_of_all = all(p["told_apart"] for p in pairs if p["ahead"] == best)
    # robust needs the other preset's rows; a failed row says NOT robust, no rows 'not checked'
    checked = len({r["accuracy"] for r in ok_rows}) >= 2
    out["presets_checked"] = checked
    out["robust"] = False if failed else (ahead_of_all if checked else None)
    return out


def _groups(order: list[str], tied: dict) -> list[list[str]]:
    """Connected groups (size >= 2) of the 'cannot tell apart' relation, in ranking order."""
    seen, groups = set(), []
    for lab in order:
        if lab in seen or lab not in tied:
            continue
        group, todo = [], [lab]
        while todo:
            x = todo.pop()
            if x in seen:
                continue
            seen.add(x)
            group.append(x)
            todo.extend(tied.get(x, ()))
        groups.append(sorted(group, key=order.index))
    return groups


def _r(v) -> str:
    return "unknown" if v is None or not math.isfinite(v) else f"{v:.2g}"


def names(labels) -> str:
    """'a', 'a and b', 'a, b and c'."""
    labels = list(labels)
    return labels[0] if len(labels) == 1 else ", ".join(labels[:-1]) + " and " + labels[-1]


def _resolves(p: dict) -> str:
    why = (f"revolution-to-revolution scatter {_r(p['scatter'])}"
           + (f", presets' spread {_r(p['spread'])}" if p.get("spread") else ""))
    return f"the {_r(p['resolution'])} the comparison resolves ({why})"


def sentence(v: dict | None) -> str | None:
    """The verdict in words, one paragraph: the same text on the terminal, in the HTML, the PDF
    and the JSON (``verdict.sentence``)."""
    if v is None:
        return None
    best = v["closest"]
    parts = []
    groups = v["cannot_tell_apart"]
    best_group = next((g for g in groups if best in g), None)
    if v["runner_up"] is None:
        parts.append(f"verdict: {best} is the only model compared")
    elif best_group is not None:
        p = next(p for p in v["pairs"] if p["ahead"] == best and p["behind"] == best_group[1])
        parts.append(f"verdict: this measurement cannot tell {names(best_group)} apart: their mean ISO ratings differ "
                     f"by {_r(abs(p['margin']))}, less than {_resolves(p)}; {best} rates highest, which does not "
                     "settle it")
    else:
        p = {k: v[k] for k in ("scatter", "spread", "resolution")}
        lead = (f"{best} is the closest, ahead of {v['runner_up']} by {_r(v['margin'])} in mean ISO rating, "
                f"more than {_resolves(p)}")
        if v["robust"]:
            parts.append(f"verdict robust: {lead}, at both solver presets and both simulated lengths")
        elif v["robust"] is None:
            parts.append(f"verdict: {lead}; the other solver preset was not checked")
        else:
            parts.append(f"verdict NOT robust: {lead}, but the check at the other preset failed "
                         f"({'; '.join(v['failed_rows'])})")
    for g in groups:
        if g is best_group:
            continue
        p = next(p for p in v["pairs"] if p["ahead"] == g[0] and p["behind"] == g[1])
        parts.append(f"this measurement cannot tell {names(g)} apart: {_r(abs(p['margin']))} apart in mean ISO "
                     f"rating, less than {_resolves(p)}")
    d = v.get("discrimination")
    if d and d.get("sentence"):
        parts.append(d["sentence"])
    for twin, first in v["same_motion"].items():
        parts.append(f"{twin} is the same motion as {first}, counted once")
    text = ". ".join(q[0].upper() + q[1:] if i else q for i, q in enumerate(parts))
    return text if text.endswith(".") else text + "."
