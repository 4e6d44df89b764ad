"""The ICP frontend's local map: a kiss-icp voxel map of the last scans, in the frontend's own frame.

kiss-icp's ``VoxelHashMap`` keeps a point only if it lies at least voxel_size / sqrt(max_points_per_voxel)
(4.5 cm at 0.2 m and 20) from the points its voxel already holds: first come, first kept. In beam order
(``order`` "beam", the default) the point kept of each run of close beams is the first in the scan's
sense of rotation, and the next one kept is the first far enough on: on a wall seen obliquely, those
whose range noise carried them on in that sense, so the kept points sit a little behind the wall where
it recedes with the bearing and before it where it comes nearer, as if the map were turned against the
scan. Each scan registered to a map so kept turns the same way (-0.5 mdeg a scan in the simulator, the
sign following the beam order; ``docs/navigation.md``). ``order`` "random" puts each scan's points in
in a seeded random order, which has no sense of rotation.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from slam2d import geometry
from slam2d.frontends.icp.config import IcpConfig
from slam2d.frontends.icp.grid import SearchGrid

__all__ = ["LocalMap", "get_local_map", "to3d"]


def to3d(points: np.ndarray) -> np.ndarray:
    """(M, 2) planar points -> (M, 3) with z = 0."""
    return np.column_stack([points, np.zeros(len(points))])


class LocalMap:
    """Scan points (m) in the frontend's frame: a kiss-icp ``VoxelHashMap`` (``voxels``) of voxels
    ``voxel_size`` m wide holding at most ``max_points_per_voxel`` points, none beyond ``radius`` m of
    the robot, made of the last ``window`` scans (0: every scan); each scan's points go in in beam order
    or a random ``order`` drawn from ``seed`` (module docstring)."""

    def __init__(self, voxel_size: float, radius: float, max_points_per_voxel: int, window: int,
                 order: str = "beam", seed: int = 0):
        from kiss_icp.mapping import VoxelHashMap

        self.voxels = VoxelHashMap(voxel_size, radius, max_points_per_voxel)
        self.window = window
        self._recent: deque[np.ndarray] = deque(maxlen=window or None)
        self._since_rebuild = 0
        self._shuffle = np.random.default_rng(seed) if order == "random" else None

    def empty(self) -> bool:
        return self.voxels.empty()

    def add(self, pose: np.ndarray, points: np.ndarray) -> None:
        """Insert ``points`` (base frame) at ``pose``; forget old scans and voxels beyond the radius.

        With ``window`` > 0 the map is rebuilt, newest scan first, from the
        last ``window`` scans whenever a quarter window has been added since
        the last rebuild, so it always holds between 1 and 1.25 windows of scans.
        """
        if self._shuffle is not None:
            points = points[self._shuffle.permutation(len(points))]
        world = to3d(geometry.transform_points(pose, points))
        window = self.window
        if window:
            self._recent.append(world)
            self._since_rebuild += 1
            if self._since_rebuild >= max(1, window // 4):
                self.voxels.clear()
                self.voxels.add_points(np.concatenate(list(self._recent)[::-1]))
                self._since_rebuild = 0
                return
        if len(world):
            self.voxels.add_points(world)
        self.voxels.remove_far_away_points(np.array([pose[0], pose[1], 0.0]))

    def search_grid(self, cell: float) -> SearchGrid:
        """The map's points (x, y) bucketed for neighbour search, in cells of at least ``cell`` m."""
        return SearchGrid.build(np.ascontiguousarray(self.voxels.point_cloud()[:, :2]), cell)


def get_local_map(config: IcpConfig) -> LocalMap:
    """The local map of ``config`` (``map_voxel_size``, ``map_radius``, ``map_max_points_per_voxel``,
    ``map_window``, ``map_order``, ``map_seed``)."""
    return LocalMap(config.map_voxel_size, config.map_radius, config.map_max_points_per_voxel, config.map_window,
                    config.map_order, config.map_seed)
