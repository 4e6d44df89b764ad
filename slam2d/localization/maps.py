"""The known map of localisation: occupied and free cells of any map slam2d reads.

``KnownMap.load`` takes a ``map.yaml`` (a slam2d run or any map_server map),
a floor-plan image (0.05 m/px unless told) or the built-in ``office``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage

from slam2d.errors import InputError
from slam2d.mapping.maps import load_map
from slam2d.types import GridFrame

__all__ = ["KnownMap"]

_CHUNK = 5000  # cell centres per distance query (cells x walls floats)


@dataclass(eq=False)
class KnownMap(GridFrame):
    """Occupied and free masks (H, W) bool; ``origin`` (x, y) m of cell (0, 0)'s corner,
    ``resolution`` m per cell, rows along y. Cells neither occupied nor free are unknown."""

    occupied: np.ndarray
    free: np.ndarray
    resolution: float
    origin: tuple[float, float]
    name: str = "map"
    wall_distance: np.ndarray | None = None  # distance (H, W) m from cell centres to the walls (see distance())

    def __post_init__(self):
        self.occupied = np.ascontiguousarray(self.occupied, dtype=bool)
        self.free = np.ascontiguousarray(self.free, dtype=bool) & ~self.occupied
        if self.occupied.ndim != 2 or self.occupied.shape != self.free.shape or min(self.occupied.shape) < 1:
            raise InputError(self.name, f"a map needs equal 2D occupied and free masks, got {self.occupied.shape}")
        if not self.occupied.any():
            raise InputError(self.name, "the map has no occupied cell: nothing to localise against")
        if not self.free.any():
            raise InputError(self.name, "the map has no free cell")
        self.resolution = float(self.resolution)
        self.origin = (float(self.origin[0]), float(self.origin[1]))

    @property
    def shape(self) -> tuple[int, int]:
        return self.occupied.shape

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) in metres."""
        h, w = self.shape
        x0, y0 = self.origin
        return x0, x0 + w * self.resolution, y0, y0 + h * self.resolution

    def distance(self) -> np.ndarray:
        """Distance (H, W) in metres from every cell centre to the nearest wall: the exact one when
        known (a World), else to the nearest occupied cell's edge: scipy's exact Euclidean distance
        transform between cell centres less half a cell (a wall's face is its cells' edge), computed once."""
        if self.wall_distance is None:
            edt = ndimage.distance_transform_edt(~self.occupied) * self.resolution
            self.wall_distance = np.maximum(edt - 0.5 * self.resolution, 0.0)
        return self.wall_distance

    def in_wall(self, xy) -> np.ndarray:
        """Whether points ``xy`` (P, 2) m lie in occupied cells (False off the map)."""
        cells = self.world_to_cell(xy)
        inside = self.in_bounds(cells)
        out = np.zeros(len(cells), dtype=bool)
        out[inside] = self.occupied[cells[inside, 0], cells[inside, 1]]
        return out

    def free_cells(self, clearance: float = 0.0) -> np.ndarray:
        """Flat indices of free cells at least ``clearance`` m from every occupied cell (all free cells
        if none is that far)."""
        free = self.free
        if clearance > 0:
            far = free & (self.distance() >= clearance)
            free = far if far.any() else free
        return np.flatnonzero(free)

    @classmethod
    def from_occupancy(cls, grid, occupied_thresh: float = 0.65, free_thresh: float = 0.196, name: str = "map"):
        """From an :class:`~slam2d.mapping.occupancy.OccupancyGrid` by its probabilities."""
        return cls(grid.occupied_mask(occupied_thresh), grid.free_mask(free_thresh), grid.resolution,
                   grid.origin, name)  # fmt: skip

    @classmethod
    def from_world(cls, world, resolution: float = 0.05) -> KnownMap:
        """From a :class:`~slam2d.sim.World`: its own cells if read from a plan; else cells whose centre
        lies inside an obstacle or within half a cell of a wall are occupied, the others free, and the
        exact distance of every cell centre to the walls is kept (no half-cell bias)."""
        if world.grid is not None:
            occ, res = world.grid
            return cls(occ, ~np.asarray(occ, dtype=bool), res, (0.0, 0.0), world.name)
        (x0, y0), (x1, y1) = world.bounds
        origin = (x0 - resolution, y0 - resolution)
        shape = (int(np.ceil((y1 - y0) / resolution)) + 2, int(np.ceil((x1 - x0) / resolution)) + 2)
        rows, cols = np.indices(shape)
        centres = np.column_stack([origin[0] + (cols.ravel() + 0.5) * resolution,
                                   origin[1] + (rows.ravel() + 0.5) * resolution])  # fmt: skip
        chunks = np.array_split(centres, max(1, len(centres) // _CHUNK))
        inside = np.concatenate([world.occupied(c) for c in chunks]).reshape(shape)
        distance = np.where(inside, 0.0, np.concatenate([world.distance(c) for c in chunks]).reshape(shape))
        occupied = inside | (distance < resolution / 2)
        return cls(occupied, ~occupied, resolution, origin, world.name, distance)

    @classmethod
    def load(cls, path, resolution: float = 0.05) -> KnownMap:
        """``office``, a map_server ``map.yaml`` or a floor-plan image (``resolution`` m/px)."""
        if str(path) == "office":
            from slam2d.sim.world import World

            return cls.from_world(World.office(), resolution)
        path = Path(path)
        if not path.exists():
            raise InputError(path, "map not found (a map.yaml, a results folder, a floor-plan image or 'office')")
        if path.is_file() and path.suffix.lower() not in (".yaml", ".yml", ".png", ".pgm", ".jpg", ".jpeg", ".bmp"):
            raise InputError(path, "a map is a map.yaml or an image (png, pgm)")
        return cls.from_occupancy(load_map(path, resolution), name=path.stem)
