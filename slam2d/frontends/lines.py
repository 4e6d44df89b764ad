"""Line-segment frontend: per-scan segment extraction, a global line map, SE(2) from line normals.

After the patrol-robot thesis (Tian 2016, sections 2.3.1 and 2.3.3):

- Extraction walks the ordered scan points. The turning angle between the
  chords (p_lo, p_i) and (p_i, p_hi), where p_lo and p_hi lie ``support_length``
  metres of path before and after p_i (one beam each side in the thesis; a
  fixed path length is steadier under range noise), forms a sequence. Long
  runs near zero are line segments, fitted by total least squares and grown
  over neighbouring points within ``grow_tolerance`` of the line (touching
  runs whose union stays within it merge); peaks above ``corner_angle_deg``
  (adjacent peak samples merged) are corners. Chains are split at range
  jumps. Split-and-merge (iterative end-point fit) is the alternative ``method``.
- The global line map holds each line's point moments (count, centroid,
  scatter) in the map frame; a re-observed line is merged into its map line
  (moments added, TLS refitted, endpoints extended), never re-extracted.
- Matching associates observed segments (at the odometry guess) with map
  lines by normal angle, distance and overlap, then solves the base pose by
  Gauss-Newton: each matched line gives a distance residual along its map
  normal at the observed centroid (variance sigma^2 / N) and an angle residual
  (variance sigma^2 / scatter along the line), Cauchy-weighted, plus the
  odometry delta as a prior. When a histogram of normal-angle differences
  points to another heading, the solve also starts from there and the more
  consistent solution wins (odometry turns can be off by 10 degrees and
  more). A corridor constrains nothing along itself, so the information is
  small there (only the odometry prior).
- Confidence is the thesis's eq. 7: matched observed length / observed length.
- Optionally (``calibration``, off by default) the odometry heading is
  calibrated online from the accepted matches (see ``odometry.HeadingCalibration``).

:func:`lines_from_grid` extracts map lines from an occupancy grid (Canny and
probabilistic Hough, scikit-image, through ``slam2d.mapping.geometric``); :meth:`LineFrontend.reanchor` rebuilds the
map lines from such a grid (the ``reanchor_every`` option does it from the
frontend's own recent scans).
"""

from __future__ import annotations

import logging
from collections import Counter, deque
from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field

from slam2d import geometry
from slam2d.config import Section
from slam2d.frontends.base import FrontendResult, register_frontend
from slam2d.frontends.common import (
    MaxCorrectionThetaDeg,
    MaxCorrectionXY,
    MaxRange,
    MaxSigmaThetaDeg,
    MaxSigmaXY,
    MinRange,
    MinSigmaThetaDeg,
    MinSigmaXY,
    OdomSigmaThetaDeg,
    OdomSigmaXY,
    beyond_correction,
    bound_information,
    local_information,
    sigma_bounds,
)
from slam2d.frontends.gate import SimilarityGate
from slam2d.frontends.odometry import HeadingCalibration, odometry_information
from slam2d.types import Scan

log = logging.getLogger(__name__)

__all__ = [
    "LineExtractionConfig",
    "LineMatchConfig",
    "Segments",
    "LineExtraction",
    "LineMap",
    "LineMatch",
    "fit_line",
    "extract_lines",
    "match_lines",
    "lines_from_grid",
    "LineFrontend",
]

_BIG = 1e6  # m; path length inserted at a chain break so supports never cross it


# --------------------------------------------------------------------------- configuration


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


class LineMatchConfig(Section):
    """Association of observed segments with map lines, and the pose solve."""

    max_angle_deg: float = Field(8.0, gt=0, description="largest normal-angle difference of a match")
    max_distance: float = Field(0.3, gt=0, description="m; largest distance of the observed centroid to the map line")
    max_gap: float = Field(0.5, ge=0, description="m; largest gap along the line between observed and map extents")
    heading_window_deg: float = Field(20.0, ge=0, description="heading search around odometry (0: none)")
    heading_bin_deg: float = Field(1.0, gt=0, description="bin of the heading search")
    rounds: int = Field(2, gt=0, description="association rounds (re-associate at the updated pose)")
    iterations: int = Field(5, gt=0, description="Gauss-Newton steps per round")
    robust_scale: float = Field(3.0, gt=0, description="Cauchy kernel width in sigmas")
    sigma_point: float = Field(0.02, gt=0, description="m; floor of the per-point noise of a segment fit")
    sigma_map_distance: float = Field(0.01, gt=0, description="m; map line position noise")
    sigma_map_angle_deg: float = Field(0.3, gt=0, description="map line direction noise")
    max_correction_xy: MaxCorrectionXY = 0.5
    max_correction_theta_deg: MaxCorrectionThetaDeg = 25.0


