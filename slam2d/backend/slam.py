"""Keyframes, loop closures and optimisation over a frontend's results.

Every scan arrives with its FrontendResult. Scans become keyframes after the
configured travel or rotation; between keyframes the frontend's deltas are
composed (with their covariances) into one between factor. Each new keyframe
is checked for loop closures against the current estimate; a closure needs the
matcher's score, enters the graph under the robust kernel, and is removed
after the batch optimisation if the optimised graph cannot accommodate it
(chi-square test on its residual, see ``PoseGraph.optimize_batch``). Poses
for every scan are keyframe poses composed with the scan's offset from its keyframe.
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from slam2d import geometry
from slam2d.backend.base import register_backend
from slam2d.config import BackendConfig
from slam2d.frontends.base import FrontendResult
from slam2d.types import Scan


@register_backend("pose_graph")
class GraphSlamBackend:
    """Builds and optimises the pose graph with GTSAM; returns a pose for every scan."""

    def __init__(self, cfg: BackendConfig):
        from slam2d.backend.loop_closure import LoopCloser
        from slam2d.backend.pose_graph import PoseGraph

        self.cfg = cfg
        self.graph = PoseGraph(cfg)
        self.loops = LoopCloser(cfg.loop_closure) if cfg.loop_closure.enabled else None
        self.stats: Counter[str] = Counter()
        self._scan_keyframe: list[int] = []  # keyframe key each scan hangs off
        self._scan_offset: list[np.ndarray] = []  # scan pose in its keyframe's frame
        self._delta = np.zeros(3)  # motion since the last keyframe
        self._cov = np.zeros((3, 3))
        self._travelled = 0.0
        self._searches = 0  # loop searches so far

    def add(self, scan: Scan, result: FrontendResult) -> None:
        """Take one scan and its frontend result (``result.delta`` unused for the first)."""
        if not self._scan_keyframe:
            self._new_keyframe(scan, np.asarray(scan.odom, float), None, None, result.landmarks)
            return
        cov = np.linalg.inv(result.information)
        self._cov = geometry.compose_covariance(self._cov, result.delta, cov)
        self._delta = geometry.compose(self._delta, result.delta)
        self._travelled += float(np.hypot(*result.delta[:2]))
        if self._is_keyframe(self._delta):
            prev = self._scan_keyframe[-1]
            pose = geometry.compose(self.graph.pose(prev), self._delta)
            self._new_keyframe(scan, pose, self._delta, np.linalg.inv(self._cov), result.landmarks)
        else:
            self._scan_keyframe.append(self._scan_keyframe[-1])
            self._scan_offset.append(self._delta.copy())

    def finish(self) -> np.ndarray:
        """Final batch optimisation; poses (N, 3) for every scan added."""
        kf = self.graph.optimize_batch() if self.graph.num_keyframes > 1 else self.graph.estimate()
        return geometry.compose(kf[np.array(self._scan_keyframe)], np.array(self._scan_offset))

    def current_pose(self) -> np.ndarray:
        """Current estimate (3,) (m, m, rad) of the latest scan: its keyframe's estimate composed
        with the scan's offset, as ``finish`` composes them (before the final optimisation)."""
        return geometry.compose(self.graph.pose(self._scan_keyframe[-1]), self._scan_offset[-1])

    def scan_anchors(self, start: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Keyframe key (M,) and pose in that keyframe's frame (M, 3) of scans ``start`` onwards."""
        return np.array(self._scan_keyframe[start:], dtype=int), np.array(self._scan_offset[start:]).reshape(-1, 3)

    def _is_keyframe(self, delta: np.ndarray) -> bool:
        return bool(
            np.hypot(delta[0], delta[1]) >= self.cfg.keyframe_distance
            or abs(delta[2]) >= np.deg2rad(self.cfg.keyframe_angle_deg)
        )

    def _new_keyframe(self, scan: Scan, pose, delta, information, landmarks=()) -> None:
        key = self.graph.add_keyframe(pose, delta, information)
        for obs in landmarks:  # landmarks seen from keyframes become bearing-range factors
            self.graph.add_landmark_observation(key, obs.landmark_id, obs.bearing, obs.range, obs.covariance)
            self.stats["landmark observations"] += 1
        self._scan_keyframe.append(key)
        self._scan_offset.append(np.zeros(3))
        self._delta, self._cov = np.zeros(3), np.zeros((3, 3))
        self.stats["keyframes"] += 1
        self.graph.update()
        if self.loops is not None:
            self.loops.add_keyframe(key, scan.points_in_base(), self._travelled)
            if key % self.cfg.loop_closure.every_n_keyframes == 0 and self._close_loops(key):
                self.graph.update()

    def _close_loops(self, key: int) -> int:
        """Verify loop candidates for ``key`` (local ones, and at every ``wide_every``-th search
        the wide search); add the accepted ones. Returns how many."""
        estimate = self.graph.estimate()
        closures = [self.loops.verify(key, cand, estimate) for cand in self.loops.candidates(key, estimate)]
        self._searches += 1
        every = self.cfg.loop_closure.wide_every
        if every and self._searches % every == 0:
            closures.append(self.loops.wide_search(key, estimate))
        added = 0
        for closure in closures:
            if closure is not None:
                self.graph.add_loop(closure.i, closure.j, closure.delta, closure.information)
                self.stats["loop closures added"] += 1
                added += 1
        return added

    def summary(self) -> dict[str, int]:
        """Counts of keyframes and loop-closure outcomes (matcher and graph checks).

        ``loop closures kept``: added and not removed by the final check;
        ``loop closures rejected``: by the matcher (score, points) or removed.
        """
        out = dict(self.stats)
        removed = self.graph.rejected_inconsistent
        out["loop closures removed as inconsistent"] = removed
        if self.loops is not None:
            out.update({f"loop matcher {k}": v for k, v in self.loops.stats.items()})
            matcher = sum(v for k, v in self.loops.stats.items() if k.startswith("rejected"))
            out["loop closures kept"] = self.stats["loop closures added"] - removed
            out["loop closures rejected"] = matcher + removed
        return out
