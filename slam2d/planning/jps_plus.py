"""JPS+: Jump Point Search over precomputed jump distances (Harabor & Grastien, ICAPS 2014; Rabin,
Game AI Pro 2, ch. 14), numba.

Preprocessing stores, for every free cell and each of the 8 moves, how far the
online jump of :mod:`~slam2d.planning.jps` would go without a goal: ``d > 0``
steps to the next jump point, or ``-d >= 0`` steps before the next move is not
allowed (a wall). One sweep per move (int16, 8 values a cell; tens of ms on a
512×512 map), so the table is cheap to rebuild when the map changes: build a new
planner on the new grid.

A query is the A* of JPS (its kernel in jps.py) with each jump replaced by a table look-up and a goal
test: a straight move reaches the goal when it lies ahead on the line within
``|d|`` steps; a diagonal move stops at the cell in line with the goal (the
*target* point, ``min(|Δrow|, |Δcol|)`` steps) when the goal lies in its quadrant
within ``|d|`` steps; otherwise the move reaches its jump point if ``d > 0``.
Same graph, pruning rules and optimal lengths as JPS and A*; no costmaps.
"""

from __future__ import annotations

import time

import numpy as np
from numba import njit

from slam2d.planning.astar import _DC, _DR, move_mask
from slam2d.planning.base import register_planner
from slam2d.planning.grid import PlanningGrid
from slam2d.planning.jps import JPS, _forced, _horiz, _vert

__all__ = ["JPSPlus", "jump_distances"]


def _table(moves, free, h: int, w: int) -> np.ndarray:
    """((h + 2) (w + 2), 8) jump distances of the padded grid (module docstring), int16 (int32 on maps
    over 32 000 cells a side); 0 on blocked cells. A cell's 8 values are adjacent in memory: a query
    reads them together."""
    dist = np.zeros(((h + 2) * (w + 2), 8), np.int16 if max(h, w) < 32_000 else np.int32)
    _jump_distances(moves, free, h, w, _DR, _DC, dist)
    return dist


@njit(cache=True)
def _jump_distances(moves, free, h, w, dr_of, dc_of, dist):
    """Fill ``dist`` (zeros, see :func:`_table`) with the jump distances of the padded grid."""
    width = w + 2
    for k in range(8):  # axial moves first: the diagonal ones read them
        dr = dr_of[k]
        dc = dc_of[k]
        step = dr * width + dc
        kv = _vert(dr)
        kh = _horiz(dc)
        # visit cell n after n + step: rows against dr, columns against dc
        r_first, r_last, r_inc = (h, 0, -1) if dr > 0 else (1, h + 1, 1)
        c_first, c_last, c_inc = (w, 0, -1) if dc > 0 else (1, w + 1, 1)
        for r in range(r_first, r_last, r_inc):
            for c in range(c_first, c_last, c_inc):
                n = r * width + c
                if not (moves[n] >> k) & 1:
                    continue  # 0: no step possible (or a blocked cell)
                m = n + step
                if dr == 0 or dc == 0:
                    stop = _forced(free, width, m, dr, dc)
                else:
                    stop = dist[m, kv] > 0 or dist[m, kh] > 0
                if stop:
                    dist[n, k] = 1
                elif dist[m, k] > 0:
                    dist[n, k] = dist[m, k] + 1
                else:
                    dist[n, k] = dist[m, k] - 1


def jump_distances(free: np.ndarray) -> np.ndarray:
    """JPS+ jump distances (8, H, W) of a free mask (H, W): per move of astar.py's order (up, down,
    left, right, then the diagonals), ``d > 0`` steps to the jump point, ``-d`` steps to a wall."""
    free = np.asarray(free, dtype=bool)
    h, w = free.shape
    d = _table(move_mask(free), np.pad(free, 1).astype(np.uint8).ravel(), h, w)
    return d.T.reshape(8, h + 2, w + 2)[:, 1:-1, 1:-1].copy()


class JPSPlus(JPS):
    """JPS+ over a :class:`PlanningGrid` (or a bool mask): the jump distances are built once
    (``build_seconds`` wall time, ``table_bytes``); queries as :class:`~slam2d.planning.jps.JPS`."""

    name = "JPS+"

    def __init__(self, grid: PlanningGrid | np.ndarray, cost: np.ndarray | None = None):
        t0 = time.perf_counter()
        super().__init__(grid, cost)
        h, w = self.shape
        self.table = _table(self.moves, self.free_p, h, w)
        self.use_table = True
        self.build_seconds = time.perf_counter() - t0
        self.table_bytes = self.table.nbytes


@register_planner("jps_plus")
def jps_plus_planner(grid: PlanningGrid | np.ndarray) -> JPSPlus:
    """JPS+: Jump Point Search with jump distances precomputed per cell and move (rebuilt per map)."""
    return JPSPlus(grid)