# --------------------------------------------------------------------------- segments


@dataclass(frozen=True, eq=False)
class Segments:
    """K line segments with their point moments, all in one frame (metres).

    ends (K, 2, 2) endpoints (scan order); count (K,) points; centroid (K, 2);
    scatter (K, 2, 2) central second moments sum (p - c)(p - c)^T, m^2;
    normal (K, 2) unit, towards the side the segment was seen from; rms (K,)
    TLS residual, m.
    """

    ends: np.ndarray
    count: np.ndarray
    centroid: np.ndarray
    scatter: np.ndarray
    normal: np.ndarray
    rms: np.ndarray

    def __len__(self) -> int:
        return len(self.count)

    @classmethod
    def from_ends(cls, ends, spacing: float = 0.05) -> Segments:
        """Segments (K, 2, 2) as if sampled every ``spacing`` m; normals on the left of p0 -> p1."""
        ends = np.asarray(ends, float).reshape(-1, 2, 2)
        d = ends[:, 1] - ends[:, 0]
        length = np.linalg.norm(d, axis=1)
        u = d / np.maximum(length, 1e-12)[:, None]
        count = np.maximum(length / spacing, 2.0)
        scatter = (count * length**2 / 12.0)[:, None, None] * np.einsum("ki,kj->kij", u, u)
        return cls(ends, count, ends.mean(axis=1), scatter, np.column_stack([-u[:, 1], u[:, 0]]),
                   np.zeros(len(ends)))

    @classmethod
    def empty(cls) -> Segments:
        return cls(np.zeros((0, 2, 2)), np.zeros(0), np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros((0, 2)),
                   np.zeros(0))

    @property
    def length(self) -> np.ndarray:
        """(K,) m."""
        return np.linalg.norm(self.ends[:, 1] - self.ends[:, 0], axis=1)

    @property
    def direction(self) -> np.ndarray:
        """(K, 2) unit direction, the normal turned by -90 degrees."""
        return np.column_stack([self.normal[:, 1], -self.normal[:, 0]])

    @property
    def alpha(self) -> np.ndarray:
        """(K,) normal angle, rad."""
        return np.arctan2(self.normal[:, 1], self.normal[:, 0])

    @property
    def offset(self) -> np.ndarray:
        """(K,) signed distance d of the line n . p = d, m."""
        return np.einsum("ki,ki->k", self.normal, self.centroid)

    @property
    def spread(self) -> np.ndarray:
        """(K,) scatter along the line, sum ((p - c) . u)^2, m^2."""
        u = self.direction
        return np.einsum("ki,kij,kj->k", u, self.scatter, u)

    def transformed(self, pose) -> Segments:
        """The segments mapped from the frame of ``pose`` (3,) to its parent frame."""
        pose = geometry.as_pose(pose)
        c, s = np.cos(pose[2]), np.sin(pose[2])
        rot = np.array([[c, -s], [s, c]])
        return Segments(
            ends=geometry.transform_points(pose, self.ends),
            count=self.count,
            centroid=geometry.transform_points(pose, self.centroid),
            scatter=rot @ self.scatter @ rot.T,
            normal=self.normal @ rot.T,
            rms=self.rms,
        )

    def subset(self, keep) -> Segments:
        return Segments(self.ends[keep], self.count[keep], self.centroid[keep], self.scatter[keep],
                        self.normal[keep], self.rms[keep])


