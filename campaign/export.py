"""A campaign's curves: one set per finished point (labtool.reports.curves' layout), for
``labtool export campaign/ --format ...``."""
from __future__ import annotations

from pathlib import Path

import xarray as xr

from labtool.common.errors import InputError
from labtool.common.names import shown
from labtool.reports.export import point_curves


def campaign_curves(folder: Path) -> list[tuple[str, xr.Dataset]]:
    """One set of curves per finished point of a campaign folder (its cycles.nc and summary.json)."""
    from labtool.campaign.collect import load_point_folder

    out = []
    for pf in sorted(p for p in (folder / "points").iterdir() if p.is_dir()):
        if not ((pf / "summary.json").is_file() and (pf / "cycles.nc").is_file()):
            continue
        rec = load_point_folder(pf, pf.name)
        meta = {"campaign": shown(str(folder)), "point": pf.name}
        run = rec.summary.get("measured", {}).get("run", {}) or {}
        meta.update({k: v for k, v in run.items() if v is not None})
        for k, v in (rec.summary.get("operating_point") or {}).items():
            if isinstance(v, (str, int, float)) and not isinstance(v, bool):
                meta[f"op_{k}"] = v
        verdict = (rec.summary.get("verdict") or {}).get("sentence")
        if verdict:
            meta["verdict"] = verdict
        out.append((pf.name, point_curves(rec.cycles, meta)))
    if not out:
        raise InputError(f"campaign {shown(folder)} has no finished point yet; run 'labtool campaign run' first")
    return out
