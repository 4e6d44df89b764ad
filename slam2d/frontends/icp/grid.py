"""The local map's points bucketed on a dense grid, and their nearest neighbours (numba)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

__all__ = ["SearchGrid", "knn"]

GRID_CELLS_PER_POINT = 16  # the neighbour-search grid has at most this many cells per map point


class SearchGrid(NamedTuple):
    """The local map's points bucketed on a dense grid for neighbour search.

    ``points`` (N, 2) are sorted by cell; those of cell (ix, iy) are
    ``points[start[ix * ny + iy]:start[ix * ny + iy + 1]]``. Cell (0, 0) has
    its lower corner at (x0, y0); cells are ``cell`` m wide.
    """

    points: np.ndarray
    start: np.ndarray
    nx: int
    ny: int
    x0: float
    y0: float
    cell: float

    @classmethod
    def build(cls, points: np.ndarray, cell: float) -> SearchGrid:
        """Bucket ``points`` (N >= 1, 2) in cells of at least ``cell`` m (wider over sparse maps)."""
        lo = points.min(axis=0)
        extent = points.max(axis=0) - lo
        cell = max(cell, float(np.sqrt(extent[0] * extent[1] / (GRID_CELLS_PER_POINT * len(points)))))
        nx, ny = (extent // cell).astype(np.int64) + 1
        ordered, start = _bucket(points, lo[0], lo[1], cell, nx, ny)
        return cls(ordered, start, int(nx), int(ny), float(lo[0]), float(lo[1]), cell)


@njit(cache=True, nogil=True)
def _bucket(points, x0, y0, cell, nx, ny):
    """``points`` (N, 2) sorted by grid cell and the cells' start offsets (nx * ny + 1,); see ``SearchGrid``."""
    n = len(points)
    cells = np.empty(n, np.int64)
    start = np.zeros(nx * ny + 1, np.int64)
    for i in range(n):
        ix = min(int((points[i, 0] - x0) / cell), nx - 1)
        iy = min(int((points[i, 1] - y0) / cell), ny - 1)
        cells[i] = ix * ny + iy
        start[cells[i] + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    ordered = np.empty((n, 2))
    for i in range(n):
        ordered[fill[cells[i]]] = points[i]
        fill[cells[i]] += 1
    return ordered, start


@njit(cache=True, nogil=True)
def knn(grid, x, y, radius, idx, d2):
    """The up to ``len(idx)`` map points nearest to (x, y) within ``radius``; returns their count.

    Rings of cells of ``grid`` (a ``SearchGrid``) are searched outwards until the
    next ring cannot hold a closer point. Fills ``idx`` (rows of
    ``grid.points``) and ``d2`` (squared m) in increasing distance.
    """
    pts, start, nx, ny, cell = grid.points, grid.start, grid.nx, grid.ny, grid.cell
    k, n = len(idx), 0
    cx, cy = int(np.floor((x - grid.x0) / cell)), int(np.floor((y - grid.y0) / cell))
    r2 = radius * radius
    ring = 0
    while (ring - 1) * cell <= radius and (n < k or ((ring - 1) * cell) ** 2 <= d2[n - 1]):
        for ix in range(max(cx - ring, 0), min(cx + ring + 1, nx)):
            edge = ix == cx - ring or ix == cx + ring
            for iy in range(cy - ring, cy + ring + 1, 1 if edge else 2 * ring):  # a ring's cells only
                if iy < 0 or iy >= ny:
                    continue
                c = ix * ny + iy
                for p in range(start[c], start[c + 1]):
                    dd = (pts[p, 0] - x) ** 2 + (pts[p, 1] - y) ** 2
                    if dd <= r2 and (n < k or dd < d2[n - 1]):
                        m = min(n, k - 1)
                        while m > 0 and d2[m - 1] > dd:
                            d2[m], idx[m] = d2[m - 1], idx[m - 1]
                            m -= 1
                        d2[m], idx[m] = dd, p
                        n = min(n + 1, k)
        ring += 1
    return n