def _tls(count, centroid, scatter) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (K, 2) and rms residuals (K,) of total-least-squares lines through point moments."""
    sxx, syy, sxy = scatter[:, 0, 0], scatter[:, 1, 1], scatter[:, 0, 1]
    phi = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)  # direction of largest spread
    normal = np.column_stack([-np.sin(phi), np.cos(phi)])
    lam_min = 0.5 * (sxx + syy) - np.hypot(0.5 * (sxx - syy), sxy)
    return normal, np.sqrt(np.maximum(lam_min, 0.0) / np.maximum(count, 1))


def fit_line(points) -> tuple[np.ndarray, np.ndarray, float]:
    """Total-least-squares line of points (N, 2): centroid (2,), unit normal (2,), rms distance (m)."""
    p = np.asarray(points, float).reshape(-1, 2)
    c = p.mean(axis=0)
    d = p - c
    normal, rms = _tls(np.array([len(p)]), c[None], (d.T @ d)[None])
    return c, normal[0], float(rms[0])


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
        normal, rms = _tls(n, c, scatter)
        normal = np.where(np.einsum("ki,ki->k", normal, c)[:, None] > 0, -normal, normal)
        u = np.column_stack([normal[:, 1], -normal[:, 0]])
        first, last = self.points[start], self.points[stop - 1]
        t0 = np.einsum("ki,ki->k", first - c, u)
        t1 = np.einsum("ki,ki->k", last - c, u)
        ends = np.stack([c + t0[:, None] * u, c + t1[:, None] * u], axis=1)
        return Segments(ends, n, c, scatter, normal, rms)


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


# --------------------------------------------------------------------------- the global line map


class LineMap:
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
        normal, rms = _tls(n, c, scatter)
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


# --------------------------------------------------------------------------- matching


def associate(obs: Segments, lines: Segments, cfg: LineMatchConfig) -> np.ndarray:
    """Map line index (K,) for each observed segment (same frame), -1 if none qualifies.

    A pair qualifies by normal angle (< max_angle_deg; normals face the observer,
    so the two faces of a thin wall never match), distance of the observed
    centroid to the map line (< max_distance) and along-line gap of their
    extents (< max_gap); the lowest normalised cost wins.
    """
    if not len(obs) or not len(lines):
        return np.full(len(obs), -1)
    dalpha = geometry.wrap_angle(obs.alpha[:, None] - lines.alpha[None])
    dist = obs.centroid @ lines.normal.T - lines.offset[None]
    u = lines.direction
    t_obs = np.einsum("kei,mi->kme", obs.ends, u)  # (K, M, 2) along each map line
    t_map = np.einsum("mei,mi->me", lines.ends, u)  # (M, 2)
    gap = np.maximum(t_obs.min(-1), t_map.min(-1)[None]) - np.minimum(t_obs.max(-1), t_map.max(-1)[None])
    max_angle = np.deg2rad(cfg.max_angle_deg)
    ok = (np.abs(dalpha) < max_angle) & (np.abs(dist) < cfg.max_distance) & (gap < cfg.max_gap)
    cost = np.where(ok, (dist / cfg.max_distance) ** 2 + (dalpha / max_angle) ** 2, np.inf)
    best = np.argmin(cost, axis=1)
    return np.where(np.isfinite(cost[np.arange(len(obs)), best]), best, -1)


def _line_weights(obs: Segments, cfg: LineMatchConfig) -> tuple[np.ndarray, np.ndarray]:
    """Information of the distance (1/m^2) and angle (1/rad^2) residual of each observed segment.

    A TLS fit of N points with noise sigma has centroid-offset variance
    sigma^2 / N and direction variance sigma^2 / sum((p - c) . u)^2; the map
    line adds its own noise.
    """
    sigma2 = np.maximum(obs.rms, cfg.sigma_point) ** 2
    var_d = sigma2 / obs.count + cfg.sigma_map_distance**2
    var_a = sigma2 / np.maximum(obs.spread, 1e-9) + np.deg2rad(cfg.sigma_map_angle_deg) ** 2
    return 1.0 / var_d, 1.0 / var_a


def _normal_equations(pose, c_obs, a_obs, w_d, w_a, n_map, d_map, a_map, robust: float):
    """H (3, 3), g (3,) of the Cauchy-weighted line residuals at ``pose`` (world-frame parameters).

    The Cauchy kernel width ``robust`` is in sigmas of each residual.
    """
    c, s = np.cos(pose[2]), np.sin(pose[2])
    pc = np.column_stack([c * c_obs[:, 0] - s * c_obs[:, 1], s * c_obs[:, 0] + c * c_obs[:, 1]])
    dpc = np.column_stack([-pc[:, 1], pc[:, 0]])  # d(R c)/d theta
    r_d = np.einsum("ki,ki->k", n_map, pc + pose[:2]) - d_map
    r_a = geometry.wrap_angle(a_obs + pose[2] - a_map)
    w_d = w_d / (1.0 + w_d * r_d**2 / robust**2)
    w_a = w_a / (1.0 + w_a * r_a**2 / robust**2)
    j_d = np.column_stack([n_map, np.einsum("ki,ki->k", n_map, dpc)])
    h = (j_d * w_d[:, None]).T @ j_d
    h[2, 2] += w_a.sum()
    g = j_d.T @ (w_d * r_d)
    g[2] += (w_a * r_a).sum()
    return h, g


def _prior_terms(pose, guess, prior: np.ndarray):
    """H, g of the odometry prior ||guess^-1 pose||^2_prior (translation in the guess frame)."""
    c, s = np.cos(guess[2]), np.sin(guess[2])
    j = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    d = pose - guess
    r = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], (d[2] + np.pi) % (2 * np.pi) - np.pi])
    return j.T @ prior @ j, j.T @ prior @ r


@dataclass(frozen=True, eq=False)
class LineMatch:
    """Outcome of :func:`match_lines`: base ``pose`` (map frame), ``information`` of the line
    constraints alone (3, 3, local frame of ``pose``), ``confidence`` (matched / observed
    length), ``matched`` (K,) map line per observed segment (-1: none)."""

    pose: np.ndarray
    information: np.ndarray
    confidence: float
    matched: np.ndarray


def heading_correction(obs: Segments, lines: Segments, guess, cfg: LineMatchConfig) -> float:
    """Rotation (rad) of ``guess`` that best aligns observed normals with map normals.

    The peak of a histogram (``heading_bin_deg`` bins within +-``heading_window_deg``)
    of normal-angle differences of all observed/map pairs, each weighted by the
    shorter length; refined by the weighted mean around the peak.
    """
    window, width = np.deg2rad(cfg.heading_window_deg), np.deg2rad(cfg.heading_bin_deg)
    if not len(obs) or not len(lines):
        return 0.0
    d = geometry.wrap_angle(lines.alpha[None] - (obs.alpha[:, None] + guess[2])).ravel()
    w = np.minimum(obs.length[:, None], lines.length[None]).ravel()
    near = np.abs(d) < window
    d, w = d[near], w[near]
    if not len(d):
        return 0.0
    bins = int(np.ceil(window / width))
    hist = np.bincount(np.clip(((d + window) / width).astype(int), 0, 2 * bins - 1), w, 2 * bins)
    hist = np.convolve(hist, [1.0, 2.0, 1.0], mode="same")
    peak = -window + (np.argmax(hist) + 0.5) * width
    around = np.abs(d - peak) < 1.5 * width
    return float(np.average(d[around], weights=w[around])) if around.any() else 0.0


def match_lines(obs: Segments, lines: Segments, guess, prior: np.ndarray,
                config: LineMatchConfig | None = None) -> LineMatch:
    """Base pose (map frame) that best lays ``obs`` (base frame) on ``lines`` (map frame), from ``guess``.

    ``prior`` (3, 3) is the information of the odometry guess (local frame).
    The solve starts from ``guess`` and, when the heading search disagrees
    with it, also from ``guess`` turned by :func:`heading_correction`; the
    solution with the larger length of consistent matches wins.
    """
    cfg = config or LineMatchConfig()
    guess = geometry.as_pose(guess)
    w = _line_weights(obs, cfg)
    best, score = _solve(obs, lines, guess.copy(), guess, prior, w, cfg)
    if cfg.heading_window_deg > 0:
        turn = heading_correction(obs, lines, guess, cfg)
        if abs(turn) > 0.5 * np.deg2rad(cfg.heading_bin_deg):
            other, other_score = _solve(obs, lines, guess + [0.0, 0.0, turn], guess, prior, w, cfg)
            if other_score > score:
                best = other
    return best


def _solve(obs, lines, start, guess, prior, weights, cfg: LineMatchConfig) -> tuple[LineMatch, float]:
    """Associate and solve by Gauss-Newton from ``start``; the match and its score.

    The score is the observed length of the matched segments, each weighted by
    its Cauchy weight at the solution (1 for a perfect fit, small for a poor one).
    """
    w_d, w_a = weights
    pose = start.copy()
    matched = np.full(len(obs), -1)
    h_lines = np.zeros((3, 3))
    args = None
    for k in range(cfg.rounds):
        new = associate(obs.transformed(pose), lines, cfg)
        if k > 0 and np.array_equal(new, matched):
            break
        matched = new
        sel = matched >= 0
        if not sel.any():
            break
        m = lines.subset(matched[sel])
        args = (obs.centroid[sel], obs.alpha[sel], w_d[sel], w_a[sel], m.normal, m.offset, m.alpha)
        for _ in range(cfg.iterations):
            h_lines, g = _normal_equations(pose, *args, cfg.robust_scale)
            hp, gp = _prior_terms(pose, guess, prior)
            step = np.linalg.solve(h_lines + hp, -(g + gp))
            pose = pose + step
            if np.max(np.abs(step)) < 1e-7:
                break
        h_lines, _ = _normal_equations(pose, *args, cfg.robust_scale)
    pose[2] = geometry.wrap_angle(pose[2])
    length = obs.length
    sel = matched >= 0
    confidence = float(length[sel].sum() / length.sum()) if len(obs) else 0.0
    score = 0.0
    if args is not None and sel.any():
        chi2 = _chi2(pose, *args)
        score = float((length[sel] / (1.0 + chi2 / cfg.robust_scale**2)).sum())
    return LineMatch(pose, local_information(h_lines, pose[2]), confidence, matched), score


def _chi2(pose, c_obs, a_obs, w_d, w_a, n_map, d_map, a_map) -> np.ndarray:
    """Squared whitened distance plus angle residuals (K,) of matched lines at ``pose``."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    pc = np.column_stack([c * c_obs[:, 0] - s * c_obs[:, 1], s * c_obs[:, 0] + c * c_obs[:, 1]])
    r_d = np.einsum("ki,ki->k", n_map, pc + pose[:2]) - d_map
    r_a = geometry.wrap_angle(a_obs + pose[2] - a_map)
    return w_d * r_d**2 + w_a * r_a**2


