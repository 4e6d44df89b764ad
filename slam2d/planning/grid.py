"""Planning grids: free-space masks from occupancy maps, floor plans and Moving AI maps.

Convention (as :class:`~slam2d.mapping.occupancy.OccupancyGrid`): ``free[row, col]``
with row = y index and col = x index; cell ``[0, 0]`` has its lower-left corner
at ``origin`` (m). Occupancy maps and PNG floor plans are flipped so that rows
go up (image row 0 is the top of the map). Moving AI maps keep their file
order: ``row`` is the ``.scen`` y and ``col`` the ``.scen`` x, with resolution 1
and origin (0, 0), so cell ``(y, x)`` has its centre at world ``(x + 0.5, y + 0.5)``.

Loaders raise :class:`~slam2d.errors.InputError` naming the file and line.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage

from slam2d.errors import InputError, not_a_file
from slam2d.mapping.export import map_yaml_free_thresh
from slam2d.mapping.maps import is_map_yaml, load_map, read_movingai_map
from slam2d.types import GridFrame

__all__ = [
    "PlanningGrid",
    "Scenarios",
    "load_grid",
    "load_movingai_map",
    "load_scenarios",
    "grid_from_occupancy",
    "inflate",
    "wall_cost",
]

DEFAULT_FREE_THRESH = 0.196
"""Occupancy probability below which a cell is free (map_server's default ``free_thresh``)."""


@dataclass(eq=False)
class PlanningGrid(GridFrame):
    """Free-space mask ``free`` (H, W) bool, ``resolution`` m/cell, ``origin`` (x, y) m
    of the lower-left corner of cell ``[0, 0]``; ``name`` is where it came from."""

    free: np.ndarray
    resolution: float = 1.0
    origin: tuple[float, float] = (0.0, 0.0)
    name: str = ""

    def __post_init__(self):
        self.free = np.ascontiguousarray(self.free, dtype=bool)
        if self.free.ndim != 2 or min(self.free.shape) < 1:
            raise ValueError(f"free must be a non-empty 2-D mask, got shape {self.free.shape}")
        if not self.resolution > 0:
            raise ValueError(f"resolution must be > 0, got {self.resolution}")
        self.resolution = float(self.resolution)
        self.origin = (float(self.origin[0]), float(self.origin[1]))

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) in cells."""
        return self.free.shape

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(x_min, x_max, y_min, y_max) in m (matplotlib ``extent`` with ``origin="lower"``)."""
        h, w = self.shape
        ox, oy = self.origin
        return ox, ox + w * self.resolution, oy, oy + h * self.resolution

    def is_free(self, cells) -> np.ndarray:
        """Whether (row, col) cells ``(..., 2)`` are inside the grid and free."""
        rc = np.asarray(cells, dtype=np.int64)
        ok = self.in_bounds(rc)
        out = np.zeros(ok.shape, dtype=bool)
        out[ok] = self.free[rc[..., 0][ok], rc[..., 1][ok]]
        return out

    def clearance(self) -> np.ndarray:
        """Distance (H, W) in m from each cell centre to the nearest blocked cell centre
        (the area outside the grid counts as blocked); 0 on blocked cells."""
        padded = np.pad(self.free, 1, constant_values=False)
        return ndimage.distance_transform_edt(padded)[1:-1, 1:-1] * self.resolution

    def inflated(self, radius: float) -> PlanningGrid:
        """A copy with obstacles grown by ``radius`` m (see :func:`inflate`)."""
        return PlanningGrid(inflate(self.free, radius / self.resolution), self.resolution, self.origin, self.name)


