"""Line segments of one scan (turning-angle runs or split-and-merge), and of an occupancy grid.

See the package docstring for the method (Tian 2016, section 2.3.1). Points, segments and
tolerances are in metres, angles in radians (config angles in degrees).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field

from slam2d.config import Section
from slam2d.frontends.common import MaxRange, MinRange
from slam2d.frontends.lines.segments import Segments, tls_from_moments

__all__ = ["LineExtractionConfig", "LineExtraction", "extract_lines", "lines_from_grid"]

_BIG = 1e6  # m; path length inserted at a chain break so supports never cross it


class LineExtractionConfig(Section):
    """Per-scan segment extraction; the thesis gives no values, these suit 1-degree scans, ~1 cm noise."""

    method: Literal["angle", "split_merge"] = Field("angle", description="turning-angle runs, or split-and-merge")
    min_range: MinRange = 0.1
    max_range: MaxRange = 20.0
    jump_distance: float = Field(0.2, gt=0, description="m; consecutive points farther apart split a chain ...")
    jump_factor: float = Field(4.0, gt=0, description="... when also beyond this many beam spacings (range x angle)")
    support_length: float = Field(0.15, gt=0, description="m of path on each side of a point for its turning angle")
    flat_angle_deg: float = Field(15.0, gt=0, description="|turning angle| below this is 'near zero'")
    corner_angle_deg: float = Field(35.0, gt=0, description="turning-angle peaks above this are corners")
    split_distance: float = Field(0.04, gt=0, description="m; split_merge: split where a point is this far off")
    grow_tolerance: float = Field(0.04, gt=0, description="m; neighbouring points this close to a line join it")
    min_points: int = Field(6, ge=3, description="fewer points: no segment")
    min_length: float = Field(0.3, gt=0, description="m; shorter segments are dropped (the thesis's 'length')")
    max_rms: float = Field(0.03, gt=0, description="m; segments with a larger TLS residual (curved) are dropped")


@dataclass(frozen=True, eq=False)
class LineExtraction:
    """Result of :func:`extract_lines`, sensor frame.

    points (M, 2) the hit points used; chain (M,) chain id (chains split at
    range jumps); turn (M,) turning angle (rad, NaN where undefined);
    segments; spans (K, 2) point index range [start, stop) of each segment;
    corners (C,) point indices of turning-angle peaks.
    """

    points: np.ndarray
    chain: np.ndarray
    turn: np.ndarray
    segments: Segments
    spans: np.ndarray
    corners: np.ndarray


class _Moments:
    """Prefix sums of (1, x, y, xx, xy, yy) over ordered points: moments of any index range in O(1)."""

    def __init__(self, points: np.ndarray):
        x, y = points[:, 0], points[:, 1]
        terms = np.column_stack([np.ones(len(x)), x, y, x * x, x * y, y * y])
        self.cum = np.vstack([np.zeros(6), np.cumsum(terms, axis=0)])
        self.points = points

    def max_distance(self, lo: int, hi: int) -> float:
        """Largest distance (m) of points [lo, hi) to their TLS line."""
        n, sx, sy, sxx, sxy, syy = self.cum[hi] - self.cum[lo]
        cx, cy = sx / n, sy / n
        phi = 0.5 * np.arctan2(2.0 * (sxy - n * cx * cy), (sxx - n * cx * cx) - (syy - n * cy * cy))
        p = self.points[lo:hi]
        return float(np.abs((p[:, 1] - cy) * np.cos(phi) - (p[:, 0] - cx) * np.sin(phi)).max())

    def segments(self, start, stop) -> Segments:
        """Segments fitted to index ranges [start, stop) (arrays), normals towards the frame origin."""
        start, stop = np.asarray(start, int), np.asarray(stop, int)
        m = self.cum[stop] - self.cum[start]
        n = m[:, 0]
        c = m[:, 1:3] / n[:, None]
        sxx = m[:, 3] - n * c[:, 0] ** 2
        sxy = m[:, 4] - n * c[:, 0] * c[:, 1]
        syy = m[:, 5] - n * c[:, 1] ** 2
        scatter = np.stack([np.stack([sxx, sxy], -1), np.stack([sxy, syy], -1)], -2)
        normal, rms = tls_from_moments(n, c, scatter)
        normal = np.where(np.einsum("ki,ki->k", normal, c)[:, None] > 0, -normal, normal)
        u = np.column_stack([normal[:, 1], -normal[:, 0]])
        first, last = self.points[start], self.points[stop - 1]
        t0 = np.einsum("ki,ki->k", first - c, u)
        t1 = np.einsum("ki,ki->k", last - c, u)
        ends = np.stack([c + t0[:, None] * u, c + t1[:, None] * u], axis=1)
        return Segments(ends, n, c, scatter, normal, rms)


def _chains(points, ranges, angles, cfg: LineExtractionConfig):
    """Chain id (M,) and step lengths (M-1,); a chain breaks at a range jump."""
    step = np.linalg.norm(np.diff(points, axis=0), axis=1)
    spacing = np.minimum(ranges[:-1], ranges[1:]) * np.abs(np.diff(angles))
    brk = step > np.maximum(cfg.jump_distance, cfg.jump_factor * spacing)
    return np.concatenate([[0], np.cumsum(brk)]), step, brk


def _turning_angles(points, chain, step, brk, support: float) -> np.ndarray:
    """Turning angle (M,) at each point between chords ``support`` m of path back and ahead; NaN at chain ends."""
    m = len(points)
    s = np.concatenate([[0.0], np.cumsum(np.where(brk, _BIG, step))])
    lo = np.searchsorted(s, s - support, side="right") - 1
    hi = np.searchsorted(s, s + support, side="left")
    ok = (lo >= 0) & (hi < m)
    lo, hi = np.clip(lo, 0, m - 1), np.clip(hi, 0, m - 1)
    ok &= (chain[lo] == chain) & (chain[hi] == chain) & (lo < np.arange(m)) & (hi > np.arange(m))
    u, v = points - points[lo], points[hi] - points
    turn = np.arctan2(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0], np.einsum("ki,ki->k", u, v))
    return np.where(ok, turn, np.nan)


def _runs(mask: np.ndarray, chain: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Maximal runs [start, stop) of True in ``mask`` that stay within one chain."""
    cont = np.r_[False, mask[:-1] & mask[1:] & (chain[1:] == chain[:-1])]
    starts = np.flatnonzero(mask & ~cont)
    ends = np.flatnonzero(mask & ~np.r_[cont[1:], False]) + 1
    return starts, ends


