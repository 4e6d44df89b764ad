"""Keyframes, loop closures and optimisation over a frontend's results.

Every scan arrives with its FrontendResult. Scans become keyframes after the
configured travel or rotation; between keyframes the frontend's deltas are
composed (with their covariances) into one between factor. Each new keyframe
is checked for loop closures against the current estimate; a closure needs the
matcher's score, enters the graph under the robust kernel, and is removed
after the batch optimisation if the optimised graph cannot accommodate it
(chi-square test on its residual, see ``PoseGraph.optimize_batch``). Poses
for every scan are keyframe poses composed with the scan's offset from its keyframe.

A back end can start from a saved :class:`~slam2d.backend.session.Session` (``resume``): the scans
then continue its last one, or start a trajectory whose first pose a global search of the saved map
finds (``_place``); ``session`` returns what a later run goes on from.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import replace

import numpy as np

from slam2d import geometry
from slam2d.backend.base import register_backend
from slam2d.backend.loop_closure import SESSION_GAP, LoopClosure
from slam2d.backend.refine import refine
from slam2d.backend.session import LOOP, ODOMETRY, Session
from slam2d.config import BackendConfig
from slam2d.errors import InputError
from slam2d.frontends.base import FrontendResult
from slam2d.types import Scan

PLACE_KEYFRAMES = 5  # scans (at keyframe spacing) matched together to place a new session in a saved map


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
        self._placing: list | None = None  # scans of a session not yet placed in the saved map (resume)
        self._link: tuple | None = None  # (pose, keyframe, delta, information) of the next scan's keyframe
        self._pin: LoopClosure | None = None  # ... and the loop its link pins
        self._attempts = 0  # global searches to place this session
        self._points: list[np.ndarray] = []  # keyframes' points (M, 2), base frame, for the dense refinement

    def add(self, scan: Scan, result: FrontendResult) -> None:
        """Take one scan and its frontend result (``result.delta`` unused for the first)."""
        if self._placing is not None:
            self._place(scan, result)
            return
        if self._link is not None or not self._scan_keyframe:
            pose, previous, delta, information = self._link or (np.asarray(scan.odom, float), None, None, None)
            self._link = None
            self._new_keyframe(scan, pose, delta, information, result.landmarks, previous)
            return
        cov = np.linalg.inv(result.information)
        cov[2, 2] += (self.cfg.turn_sigma * result.delta[2]) ** 2
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
        if self._placing is not None:
            raise InputError("session.localize_in", f"no scan of the {len(self._placing)} of this session "
                             f"matched the saved map unambiguously ({self._attempts} global searches)")
        kf = self.graph.optimize_batch() if self.graph.num_keyframes > 1 else self.graph.estimate()
        if self.cfg.refine.rounds and self.graph.num_keyframes > 1:
            kf, counts = refine(self.graph, self._points, self.cfg.refine)
            self.stats.update(counts)
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

    def _new_keyframe(self, scan: Scan, pose, delta, information, landmarks=(), previous=None) -> None:
        key = self.graph.add_keyframe(pose, delta, information, previous)
        for obs in landmarks:  # landmarks seen from keyframes become bearing-range factors
            self.graph.add_landmark_observation(key, obs.landmark_id, obs.bearing, obs.range, obs.covariance)
            self.stats["landmark observations"] += 1
        self._scan_keyframe.append(key)
        self._scan_offset.append(np.zeros(3))
        if self.cfg.refine.rounds:
            self._points.append(scan.points_in_base())
        self._delta, self._cov = np.zeros(3), np.zeros((3, 3))
        self.stats["keyframes"] += 1
        self.graph.update()
        if self.loops is not None:
            self.loops.add_keyframe(key, scan.points_in_base(), self._travelled)
            if self._pin is not None:
                self.loops.pin(replace(self._pin, j=key))
                self._pin = None
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
        added, gate = 0, self.cfg.loop_closure.innovation_gate
        for closure in closures:
            if closure is None:
                continue
            if gate and self.graph.loop_consistency(closure.i, closure.j, closure.delta, closure.information) > gate:
                self.stats["loop closures gated"] += 1  # far from where the graph, with its uncertainty, puts it
                continue
            self.graph.add_loop(closure.i, closure.j, closure.delta, closure.information)
            self.stats["loop closures added"] += 1
            added += 1
        return added

    # ------------------------------------------------------------ sessions

    def session(self, scans: list[Scan]) -> Session:
        """The state to go on from (after :meth:`finish`); ``scans``: every scan added, in order."""
        kf, offsets = self.scan_anchors()
        keep = np.zeros(len(scans), bool)
        keep[np.flatnonzero(np.r_[True, np.diff(kf) != 0])] = True  # each keyframe's first scan
        keep[-1] = True
        edges = self.graph.edges()
        pinned = {(c.i, c.j) for c in (self.loops.pinned if self.loops is not None else ())}
        travelled = [self.loops.travelled(k) for k in range(self.graph.num_keyframes)] if self.loops else \
            np.zeros(self.graph.num_keyframes)  # fmt: skip
        kept = [s for s, k in zip(scans, keep) if k]
        return Session(
            keyframe_poses=self.graph.estimate(),
            travelled=np.asarray(travelled, float),
            edge_kind=np.array([LOOP if e[0] == "loop" else ODOMETRY for e in edges], np.int8),
            edge_ij=np.array([(e[1], e[2]) for e in edges], int).reshape(-1, 2),
            edge_delta=np.array([e[3] for e in edges], float).reshape(-1, 3),
            edge_information=np.array([e[4] for e in edges], float).reshape(-1, 3, 3),
            edge_pinned=np.array([e[0] == "loop" and (e[1], e[2]) in pinned for e in edges], bool),
            tail=np.concatenate([self._delta, self._cov.ravel(), [self._travelled, self._searches]]),
            stamp=np.array([s.stamp for s in scans]),
            odom=np.array([s.odom for s in scans], float),
            sensor_pose=np.array([s.sensor_pose for s in scans], float),
            ground_truth=np.array([np.full(3, np.nan) if s.ground_truth is None else s.ground_truth for s in scans]),
            range_limits=np.array([(s.range_min, s.range_max) for s in scans], float),
            keyframe=kf,
            offset=offsets,
            beams=np.array([len(s.ranges) if k else 0 for s, k in zip(scans, keep)]),
            ranges=np.concatenate([s.ranges for s in kept]).astype(float),
            angles=np.concatenate([s.angles for s in kept]).astype(float),
        )

    def resume(self, session: Session, localize: bool = False) -> None:
        """Start from a saved ``session`` (before any scan is added): its graph at its estimate, its
        keyframes in the loop closer and its scans' places. The next scans continue its last one;
        with ``localize`` they start a new trajectory whose pose is found by a global search of
        the first scans in the session's map (:meth:`_place`) and which closes loops with it."""
        if self._scan_keyframe:
            raise ValueError("resume needs a back end that has taken no scan")
        if localize and self.loops is None:
            raise InputError("session.localize_in", "placing a session needs backend.loop_closure.enabled")
        odometry = {int(j): (int(i), d, info) for kind, (i, j), d, info in zip(
            session.edge_kind, session.edge_ij, session.edge_delta, session.edge_information) if kind == ODOMETRY}
        for k, pose in enumerate(session.keyframe_poses):
            if k == 0:
                self.graph.add_keyframe(pose)
            else:
                i, delta, info = odometry[k]
                self.graph.add_keyframe(pose, delta, info, previous=i)
        loops = session.edge_kind == LOOP
        for (i, j), delta, info in zip(session.edge_ij[loops], session.edge_delta[loops],
                                       session.edge_information[loops]):  # fmt: skip
            self.graph.add_loop(int(i), int(j), delta, info)
        if session.num_keyframes > 1:
            self.graph.optimize_batch()  # from the saved optimum: restarts iSAM2 there
        else:
            self.graph.update()
        scans = session.scans()
        if self.cfg.refine.rounds:
            self._points = [scans[n].points_in_base() for n in session.keyframe_scans()]
        if self.loops is not None:
            for k, n in enumerate(session.keyframe_scans()):
                self.loops.add_keyframe(k, scans[n].points_in_base(), session.travelled[k])
            for (i, j), delta, info in zip(session.edge_ij[session.edge_pinned], session.edge_delta[session.edge_pinned],
                                           session.edge_information[session.edge_pinned]):  # fmt: skip
                self.loops.pin(LoopClosure(int(i), int(j), delta, info, np.nan))
        self._scan_keyframe = session.keyframe.tolist()
        self._scan_offset = list(session.offset)
        self.stats["keyframes"] = session.num_keyframes
        self.stats["loop closures added"] = int(loops.sum())
        tail = session.tail
        if localize:  # no path along the trajectory between the sessions: every saved keyframe is a candidate
            self._travelled = float(tail[12]) + SESSION_GAP
            self._placing, self._attempts = [], 0
        else:
            self._delta, self._cov = tail[:3].copy(), tail[3:12].reshape(3, 3).copy()
            self._travelled, self._searches = float(tail[12]), int(tail[13])

    def _place(self, scan: Scan, result: FrontendResult) -> None:
        """Hold ``scan`` of a session not yet placed; at every ``every_n_keyframes``-th scan that would
        be a keyframe, search the saved map globally for the last ``PLACE_KEYFRAMES`` such scans
        together. Once one is found, the held scans go into the graph from the pose it implies,
        the first one joined to the saved keyframe it matched by the match."""
        held = self._placing
        chain = np.zeros(3) if not held else geometry.compose(held[-1][2], result.delta)
        tried = [h for h in held if h[3]]
        is_keyframe = not tried or self._is_keyframe(geometry.between(tried[-1][2], chain))
        held.append((scan, result, chain, is_keyframe))
        if not is_keyframe or len(tried) % self.cfg.loop_closure.every_n_keyframes:
            return
        group = [h for h in held if h[3]][-PLACE_KEYFRAMES:]
        points = np.vstack([geometry.transform_points(geometry.between(chain, c), s.points_in_base())
                            for s, _, c, _ in group])  # fmt: skip
        self._attempts += 1
        found = self.loops.localize(points, self.graph.estimate())
        if found is None:
            return
        start = geometry.compose(found.delta, geometry.inverse(chain))  # first held scan in the anchor's frame
        cov = geometry.compose_covariance(np.linalg.inv(found.information), geometry.inverse(chain), np.zeros((3, 3)))
        info = np.linalg.inv(cov)
        info = 0.5 * (info + info.T)
        pose = geometry.compose(self.graph.pose(found.i), start)
        self._link = (pose, found.i, start, info)
        self._pin = LoopClosure(found.i, -1, start, info, found.score)
        self._placing = None
        self.stats["sessions placed"] += 1
        for s, r, _, _ in held:
            self.add(s, r)

    def summary(self) -> dict[str, int]:
        """Counts of keyframes and loop-closure outcomes (matcher and graph checks).

        ``loop closures kept``: added and not removed by the final check;
        ``loop closures rejected``: by the matcher (score, points), the innovation gate, or removed.
        """
        out = dict(self.stats)
        removed = self.graph.rejected_inconsistent
        out["loop closures removed as inconsistent"] = removed
        if self.loops is not None:
            out.update({f"loop matcher {k}": v for k, v in self.loops.stats.items()})
            matcher = sum(v for k, v in self.loops.stats.items() if k.startswith("rejected"))
            out["loop closures kept"] = self.stats["loop closures added"] - removed
            out["loop closures rejected"] = matcher + self.stats["loop closures gated"] + removed
        return out
