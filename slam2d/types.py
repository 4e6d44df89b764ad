"""The data every part of slam2d passes around."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from slam2d import geometry


@dataclass(frozen=True, eq=False)
class Scan:
    """One laser scan with everything known at its time.

    ranges: (n,) metres; invalid beams (no return, NaN, inf, negative) are NaN.
    angles: (n,) beam angles in the sensor frame, radians.
    range_min, range_max: the sensor's limits in metres; a range >= range_max
        is "no return" (free up to range_max, no hit).
    sensor_pose: mounting pose of the laser in the robot base frame (3,).
    odom: odometry pose of the robot base at ``stamp`` (3,).
    ground_truth: true base pose (3,) when known (simulator), else None.
    index: position of the scan in its stream, 0-based.
    """

    stamp: float
    ranges: np.ndarray
    angles: np.ndarray
    range_min: float
    range_max: float
    sensor_pose: np.ndarray = field(default_factory=lambda: np.zeros(3))
    odom: np.ndarray = field(default_factory=lambda: np.zeros(3))
    ground_truth: np.ndarray | None = None
    index: int = 0

    def hit_mask(self, min_range: float = 0.0, max_range: float = np.inf) -> np.ndarray:
        """Beams that returned a hit: finite and within [range_min, range_max); with a range window
        (a frontend's ``min_range``, ``max_range``, m) also within [min_range, max_range]."""
        r = self.ranges
        with np.errstate(invalid="ignore"):
            hit = np.isfinite(r) & (r >= self.range_min) & (r < self.range_max)
            if min_range > 0.0 or max_range < np.inf:
                hit &= (r >= min_range) & (r <= max_range)
        return hit

    def points(self, min_range: float = 0.0, max_range: float = np.inf) -> np.ndarray:
        """Hit points (M, 2) in the sensor frame, metres, in beam order (range window as ``hit_mask``)."""
        m = self.hit_mask(min_range, max_range)
        r, a = self.ranges[m], self.angles[m]
        return np.column_stack([r * np.cos(a), r * np.sin(a)])

    def points_in_base(self, min_range: float = 0.0, max_range: float = np.inf) -> np.ndarray:
        """Hit points (M, 2) in the robot base frame, metres, in beam order (range window as ``hit_mask``)."""
        return geometry.transform_points(self.sensor_pose, self.points(min_range, max_range))


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Timed poses: ``stamps`` (N,) seconds, ``poses`` (N, 3)."""

    stamps: np.ndarray
    poses: np.ndarray

    def __post_init__(self):
        stamps = np.asarray(self.stamps, dtype=np.float64).reshape(-1)
        poses = geometry.as_pose(self.poses).reshape(-1, 3)
        if len(stamps) != len(poses):
            raise ValueError(f"{len(stamps)} stamps but {len(poses)} poses")
        object.__setattr__(self, "stamps", stamps)
        object.__setattr__(self, "poses", poses)

    def __len__(self) -> int:
        return len(self.stamps)

    def at(self, query) -> np.ndarray:
        """Poses at times ``query`` (interpolated, clamped at the ends)."""
        return geometry.interpolate(self.stamps, self.poses, query)


@dataclass(frozen=True, eq=False)
class LandmarkObservation:
    """A landmark seen from the robot base: range (m), bearing (rad, from the base x axis).

    covariance: 2x2 in (bearing, range) order (rad², m²), as gtsam's BearingRange.
    """

    landmark_id: int
    range: float
    bearing: float
    covariance: np.ndarray = field(default_factory=lambda: np.diag([np.deg2rad(2.0) ** 2, 0.05**2]))


class GridFrame:
    """World <-> cell conversions of a 2D grid with ``origin`` (x, y) m of cell (0, 0)'s
    corner, ``resolution`` m per cell and ``shape`` (rows, cols); rows run along y."""

    origin: tuple[float, float]
    resolution: float
    shape: tuple[int, int]

    def world_to_cell(self, xy) -> np.ndarray:
        """Integer (row, col) cells ``(..., 2)`` containing points ``xy (..., 2)`` m
        (outside the grid for points outside it; see :meth:`in_bounds`)."""
        xy = np.asarray(xy, dtype=np.float64)
        col = np.floor((xy[..., 0] - self.origin[0]) / self.resolution)
        row = np.floor((xy[..., 1] - self.origin[1]) / self.resolution)
        return np.stack([row, col], -1).astype(np.int64)

    def cell_to_world(self, cells) -> np.ndarray:
        """Centres (x, y) m ``(..., 2)`` of (row, col) cells ``(..., 2)``."""
        rc = np.asarray(cells, dtype=np.float64)
        x = self.origin[0] + (rc[..., 1] + 0.5) * self.resolution
        y = self.origin[1] + (rc[..., 0] + 0.5) * self.resolution
        return np.stack([x, y], -1)

    def in_bounds(self, cells) -> np.ndarray:
        """Whether (row, col) cells ``(..., 2)`` lie inside the grid."""
        rc = np.asarray(cells)
        h, w = self.shape
        return (rc[..., 0] >= 0) & (rc[..., 0] < h) & (rc[..., 1] >= 0) & (rc[..., 1] < w)
