"""Sparse storage of an occupancy grid (Tian 2016, section 3.1.1): a triplet (COO) table and a hash table.

Both keep the cells whose log-odds is non-zero (unknown, log-odds 0, is the
background) with their exact float32 values, so ``to_grid`` gives back the
grid bit for bit. The thesis stores a grid sparsely when the non-zero share is
below :data:`SPARSE_SHARE` (5 %); :func:`sparsity` reports that share for the
log-odds (free and occupied cells) and for the occupied cells alone.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np

from slam2d.mapping.grid import OccupancyGrid

__all__ = ["SPARSE_SHARE", "Triplets", "HashedGrid", "sparsity"]

SPARSE_SHARE = 0.05
"""Largest non-zero share for which the thesis stores a grid sparsely."""


def sparsity(grid: OccupancyGrid, occupied_thresh: float = 0.65) -> dict:
    """Non-zero and occupied shares of ``grid``'s cells in [0, 1], and whether each is below the 5 % rule."""
    n = grid.log_odds.size
    nonzero = np.count_nonzero(grid.log_odds) / n
    occupied = np.count_nonzero(grid.occupied_mask(occupied_thresh)) / n
    return {"cells": int(n), "nonzero_share": float(nonzero), "occupied_share": float(occupied),
            "nonzero_sparse": bool(nonzero < SPARSE_SHARE), "occupied_sparse": bool(occupied < SPARSE_SHARE)}


@dataclass(eq=False)
class Triplets:
    """COO table of a grid's non-zero cells: ``rows``, ``cols`` (int32), ``values`` (float32 log-odds),
    ``shape`` (H, W) cells, ``resolution`` m/cell, ``origin`` (x, y) m; row-major order."""

    rows: np.ndarray
    cols: np.ndarray
    values: np.ndarray
    shape: tuple[int, int]
    resolution: float
    origin: tuple[float, float]

    @classmethod
    def from_grid(cls, grid: OccupancyGrid) -> Triplets:
        rows, cols = np.nonzero(grid.log_odds)
        return cls(rows.astype(np.int32), cols.astype(np.int32), grid.log_odds[rows, cols].copy(),
                   grid.shape, grid.resolution, grid.origin)

    def to_grid(self) -> OccupancyGrid:
        log_odds = np.zeros(self.shape, np.float32)
        log_odds[self.rows, self.cols] = self.values
        return OccupancyGrid(log_odds, self.resolution, self.origin)

    def to_scipy(self):
        """The table as a ``scipy.sparse.coo_array`` (H, W)."""
        from scipy.sparse import coo_array

        return coo_array((self.values, (self.rows, self.cols)), shape=self.shape)

    def __len__(self) -> int:
        return len(self.rows)

    @property
    def nbytes(self) -> int:
        """Bytes of the three columns (4 + 4 + 4 a cell)."""
        return self.rows.nbytes + self.cols.nbytes + self.values.nbytes


class HashedGrid:
    """Hash table of a grid's non-zero cells, ``row * W + col`` -> log-odds; ``grid[row, col]`` reads
    one cell (0.0, unknown, where absent), as the thesis suggests for a map indexed often."""

    def __init__(self, cells: dict[int, float], shape: tuple[int, int], resolution: float, origin):
        self.cells, self.shape = cells, (int(shape[0]), int(shape[1]))
        self.resolution, self.origin = float(resolution), (float(origin[0]), float(origin[1]))

    @classmethod
    def from_grid(cls, grid: OccupancyGrid) -> HashedGrid:
        flat = np.flatnonzero(grid.log_odds)
        return cls(dict(zip(flat.tolist(), grid.log_odds.ravel()[flat].tolist())), grid.shape, grid.resolution,
                   grid.origin)

    def __getitem__(self, rc) -> float:
        row, col = rc
        if not (0 <= row < self.shape[0] and 0 <= col < self.shape[1]):
            raise IndexError(f"cell ({row}, {col}) outside a {self.shape} grid")
        return self.cells.get(row * self.shape[1] + col, 0.0)

    def __len__(self) -> int:
        return len(self.cells)

    def to_grid(self) -> OccupancyGrid:
        log_odds = np.zeros(self.shape[0] * self.shape[1], np.float32)
        log_odds[np.fromiter(self.cells.keys(), np.int64, len(self.cells))] = np.fromiter(
            self.cells.values(), np.float32, len(self.cells))
        return OccupancyGrid(log_odds.reshape(self.shape), self.resolution, self.origin)

    @property
    def nbytes(self) -> int:
        """CPython bytes: the table plus one int key (28 B) and one float value (24 B) per cell."""
        return sys.getsizeof(self.cells) + len(self.cells) * (28 + 24)
