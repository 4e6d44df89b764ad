"""Loop-closure candidates over the optimised keyframe poses, verified by scan-to-submap matching.

:class:`LoopCloser` keeps every keyframe's points (decimated) and travelled
distance. :meth:`LoopCloser.candidates` finds earlier keyframes near a new
one; :meth:`LoopCloser.verify` matches the new keyframe's scan against the
submap around a candidate with the correlative matcher and accepts on score
when no rival match elsewhere in the window scores nearly as well (a
periodic or featureless place aliases: the rival may be the true one).

How far a revisit can be from where the graph puts it grows with the path
between the two keyframes in the graph (along the trajectory, and across
loops already closed): the search radius and window widen by ``drift`` per
metre of that path, up to ``max_window_xy``. A window wider than
``window_xy`` is searched on a proportionally coarser grid first, then
refined on the fine one, so a wide search costs about as much as a local one.
Consistency with the graph (the residual check after the batch optimisation)
is the pose graph's job.

Keys index the ``poses`` arrays: ``poses[k]`` is the pose of keyframe ``k``.
"""

from __future__ import annotations

import logging
from collections import Counter, OrderedDict
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from slam2d import geometry
from slam2d.backend.correlative import ProbabilityGrid, angular_step, match, voxel_filter
from slam2d.config import LoopClosureConfig

__all__ = ["LoopClosure", "LoopCloser"]

log = logging.getLogger(__name__)

KEYFRAME_VOXEL_CELLS = 0.5  # keyframe points are kept one per half cell of the matcher's grid
MIN_POINTS = 20  # a keyframe scan with fewer points is not verified
SEARCH_MARGIN = 0.05  # the search prunes below min_score minus this (its grid score only approximates the final one)
SUBMAP_CACHE = 16  # submap grids kept for reuse while their keyframes' poses stay put
SUBMAP_REUSE_XY_CELLS = 0.25  # a cached submap is rebuilt once a member moves more than this (cells)
SUBMAP_REUSE_THETA = np.deg2rad(0.1)  # ... or turns more than this (rad)


@dataclass(frozen=True, eq=False)
class LoopClosure:
    """A verified loop closure: pose ``delta`` (3,) of keyframe ``j`` in the frame of keyframe ``i``.

    information: (3, 3) inverse covariance of ``delta`` (1/m^2, 1/rad^2);
    score: the matcher's score in [0, 1].
    """

    i: int
    j: int
    delta: np.ndarray
    information: np.ndarray
    score: float


@dataclass(frozen=True, eq=False)
class _Submap:
    members: tuple[int, ...]
    relative: np.ndarray  # (n, 3) member poses in the anchor's frame when built
    grid: ProbabilityGrid
    points: np.ndarray  # (M, 2) member points in the anchor's frame
    coarse: dict[int, ProbabilityGrid] = field(default_factory=dict)  # coarsening factor -> grid

    def coarse_grid(self, factor: int) -> ProbabilityGrid:
        """The submap on a grid ``factor`` times coarser (cached)."""
        if factor not in self.coarse:
            self.coarse[factor] = ProbabilityGrid(self.points, self.grid.resolution * factor)
        return self.coarse[factor]


