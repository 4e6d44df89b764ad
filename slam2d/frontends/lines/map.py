"""The line frontend's global segment map: lines in the map frame as point moments (metres)."""

from __future__ import annotations

import numpy as np

from slam2d.frontends.lines.segments import Segments, tls_from_moments

__all__ = ["SegmentMap"]


class SegmentMap:
    """Lines in the map frame as point moments; extended by merging re-observations.

    Arrays (M, ...) as in :class:`Segments`, plus ``seen`` (times observed) and
    ``last_seen`` (scan index). ``max_count`` caps a line's point count (older
    evidence is scaled down) so a line can still follow slow corrections.
    """

    def __init__(self, max_count: float = 5000.0):
        self.lines = Segments.empty()
        self.seen = np.zeros(0, int)
        self.last_seen = np.zeros(0, int)
        self.max_count = max_count

    def __len__(self) -> int:
        return len(self.lines)

    def near(self, center, radius: float) -> np.ndarray:
        """Indices of lines whose bounding box comes within ``radius`` m of ``center`` (2,)."""
        if not len(self):
            return np.zeros(0, int)
        lo, hi = self.lines.ends.min(axis=1), self.lines.ends.max(axis=1)
        c = np.asarray(center, float)[:2]
        return np.flatnonzero(np.all((hi >= c - radius) & (lo <= c + radius), axis=1))

    def add(self, segs: Segments, index: int, seen: int = 1) -> None:
        """Append ``segs`` (map frame) as new lines observed at scan ``index``."""
        if not len(segs):
            return
        segs = _cap(segs, self.max_count)
        old = self.lines
        self.lines = Segments(*(np.concatenate([getattr(old, f), getattr(segs, f)]) for f in _FIELDS))
        self.seen = np.concatenate([self.seen, np.full(len(segs), seen)])
        self.last_seen = np.concatenate([self.last_seen, np.full(len(segs), index)])

    def merge(self, map_idx: np.ndarray, segs: Segments, index: int) -> None:
        """Add the moments of ``segs`` (map frame) to lines ``map_idx`` (K,); refit, extend the endpoints.

        Raw moments (count, sum p, sum p p^T) add exactly, so several segments
        may merge into one line at once.
        """
        L, j = self.lines, np.asarray(map_idx, int)
        lines = np.unique(j)
        slot = np.searchsorted(lines, j)
        old_c = L.centroid[lines]
        n = L.count[lines].copy()
        s = n[:, None] * old_c
        q = L.scatter[lines] + n[:, None, None] * np.einsum("ki,kj->kij", old_c, old_c)
        np.add.at(n, slot, segs.count)
        np.add.at(s, slot, segs.count[:, None] * segs.centroid)
        np.add.at(q, slot, segs.scatter + segs.count[:, None, None] * np.einsum("ki,kj->kij", segs.centroid,
                                                                                segs.centroid))
        c = s / n[:, None]
        scatter = q - n[:, None, None] * np.einsum("ki,kj->kij", c, c)
        normal, rms = tls_from_moments(n, c, scatter)
        normal = np.where(np.einsum("ki,ki->k", normal, L.normal[lines])[:, None] < 0, -normal, normal)
        u = np.column_stack([normal[:, 1], -normal[:, 0]])
        t_old = np.einsum("kei,ki->ke", L.ends[lines] - c[:, None], u)
        t_new = np.einsum("kei,ki->ke", segs.ends - c[slot][:, None], u[slot])
        t_min, t_max = t_old.min(axis=1), t_old.max(axis=1)
        np.minimum.at(t_min, slot, t_new.min(axis=1))
        np.maximum.at(t_max, slot, t_new.max(axis=1))
        f = np.minimum(1.0, self.max_count / n)
        L.ends[lines] = c[:, None] + np.stack([t_min, t_max], axis=1)[..., None] * u[:, None]
        L.count[lines], L.centroid[lines], L.scatter[lines] = n * f, c, scatter * f[:, None, None]
        L.normal[lines], L.rms[lines] = normal, rms
        self.seen[lines] += 1
        self.last_seen[lines] = index

    def prune(self, index: int, min_seen: int, max_age: int) -> None:
        """Forget lines seen fewer than ``min_seen`` times and not for ``max_age`` scans."""
        keep = (self.seen >= min_seen) | (index - self.last_seen <= max_age)
        if not keep.all():
            self.lines = self.lines.subset(keep)
            self.seen, self.last_seen = self.seen[keep], self.last_seen[keep]


_FIELDS = ("ends", "count", "centroid", "scatter", "normal", "rms")


def _cap(segs: Segments, max_count: float) -> Segments:
    """Segments with counts (and scatters) scaled down to at most ``max_count``."""
    f = np.minimum(1.0, max_count / np.maximum(segs.count, 1e-12))
    return Segments(segs.ends, segs.count * f, segs.centroid, segs.scatter * f[:, None, None], segs.normal, segs.rms)