def refresh_clearance(clear: np.ndarray, free: np.ndarray, changed: np.ndarray, resolution: float,
                      cap: float) -> tuple[slice, slice]:  # fmt: skip
    """Brings ``clear`` (H, W) m, the :meth:`PlanningGrid.clearance` of a grid capped at ``cap`` m, up to date
    in place after the cells ``changed`` (H, W) bool of ``free`` (H, W), the grid now, changed: only cells
    within ``cap`` of the changed ones can differ, and only blocked cells within ``2 cap`` of them count.
    Returns the window (rows, cols) rewritten."""
    rows, cols = np.nonzero(changed)
    if len(rows) == 0:
        return slice(0, 0), slice(0, 0)
    k = int(np.ceil(cap / resolution)) + 1
    h, w = free.shape
    # windows in the coordinates of the grid padded by one blocked cell, as ``clearance`` has it
    lo, hi = np.array([rows.min(), cols.min()]) + 1, np.array([rows.max(), cols.max()]) + 2
    in_lo, in_hi = np.maximum(lo - 2 * k, 0), np.minimum(hi + 2 * k, (h + 2, w + 2))
    out_lo, out_hi = np.maximum(lo - k, 1), np.minimum(hi + k, (h + 1, w + 1))
    window = np.zeros(in_hi - in_lo, dtype=bool)
    r0, c0 = np.maximum(in_lo, 1)
    r1, c1 = np.minimum(in_hi, (h + 1, w + 1))
    window[r0 - in_lo[0] : r1 - in_lo[0], c0 - in_lo[1] : c1 - in_lo[1]] = free[r0 - 1 : r1 - 1, c0 - 1 : c1 - 1]
    dist = ndimage.distance_transform_edt(window) * resolution
    a, b = out_lo - in_lo, out_hi - in_lo
    near = slice(out_lo[0] - 1, out_hi[0] - 1), slice(out_lo[1] - 1, out_hi[1] - 1)
    clear[near] = np.minimum(dist[a[0] : b[0], a[1] : b[1]], cap)
    return near


def around(values: np.ndarray, rows, cols, offsets, outside) -> np.ndarray:
    """``values`` (H, W) at each cell (``rows``, ``cols``) (N,) moved by each of ``offsets`` (K, 2) (rows, cols):
    (N, K), ``outside`` where that falls off the grid."""
    r = np.asarray(rows)[:, None] + np.asarray(offsets)[None, :, 0]
    c = np.asarray(cols)[:, None] + np.asarray(offsets)[None, :, 1]
    h, w = values.shape
    ok = (r >= 0) & (r < h) & (c >= 0) & (c < w)
    out = np.full(r.shape, outside, dtype=values.dtype)
    out[ok] = values[r[ok], c[ok]]
    return out


def inflate(free: np.ndarray, radius_cells: float) -> np.ndarray:
    """Free cells whose centre is farther than ``radius_cells`` from every blocked cell centre.

    Uses the exact Euclidean distance transform; outside the grid counts as
    blocked. ``radius_cells <= 0`` returns a copy of ``free``.
    """
    free = np.asarray(free, dtype=bool)
    if radius_cells <= 0:
        return free.copy()
    dist = ndimage.distance_transform_edt(np.pad(free, 1, constant_values=False))[1:-1, 1:-1]
    return dist > radius_cells


def wall_cost(grid: PlanningGrid, distance: float, weight: float = 1.0) -> np.ndarray:
    """Extra cost layer (H, W) >= 0 that rises linearly to ``weight`` towards walls.

    ``weight * (1 - d / distance)`` for a cell at clearance ``d < distance`` m,
    0 farther away. With the A* step cost ``len * (1 + (c_u + c_v) / 2)`` the
    octile heuristic stays admissible because the layer is never negative.
    """
    if distance <= 0 or weight < 0:
        raise ValueError("wall_cost needs distance > 0 and weight >= 0")
    d = grid.clearance()
    return (weight * np.clip(1.0 - d / distance, 0.0, None)).astype(np.float64)


# ---------------------------------------------------------------- loaders


def load_grid(path, *, resolution: float | None = None, free_thresh: float | None = None) -> PlanningGrid:
    """The planning grid of any map file :func:`slam2d.mapping.maps.load_map` reads: free = occupancy
    probability < ``free_thresh`` (default: a map.yaml's own, else 0.196); unknown cells are blocked."""
    if free_thresh is None:
        free_thresh = map_yaml_free_thresh(path) if is_map_yaml(path) else DEFAULT_FREE_THRESH
    return grid_from_occupancy(load_map(path, resolution), free_thresh, name=str(path))


