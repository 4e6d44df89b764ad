"""Frontiers on the occupancy grid (Yamauchi 1997; the 2018 thesis, summary §4).

A frontier cell is a known-free cell with an unknown 4-neighbour beyond which the unknown runs
deeper than the robot's width; 8-connected frontier cells form a region; a region shorter than
the robot's width is no frontier. The region's goal is its centre, or the reachable cell nearest
to it (the region's own cells first, then cells within the robot's reach of the region). Goals
near a visited or inaccessible goal, and regions outside an optional bounding polygon, are left
out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from slam2d.exploration.gridops import (
    FREE,
    OCCUPIED,
    UNKNOWN,
    GridView,
    inside_polygon,
    true_cells,
)
from slam2d.exploration.paths import as_paths

WALL_GAP = 2  # cells: frontier cells this close to an occupied cell are left out


@dataclass(eq=False)
class Frontier:
    """A frontier region: ``cells`` (K, 2) (row, col), ``centre`` (x, y) m, ``goal`` (x, y) m
    (reachable), ``size`` cells, ``path`` m from the robot to the goal, ``min_distance`` m
    (Euclidean, robot to the region's nearest cell)."""

    cells: np.ndarray
    centre: np.ndarray
    goal: np.ndarray
    size: int
    path: float
    min_distance: float


def frontier_mask(state: np.ndarray, wall_gap: int = WALL_GAP, depth: int = 0) -> np.ndarray:
    """Frontier cells (H, W) bool: free cells with an unknown 4-neighbour (the grid's edge counts as
    unknown) and no occupied cell within ``wall_gap`` cells (Chebyshev): unknown cells seen through
    gaps in a wall's cells are not open space. With ``depth`` (cells), the unknown must also run
    straight on from a neighbour for more than ``depth`` cells (or to the grid's edge): a strip of
    unknown no deeper than that between known cells, such as the unseen face of a thick wall, is
    no opening."""
    return _frontier_mask(np.asarray(state, dtype=np.int8), int(wall_gap), int(depth))


@njit(cache=True)
def _frontier_mask(state, wall_gap, depth):
    h, w = state.shape
    mask = np.zeros((h, w), dtype=np.bool_)
    for r in range(h):
        for c in range(w):
            if state[r, c] == FREE and _opens(state, r, c, depth):
                mask[r, c] = not _occupied_within(state, r, c, wall_gap)
    return mask


@njit(cache=True)
def _opens(state, r, c, depth):
    """Whether the unknown runs on from (r, c) in one of the four steps for more than ``depth`` cells (at
    least one), or up to the grid's edge."""
    for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        if _unknown_run(state, r, c, dr, dc, depth):
            return True
    return False


def shallow_entries(state: np.ndarray, depth: int) -> np.ndarray:
    """Unknown cells (H, W) bool next to free ones, through which no free 4-neighbour sees the unknown
    run on straight for more than ``depth`` cells (the strips ``frontier_mask`` finds no opening in: a
    thick wall's unseen face; a wedge of unknown beside a wall is entered where it is deep)."""
    return _shallow_entries(np.asarray(state, dtype=np.int8), int(depth))


@njit(cache=True)
def _shallow_entries(state, depth):
    h, w = state.shape
    out = np.zeros((h, w), dtype=np.bool_)
    for r in range(h):
        for c in range(w):
            if state[r, c] != UNKNOWN:
                continue
            entered = deep = False
            for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1)):
                fr, fc = r - dr, c - dc  # a free neighbour looking in the step (dr, dc)
                if 0 <= fr < h and 0 <= fc < w and state[fr, fc] == FREE:
                    entered = True
                    deep |= _unknown_run(state, fr, fc, dr, dc, depth)
            out[r, c] = entered and not deep
    return out


@njit(cache=True)
def _unknown_run(state, r, c, dr, dc, depth):
    """Whether the cells from (r, c) in the step (dr, dc) are unknown for more than ``depth`` cells
    (at least one), or up to the grid's edge."""
    h, w = state.shape
    for k in range(1, depth + 2):
        rr, cc = r + k * dr, c + k * dc
        if rr < 0 or cc < 0 or rr >= h or cc >= w:
            return True
        if state[rr, cc] != UNKNOWN:
            return False
    return True


@njit(cache=True)
def _occupied_within(state, r, c, k):
    h, w = state.shape
    for rr in range(max(r - k, 0), min(r + k + 1, h)):
        for cc in range(max(c - k, 0), min(c + k + 1, w)):
            if state[rr, cc] == OCCUPIED:
                return True
    return False


def depth_cells(depth: float, resolution: float) -> int:
    """``depth`` m in whole cells of ``resolution`` m."""
    return int(round(depth / resolution))


def frontier_regions(mask: np.ndarray, min_cells: int) -> list[np.ndarray]:
    """8-connected regions of ``mask`` with at least ``min_cells`` cells, each (K, 2) (row, col) in raster
    order; regions in the raster order of their first cell."""
    cells, label, n = _label8(np.asarray(mask, dtype=np.bool_))
    order = np.argsort(label, kind="stable")
    sizes = np.bincount(label, minlength=n + 1)
    ends = np.cumsum(sizes)
    return [cells[order[ends[k - 1] : ends[k]]] for k in range(1, n + 1) if sizes[k] >= min_cells]


