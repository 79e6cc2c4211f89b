"""What every model level returns: ``SimulationResult`` and the indicator keys of the paper's tables.

A model computes its time series as numpy columns and its indicators from them; the xarray
Dataset is assembled from those columns once, when something first reads ``result.dataset``
(``DatasetParts``, labtool.common.datasets.dataset): a caller that wants the indicators and the
warnings (``labtool simulate --json``, a sweep through ``simulate``) never builds it, nor imports
xarray. The values are the same either way: the Dataset is made of the very arrays.
"""
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
class DatasetParts:
    """A Dataset not built yet: labtool.common.datasets.dataset's arguments (numpy columns, 1-D
    dimension coordinates) and its attributes, which may still be added to."""

    data_vars: dict
    coords: dict
    attrs: dict = dataclasses.field(default_factory=dict)

    def build(self) -> xr.Dataset:
        from labtool.common.datasets import dataset

        return dataset(self.data_vars, self.coords, self.attrs)


class SimulationResult:
    """Time series (xarray, SI, units on every variable), the paper's indicators, and what the
    model found doubtful about its own validity (``warnings``: one sentence each, also in the
    dataset's ``validity_warnings`` attribute).

    ``dataset``: an xarray Dataset, or its ``DatasetParts``, built at the first read of
    ``.dataset`` (module doc); ``attrs`` are the dataset's attributes either way (added to before
    the build, they are in it)."""

    def __init__(self, dataset, indicators: dict, model: str, reason: str = "", wall_s: float = 0.0,
                 warnings: list | None = None):
        self._dataset = dataset
        self.indicators, self.model, self.reason, self.wall_s = indicators, model, reason, wall_s
        self.warnings = [] if warnings is None else warnings

    @property
    def dataset(self) -> xr.Dataset:
        if isinstance(self._dataset, DatasetParts):
            self._dataset = self._dataset.build()
        return self._dataset

    @property
    def attrs(self) -> dict:
        return self._dataset.attrs

    def __repr__(self) -> str:
        return (f"SimulationResult(model={self.model!r}, reason={self.reason!r}, wall_s={self.wall_s!r}, "
                f"indicators={self.indicators!r}, warnings={self.warnings!r})")


def empty_indicators() -> dict:
    return {k: None for k in INDICATORS}
