"""What every model level returns: ``SimulationResult`` and the indicator keys of the paper's tables."""
from __future__ import annotations

import dataclasses

from typing import TYPE_CHECKING

if TYPE_CHECKING:  # xarray is loaded where a Dataset is built (the indicator path of a sweep needs none)
    import xarray as xr

# indicator keys of the paper's Tables 2 and 3 (docs/architecture.md, --json contract)
INDICATORS = (
    "MR13D_max_Nm", "MR13D_min_Nm", "dphi2_max_deg", "domega2_max_rad_s", "domega1_max_rad_s",
    "percussion_max_Ns", "jumps", "impacts", "xel_max_mm", "xel_min_mm",
)


@dataclasses.dataclass
class SimulationResult:
    """Time series (xarray, SI, units on every variable), the paper's indicators, and what the
    model found doubtful about its own validity (``warnings``: one sentence each, also in the
    dataset's ``validity_warnings`` attribute)."""

    dataset: xr.Dataset
    indicators: dict
    model: str
    reason: str = ""
    wall_s: float = 0.0
    warnings: list = dataclasses.field(default_factory=list)


def empty_indicators() -> dict:
    return {k: None for k in INDICATORS}
