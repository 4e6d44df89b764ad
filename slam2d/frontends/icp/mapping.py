"""The ICP frontend's local map: a kiss-icp voxel map of the last scans, in the frontend's own frame."""

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
    the robot, made of the last ``window`` scans (0: every scan)."""

    def __init__(self, voxel_size: float, radius: float, max_points_per_voxel: int, window: int):
        from kiss_icp.mapping import VoxelHashMap

        self.voxels = VoxelHashMap(voxel_size, radius, max_points_per_voxel)
        self.window = window
        self._recent: deque[np.ndarray] = deque(maxlen=window or None)
        self._since_rebuild = 0

    def empty(self) -> bool:
        return self.voxels.empty()

    def add(self, pose: np.ndarray, points: np.ndarray) -> None:
        """Insert ``points`` (base frame) at ``pose``; forget old scans and voxels beyond the radius.

        With ``window`` > 0 the map is rebuilt, newest scan first, from the
        last ``window`` scans whenever a quarter window has been added since
        the last rebuild, so it always holds between 1 and 1.25 windows of scans.
        """
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
    ``map_window``)."""
    return LocalMap(config.map_voxel_size, config.map_radius, config.map_max_points_per_voxel, config.map_window)
