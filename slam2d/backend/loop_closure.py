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
metre of that path, up to ``max_window_xy``. Local searches use windows of
up to twice ``window_xy``; :meth:`LoopCloser.wide_search` matches the scan
against all places needing more at once, on a coarser grid with deeper
branch and bound, then on the fine grid. A match whose runner-up lies within its own
uncertainty (aliasing along a corridor, where the scan constrains nothing)
is kept with that uncertainty; a rival elsewhere rejects it.
Consistency with the graph (the residual check after the batch optimisation)
is the pose graph's job.

Keys index the ``poses`` arrays: ``poses[k]`` is the pose of keyframe ``k``.
"""

from __future__ import annotations

import logging
from collections import Counter, OrderedDict
from dataclasses import dataclass, replace

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from slam2d import geometry
from slam2d.backend.correlative import angular_step, match
from slam2d.backend.pose_graph import CHI2_3DOF_99
from slam2d.backend.probability_grid import ProbabilityGrid, voxel_filter
from slam2d.config import LoopClosureConfig

__all__ = ["LoopClosure", "LoopCloser"]

log = logging.getLogger(__name__)

KEYFRAME_VOXEL_CELLS = 0.5  # keyframe points are kept one per half cell of the matcher's grid
MIN_POINTS = 20  # a keyframe scan with fewer points is not verified
SEARCH_MARGIN = 0.05  # the search prunes below min_score minus this (its grid score only approximates the final one)
SUBMAP_CACHE = 16  # submap grids kept for reuse while their keyframes' poses stay put
SUBMAP_REUSE_XY_CELLS = 0.25  # a cached submap is rebuilt once a member moves more than this (cells)
SUBMAP_REUSE_THETA = np.deg2rad(0.1)  # ... or turns more than this (rad)
WINDOW_STEP = 0.5  # m; grown windows are rounded up to this step (each window size builds its own levels)
WIDE_COARSENING = 2  # a wide search runs on a grid this many times coarser than ``resolution``
WIDE_TOP_BLOCKS = 8  # ... with enough pooled levels for about this many top blocks across the window
WIDE_MAX_DEPTH = 7  # ... but no more levels than this
SESSION_GAP = 1e6  # m of travel put between a saved session and one placed in it (they share no path)
LOCALIZE_COARSENING = 4  # a global search (:meth:`LoopCloser.localize`) starts on a grid this many times coarser
VIEW_PERCENTILE = 95  # a wide match is verified on the keyframes within this percentile of the scan's ranges


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
        self._loops: list[LoopClosure] = []  # accepted closures that pin their pair
        self._path: tuple[tuple, np.ndarray] | None = None  # (cache key, graph path length to every keyframe)

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

    def path_lengths(self, key: int, poses) -> np.ndarray:
        """Shortest path (m) from keyframe ``key`` to every keyframe (in insertion order) through
        the graph: along the trajectory (the distance travelled between consecutive keyframes)
        and across accepted loops. What a search must allow for grows with it.

        A loop the estimate ``poses`` (K, 3) satisfies is a free shortcut; one it does not
        yet follow (a robust kernel holds back a single large correction until others
        confirm it) costs the path its residual divided by ``drift``, so the windows
        still cover the error it reports."""
        n = len(self._keys)
        loops = self._loops
        pairs = np.array([(self._position(c.i), self._position(c.j)) for c in loops], dtype=np.int64).reshape(-1, 2)
        lengths = np.zeros(len(loops))
        if loops and self.cfg.drift > 0:
            poses = geometry.as_pose(poses).reshape(-1, 3)
            ij = np.array([(c.i, c.j) for c in loops])
            measured = np.array([c.delta for c in loops])
            residual = geometry.between(geometry.between(poses[ij[:, 0]], poses[ij[:, 1]]), measured)
            lengths = np.hypot(residual[:, 0], residual[:, 1]) / self.cfg.drift
        cache = (key, n, lengths.tobytes())
        if self._path is not None and self._path[0] == cache:
            return self._path[1]
        trav = np.asarray(self._travelled)
        i = np.concatenate([np.arange(n - 1), pairs[:, 0]])
        j = np.concatenate([np.arange(1, n), pairs[:, 1]])
        w = np.concatenate([np.diff(trav), lengths]) + 1e-9  # 0 would drop the edge
        graph = coo_matrix((w, (i, j)), shape=(n, n)).tocsr()
        path = dijkstra(graph, directed=False, indices=self._position(key))
        self._path = (cache, path)
        return path

    def window(self, path_length) -> np.ndarray:
        """Translational search half-width (m) for keyframes ``path_length`` (m) apart in the graph:
        ``window_xy`` plus ``drift`` per metre of path (rounded up to ``WINDOW_STEP``), at most
        ``max_window_xy``."""
        cfg = self.cfg
        grown = np.ceil(cfg.drift * np.asarray(path_length) / WINDOW_STEP) * WINDOW_STEP  # few distinct windows
        return np.minimum(cfg.window_xy + grown, max(cfg.max_window_xy, cfg.window_xy))

    def candidates(self, key: int, poses) -> list[int]:
        """Earlier keyframes near ``key`` for a local search, at least ``min_travel`` away along the path.

        poses: (K, 3) current keyframe poses, indexed by key. A keyframe is a
        candidate within ``search_radius`` of ``key``, widened by as much as
        its search window (``window``, at most twice ``window_xy`` here;
        wider is for :meth:`wide_search`) is wider than ``window_xy``.
        Nearest first, at most ``max_candidates``; a
        candidate within ``submap_keyframes`` of one already chosen is
        skipped, as its submap would be nearly the same.
        """
        cfg = self.cfg
        positions, dist, window = self._in_reach(key, poses)
        local = dist <= cfg.search_radius + np.minimum(window, self._local_window_cap) - cfg.window_xy
        chosen: list[int] = []
        for pos in positions[local][np.argsort(dist[local], kind="stable")]:
            if all(abs(pos - self._order[c]) > cfg.submap_keyframes for c in chosen):
                chosen.append(self._keys[pos])
                if len(chosen) == cfg.max_candidates:
                    break
        self.stats["candidates"] += len(chosen)
        return chosen

    @property
    def _local_window_cap(self) -> float:
        """Widest window (m) of a local search: twice ``window_xy``; wider is :meth:`wide_search`'s."""
        return 2 * self.cfg.window_xy

    def _in_reach(self, key: int, poses) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions of the keyframes in reach of ``key`` (see :meth:`candidates`), their distance
        from it (m) and their search windows (m)."""
        cfg = self.cfg
        poses = geometry.as_pose(poses).reshape(-1, 3)
        keys = np.asarray(self._keys, dtype=np.int64)
        trav = np.asarray(self._travelled)
        eligible = (keys < len(poses)) & (np.abs(trav - self.travelled(key)) >= cfg.min_travel)
        positions = np.flatnonzero(eligible)
        dist = np.hypot(*(poses[keys[positions], :2] - poses[key, :2]).T)
        window = np.full(len(positions), cfg.window_xy)
        if cfg.drift > 0 and len(positions):
            window = self.window(self.path_lengths(key, poses)[positions])
        near = dist <= cfg.search_radius + window - cfg.window_xy
        return positions[near], dist[near], window[near]

    def wide_search(self, key: int, poses) -> LoopClosure | None:
        """Match ``key``'s scan against the map of every keyframe in reach that needs a wide window.

        After long drift the estimate no longer says which of the places in
        reach the robot is at, so the scan is matched against all of them at
        once: their points at their current poses on a grid ``WIDE_COARSENING``
        times coarser than ``resolution``, within the widest of their windows
        around ``key``'s pose, with the rival check. The pose found is then
        verified like a local candidate against the submap of the nearest of
        those keyframes, in a window of two coarse cells.
        """
        cfg = self.cfg
        poses = geometry.as_pose(poses).reshape(-1, 3)
        positions, _, window = self._in_reach(key, poses)
        wide = positions[window > self._local_window_cap]
        points = self._points[int(key)]
        if len(wide) == 0 or len(points) < MIN_POINTS:
            return None
        self.stats["wide searches"] += 1
        members = [self._keys[p] for p in wide]
        region = np.vstack([geometry.transform_points(poses[k], self._points[k]) for k in members])
        coarse = ProbabilityGrid(region, WIDE_COARSENING * cfg.resolution)
        window_xy, window_theta = float(window.max()), np.deg2rad(cfg.window_theta_deg)
        cells = window_xy / coarse.resolution
        depth = int(np.clip(np.ceil(np.log2((2 * cells + 1) / WIDE_TOP_BLOCKS)), 1, WIDE_MAX_DEPTH))
        prune = max(0.0, cfg.min_score - SEARCH_MARGIN)
        found = match(
            coarse, points, poses[key], window_xy, window_theta, min_score=prune, depth=depth,
            ambiguity_xy=max(cfg.ambiguity_distance, 2 * coarse.resolution), ambiguity_ratio=cfg.ambiguity_ratio,
        )  # fmt: skip
        if found.search_score < prune:
            self.stats["rejected_score"] += 1
            log.debug("wide search -> %d rejected: coarse score %.3f over %d keyframes within %.1f m",
                      key, found.search_score, len(members), window_xy)  # fmt: skip
            return None
        submap, anchor = self._view_submap(members, found.pose, points, poses)
        step = angular_step(voxel_filter(points, coarse.resolution), coarse.resolution)
        fine = match(submap.grid, points, geometry.between(poses[anchor], found.pose), 2 * coarse.resolution, step,
                     min_score=prune, prior_window=[window_xy, window_xy, window_theta])  # fmt: skip
        rival = None if found.rival is None else geometry.between(poses[anchor], found.rival)
        return self._accept(anchor, key, poses, replace(fine, runner_up=found.runner_up, rival=rival), window_xy, True)

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
            window_xy = float(self.window(self.path_lengths(key, poses)[self._position(anchor)]))
            window_xy = min(window_xy, self._local_window_cap)
        window_theta = np.deg2rad(cfg.window_theta_deg)
        result = match(
            submap.grid, points, guess, window_xy, window_theta, min_score=max(0.0, cfg.min_score - SEARCH_MARGIN),
            ambiguity_xy=cfg.ambiguity_distance, ambiguity_ratio=cfg.ambiguity_ratio,
        )  # fmt: skip
        return self._accept(anchor, key, poses, result, window_xy, False)

    def _accept(self, anchor: int, key: int, poses: np.ndarray, result, window_xy: float, wide: bool):
        """The LoopClosure of a match of ``key`` in ``anchor``'s submap (``wide``: found by the wide
        search) if it passes the score and rival checks, else None; counted in ``stats``."""
        cfg = self.cfg
        if result.score < cfg.min_score:
            self.stats["rejected_score"] += 1
            log.debug("loop %d -> %d rejected: score %.3f < %.3f", anchor, key, result.score, cfg.min_score)
            return None
        aliased = result.runner_up > 0
        if aliased and not self._rival_within_uncertainty(result):
            self.stats["rejected_ambiguous"] += 1
            log.debug("loop %d -> %d rejected: rival match %.3f vs %.3f", anchor, key, result.runner_up,
                      result.search_score)  # fmt: skip
            return None
        self.stats["accepted"] += 1
        if wide:
            self.stats["accepted_wide"] += 1
        elif window_xy > cfg.window_xy:
            self.stats["accepted_grown_window"] += 1
        guess = geometry.between(poses[anchor], poses[key])
        moved = geometry.between(guess, result.pose)
        log.debug(
            "loop %d -> %d accepted: score %.3f, correction %.3f m %.2f deg (window %.1f m)",
            anchor, key, result.score, np.hypot(moved[0], moved[1]), np.rad2deg(moved[2]), window_xy,
        )  # fmt: skip
        info = np.linalg.inv(result.covariance)
        closure = LoopClosure(int(anchor), int(key), result.pose, 0.5 * (info + info.T), result.score)
        if aliased:
            self.stats["accepted_along_degenerate_direction"] += 1
        else:
            self.pin(closure)
        return closure

    def pin(self, closure: LoopClosure) -> None:
        """Count ``closure`` among the loops that pin their pair once the estimate follows them
        (a shortcut in :meth:`path_lengths`): the accepted, unaliased ones."""
        self._loops.append(closure)

    @property
    def pinned(self) -> list[LoopClosure]:
        """The loops :meth:`pin` took, in order."""
        return list(self._loops)

    def localize(self, points, poses) -> LoopClosure | None:
        """Where scan ``points`` (M, 2) (base frame, m) lie in the map of every stored keyframe at
        ``poses`` (K, 3), the pose unknown: a global search, or None if no place matches unambiguously.

        The scan is matched over the whole map at every heading: on a grid
        ``LOCALIZE_COARSENING`` times coarser than ``resolution`` within a window
        reaching every keyframe point from the map's centre, with the rival check;
        then on the fine grid against the keyframes within its view (as
        :meth:`wide_search` does). The LoopClosure's ``i`` is the nearest keyframe,
        its ``delta`` the scan's pose in that keyframe's frame; ``j`` is -1 (the scan
        is no keyframe yet).
        """
        cfg = self.cfg
        poses = geometry.as_pose(poses).reshape(-1, 3)
        points = voxel_filter(points, KEYFRAME_VOXEL_CELLS * cfg.resolution)
        members = [k for k in self._keys if k < len(poses)]
        if len(points) < MIN_POINTS or not members:
            return None
        self.stats["global searches"] += 1
        region = np.vstack([geometry.transform_points(poses[k], self._points[k]) for k in members])
        low, high = region.min(axis=0), region.max(axis=0)
        centre = np.array([*(0.5 * (low + high)), 0.0])
        window_xy = float(0.5 * np.max(high - low)) + 1.0
        coarse = ProbabilityGrid(region, LOCALIZE_COARSENING * cfg.resolution)
        cells = window_xy / coarse.resolution
        depth = int(np.clip(np.ceil(np.log2((2 * cells + 1) / WIDE_TOP_BLOCKS)), 1, WIDE_MAX_DEPTH))
        prune = max(0.0, cfg.min_score - SEARCH_MARGIN)
        found = match(coarse, points, centre, window_xy, np.pi, min_score=prune, depth=depth,
                      ambiguity_xy=max(cfg.ambiguity_distance, 2 * coarse.resolution),
                      ambiguity_ratio=cfg.ambiguity_ratio)  # fmt: skip
        if found.search_score < prune:
            self.stats["rejected_score"] += 1
            return None
        submap, anchor = self._view_submap(members, found.pose, points, poses)
        step = angular_step(voxel_filter(points, coarse.resolution), coarse.resolution)
        fine = match(submap.grid, points, geometry.between(poses[anchor], found.pose), 2 * coarse.resolution, step,
                     min_score=prune, prior_window=[window_xy, window_xy, np.pi])  # fmt: skip
        rival = None if found.rival is None else geometry.between(poses[anchor], found.rival)
        result = replace(fine, runner_up=found.runner_up, rival=rival)
        if result.score < cfg.min_score:
            self.stats["rejected_score"] += 1
            return None
        if result.runner_up > 0 and not self._rival_within_uncertainty(result):
            self.stats["rejected_ambiguous"] += 1
            return None
        self.stats["localized"] += 1
        info = np.linalg.inv(result.covariance)
        return LoopClosure(int(anchor), -1, result.pose, 0.5 * (info + info.T), result.score)

    @staticmethod
    def _rival_within_uncertainty(result) -> bool:
        """Whether the runner-up pose lies within the match's own uncertainty (chi-square 99 %, 3 dof):
        aliasing only along a direction the scan does not constrain (a corridor), which the
        match's covariance already leaves free; a rival elsewhere (a repeated room) is not."""
        d = result.rival - result.pose
        d[2] = geometry.wrap_angle(d[2])
        return bool(d @ np.linalg.solve(result.covariance, d) <= CHI2_3DOF_99)

    def _anchor(self, cand: int) -> int:
        """The submap anchor for ``cand``: the nearest keyframe whose position is a multiple of ``submap_keyframes``,
        in ``cand``'s session (the multiple before it when the nearest lies in a session placed after it)."""
        n, pos = self.cfg.submap_keyframes, self._position(cand)
        if n == 0:
            return int(cand)
        p = min(int(round(pos / n)) * n, len(self._keys) - 1)
        if abs(self._travelled[p] - self._travelled[pos]) >= SESSION_GAP / 2:
            p = pos // n * n
        return self._keys[p]

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
        if sum(len(self._points[k]) for k in members) < MIN_POINTS:
            return None
        submap = _Submap(members, relative, self._grid(members, relative))
        self._submaps[anchor] = submap
        if len(self._submaps) > SUBMAP_CACHE:
            self._submaps.popitem(last=False)
        return submap

    def _view_submap(self, members: list[int], pose: np.ndarray, points: np.ndarray, poses: np.ndarray):
        """The grid of the ``members`` within the scan's view of ``pose`` (the 95th percentile of its
        ``points``' ranges, m) in the frame of the nearest of them (its anchor), and that anchor.

        A revisit in the opposite direction sees what keyframes far behind the
        nearest one saw, not what the nearest one saw. The anchor is always a member, even
        when the scan's view reaches none of their positions (a short-ranged scan in the open)."""
        dist = np.hypot(*(poses[members, :2] - pose[:2]).T)
        reach = float(np.percentile(np.hypot(points[:, 0], points[:, 1]), VIEW_PERCENTILE))
        anchor = members[int(np.argmin(dist))]
        near = [k for k, d in zip(members, dist) if d <= reach or k == anchor]
        relative = geometry.between(poses[anchor], poses[near])
        return _Submap(tuple(near), relative, self._grid(near, relative)), anchor

    def _grid(self, members, relative: np.ndarray) -> ProbabilityGrid:
        """The sided grid of the members' points at their poses ``relative`` (n, 3), each point
        seen from its keyframe's position."""
        pts = [geometry.transform_points(p, self._points[k]) for k, p in zip(members, relative)]
        views = np.vstack([p[:2] - q for p, q in zip(relative, pts)])
        views /= np.maximum(np.hypot(views[:, 0], views[:, 1]), 1e-9)[:, None]
        return ProbabilityGrid(np.vstack(pts), self.cfg.resolution, views=views)

    def _unmoved(self, old: np.ndarray, new: np.ndarray) -> bool:
        """Whether relative member poses changed less than the reuse tolerances."""
        d = geometry.between(old, new)
        return bool(
            np.all(np.hypot(d[:, 0], d[:, 1]) < SUBMAP_REUSE_XY_CELLS * self.cfg.resolution)
            and np.all(np.abs(d[:, 2]) < SUBMAP_REUSE_THETA)
        )