def _peaks(values: np.ndarray, mask: np.ndarray, chain: np.ndarray) -> np.ndarray:
    """Index of the largest ``values`` in each run of ``mask`` (adjacent peak samples merged into one)."""
    starts, ends = _runs(mask, chain)
    if len(starts) == 0:
        return np.zeros(0, int)
    idx = np.flatnonzero(mask)
    group = np.searchsorted(starts, idx, side="right") - 1
    order = np.lexsort((-values[idx], group))
    first = np.r_[True, group[order][1:] != group[order][:-1]]
    return idx[order][first]


def _grow(moments: _Moments, chain_start, chain_stop, start, stop, tolerance: float):
    """Extend each run [start, stop) over contiguous chain points within ``tolerance`` m of its line."""
    seg = moments.segments(start, stop)
    new_start, new_stop = start.copy(), stop.copy()
    for k in range(len(start)):
        a, b = chain_start[k], chain_stop[k]
        far = np.abs((moments.points[a:b] - seg.centroid[k]) @ seg.normal[k]) > tolerance
        left = np.flatnonzero(far[: start[k] - a])
        right = np.flatnonzero(far[stop[k] - a:])
        new_start[k] = a + (left[-1] + 1 if len(left) else 0)
        new_stop[k] = stop[k] + (right[0] if len(right) else b - stop[k])
    return new_start, new_stop


def _merge_collinear(moments: _Moments, chain, start, stop, cfg: LineExtractionConfig):
    """Merge overlapping or touching spans of one chain whose union is one line.

    The union is one line when every point of it lies within ``grow_tolerance``
    of its TLS fit; a span inside the previous one (a short run its growth
    covered) is absorbed.
    """
    if len(start) < 2:
        return start, stop
    order = np.lexsort((-stop, start))  # by start, the longest first: contained spans come after
    spans = [[int(start[order[0]]), int(stop[order[0]])]]
    for a, b in zip(start[order[1:]], stop[order[1:]]):
        pa, pb = spans[-1]
        if chain[a] == chain[pa] and a <= pb:
            lo, hi = pa, max(pb, b)
            if hi == pb or moments.max_distance(lo, hi) <= cfg.grow_tolerance:
                spans[-1] = [lo, hi]
                continue
        spans.append([int(a), int(b)])
    spans = np.array(spans, int)
    return spans[:, 0], spans[:, 1]


def _split_merge_spans(points, chain, cfg: LineExtractionConfig):
    """Iterative end-point fit: split each chain where a point is beyond ``split_distance`` of the chord."""
    bounds = np.flatnonzero(np.r_[True, chain[1:] != chain[:-1], True])
    spans, stack = [], [(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:])]
    while stack:
        a, b = stack.pop()
        if b - a < 3:
            continue
        p0, p1 = points[a], points[b - 1]
        d = p1 - p0
        norm = np.hypot(*d)
        if norm == 0:
            continue
        dist = np.abs((points[a:b, 0] - p0[0]) * d[1] - (points[a:b, 1] - p0[1]) * d[0]) / norm
        k = int(np.argmax(dist))
        if dist[k] > cfg.split_distance and 0 < k < b - a - 1:
            stack += [(a, a + k + 1), (a + k, b)]
        else:
            spans.append((a, b))
    spans = np.array(sorted(spans), int).reshape(-1, 2)
    return spans[:, 0], spans[:, 1]