@njit(cache=True)
def _label8(mask):
    """The cells (N, 2) of ``mask`` in raster order, each one's region label (N,) (1..n, numbered in the
    raster order of the regions' first cells; 8-connected, by depth-first search) and n."""
    h, w = mask.shape
    labels = np.zeros((h, w), dtype=np.int32)
    n_cells = 0
    for r in range(h):
        for c in range(w):
            n_cells += mask[r, c]
    stack = np.empty(n_cells, dtype=np.int64)
    cells = np.empty((n_cells, 2), dtype=np.int64)
    label = np.empty(n_cells, dtype=np.int64)
    n = k = 0
    for r in range(h):
        for c in range(w):
            if not mask[r, c]:
                continue
            if labels[r, c] == 0:
                n += 1
                labels[r, c], stack[0], top = n, r * w + c, 1
                while top > 0:
                    top -= 1
                    vr, vc = stack[top] // w, stack[top] % w
                    for rr in range(max(vr - 1, 0), min(vr + 2, h)):
                        for cc in range(max(vc - 1, 0), min(vc + 2, w)):
                            if mask[rr, cc] and labels[rr, cc] == 0:
                                labels[rr, cc], stack[top] = n, rr * w + cc
                                top += 1
            cells[k, 0], cells[k, 1], label[k] = r, c, labels[r, c]
            k += 1
    return cells, label, n


def find_frontiers(view: GridView, robot_xy, distance, min_size: float, reach: float, polygon=None, avoid=(),
                   avoid_radius: float = 0.5, depth: float = 0.0, nearest: bool = False) -> list[Frontier]:
    """Reachable frontier regions of ``view``.

    ``distance``: path lengths from the robot over traversable cells, a :class:`~slam2d.exploration.paths.Paths`
    or an (H, W) array m (inf: unreachable); ``min_size`` m: shortest region (cells × resolution); ``reach`` m:
    how far from the region a goal cell may lie; ``polygon`` (K, 2) m: frontier cells outside are ignored; goals
    within ``avoid_radius`` of an ``avoid`` point (visited, inaccessible) are left out; ``depth`` m: how deep
    the unknown must run on from a frontier cell (``frontier_mask``); ``nearest``: only the nearest region's
    ``path`` need be exact (the others' may be a lower bound above it: the search stops there).
    """
    paths = as_paths(distance)
    mask = frontier_mask(view.state, depth=depth_cells(depth, view.resolution))
    if polygon is not None:
        rows, cols = np.nonzero(mask)
        keep = inside_polygon(view.to_world(np.column_stack([rows, cols])), polygon)
        mask[rows[~keep], cols[~keep]] = False
    min_cells = max(1, int(np.ceil(min_size / view.resolution)))
    avoid = np.asarray(avoid, dtype=np.float64).reshape(-1, 2)
    robot_xy = np.asarray(robot_xy, dtype=np.float64)[:2]
    kept = []
    for cells in frontier_regions(mask, min_cells):
        goal_cell = _goal_cell(cells, paths.reach, reach / view.resolution)
        if goal_cell is None:
            continue
        goal = view.to_world(goal_cell)
        if len(avoid) and np.hypot(*(avoid - goal).T).min() < avoid_radius:
            continue
        kept.append((cells, goal_cell, goal))
    if not kept:
        return []
    path = paths.lengths(np.array([g for _, g, _ in kept]), nearest=nearest)
    out = []
    for (cells, _, goal), p in zip(kept, path):
        xy = view.to_world(cells)
        out.append(Frontier(cells, xy.mean(axis=0), goal, len(cells), float(p),
                            float(np.hypot(*(xy - robot_xy).T).min())))  # fmt: skip
    return out


def _goal_cell(cells: np.ndarray, reachable: np.ndarray, reach_cells: float):
    """The ``reachable`` (H, W) cell nearest the region's centre: among its own cells, else among cells
    within ``reach_cells`` of them; None if none is reachable."""
    centre = cells.mean(axis=0)
    ok = reachable[cells[:, 0], cells[:, 1]]
    if ok.any():
        own = cells[ok]
        return own[np.argmin(np.hypot(*(own - centre).T))]
    k = int(np.ceil(reach_cells))
    lo = np.maximum(cells.min(axis=0) - k, 0)
    hi = np.minimum(cells.max(axis=0) + k + 1, reachable.shape)
    found = _cells_within(np.ascontiguousarray(cells, dtype=np.int64), reachable[lo[0] : hi[0], lo[1] : hi[1]], lo,
                          k, float(reach_cells))  # fmt: skip
    if len(found) == 0:
        return None
    return found[np.argmin(np.hypot(*(found - centre).T))]


@njit(cache=True)
def _cells_within(cells, reachable, lo, k, reach):
    """The ``reachable`` cells (window (h, w) bool whose cell (0, 0) is ``lo``) within ``reach`` cells (Euclidean,
    between centres) of one of ``cells`` (K, 2) (row, col), in raster order (K', 2); ``k`` = ceil(reach)."""
    h, w = reachable.shape
    near = np.zeros((h, w), dtype=np.bool_)
    n = 0
    for i in range(cells.shape[0]):
        cr, cc = cells[i, 0] - lo[0], cells[i, 1] - lo[1]
        for r in range(max(cr - k, 0), min(cr + k + 1, h)):
            for c in range(max(cc - k, 0), min(cc + k + 1, w)):
                if not near[r, c] and reachable[r, c] and np.sqrt(float((r - cr) ** 2 + (c - cc) ** 2)) <= reach:
                    near[r, c] = True
                    n += 1
    return true_cells(near, n, lo[0], lo[1])
