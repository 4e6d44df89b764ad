"""Moving points: where an earlier scan of the local map saw through, a point now is something that moved.

A person walking beside the robot is a cluster of points that moves together: matched to the
local map, which holds the person's earlier places, it drags the pose along with them, and
along a corridor, where the walls fix nothing lengthwise, it alone decides the position there.
A static world is never seen through: a point that lies clearly in front of where an earlier
scan's beams ended (they passed through the point's place) was not there then. Such points
are left out of the match and of the local map (the visibility test of Pomerleau et al.,
"Long-term 3D map maintenance in dynamic environments", ICRA 2014).

A point is seen through by an earlier scan when the four beams of that scan nearest to the
point's bearing (the two either side) all reach ``margin`` beyond it; a beam with no return
reaches the sensor's range limit, an invalid one (NaN) nowhere. Two such scans make a point
moving. Poses are (x, y, theta) in the frontend's frame (m, m, rad).
"""

from __future__ import annotations

from collections import deque

import numpy as np

from slam2d import geometry
from slam2d.types import Scan

__all__ = ["SEEN_BY", "Views"]

SEEN_BY = 2  # earlier scans that must have seen through a point for it to be moving


class Views:
    """The last ``size`` registered scans as their sensor saw them: sensor pose, sorted beam
    angles and the range each beam reached (m; no return: the range limit; invalid: 0)."""

    def __init__(self, size: int):
        self._views: deque[tuple[np.ndarray, np.ndarray, np.ndarray]] = deque(maxlen=max(size, 1))

    def add(self, pose: np.ndarray, scan: Scan) -> None:
        """Keep ``scan`` seen from base ``pose`` (3,)."""
        sensor = geometry.compose(pose, scan.sensor_pose)
        with np.errstate(invalid="ignore"):
            reach = np.where(scan.ranges >= scan.range_max, scan.range_max, scan.ranges)
        reach = np.nan_to_num(reach, nan=0.0, posinf=0.0, neginf=0.0)
        order = np.argsort(scan.angles, kind="stable")
        self._views.append((sensor, np.asarray(scan.angles, float)[order], reach[order]))

    def moving(self, points: np.ndarray, margin: float) -> np.ndarray:
        """(M,) bool: ``points`` (M, 2, frontend frame) that at least SEEN_BY kept scans saw through by
        more than ``margin`` (m)."""
        seen = np.zeros(len(points), dtype=np.int64)
        if len(points) == 0 or margin <= 0:
            return seen.astype(bool)
        for sensor, angles, reach in self._views:
            seen += seen_through(sensor, angles, reach, points, margin)
        return seen >= SEEN_BY


def seen_through(sensor: np.ndarray, angles: np.ndarray, reach: np.ndarray, points: np.ndarray,
                 margin: float) -> np.ndarray:
    """(M,) bool: whether the four beams (``angles`` sorted, rad; ``reach`` m) of a scan from ``sensor``
    (3,) nearest to each point's bearing all reach ``margin`` beyond it; a point outside the beams'
    span is not seen through."""
    d = points - sensor[:2]
    distance = np.hypot(d[:, 0], d[:, 1])
    bearing = geometry.wrap_angle(np.arctan2(d[:, 1], d[:, 0]) - sensor[2])
    n = len(angles)
    if n < 4:
        return np.zeros(len(points), bool)
    right = np.clip(np.searchsorted(angles, bearing), 2, n - 2)
    beams = right[:, None] + np.arange(-2, 2)
    inside = (bearing >= angles[0]) & (bearing <= angles[-1])
    return inside & (reach[beams].min(axis=1) > distance + margin)
