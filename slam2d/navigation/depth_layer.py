"""An obstacle layer of the local costmap from a depth camera (what a 2D laser does not see:
low boxes, table tops, overhanging shelves), as nav2's obstacle / voxel layers.

Each depth image (:class:`slam2d.sim.depth.DepthCamera`) becomes a cloud in the robot base frame;
open3d down-samples it to ``voxel`` cubes and finds the floor by RANSAC (``segment_plane``); the
floor's inliers go, and the points whose height above that plane lies in ``band`` (the robot's
height) within ``mark_range`` are obstacles. (A plane RANSAC picks that is not level within 15°
or 5 cm of the floor under the robot, e.g. a wall filling the view, is not taken for the floor: the
heights are then measured from z = 0.) Obstacle points within ``laser_overlap`` of a laser point
are left to the laser. The layer keeps one point per ``resolution`` cell (world frame) with the
time it was last seen. A kept point goes when the camera sees through it (the pixel it projects to
reads deeper than it by ``clear_margin`` + 3 sigma of the noise), or after ``persistence`` s unseen
(out of the camera's view, e.g. too near for it). A camera looks one way: before the robot drives off,
:class:`LookAround` turns it on the spot until the camera has swept every bearing (as nav2's spin
behaviour), so that a box beside or behind the start is in the layer before the robot turns into it
(the layer keeps it ``persistence`` s). The navigator (:meth:`Navigator.step`, its
``obstacles``: :meth:`ObstacleLayer.corners`) blocks the layer's cells in its map and hands them to the local planner as
points that stay.
"""

from __future__ import annotations

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree

from slam2d import geometry
from slam2d.navigation.common import Command
from slam2d.sim.depth import CameraGeometry, DepthCameraConfig, depth_noise_sd

__all__ = ["LookAround", "ObstacleLayer", "obstacle_points"]

_LEVEL = np.cos(np.deg2rad(15.0))  # a floor plane's normal is within 15 degrees of vertical ...
_FLOOR_OFFSET = 0.05  # m ... and the plane passes within this of z = 0 under the robot
_RANSAC_ITERATIONS = 200


def obstacle_points(cloud, cfg: DepthCameraConfig) -> np.ndarray:
    """Obstacle points (M, 3) (base frame, z: height above the floor plane) of a cloud (N, 3) in the
    robot base frame: voxel down-sampling, RANSAC floor removal, the height band, ``mark_range``."""
    cloud = np.asarray(cloud, dtype=np.float64).reshape(-1, 3)
    if len(cloud) == 0:
        return np.zeros((0, 3))
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud)).voxel_down_sample(cfg.voxel)
    pts = np.asarray(pc.points)
    height, floor = pts[:, 2].copy(), np.zeros(len(pts), dtype=bool)
    if len(pts) >= 3:
        plane, inliers = pc.segment_plane(cfg.plane_threshold, 3, _RANSAC_ITERATIONS)
        normal, offset = np.asarray(plane[:3]), float(plane[3])
        scale = np.linalg.norm(normal)
        normal, offset = (normal, offset) if normal[2] >= 0 else (-normal, -offset)
        if scale > 0 and normal[2] / scale >= _LEVEL and abs(offset / scale) <= _FLOOR_OFFSET:
            height = (pts @ normal + offset) / scale
            floor[np.asarray(inliers, dtype=np.int64)] = True
    lo, hi = cfg.band
    keep = ~floor & (height >= lo) & (height <= hi) & (np.hypot(pts[:, 0], pts[:, 1]) <= cfg.mark_range)
    return np.column_stack([pts[keep, :2], height[keep]])


