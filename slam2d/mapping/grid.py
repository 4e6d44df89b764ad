"""The occupancy grid type: log-odds cells, resolution and origin, rows going up in y. Built by
:func:`slam2d.mapping.occupancy.build_grid` from poses and scans, read by :func:`slam2d.mapping.maps.load_map`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slam2d.types import GridFrame

__all__ = ["OccupancyGrid", "logit"]


@dataclass(eq=False)
class OccupancyGrid(GridFrame):
    """Log-odds grid: ``log_odds`` (H, W) float32, ``resolution`` m/cell,
    ``origin`` (x, y) m of the lower-left corner of cell ``[0, 0]``."""

    log_odds: np.ndarray
    resolution: float
    origin: tuple[float, float]

    def __post_init__(self):
        self.log_odds = np.asarray(self.log_odds, dtype=np.float32)
        if self.log_odds.ndim != 2:
            raise ValueError(f"log_odds must be 2-D, got shape {self.log_odds.shape}")
        self.resolution = float(self.resolution)
        self.origin = (float(self.origin[0]), float(self.origin[1]))

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) in cells."""
        return self.log_odds.shape

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(x_min, x_max, y_min, y_max) in metres (matplotlib ``extent``)."""
        h, w = self.shape
        ox, oy = self.origin
        return ox, ox + w * self.resolution, oy, oy + h * self.resolution

    def probability(self) -> np.ndarray:
        """Occupancy probability (H, W) in [0, 1]."""
        return 1.0 / (1.0 + np.exp(-self.log_odds.astype(np.float64)))

    def occupied_mask(self, thresh: float = 0.65) -> np.ndarray:
        """Cells with occupancy probability > ``thresh`` (as map_server reads a map), bool (H, W)."""
        return self.log_odds > np.float64(logit(thresh))

    def free_mask(self, thresh: float = 0.196) -> np.ndarray:
        """Cells with occupancy probability < ``thresh`` (as map_server reads a map), bool (H, W)."""
        return self.log_odds < np.float64(logit(thresh))


def logit(p: float) -> float:
    """Log-odds ``log(p / (1 - p))`` of a probability ``p`` in (0, 1).

    ``log_odds > logit(t)`` is ``probability > t`` without a float64 copy of the grid.
    """
    return float(np.log(p) - np.log1p(-p))
