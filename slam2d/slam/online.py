"""OnlineSlam: the configured frontend and pose graph fed one scan at a time.

The same objects as ``SlamPipeline``: ``create_frontend`` for the frontend, the
back end ``backend.name`` names (one with a pose graph: ``GraphSlamBackend``) for
keyframes, loop closures and optimisation, so that
``finish()`` returns the batch pipeline's poses for the same stream. At any
moment ``pose`` is the back end's current estimate of the latest scan and
``grid`` the occupancy grid at the current keyframe estimates, kept by a
:class:`KeyframeGrid` (closed keyframes traced as they close; after a loop
closure only the keyframes that moved are traced again).
"""

from __future__ import annotations

import numpy as np

from slam2d import geometry
from slam2d.backend.base import BACKENDS
from slam2d.config import ExperimentConfig
from slam2d.errors import InputError
from slam2d.frontends import create_frontend
from slam2d.frontends.base import FrontendResult
from slam2d.mapping.grid import OccupancyGrid
from slam2d.slam.keyframe_grid import GridUpdate, KeyframeGrid
from slam2d.types import Scan


class OnlineSlam:
    """SLAM session: ``add(scan)`` one scan at a time; ``pose``, ``poses`` and ``grid`` at any moment;
    ``finish()`` for the final batch optimisation.

    ``tolerance`` (m, default a quarter cell): how far a keyframe's beam ends may have
    moved before its part of the grid is traced again.
    """

    def __init__(self, cfg: ExperimentConfig, tolerance: float | None = None):
        self.backend = BACKENDS.create(cfg.backend.name, None, cfg.backend)
        if self.backend.graph is None:
            raise InputError("backend.name", f"online SLAM needs a back end with a pose graph ('pose_graph'), "
                                             f"got '{cfg.backend.name}'")
        self.cfg = cfg
        self.frontend = create_frontend(cfg.frontend.name, cfg.frontend.options)
        self.map = KeyframeGrid(cfg.mapping, tolerance)
        self.scans: list[Scan] = []
        self.confidences: list[float] = []

    def add(self, scan: Scan) -> FrontendResult:
        """Process one scan (odometry delta from the previous scan's odometry, as ``frontend_steps``);
        when it closes a keyframe, the grid takes that keyframe and re-places those that moved."""
        delta = np.zeros(3) if not self.scans else geometry.between(self.scans[-1].odom, scan.odom)
        result = self.frontend.process(scan, delta)
        keyframes = self.backend.graph.num_keyframes
        self.backend.add(scan, result)
        n = len(self.scans)
        self.scans.append(scan)
        self.confidences.append(result.confidence)
        key, offset = self.backend.scan_anchors(n)
        self.map.reserve(int(key[0]) + 1)
        if n % self.cfg.mapping.every_nth_scan == 0:
            self.map.add_scan(int(key[0]), offset[0], scan)
        if self.backend.graph.num_keyframes > keyframes > 0:
            self.update_grid(open_keyframe=False)
        return result

    @property
    def pose(self) -> np.ndarray:
        """Current estimate (3,) (m, m, rad) of the latest scan's base pose."""
        if not self.scans:
            raise ValueError("no scan added yet")
        return self.backend.current_pose()

    @property
    def poses(self) -> np.ndarray:
        """Current estimates (N, 3) of every scan's base pose: keyframe estimate composed with the scan's offset."""
        keys, offsets = self.backend.scan_anchors()
        return geometry.compose(self.backend.graph.estimate()[keys], offsets)

    @property
    def grid(self) -> OccupancyGrid:
        """The occupancy grid of every scan so far at the current estimates (within the tolerance)."""
        self.update_grid(open_keyframe=True)
        return self.map.grid()

    def update_grid(self, open_keyframe: bool = True) -> GridUpdate:
        """Trace new keyframes and re-trace moved ones at the current estimate; the open (latest)
        keyframe, still gaining scans, only with ``open_keyframe``."""
        if not self.scans:
            return GridUpdate()
        estimate = self.backend.graph.estimate()
        return self.map.update(estimate if open_keyframe else estimate[:-1], closed=len(estimate) - 1)

    def finish(self) -> np.ndarray:
        """Final batch optimisation; poses (N, 3) of every scan added (as ``SlamPipeline.run``)."""
        if not self.scans:
            raise ValueError("no scan added yet")
        return self.backend.finish()