class ObstacleLayer:
    """The obstacles a depth camera has seen, in the world frame, kept and cleared as the module says."""

    def __init__(self, cfg: DepthCameraConfig | None = None, resolution: float = 0.05):
        self.cfg = cfg or DepthCameraConfig()
        self.geometry = CameraGeometry(self.cfg)
        self.resolution = float(resolution)
        self.xy = np.zeros((0, 2))  # (K, 2) world m, one per cell
        self.z = np.zeros(0)  # (K,) m above the floor
        self.seen = np.zeros(0)  # (K,) s, last seen

    def __len__(self) -> int:
        return len(self.xy)

    def update(self, pose, depth, now: float, laser_points=None) -> None:
        """Take the depth image (H, W) m seen from ``pose`` (3,) (world) at ``now`` (s); ``laser_points``
        (M, 2) in the robot frame are what the laser sees at the same time."""
        pose = np.asarray(pose, dtype=np.float64)
        self._clear(pose, np.asarray(depth, dtype=np.float64).reshape(-1), now)
        found = obstacle_points(self.geometry.points(depth), self.cfg)
        if laser_points is not None and len(laser_points) and len(found) and self.cfg.laser_overlap > 0:
            near = cKDTree(np.asarray(laser_points, dtype=np.float64).reshape(-1, 2)).query(found[:, :2])[0]
            found = found[near > self.cfg.laser_overlap]
        if len(found) == 0:
            return
        xy = geometry.transform_points(pose, found[:, :2])
        xy, z = np.vstack([xy, self.xy]), np.concatenate([found[:, 2], self.z])  # newest first
        seen = np.concatenate([np.full(len(found), float(now)), self.seen])
        _, first = np.unique(np.floor(xy / self.resolution).astype(np.int64), axis=0, return_index=True)
        self.xy, self.z, self.seen = xy[first], z[first], seen[first]

    def _clear(self, pose, depth: np.ndarray, now: float) -> None:
        """Forgets points unseen for ``persistence`` s and those the image (flattened) sees through."""
        keep = self.seen >= now - self.cfg.persistence
        if keep.any():
            base = np.column_stack([geometry.transform_points(geometry.inverse(pose), self.xy), self.z])
            pixel, z = self.geometry.project(base)
            inside = pixel >= 0
            seen = np.full(len(z), np.nan)
            seen[inside] = depth[pixel[inside]]
            tol = self.cfg.clear_margin + 3 * self.cfg.noise_scale * depth_noise_sd(z)
            keep &= ~(seen > z + tol)  # NaN (outside, too near): kept; inf (nothing within range): cleared
        self.xy, self.z, self.seen = self.xy[keep], self.z[keep], self.seen[keep]

    def points(self) -> np.ndarray:
        """The kept obstacle points (K, 2), world frame, m."""
        return self.xy.copy()

    def corners(self) -> np.ndarray:
        """The corners (C, 2) world m of the kept points' ``resolution`` cells, each once: what the navigator
        avoids. A cell is blocked in full, as a costmap's lethal cell (a point seen on a box's top lies up to
        a voxel inside its edge; the cell's corners reach the edge or beyond)."""
        cells = np.floor(self.xy / self.resolution).astype(np.int64)
        corners = (cells[:, None, :] + np.array([[0, 0], [1, 0], [0, 1], [1, 1]])[None]).reshape(-1, 2)
        return np.unique(corners, axis=0) * self.resolution


_SWEEP_OVERLAP = 0.8  # the share of the camera's horizontal field of view counted as seen by one frame


class LookAround:
    """The start-up sweep: turning on the spot (a disc touches nothing doing so) through at least 360 degrees
    less ``_SWEEP_OVERLAP`` x the camera's horizontal field of view, in the direction that then ends facing
    ``bearing`` (the path's), the shorter way; :meth:`command` gives the turn, None once done."""

    def __init__(self, cfg: DepthCameraConfig, max_turn_rate: float, max_turn_accel: float, period: float):
        self.sweep = 2 * np.pi - _SWEEP_OVERLAP * np.deg2rad(cfg.fov_deg[0])  # rad turned at least
        self.rate, self.accel, self.period = max_turn_rate, max_turn_accel, period
        self.left: float | None = None  # rad still to turn (signed), None before the first call
        self.heading = 0.0  # rad, the last pose's heading
        self.done = False
        self._sign = 1.0

    def command(self, pose, velocity, bearing: float) -> Command | None:
        """Turn (v = 0, w rad/s) for the robot at ``pose`` (3,) moving at ``velocity`` (v, w) whose path leaves
        at ``bearing`` (rad, robot frame); None once the sweep is done (and thereafter)."""
        if self.done:
            return None
        if self.left is None:
            ahead = np.mod(bearing - self.sweep, 2 * np.pi) + self.sweep  # turning left, ending facing the path
            behind = np.mod(-bearing - self.sweep, 2 * np.pi) + self.sweep  # turning right
            self.left = ahead if ahead <= behind else -behind
            self._sign = float(np.sign(self.left))
        else:
            self.left -= float(geometry.wrap_angle(pose[2] - self.heading))
        self.heading = float(pose[2])
        w0 = float(velocity[1])
        if self.left * self._sign < 0.02:  # turned through (or past) the sweep
            self.done = True
            return None
        w = np.sign(self.left) * min(self.rate, np.sqrt(self.accel * abs(self.left)))  # stops at half the accel
        w = float(np.clip(w, w0 - self.accel * self.period, w0 + self.accel * self.period))
        return Command(0.0, w, False, "look around")
