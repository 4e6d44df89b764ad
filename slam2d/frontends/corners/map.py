"""The corner frontend's global corner list (map frame, metres and radians) with stable ids."""

from __future__ import annotations

import numpy as np

from slam2d import geometry

__all__ = ["CornerMap"]


class CornerMap:
    """The global corner list (map frame): positions, bisector headings, sighting counts, stable ids.

    ``xy`` (N, 2) m, ``direction`` (N,) rad (the corner's bisector, NaN if
    never given), ``count`` (N,) sightings, ``ids`` (N,) stable ids (never
    reused), ``last_seen`` (N,) scan index. Look-ups go through a KD-tree over
    the positions; entries appended since the last build are checked directly,
    and the tree is rebuilt after ``rebuild_every`` appends, or when an entry
    has moved more than a quarter of the look-up radius from where the tree has it.
    """

    def __init__(self, merge_radius: float = 0.25, rebuild_every: int = 16, max_count: int = 50,
                 max_angle_deg: float = 30.0):
        self.merge_radius = merge_radius
        self.rebuild_every = rebuild_every
        self.max_count = max_count
        self.max_angle = np.deg2rad(max_angle_deg)
        self.xy = np.zeros((0, 2))
        self.direction = np.zeros(0)
        self.count = np.zeros(0, int)
        self.ids = np.zeros(0, int)
        self.last_seen = np.zeros(0, int)
        self.tree = None  # scipy cKDTree over xy[:_built] as they were at build time
        self._built = 0
        self._built_xy = np.zeros((0, 2))
        self._next_id = 0

    def __len__(self) -> int:
        return len(self.xy)

    def rebuild(self) -> None:
        """Build the KD-tree over every entry now."""
        from scipy.spatial import cKDTree

        self._built_xy = self.xy.copy()
        self._built = len(self.xy)
        self.tree = cKDTree(self._built_xy) if self._built else None

    def _stale(self, radius: float) -> bool:
        if len(self.xy) - self._built > self.rebuild_every:
            return True
        if not self._built:
            return False
        return float(np.max(np.linalg.norm(self.xy[: self._built] - self._built_xy, axis=1))) > radius / 4

    def nearest(self, points, radius: float, min_count: int = 1, directions=None) -> tuple[np.ndarray, np.ndarray]:
        """Index (P,) of the nearest entry within ``radius`` m of each point (-1: none) and its distance (inf).

        Only entries seen ``min_count`` times qualify, and with ``directions``
        (P,) rad only those whose bisector differs by less than ``max_angle_deg``.
        """
        pts = np.asarray(points, float).reshape(-1, 2)
        dirs = None if directions is None else np.asarray(directions, float).reshape(-1)
        best = np.full(len(pts), -1)
        dist = np.full(len(pts), np.inf)
        if not len(self.xy) or not len(pts):
            return best, dist
        if self._stale(radius):
            self.rebuild()
        if self.tree is not None:
            k = min(4, self._built)
            _, cand = self.tree.query(pts, k=k, distance_upper_bound=radius * 1.25 + 1e-9)
            cand = cand.reshape(len(pts), k)
            self._pick(pts, dirs, cand, cand < self._built, min_count, best, dist)
        if len(self.xy) > self._built:
            cand = np.broadcast_to(np.arange(self._built, len(self.xy)), (len(pts), len(self.xy) - self._built))
            self._pick(pts, dirs, cand, np.ones(cand.shape, bool), min_count, best, dist)
        far = dist > radius
        best[far], dist[far] = -1, np.inf
        return best, dist

    def _pick(self, pts, dirs, cand, valid, min_count, best, dist) -> None:
        """Update ``best``/``dist`` in place with the closest current position among ``cand`` (P, k)."""
        c = np.where(valid, cand, 0)
        ok = valid & (self.count[c] >= min_count)
        if dirs is not None:
            turn = np.abs(geometry.wrap_angle(self.direction[c] - dirs[:, None]))
            ok &= ~(turn >= self.max_angle)  # NaN (no heading stored) passes
        d = np.where(ok, np.linalg.norm(self.xy[c] - pts[:, None], axis=2), np.inf)
        j = np.argmin(d, axis=1)
        dj = d[np.arange(len(pts)), j]
        better = dj < dist
        best[better], dist[better] = c[better, j[better]], dj[better]

    def update(self, points, index: int, directions=None) -> np.ndarray:
        """Merge each point (P, 2) into the entry within ``merge_radius`` (and ``max_angle_deg`` of its
        bisector ``directions`` (P,), if given) or append it; entry indices (P,)."""
        pts = np.asarray(points, float).reshape(-1, 2)
        dirs = np.full(len(pts), np.nan) if directions is None else np.asarray(directions, float).reshape(-1)
        idx, _ = self.nearest(pts, self.merge_radius, directions=None if directions is None else dirs)
        out = idx.copy()
        self.observe(idx[idx >= 0], pts[idx >= 0], index, dirs[idx >= 0])
        for k in np.flatnonzero(idx < 0):  # a few new corners per scan; one may repeat another
            j, _ = self.nearest(pts[k], self.merge_radius, directions=None if directions is None else dirs[k:k + 1])
            if j[0] >= 0:
                self.observe(j, pts[k:k + 1], index, dirs[k:k + 1])
                out[k] = j[0]
            else:
                out[k] = self._append(pts[k], dirs[k], index)
        return out

    def observe(self, entries, points, index: int, directions=None) -> None:
        """Entries ``entries`` seen again at ``points`` (map frame): running means, count capped at max_count."""
        entries = np.asarray(entries, int)
        if not len(entries):
            return
        w = np.minimum(self.count[entries], self.max_count) + 1.0
        self.xy[entries] += (np.asarray(points, float) - self.xy[entries]) / w[:, None]
        if directions is not None:
            new, old = np.asarray(directions, float), self.direction[entries]
            merged = geometry.wrap_angle(old + geometry.wrap_angle(new - old) / w)
            self.direction[entries] = np.where(np.isnan(old), new, np.where(np.isnan(new), old, merged))
        self.count[entries] += 1
        self.last_seen[entries] = index

    def _append(self, point, direction: float, index: int) -> int:
        self.xy = np.vstack([self.xy, point])
        self.direction = np.append(self.direction, direction)
        self.count = np.append(self.count, 1)
        self.ids = np.append(self.ids, self._next_id)
        self.last_seen = np.append(self.last_seen, index)
        self._next_id += 1
        return len(self.xy) - 1

    def prune(self, index: int, min_count: int, max_age: int) -> None:
        """Drop entries seen fewer than ``min_count`` times and not for ``max_age`` scans; rebuild the tree."""
        keep = (self.count >= min_count) | (index - self.last_seen <= max_age)
        if not keep.all():
            self.xy, self.direction, self.count = self.xy[keep], self.direction[keep], self.count[keep]
            self.ids, self.last_seen = self.ids[keep], self.last_seen[keep]
            self.rebuild()
