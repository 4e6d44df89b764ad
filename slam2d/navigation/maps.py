"""Maps for navigation: a World rasterised to a planning grid, and free masks from any map.

A navigator takes its map as an argument at every call (a known map now, the
live SLAM grid later): a :class:`~slam2d.planning.grid.PlanningGrid` (free mask;
everything else blocked) or an :class:`~slam2d.mapping.occupancy.OccupancyGrid`
(free / occupied / unknown by probability; unknown cells free or blocked as asked).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from slam2d.planning.grid import PlanningGrid

__all__ = ["world_grid", "free_mask", "mark_points", "nearest_free", "pad_to_reach"]

_CHUNK = 20_000  # cell centres per point-in-polygon batch


def world_grid(world, resolution: float = 0.05) -> PlanningGrid:
    """Planning grid (free mask) of a :class:`~slam2d.sim.World` at ``resolution`` (m/cell).

    A cell is blocked when a wall segment crosses it or its centre lies inside an
    obstacle; the grid spans ``world.bounds`` and one cell more on every side, so
    that walls lying on the bounds are in it. A world read from a PNG keeps its
    own cells and resolution.
    """
    if world.grid is not None:
        occ, res = world.grid
        return PlanningGrid(~np.asarray(occ, dtype=bool), res, (0.0, 0.0), world.name)
    (x0, y0), (x1, y1) = world.bounds - [[resolution], [-resolution]]  # a cell beyond: walls on the bounds
    shape = (max(1, int(np.ceil((y1 - y0) / resolution))), max(1, int(np.ceil((x1 - x0) / resolution))))
    grid = PlanningGrid(np.ones(shape, dtype=bool), resolution, (x0, y0), world.name)
    blocked = np.zeros(shape, dtype=bool)
    _mark_cells(grid, blocked, _points_on_segments(world.segments, resolution / 3))
    rows, cols = np.indices(shape)
    centres = grid.cell_to_world(np.stack([rows.ravel(), cols.ravel()], axis=1))
    inside = np.concatenate([world.occupied(centres[i : i + _CHUNK]) for i in range(0, len(centres), _CHUNK)])
    grid.free = ~(blocked | inside.reshape(shape))
    return grid


def _points_on_segments(segments: np.ndarray, spacing: float) -> np.ndarray:
    """Points (P, 2) along segments (K, 2, 2) no farther apart than ``spacing`` (m), ends included."""
    if len(segments) == 0:
        return np.zeros((0, 2))
    a, b = segments[:, 0], segments[:, 1]
    n = np.maximum(1, np.ceil(np.linalg.norm(b - a, axis=1) / spacing).astype(np.int64))
    seg = np.repeat(np.arange(len(segments)), n + 1)
    f = np.concatenate([np.linspace(0.0, 1.0, k + 1) for k in n])
    return a[seg] + f[:, None] * (b - a)[seg]


def _mark_cells(grid, mask: np.ndarray, points: np.ndarray) -> None:
    """Set ``mask`` True at the cells of ``points`` (P, 2) inside the grid."""
    cells = grid.world_to_cell(points)
    ok = grid.in_bounds(cells)
    mask[cells[ok, 0], cells[ok, 1]] = True


def free_mask(map_grid, unknown_free: bool = False, free_thresh: float = 0.196, occupied_thresh: float = 0.65):
    """(free (H, W) bool, resolution m, origin (x, y) m) of a planning or occupancy grid.

    An occupancy grid's cells are free below ``free_thresh``, occupied above
    ``occupied_thresh`` and unknown between; ``unknown_free`` makes unknown free.
    """
    if isinstance(map_grid, PlanningGrid):
        return map_grid.free, map_grid.resolution, map_grid.origin
    if hasattr(map_grid, "log_odds"):
        free = map_grid.free_mask(free_thresh)
        if unknown_free:
            free = free | ~map_grid.occupied_mask(occupied_thresh)
        return free, map_grid.resolution, map_grid.origin
    raise TypeError(f"a map must be a PlanningGrid or an OccupancyGrid, got {type(map_grid).__name__}")


def mark_points(grid: PlanningGrid, points) -> PlanningGrid:
    """A copy of ``grid`` with the cells of world ``points`` (P, 2) blocked."""
    out = PlanningGrid(grid.free.copy(), grid.resolution, grid.origin, grid.name)
    blocked = np.zeros(grid.shape, dtype=bool)
    _mark_cells(grid, blocked, np.asarray(points, dtype=np.float64).reshape(-1, 2))
    out.free &= ~blocked
    return out


def nearest_free(grid: PlanningGrid, xy, within: float):
    """The cell of ``xy`` (m) if free, else the nearest free cell within ``within`` m; None if none."""
    cell = grid.world_to_cell(xy)
    if grid.is_free(cell):
        return cell
    if not grid.in_bounds(cell):
        return None
    dist, (rows, cols) = ndimage.distance_transform_edt(~grid.free, return_indices=True)
    r, c = int(cell[0]), int(cell[1])
    if dist[r, c] * grid.resolution > within:
        return None
    return np.array([rows[r, c], cols[r, c]])


def pad_to_reach(free: np.ndarray, res: float, origin, point, margin: float):
    """``free`` (H, W) padded with free cells so that ``point`` (x, y) m and ``margin`` m around it
    lie inside; the new origin (x, y) m of cell (0, 0)."""
    origin = np.asarray(origin, dtype=np.float64)
    lo = np.floor((np.asarray(point) - margin - origin) / res).astype(int)  # (col, row) of the corner
    hi = np.floor((np.asarray(point) + margin - origin) / res).astype(int)
    before = np.maximum(-lo, 0)[::-1]  # (rows, cols) to add before
    after = np.maximum(hi - (np.array(free.shape[::-1]) - 1), 0)[::-1]
    if not (before.any() or after.any()):
        return free, tuple(origin)
    padded = np.pad(free, ((before[0], after[0]), (before[1], after[1])), constant_values=True)
    return padded, tuple(origin - res * before[::-1])