class LoopCloser:
    """Candidate search and verification for loop closures.

    ``stats`` counts candidates proposed, pairs verified, accepted, and
    rejections by reason (``rejected_score``, ``rejected_points``, ``rejected_ambiguous``).
    """

    def __init__(self, cfg: LoopClosureConfig | None = None):
        self.cfg = cfg if cfg is not None else LoopClosureConfig()
        self.stats: Counter[str] = Counter()
        self._keys: list[int] = []
        self._order: dict[int, int] = {}
        self._travelled: list[float] = []
        self._points: dict[int, np.ndarray] = {}
        self._submaps: OrderedDict[int, _Submap] = OrderedDict()
        self._loop_edges: list[tuple[int, int]] = []  # positions of accepted loops' keyframes
        self._path: tuple[int, np.ndarray] | None = None  # (key, graph path length to every keyframe)

    def __len__(self) -> int:
        return len(self._keys)

    def add_keyframe(self, key: int, points, travelled: float) -> None:
        """Store keyframe ``key``: its points (M, 2) in the base frame (m) and the distance travelled so far (m)."""
        key = int(key)
        if key in self._order:
            raise ValueError(f"keyframe {key} was already added")
        if self._travelled and travelled < self._travelled[-1]:
            raise ValueError(f"keyframe {key}: travelled {travelled} m is less than the previous keyframe's")
        self._order[key] = len(self._keys)
        self._keys.append(key)
        self._travelled.append(float(travelled))
        self._points[key] = voxel_filter(points, KEYFRAME_VOXEL_CELLS * self.cfg.resolution)

    def travelled(self, key: int) -> float:
        """Distance travelled (m) when keyframe ``key`` was taken."""
        return self._travelled[self._position(key)]

    def _position(self, key: int) -> int:
        try:
            return self._order[int(key)]
        except KeyError:
            raise KeyError(f"keyframe {key} was never added") from None

    def path_lengths(self, key: int) -> np.ndarray:
        """Shortest path (m) from keyframe ``key`` to every keyframe (in insertion order) through
        the graph: along the trajectory (the distance travelled between consecutive keyframes)
        and across accepted loops (free). What a search must allow for grows with it."""
        if self._path is not None and self._path[0] == key:
            return self._path[1]
        n = len(self._keys)
        trav = np.asarray(self._travelled)
        loops = np.array(self._loop_edges, dtype=np.int64).reshape(-1, 2)
        i = np.concatenate([np.arange(n - 1), loops[:, 0]])
        j = np.concatenate([np.arange(1, n), loops[:, 1]])
        w = np.concatenate([np.diff(trav), np.zeros(len(loops))]) + 1e-9  # 0 would drop the edge
        graph = coo_matrix((w, (i, j)), shape=(n, n)).tocsr()
        path = dijkstra(graph, directed=False, indices=self._position(key))
        self._path = (key, path)
        return path

    def window(self, path_length) -> np.ndarray:
        """Translational search half-width (m) for keyframes ``path_length`` (m) apart in the graph:
        ``window_xy`` plus ``drift`` per metre of path, at most ``max_window_xy``."""
        cfg = self.cfg
        return np.minimum(cfg.window_xy + cfg.drift * np.asarray(path_length), max(cfg.max_window_xy, cfg.window_xy))

    def candidates(self, key: int, poses) -> list[int]:
        """Earlier keyframes that may be the place ``key`` is at, at least ``min_travel`` away along the path.

        poses: (K, 3) current keyframe poses, indexed by key. A keyframe is a
        candidate within ``search_radius`` of ``key``, widened by as much as
        its search window (``window``) is wider than ``window_xy``: the drift
        the graph may hold between them. Ranked by distance over that radius,
        at most ``max_candidates``; a candidate within ``submap_keyframes`` of
        one already chosen is skipped, as its submap would be nearly the same.
        """
        cfg = self.cfg
        poses = geometry.as_pose(poses).reshape(-1, 3)
        keys = np.asarray(self._keys, dtype=np.int64)
        trav = np.asarray(self._travelled)
        here = self.travelled(key)
        eligible = (keys < len(poses)) & (np.abs(trav - here) >= cfg.min_travel)
        if not eligible.any():
            return []
        positions = np.flatnonzero(eligible)
        dist = np.hypot(*(poses[keys[positions], :2] - poses[key, :2]).T)
        near = dist <= cfg.search_radius + max(cfg.max_window_xy - cfg.window_xy, 0.0)
        if cfg.drift > 0 and near.any():
            radius = cfg.search_radius + self.window(self.path_lengths(key)[positions]) - cfg.window_xy
        else:
            radius = np.full(len(positions), cfg.search_radius)
        near &= dist <= radius
        if not near.any():
            return []
        ranked = positions[near][np.argsort(dist[near] / radius[near], kind="stable")]
        chosen: list[int] = []
        for pos in ranked:
            if all(abs(pos - self._order[c]) > cfg.submap_keyframes for c in chosen):
                chosen.append(int(keys[pos]))
                if len(chosen) == cfg.max_candidates:
                    break
        self.stats["candidates"] += len(chosen)
        return chosen

    def verify(self, key: int, cand: int, poses) -> LoopClosure | None:
        """Match keyframe ``key``'s scan against the submap around ``cand``; a LoopClosure if the score passes.

        Submaps are fixed windows of keyframes so neighbouring candidates share
        one: the window centred on the anchor nearest ``cand`` among every
        ``submap_keyframes``-th keyframe, reaching ``submap_keyframes`` to each
        side (in insertion order, leaving out any within ``min_travel`` of
        ``key``), in the anchor's frame. The closure links the anchor and
        ``key``; the initial guess is ``between(poses[anchor], poses[key])``;
        the search window is ``window`` of their path length in the graph.
        """
        cfg = self.cfg
        poses = geometry.as_pose(poses).reshape(-1, 3)
        self.stats["verified"] += 1
        self._position(key)  # a clear KeyError for a keyframe never added
        points = self._points[int(key)]
        anchor = self._anchor(cand)
        submap = self._submap(key, anchor, poses) if len(points) >= MIN_POINTS else None
        if submap is None:
            self.stats["rejected_points"] += 1
            log.debug("loop %d -> %d rejected: too few points", anchor, key)
            return None
        guess = geometry.between(poses[anchor], poses[key])
        window_xy = cfg.window_xy
        if cfg.drift > 0:
            window_xy = float(self.window(self.path_lengths(key)[self._position(anchor)]))
        result = self._match(submap, points, guess, window_xy)
        if result.score < cfg.min_score:
            self.stats["rejected_score"] += 1
            log.debug("loop %d -> %d rejected: score %.3f < %.3f", anchor, key, result.score, cfg.min_score)
            return None
        if result.runner_up > 0:
            self.stats["rejected_ambiguous"] += 1
            log.debug("loop %d -> %d rejected: rival match %.3f vs %.3f", anchor, key, result.runner_up,
                      result.search_score)  # fmt: skip
            return None
        self.stats["accepted"] += 1
        if window_xy > cfg.window_xy:
            self.stats["accepted_wide"] += 1
        self._loop_edges.append((self._position(anchor), self._position(key)))
        self._path = None
        moved = geometry.between(guess, result.pose)
        log.debug(
            "loop %d -> %d accepted: score %.3f, correction %.3f m %.2f deg (window %.1f m)",
            anchor, key, result.score, np.hypot(moved[0], moved[1]), np.rad2deg(moved[2]), window_xy,
        )  # fmt: skip
        info = np.linalg.inv(result.covariance)
        return LoopClosure(int(anchor), int(key), result.pose, 0.5 * (info + info.T), result.score)

    def _match(self, submap: _Submap, points, guess, window_xy: float):
        """Branch and bound within ``window_xy`` (m) and ``window_theta_deg`` of ``guess``, with the rival check.

        A window wider than ``window_xy`` of the config is searched on a grid
        as many times coarser (the same number of cells), then the coarse pose
        is refined on the submap's own grid within two coarse cells.
        """
        cfg = self.cfg
        window_theta = np.deg2rad(cfg.window_theta_deg)
        prune = max(0.0, cfg.min_score - SEARCH_MARGIN)
        factor = int(np.ceil(window_xy / cfg.window_xy - 1e-9))
        if factor <= 1:
            return match(
                submap.grid, points, guess, window_xy, window_theta, min_score=prune,
                ambiguity_xy=cfg.ambiguity_distance, ambiguity_ratio=cfg.ambiguity_ratio,
            )  # fmt: skip
        coarse = submap.coarse_grid(factor)
        found = match(
            coarse, points, guess, window_xy, window_theta, min_score=prune,
            ambiguity_xy=max(cfg.ambiguity_distance, 2 * coarse.resolution), ambiguity_ratio=cfg.ambiguity_ratio,
        )  # fmt: skip
        if found.search_score < prune:
            return replace(found, score=found.search_score)
        if found.runner_up > 0:
            return found
        step = angular_step(voxel_filter(points, coarse.resolution), coarse.resolution)
        return match(submap.grid, points, found.pose, 2 * coarse.resolution, step, min_score=prune)

    def _anchor(self, cand: int) -> int:
        """The submap anchor for ``cand``: the nearest keyframe whose position is a multiple of ``submap_keyframes``."""
        n, pos = self.cfg.submap_keyframes, self._position(cand)
        if n == 0:
            return int(cand)
        return self._keys[min(int(round(pos / n)) * n, len(self._keys) - 1)]

    def _submap(self, key: int, anchor: int, poses: np.ndarray) -> _Submap | None:
        """The grid of keyframes around ``anchor`` in its frame (cached while their poses hold), or None if empty."""
        n, pos = self.cfg.submap_keyframes, self._position(anchor)
        here = self.travelled(key)
        span = slice(max(0, pos - n), pos + n + 1)
        members = tuple(
            k
            for k, t in zip(self._keys[span], self._travelled[span])
            if abs(t - here) >= self.cfg.min_travel and k < len(poses)
        )
        if not members:
            return None
        relative = geometry.between(poses[anchor], poses[list(members)])
        cached = self._submaps.get(anchor)
        if cached is not None and cached.members == members and self._unmoved(cached.relative, relative):
            self._submaps.move_to_end(anchor)
            return cached
        pts = np.vstack([geometry.transform_points(p, self._points[k]) for k, p in zip(members, relative)])
        if len(pts) < MIN_POINTS:
            return None
        submap = _Submap(members, relative, ProbabilityGrid(pts, self.cfg.resolution), pts)
        self._submaps[anchor] = submap
        if len(self._submaps) > SUBMAP_CACHE:
            self._submaps.popitem(last=False)
        return submap

    def _unmoved(self, old: np.ndarray, new: np.ndarray) -> bool:
        """Whether relative member poses changed less than the reuse tolerances."""
        d = geometry.between(old, new)
        return bool(
            np.all(np.hypot(d[:, 0], d[:, 1]) < SUBMAP_REUSE_XY_CELLS * self.cfg.resolution)
            and np.all(np.abs(d[:, 2]) < SUBMAP_REUSE_THETA)
        )