def load_movingai_map(path) -> PlanningGrid:
    """A Moving AI ``.map`` (:func:`slam2d.mapping.maps.read_movingai_map`) at 1 m per cell, rows as in the file."""
    return PlanningGrid(read_movingai_map(path), 1.0, (0.0, 0.0), str(path))


def grid_from_occupancy(grid, free_thresh: float = DEFAULT_FREE_THRESH, name: str = "") -> PlanningGrid:
    """Free = occupancy probability < ``free_thresh``; unknown and occupied are blocked."""
    return PlanningGrid(grid.free_mask(free_thresh), grid.resolution, grid.origin, name)


@dataclass(eq=False)
class Scenarios:
    """Moving AI scenarios: ``bucket`` (N,), ``start``/``goal`` (N, 2) as (x, y) = (col, row),
    ``optimal`` (N,) octile lengths (cells), map ``width``/``height`` and ``map_name``."""

    bucket: np.ndarray
    map_name: str
    width: int
    height: int
    start: np.ndarray
    goal: np.ndarray
    optimal: np.ndarray

    def __len__(self) -> int:
        return len(self.bucket)

    @property
    def start_cells(self) -> np.ndarray:
        """(N, 2) (row, col) start cells."""
        return self.start[:, ::-1].copy()

    @property
    def goal_cells(self) -> np.ndarray:
        """(N, 2) (row, col) goal cells."""
        return self.goal[:, ::-1].copy()


def _scen_row(line: str, where: str) -> tuple:
    parts = line.split("\t") if "\t" in line else line.split()
    parts = [p.strip() for p in parts]
    if len(parts) != 9:
        raise InputError(where, f"expected 9 fields (bucket map width height sx sy gx gy length), got {len(parts)}")
    try:
        ints = [int(parts[i]) for i in (0, 2, 3, 4, 5, 6, 7)]
        length = float(parts[8])
    except ValueError:
        raise InputError(where, f"non-numeric field in {line.strip()!r}") from None
    b, w, h, sx, sy, gx, gy = ints
    if w <= 0 or h <= 0 or not (0 <= sx < w and 0 <= gx < w and 0 <= sy < h and 0 <= gy < h):
        raise InputError(where, f"start ({sx}, {sy}) or goal ({gx}, {gy}) outside the {w}x{h} map")
    if not np.isfinite(length) or length < 0:
        raise InputError(where, f"optimal length must be finite and >= 0, got {parts[8]}")
    return b, parts[1], w, h, sx, sy, gx, gy, length


def load_scenarios(path) -> Scenarios:
    """Moving AI ``.scen`` (``version 1``, then one scenario a line). One map per file."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, not_a_file(path) or "scenario file not found")
    lines = path.read_text(errors="replace").splitlines()
    if not lines or not lines[0].strip().startswith("version"):
        raise InputError(f"{path}:1", f"expected 'version 1', got {lines[0] if lines else ''!r}")
    rows = [(_scen_row(ln, f"{path}:{i + 1}"), i + 1) for i, ln in enumerate(lines) if i > 0 and ln.strip()]
    if not rows:
        raise InputError(path, "no scenarios")
    first, _ = rows[0]
    for row, lineno in rows:
        if (row[1], row[2], row[3]) != (first[1], first[2], first[3]):
            raise InputError(f"{path}:{lineno}", f"map {row[1]} {row[2]}x{row[3]} differs from the first line's")
    a = np.array([r[0][4:8] for r in rows], dtype=np.int64)
    return Scenarios(
        bucket=np.array([r[0][0] for r in rows], dtype=np.int64),
        map_name=first[1],
        width=first[2],
        height=first[3],
        start=a[:, 0:2].copy(),
        goal=a[:, 2:4].copy(),
        optimal=np.array([r[0][8] for r in rows], dtype=np.float64),
    )