def extract_lines(ranges, angles, config: LineExtractionConfig | None = None) -> LineExtraction:
    """Line segments and corners of one scan from its valid beams, in scan order (sensor frame).

    ``ranges`` (M,) m and ``angles`` (M,) rad of the hit beams only, ordered by angle.
    """
    cfg = config or LineExtractionConfig()
    r, a = np.asarray(ranges, float), np.asarray(angles, float)
    keep = np.isfinite(r) & (r >= cfg.min_range) & (r <= cfg.max_range)
    r, a = r[keep], a[keep]
    points = np.column_stack([r * np.cos(a), r * np.sin(a)])
    if len(points) < cfg.min_points:
        return LineExtraction(points, np.zeros(len(points), int), np.full(len(points), np.nan), Segments.empty(),
                              np.zeros((0, 2), int), np.zeros(0, int))
    chain, step, brk = _chains(points, r, a, cfg)
    turn = _turning_angles(points, chain, step, brk, cfg.support_length)
    abs_turn = np.abs(np.nan_to_num(turn, nan=0.0))
    corners = _peaks(abs_turn, abs_turn > np.deg2rad(cfg.corner_angle_deg), chain)
    moments = _Moments(points)
    if cfg.method == "split_merge":
        start, stop = _split_merge_spans(points, chain, cfg)
    else:
        start, stop = _runs(np.isfinite(turn) & (abs_turn < np.deg2rad(cfg.flat_angle_deg)), chain)
        long = stop - start >= 3
        start, stop = start[long], stop[long]
        if len(start):
            bounds = np.flatnonzero(np.r_[True, chain[1:] != chain[:-1], True])
            cid = chain[start]
            start, stop = _grow(moments, bounds[cid], bounds[cid + 1], start, stop, cfg.grow_tolerance)
    start, stop = _merge_collinear(moments, chain, start, stop, cfg)
    segs = moments.segments(start, stop) if len(start) else Segments.empty()
    good = (segs.count >= cfg.min_points) & (segs.length >= cfg.min_length) & (segs.rms <= cfg.max_rms)
    spans = np.column_stack([start, stop]).reshape(-1, 2)[good] if len(start) else np.zeros((0, 2), int)
    return LineExtraction(points, chain, turn, segs.subset(good), spans, corners)


def lines_from_grid(occupancy, resolution: float, origin=(0.0, 0.0), *, canny_sigma: float = 1.0,
                    threshold: int = 10, min_length: float = 0.5, max_gap: float = 0.15,
                    use_canny: bool = True, seed: int = 0) -> Segments:
    """Wall segments (map frame, m) of an occupancy grid by Canny edges and the probabilistic Hough transform
    (:func:`slam2d.mapping.geometric.hough_segments`, which takes the Hough options).

    ``occupancy`` (H, W): row = y, col = x, cell [0, 0] with its lower-left
    corner at ``origin``; boolean (occupied) or probability in [0, 1].
    ``min_length`` and ``max_gap`` (m) pass to Hough; ``threshold`` is its
    vote count; ``use_canny=False`` runs Hough on the occupied cells directly
    (thin walls). Normals face the free side. Each segment gets moments as if
    sampled once per cell along it.
    """
    from slam2d.mapping.geometric import hough_segments

    occupied = np.asarray(occupancy, dtype=float) >= 0.5
    ends = hough_segments(occupied, resolution, origin, canny_sigma=canny_sigma, threshold=threshold,
                          min_length=min_length, max_gap=max_gap, use_canny=use_canny, seed=seed)
    if not len(ends):
        return Segments.empty()
    segs = Segments.from_ends(ends, resolution)
    h, w = occupied.shape

    def occupied_at(p):
        col = np.clip(((p[:, 0] - origin[0]) / resolution).astype(int), 0, w - 1)
        row = np.clip(((p[:, 1] - origin[1]) / resolution).astype(int), 0, h - 1)
        return occupied[row, col]

    probe = 2.0 * resolution * segs.normal
    flip = occupied_at(segs.centroid + probe) & ~occupied_at(segs.centroid - probe)
    return Segments(segs.ends, segs.count, segs.centroid, segs.scatter,
                    np.where(flip[:, None], -segs.normal, segs.normal), segs.rms)