# --------------------------------------------------------------------------- lines from a grid


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


# --------------------------------------------------------------------------- the frontend


class LineFrontend:
    """Scan segments matched to the global line map; odometry where lines say nothing."""

    class Config(Section):
        """Line frontend options: extraction, matching, map, information, gate."""

        extraction: LineExtractionConfig = LineExtractionConfig()
        matching: LineMatchConfig = LineMatchConfig()
        map_max_count: float = Field(5000.0, gt=0, description="points of evidence a map line keeps at most")
        min_seen: int = Field(2, ge=1, description="scans a map line must appear in before it is matched")
        tentative_scans: int = Field(30, ge=1, description="scans a line seen fewer than min_seen times is kept")
        map_radius: float = Field(25.0, gt=0, description="m; map lines considered around the robot")
        match_window: int = Field(0, ge=0, description="match only lines seen in the last n scans (0: all)")
        # a tight odometry prior: with a few short segments (ACES) a loose one let the match jitter by
        # centimetres and degrees from scan to scan, also while the robot stood still
        odom_sigma_xy: OdomSigmaXY = 0.02  # the prior and the fallback
        odom_sigma_theta_deg: OdomSigmaThetaDeg = 0.5
        min_sigma_xy: MinSigmaXY = 0.005
        min_sigma_theta_deg: MinSigmaThetaDeg = 0.1
        max_sigma_xy: MaxSigmaXY = 1.0
        max_sigma_theta_deg: MaxSigmaThetaDeg = 20.0
        reanchor_every: int = Field(0, ge=0, description="rebuild the map lines from a grid of recent scans every n "
                                    "scans (0: off)")
        reanchor_window: int = Field(300, gt=0, description="recent scans in that grid")
        reanchor_resolution: float = Field(0.05, gt=0, description="m per cell of that grid")
        gate: SimilarityGate.Config = SimilarityGate.Config(min_confidence=0.3)
        # lines correct the heading on nearly every scan; on Intel calibrating it too lowered the heading
        # error but raised the translational one
        calibration: HeadingCalibration.Config = HeadingCalibration.Config(enabled=False)

    def __init__(self, config: Config | None = None):
        self.config = cfg = config or self.Config()
        self.calibration = HeadingCalibration(cfg.calibration)
        self.map = LineMap(cfg.map_max_count)
        self.pose = np.zeros(3)
        self.events: Counter[str] = Counter()
        self.gate = SimilarityGate(cfg.gate)
        self.gate.events = self.events
        self.odometry_information = odometry_information(cfg.odom_sigma_xy, cfg.odom_sigma_theta_deg)
        self._min_sigma, self._max_sigma = sigma_bounds(cfg)
        self._previous: np.ndarray | None = None
        self._index = 0
        self._recent: deque = deque(maxlen=cfg.reanchor_window)

    def process(self, scan: Scan, odom_delta) -> FrontendResult:
        """Match the scan's segments to the line map, starting from the odometry guess."""
        odom_delta = self.calibration.correct(odom_delta)
        guess = geometry.compose(self.pose, odom_delta)
        segs = self.extract(scan)
        points = scan.points_in_base()
        if self._index == 0:
            result, pose = self._odometry(odom_delta), guess
        else:
            result, pose = self._match(segs, guess, odom_delta)
            if result.confidence > 0:  # a match, not already a fallback
                gated = self.gate.check(self._previous, points, result, odom_delta)
                if gated is not result:
                    result, pose = gated, guess
                else:
                    self.calibration.observe(pose, guess)
        self._commit(pose, segs, scan)
        self._previous = points
        return result

    def extract(self, scan: Scan) -> Segments:
        """Segments of ``scan`` in the base frame."""
        m = scan.hit_mask()
        return extract_lines(scan.ranges[m], scan.angles[m], self.config.extraction).segments.transformed(
            scan.sensor_pose)

    def reanchor(self, occupancy, resolution: float, origin=(0.0, 0.0), **hough) -> int:
        """Replace the map lines by those of an occupancy grid (map frame); returns their number."""
        segs = lines_from_grid(occupancy, resolution, origin, **hough)
        self.map = LineMap(self.config.map_max_count)
        self.map.add(segs, self._index, seen=self.config.min_seen)
        return len(segs)

    # ------------------------------------------------------------------ steps

    def _match(self, segs: Segments, guess, odom_delta) -> tuple[FrontendResult, np.ndarray]:
        cfg = self.config
        if not len(segs):
            return self._fallback("no line segments", odom_delta), guess
        near = self.map.near(guess, cfg.map_radius)
        near = near[self.map.seen[near] >= cfg.min_seen]
        if cfg.match_window:
            near = near[self._index - self.map.last_seen[near] <= cfg.match_window]
        if not len(near):
            return self._fallback("no map lines nearby", odom_delta), guess
        match = match_lines(segs, self.map.lines.subset(near), guess, self.odometry_information, cfg.matching)
        if not (match.matched >= 0).any():
            return self._fallback("no matched lines", odom_delta), guess
        if beyond_correction(guess, match.pose, cfg.matching.max_correction_xy, cfg.matching.max_correction_theta_deg):
            return self._fallback("correction beyond max_correction", odom_delta), guess
        info = bound_information(match.information + self.odometry_information, self._min_sigma, self._max_sigma)
        delta = geometry.between(self.pose, match.pose)
        return FrontendResult(delta=delta, information=info, confidence=match.confidence), match.pose

    def _commit(self, pose, segs: Segments, scan: Scan) -> None:
        """Move to ``pose``; merge the scan's segments into their map lines, add the others."""
        cfg = self.config
        self.pose = pose
        world = segs.transformed(pose)
        near = self.map.near(pose, cfg.map_radius)
        idx = associate(world, self.map.lines.subset(near), cfg.matching) if len(near) else np.full(len(world), -1)
        hit = idx >= 0
        if hit.any():
            self.map.merge(near[idx[hit]], world.subset(hit), self._index)
        self.map.add(world.subset(~hit), self._index)
        if self._index % 25 == 0:
            self.map.prune(self._index, cfg.min_seen, cfg.tentative_scans)
        self._index += 1
        if cfg.reanchor_every:
            self._recent.append((pose, scan))
            if self._index % cfg.reanchor_every == 0:
                self._reanchor_from_recent()

    def _reanchor_from_recent(self) -> None:
        from slam2d.config import MappingConfig
        from slam2d.mapping.occupancy import build_grid

        poses = np.array([p for p, _ in self._recent])
        scans = [s for _, s in self._recent]
        grid = build_grid(poses, scans, MappingConfig(resolution=self.config.reanchor_resolution))
        n = self.reanchor(grid.probability(), grid.resolution, grid.origin)
        log.debug("re-anchored the line map on %d grid lines", n)

    def _odometry(self, odom_delta) -> FrontendResult:
        return FrontendResult(delta=odom_delta.copy(), information=self.odometry_information.copy(), confidence=0.0)

    def _fallback(self, reason: str, odom_delta) -> FrontendResult:
        self.events[reason] += 1
        log.debug("lines fallback to odometry: %s", reason)
        return self._odometry(odom_delta)


register_frontend("lines")(LineFrontend)
