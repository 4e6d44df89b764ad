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
    cells, starts = _regions(mask, min_cells)
    return [cells[starts[k] : starts[k + 1]] for k in range(len(starts) - 1)]


def _regions(mask: np.ndarray, min_cells: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`frontier_regions` as one array: the regions' cells (N, 2) one region after another, region k
    from ``starts[k]`` to ``starts[k + 1]`` (R + 1,)."""
    mask = np.ascontiguousarray(mask, dtype=np.bool_)
    cells, label, n = _label8(mask, np.flatnonzero(mask))
    order = np.argsort(label, kind="stable")
    sizes = np.bincount(label, minlength=n + 1)[1:]
    big = sizes >= min_cells
    keep = big[label - 1][order]
    starts = np.concatenate([[0], np.cumsum(sizes[big])])
    return cells[order[keep]], starts


@njit(cache=True)
def _label8(mask, flat):
    """The cells (N, 2) of ``mask`` (H, W) bool in raster order (``flat`` (N,): their flat indices, in order), each
    one's region label (N,) (1..n, numbered in the raster order of the regions' first cells; 8-connected, by
    depth-first search) and n."""
    h, w = mask.shape
    n_cells = flat.shape[0]
    labels = np.zeros(h * w, dtype=np.int32)
    stack = np.empty(n_cells, dtype=np.int64)
    cells = np.empty((n_cells, 2), dtype=np.int64)
    label = np.empty(n_cells, dtype=np.int64)
    n = 0
    for k in range(n_cells):
        v = flat[k]
        r, c = v // w, v % w
        if labels[v] == 0:
            n += 1
            labels[v], stack[0], top = n, v, 1
            while top > 0:
                top -= 1
                vr, vc = stack[top] // w, stack[top] % w
                for rr in range(max(vr - 1, 0), min(vr + 2, h)):
                    for cc in range(max(vc - 1, 0), min(vc + 2, w)):
                        if mask[rr, cc] and labels[rr * w + cc] == 0:
                            labels[rr * w + cc], stack[top] = n, rr * w + cc
                            top += 1
        cells[k, 0], cells[k, 1], label[k] = r, c, labels[v]
    return cells, label, n


def find_frontiers(view: GridView, robot_xy, distance, min_size: float, reach: float, polygon=None, avoid=(),
                   avoid_radius: float = 0.5, depth: float = 0.0, nearest: bool = False, mask=None) -> list[Frontier]:
    """Reachable frontier regions of ``view``.

    ``distance``: path lengths from the robot over traversable cells, a :class:`~slam2d.exploration.paths.Paths`
    or an (H, W) array m (inf: unreachable); ``min_size`` m: shortest region (cells × resolution); ``reach`` m:
    how far from the region a goal cell may lie; ``polygon`` (K, 2) m: frontier cells outside are ignored; goals
    within ``avoid_radius`` of an ``avoid`` point (visited, inaccessible) are left out; ``depth`` m: how deep
    the unknown must run on from a frontier cell (``frontier_mask``); ``nearest``: only the nearest region's
    ``path`` need be exact (the others' may be a lower bound above it: the search stops there); ``mask``: the
    view's ``frontier_mask`` of that depth if known (changed here).
    """
    paths = as_paths(distance)
    if mask is None:
        mask = frontier_mask(view.state, depth=depth_cells(depth, view.resolution))
    if polygon is not None:
        rows, cols = np.nonzero(mask)
        keep = inside_polygon(view.to_world(np.column_stack([rows, cols])), polygon)
        mask[rows[~keep], cols[~keep]] = False
    min_cells = max(1, int(np.ceil(min_size / view.resolution)))
    avoid = np.asarray(avoid, dtype=np.float64).reshape(-1, 2)
    robot_xy = np.asarray(robot_xy, dtype=np.float64)[:2]
    cells, starts = _regions(mask, min_cells)
    if len(starts) < 2:
        return []
    goal_cells = _goal_cells(cells, starts, paths.reach, reach / view.resolution)
    goals = view.to_world(goal_cells)
    kept = goal_cells[:, 0] >= 0
    if len(avoid):
        kept &= np.hypot(*(avoid[None] - goals[:, None]).transpose(2, 0, 1)).min(axis=1) >= avoid_radius
    kept = np.flatnonzero(kept)
    if not len(kept):
        return []
    path = paths.lengths(goal_cells[kept], nearest=nearest)
    xy = view.to_world(cells)
    near = np.hypot(*(xy - robot_xy).T)
    sizes = np.diff(starts)
    centres = np.add.reduceat(xy, starts[:-1]) / sizes[:, None]
    nearest_cell = np.minimum.reduceat(near, starts[:-1])
    return [Frontier(cells[starts[k] : starts[k + 1]], centres[k], goals[k].copy(), int(sizes[k]), float(p),
                     float(nearest_cell[k])) for k, p in zip(kept, path)]  # fmt: skip


def _goal_cell(cells: np.ndarray, reachable: np.ndarray, reach_cells: float):
    """The ``reachable`` (H, W) cell nearest the region's centre: among its own cells, else among cells
    within ``reach_cells`` of them; None if none is reachable."""
    cells = np.ascontiguousarray(cells, dtype=np.int64).reshape(-1, 2)
    goal = _goal_cells(cells, np.array([0, len(cells)]), reachable, float(reach_cells))[0]
    return None if goal[0] < 0 else goal


@njit(cache=True)
def _goal_cells(cells, starts, reachable, reach):
    """:func:`_goal_cell` (R, 2) of each region (cells ``starts[k]`` to ``starts[k + 1]`` of ``cells`` (N, 2)),
    (-1, -1) where none; ``reach`` cells."""
    n = starts.shape[0] - 1
    out = np.full((n, 2), -1, dtype=np.int64)
    k = int(np.ceil(reach))
    for g in range(n):
        a, b = starts[g], starts[g + 1]
        sr = sc = 0.0
        for i in range(a, b):
            sr += cells[i, 0]
            sc += cells[i, 1]
        cr, cc = sr / (b - a), sc / (b - a)  # the centre, as a mean of whole numbers: exact sums
        best = np.inf
        for i in range(a, b):  # the nearest of its own reachable cells (the first of equals)
            if reachable[cells[i, 0], cells[i, 1]]:
                d = np.hypot(cells[i, 0] - cr, cells[i, 1] - cc)
                if d < best:
                    best, out[g, 0], out[g, 1] = d, cells[i, 0], cells[i, 1]
        if best < np.inf:
            continue
        lo0, lo1 = max(cells[a:b, 0].min() - k, 0), max(cells[a:b, 1].min() - k, 0)
        hi0 = min(cells[a:b, 0].max() + k + 1, reachable.shape[0])
        hi1 = min(cells[a:b, 1].max() + k + 1, reachable.shape[1])
        near = _cells_within(cells[a:b], reachable[lo0:hi0, lo1:hi1], lo0, lo1, k, reach)
        for r in range(near.shape[0]):  # else the nearest reachable cell within reach, in raster order
            for c in range(near.shape[1]):
                if near[r, c]:
                    d = np.hypot(r + lo0 - cr, c + lo1 - cc)
                    if d < best:
                        best, out[g, 0], out[g, 1] = d, r + lo0, c + lo1
    return out


@njit(cache=True)
def _cells_within(cells, reachable, lo0, lo1, k, reach):
    """The ``reachable`` cells (window (h, w) bool whose cell (0, 0) is (``lo0``, ``lo1``)) within ``reach`` cells
    (Euclidean, between centres) of one of ``cells`` (K, 2) (row, col): (h, w) bool; ``k`` = ceil(reach)."""
    h, w = reachable.shape
    near = np.zeros((h, w), dtype=np.bool_)
    for i in range(cells.shape[0]):
        cr, cc = cells[i, 0] - lo0, cells[i, 1] - lo1
        for r in range(max(cr - k, 0), min(cr + k + 1, h)):
            for c in range(max(cc - k, 0), min(cc + k + 1, w)):
                if not near[r, c] and reachable[r, c] and np.sqrt(float((r - cr) ** 2 + (c - cc) ** 2)) <= reach:
                    near[r, c] = True
    return near
