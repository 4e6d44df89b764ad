"""Back end 'none': the frontend's deltas chained, no graph."""

from __future__ import annotations

import numpy as np

from slam2d import geometry
from slam2d.backend.base import register_backend
from slam2d.frontends.base import FrontendResult
from slam2d.types import Scan


@register_backend("none")
class ChainBackend:
    """The frontend's deltas chained from the first odometry pose."""

    graph = None

    def __init__(self, cfg=None) -> None:
        self.poses: list[np.ndarray] = []

    def add(self, scan: Scan, result: FrontendResult) -> None:
        pose = scan.odom if not self.poses else geometry.compose(self.poses[-1], result.delta)
        self.poses.append(np.asarray(pose, float))

    def finish(self) -> np.ndarray:
        return np.array(self.poses)

    def current_pose(self) -> np.ndarray:
        """Pose (3,) of the latest scan."""
        return self.poses[-1]

    def scan_anchors(self, start: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """As GraphSlamBackend's: every scan is its own keyframe, at offset zero."""
        n = len(self.poses) - start
        return np.arange(start, start + n), np.zeros((n, 3))

    def summary(self) -> dict[str, int]:
        return {}
