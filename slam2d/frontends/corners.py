"""Corner frontend: corners from the range derivative, a global corner list, pose from matched corners.

After the patrol-robot thesis (Tian 2016, sections 2.3.2, 2.3.3 and 4.2.1):

- Extraction: mean-filter the range sequence, take its first derivative
  dr/dphi; local extrema of the derivative are candidates. A corner bends the
  range curve, so its derivative jumps there: each candidate moves to the
  largest normalised jump |r'(i - g) - r'(i + g)| / r(i) within g = half
  window + 1 beams (this merges the maximum and minimum that flank one corner)
  and must reach ``min_slope_change``. Rejected: candidates in the first or
  last ``border_beams`` beams, next to a range jump or a missing beam (an
  occlusion edge), and, as a check the thesis leaves implicit, those whose two
  arms (``arm_beams`` beams each side) are not straight or do not turn by
  ``min_turn_deg`` (by ``significance`` standard errors of the arms' fits).
  An arm ends at a range jump. The corner point is the intersection of the
  arms' TLS lines; its bisector direction is kept too.
- The global corner list: a new corner within ``merge_radius`` of a listed
  one (and with a bisector within ``max_angle_deg``) is that corner (its
  estimate becomes the running mean); otherwise it is appended once. Look-ups
  use a KD-tree rebuilt lazily (after ``rebuild_every`` appends or when
  entries have moved). A corner seen in one scan only is never matched:
  entries need ``min_observations`` sightings, and tentative ones not seen
  again for ``tentative_scans`` scans are dropped.
- Pose: observed corners (at the odometry guess) are associated with listed
  corners within ``match_radius``; the base pose minimises the point residuals
  of all matched corners plus the prior (Gauss-Newton), dropping chi-square
  outliers. One corner fixes position but not heading about it, and the
  information says so. The prior is the pose's own covariance, grown by
  odometry noise (``motion``) since the last match: corners are sparse and a
  few centimetres noisy, so they correct a drifted pose strongly and a fresh
  one little. A one-scan odometry outlier (a turn undone by the next delta)
  is bridged, and the odometry heading is calibrated online (a curvature
  bias and a turn scale, from the accepted matches' heading corrections), so
  it drifts less between matches.
- Confidence: 1 matched corner 0.33, 2 corners 0.66, 3 or more 1.0 (thesis).
  Matched corners are also returned as landmark observations (range, bearing
  from the base) with the list's stable ids.
"""

from __future__ import annotations

import logging
from collections import Counter
from dataclasses import dataclass

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
    beyond_correction,
    bound_information,
    local_information,
    sigma_bounds,
)
from slam2d.frontends.gate import SimilarityGate
from slam2d.frontends.odometry import HeadingCalibration, MotionNoise, odometry_spike
from slam2d.types import LandmarkObservation, Scan

log = logging.getLogger(__name__)

__all__ = [
    "CornerExtractionConfig",
    "CornerExtraction",
    "CornerMap",
    "CornerMatch",
    "extract_corners",
    "match_corners",
    "corner_confidence",
    "CornerFrontend",
]

CHI2_2DOF_99 = 9.21  # 99% quantile of chi-square with 2 degrees of freedom
CHI2_3DOF_99 = 11.345  # ... with 3


class CornerExtractionConfig(Section):
    """Corner extraction; the thesis fixes only the 2 border beams, the rest suits 1-degree scans."""

    window: int = Field(3, ge=1, description="beams of the mean filter on the ranges (odd)")
    border_beams: int = Field(2, ge=0, description="candidates in the first or last this many beams are dropped")
    min_slope_change: float = Field(0.5, gt=0, description="jump of dr/dphi across a corner, divided by r")
    arm_beams: int = Field(8, ge=3, description="beams fitted on each side of a corner (at most)")
    arm_gap: int = Field(1, ge=0, description="beams skipped between the corner and each arm")
    min_arm_beams: int = Field(4, ge=2, description="an arm ends at a range jump; it needs this many beams")
    jump_beams: int = Field(2, ge=1, description="a range jump or missing beam this close is an occlusion edge")
    jump_distance: float = Field(0.2, gt=0, description="m; neighbouring points farther apart are a range jump ...")
    jump_factor: float = Field(4.0, gt=0, description="... when also beyond this many beam spacings (range x angle)")
    min_turn_deg: float = Field(30.0, gt=0, lt=90, description="the arms turn by at least this, at most 180 - it")
    max_arm_rms: float = Field(0.02, gt=0, description="m; TLS residual an arm may have")
    noise: float = Field(0.01, gt=0, description="m; floor of the range noise in the arms' angle error")
    significance: float = Field(3.0, ge=0, description="the turn must exceed this many of its standard errors")
    max_offset: float = Field(0.2, gt=0, description="m; the arms' intersection must lie this close to the candidate")
    min_range: MinRange = 0.1
    max_range: MaxRange = 15.0


@dataclass(frozen=True, eq=False)
class CornerExtraction:
    """Corners of one scan, sensor frame: beam ``index`` (C,), ``points`` (C, 2) m (arms'
    intersection), ``turn`` (C,) rad between the arms, ``direction`` (C,) rad of the
    bisector of the two arms (pointing between them, away from the corner) and its
    variance ``direction_var`` (C,) rad^2; ``candidates`` (K,) beam indices before the
    rejection rules."""

    index: np.ndarray
    points: np.ndarray
    turn: np.ndarray
    direction: np.ndarray
    direction_var: np.ndarray
    candidates: np.ndarray

    @classmethod
    def empty(cls, candidates=None) -> CornerExtraction:
        none = np.zeros(0)
        return cls(np.zeros(0, int), np.zeros((0, 2)), none, none, none,
                   np.zeros(0, int) if candidates is None else candidates)


def _mean_filter(r: np.ndarray, window: int) -> np.ndarray:
    """Centred moving mean of ``r`` (NaN where the window holds a NaN or leaves the scan)."""
    h = window // 2
    kernel = np.ones(2 * h + 1)
    ok = np.isfinite(r)
    total = np.convolve(np.where(ok, r, 0.0), kernel, mode="same")
    count = np.convolve(ok.astype(float), kernel, mode="same")
    out = total / (2 * h + 1)
    out[count < 2 * h + 1] = np.nan
    if h:
        out[:h] = out[-h:] = np.nan
    return out


def _candidates(r: np.ndarray, angles: np.ndarray, cfg: CornerExtractionConfig) -> tuple[np.ndarray, np.ndarray]:
    """Derivative extrema moved to their strongest nearby slope jump: (indices, normalised jump)."""
    n = len(r)
    rs = _mean_filter(r, cfg.window)
    d = np.full(n, np.nan)
    d[1:-1] = (rs[2:] - rs[:-2]) / (angles[2:] - angles[:-2])  # dr/dphi, m/rad
    with np.errstate(invalid="ignore"):
        mid, left, right = d[1:-1], d[:-2], d[2:]
        ext = np.zeros(n, bool)
        ext[1:-1] = ((mid > left) & (mid >= right)) | ((mid < left) & (mid <= right))
    g = cfg.window // 2 + 1
    jump = np.full(n, np.nan)
    jump[g:n - g] = np.abs(d[: n - 2 * g] - d[2 * g:]) / r[g:n - g]
    jump = np.nan_to_num(jump, nan=0.0)
    idx = np.flatnonzero(ext)
    if len(idx) == 0 or n < 2 * g + 1:
        return np.zeros(0, int), np.zeros(0)
    windows = np.lib.stride_tricks.sliding_window_view(np.pad(jump, g), 2 * g + 1)  # (n, 2g+1), centred
    best = np.unique(idx + np.argmax(windows[idx], axis=1) - g)
    # one candidate per corner: of candidates within g beams of each other keep the strongest
    group = np.cumsum(np.r_[True, np.diff(best) > g])
    order = np.lexsort((-jump[best], group))
    first = np.r_[True, group[order][1:] != group[order][:-1]]
    best = np.sort(best[order][first])
    return best, jump[best]


def _tls_batch(p: np.ndarray, w: np.ndarray):
    """TLS lines of point groups (C, k, 2) with 0/1 weights (C, k): centroids (C, 2), unit normals (C, 2),
    rms (C,) m and the scatter along each line (C,) m^2."""
    n = np.maximum(w.sum(axis=1), 1)
    p = np.where(w[..., None] > 0, p, 0.0)
    c = (w[..., None] * p).sum(axis=1) / n[:, None]
    d = (p - c[:, None]) * w[..., None]
    sxx, syy, sxy = (d[..., 0] ** 2).sum(1), (d[..., 1] ** 2).sum(1), (d[..., 0] * d[..., 1]).sum(1)
    phi = 0.5 * np.arctan2(2 * sxy, sxx - syy)
    root = np.hypot(0.5 * (sxx - syy), sxy)
    rms = np.sqrt(np.maximum(0.5 * (sxx + syy) - root, 0) / n)
    return c, np.column_stack([-np.sin(phi), np.cos(phi)]), rms, 0.5 * (sxx + syy) + root


def extract_corners(ranges, angles, range_min: float = 0.0, range_max: float = np.inf,
                    config: CornerExtractionConfig | None = None) -> CornerExtraction:
    """Corners of one scan from all its beams: ``ranges`` (n,) m (NaN: no hit), ``angles`` (n,) rad, in order."""
    cfg = config or CornerExtractionConfig()
    r = np.asarray(ranges, float).copy()
    a = np.asarray(angles, float)
    n = len(r)
    with np.errstate(invalid="ignore"):
        hit = np.isfinite(r) & (r >= max(range_min, cfg.min_range)) & (r < min(range_max, cfg.max_range + 1e-9))
    r[~hit] = np.nan
    reach = cfg.arm_gap + cfg.arm_beams
    if n < 2 * reach + 1:
        return CornerExtraction.empty()
    cand, strength = _candidates(r, a, cfg)
    keep = (strength >= cfg.min_slope_change) & (cand >= cfg.border_beams) & (cand < n - cfg.border_beams)
    idx = cand[keep]
    if not len(idx):
        return CornerExtraction.empty(cand)
    pts = np.column_stack([r * np.cos(a), r * np.sin(a)])  # NaN rows for missing beams
    around = idx[:, None] + np.arange(-reach, reach + 1)[None]  # (C, 2 reach + 1) beams about each candidate
    inside = (around >= 0) & (around < n)
    beams = np.clip(around, 0, n - 1)
    steps = np.linalg.norm(np.diff(pts[beams], axis=1), axis=2)
    spacing = np.fmin(r[beams[:, :-1]], r[beams[:, 1:]]) * np.abs(np.diff(a[beams], axis=1))
    with np.errstate(invalid="ignore"):
        smooth = (steps <= np.maximum(cfg.jump_distance, cfg.jump_factor * spacing)) & inside[:, 1:] & inside[:, :-1]
    # beam idx -/+ m (m = 1..reach) is reached from the corner without a jump or a missing beam
    conn_l = np.cumprod(smooth[:, reach - 1::-1], axis=1).astype(bool)
    conn_r = np.cumprod(smooth[:, reach:], axis=1).astype(bool)
    edge = ~(conn_l[:, : cfg.jump_beams].all(axis=1) & conn_r[:, : cfg.jump_beams].all(axis=1))
    m = np.arange(cfg.arm_gap + 1, reach + 1)
    left_w = conn_l[:, m - 1].astype(float)
    right_w = conn_r[:, m - 1].astype(float)
    left = pts[np.clip(idx[:, None] - m, 0, n - 1)]
    right = pts[np.clip(idx[:, None] + m, 0, n - 1)]
    corner, turn, ok, direction, var = _intersect_arms(left, left_w, right, right_w, pts[idx], cfg)
    ok &= ~edge & (left_w.sum(1) >= cfg.min_arm_beams) & (right_w.sum(1) >= cfg.min_arm_beams)
    ok &= np.linalg.norm(corner - pts[idx], axis=1) <= cfg.max_offset
    return CornerExtraction(idx[ok], corner[ok], turn[ok], direction[ok], var[ok], cand)


def _intersect_arms(left, left_w, right, right_w, apex, cfg: CornerExtractionConfig):
    """Intersection (C, 2), turn (C,) rad, validity (C,), bisector angle (C,) rad and its variance
    (C,) rad^2 of the arms' TLS lines.

    ``left``/``right`` (C, k, 2) arm points with 0/1 weights (C, k); ``apex`` (C, 2) the candidate points.
    """
    cl, nl, rms_l, spread_l = _tls_batch(left, left_w)
    cr, nr, rms_r, spread_r = _tls_batch(right, right_w)
    dl = np.column_stack([nl[:, 1], -nl[:, 0]])
    dl *= np.where(np.einsum("ki,ki->k", dl, apex - cl) < 0, -1.0, 1.0)[:, None]  # towards the corner
    dr = np.column_stack([nr[:, 1], -nr[:, 0]])
    dr *= np.where(np.einsum("ki,ki->k", dr, cr - apex) < 0, -1.0, 1.0)[:, None]  # away from it
    turn = np.arctan2(dl[:, 0] * dr[:, 1] - dl[:, 1] * dr[:, 0], np.einsum("ki,ki->k", dl, dr))
    lo = np.deg2rad(cfg.min_turn_deg)
    # TLS direction variance sigma^2 / spread per arm; the turn must be significant
    var_l = np.maximum(rms_l, cfg.noise) ** 2 / np.maximum(spread_l, 1e-12)
    var_r = np.maximum(rms_r, cfg.noise) ** 2 / np.maximum(spread_r, 1e-12)
    sigma_turn = np.sqrt(var_l + var_r)
    ok = (np.abs(turn) >= np.maximum(lo, cfg.significance * sigma_turn)) & (np.abs(turn) <= np.pi - lo)
    ok &= (rms_l <= cfg.max_arm_rms) & (rms_r <= cfg.max_arm_rms)
    det = nl[:, 0] * nr[:, 1] - nl[:, 1] * nr[:, 0]  # n . x = n . c for both lines
    safe = np.where(np.abs(det) > 1e-9, det, 1.0)
    bl, br = np.einsum("ki,ki->k", nl, cl), np.einsum("ki,ki->k", nr, cr)
    x = (bl * nr[:, 1] - br * nl[:, 1]) / safe
    y = (nl[:, 0] * br - nr[:, 0] * bl) / safe
    bisector = dr - dl  # the arms leave the corner along -dl and dr
    direction = np.arctan2(bisector[:, 1], bisector[:, 0])
    return np.column_stack([x, y]), turn, ok & (np.abs(det) > 1e-9), direction, 0.25 * (var_l + var_r)


def corner_confidence(matched: int) -> float:
    """Thesis confidence of a corner match: 1 corner 0.33, 2 corners 0.66, 3 or more 1.0 (0 for none)."""
    return (0.0, 0.33, 0.66)[matched] if matched < 3 else 1.0


# --------------------------------------------------------------------------- the global corner list


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


# --------------------------------------------------------------------------- pose from corners


@dataclass(frozen=True, eq=False)
class CornerMatch:
    """Outcome of :func:`match_corners`: base ``pose`` (map frame), ``information`` of the corner
    constraints alone (3, 3, local frame of ``pose``), ``inliers`` (M,) mask over the given pairs."""

    pose: np.ndarray
    information: np.ndarray
    inliers: np.ndarray


def _corner_normal_equations(pose, obs, ref, weight, obs_dir, ref_dir, dir_weight):
    """H (3, 3), g (3,) and squared whitened residuals (M,) at ``pose`` (world parameters) of
    R obs + t - ref (isotropic ``weight``, 1/m^2) and of the bisector angle obs_dir + theta - ref_dir
    (``dir_weight`` (M,), 1/rad^2; 0 where unknown)."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    p = np.column_stack([c * obs[:, 0] - s * obs[:, 1], s * obs[:, 0] + c * obs[:, 1]])
    r = p + pose[:2] - ref
    j = np.zeros((len(obs), 2, 3))
    j[:, 0, 0] = j[:, 1, 1] = 1.0
    j[:, 0, 2], j[:, 1, 2] = -p[:, 1], p[:, 0]
    h = weight * np.einsum("kai,kaj->ij", j, j)
    g = weight * np.einsum("kai,ka->i", j, r)
    r_a = np.nan_to_num(geometry.wrap_angle(obs_dir + pose[2] - ref_dir))
    h[2, 2] += dir_weight.sum()
    g[2] += (dir_weight * r_a).sum()
    return h, g, weight * np.einsum("ka,ka->k", r, r) + dir_weight * r_a**2


def match_corners(obs, ref, guess, prior: np.ndarray, sigma: float, iterations: int = 5,
                  obs_dir=None, ref_dir=None, dir_var=None) -> CornerMatch:
    """Base pose (map frame) laying corners ``obs`` (M, 2, base frame) on ``ref`` (M, 2, map frame).

    Least squares over all pairs (isotropic std ``sigma`` m per pair) plus the
    odometry prior (information ``prior``, local frame of ``guess``); with
    bisector angles ``obs_dir`` (base frame), ``ref_dir`` (map frame) and
    their variance ``dir_var`` (M,) rad^2, each corner also constrains the
    heading. Pairs beyond the 99% chi-square bound are dropped one at a time,
    worst first.
    """
    obs, ref = np.asarray(obs, float).reshape(-1, 2), np.asarray(ref, float).reshape(-1, 2)
    m = len(obs)
    if obs_dir is None or ref_dir is None or dir_var is None:
        obs_dir, ref_dir, dir_w = np.zeros(m), np.zeros(m), np.zeros(m)
    else:
        dir_w = np.where(np.isnan(ref_dir) | np.isnan(obs_dir), 0.0, 1.0 / np.asarray(dir_var, float))
    guess = geometry.as_pose(guess)
    inliers = np.ones(m, bool)
    w = 1.0 / sigma**2
    bound = np.where(dir_w > 0, CHI2_3DOF_99, CHI2_2DOF_99)
    cg, sg = np.cos(guess[2]), np.sin(guess[2])
    jp = np.array([[cg, sg, 0.0], [-sg, cg, 0.0], [0.0, 0.0, 1.0]])  # world perturbation -> guess frame
    hp = jp.T @ prior @ jp
    while True:
        pose = guess.copy()
        args = (obs[inliers], ref[inliers], w, obs_dir[inliers], ref_dir[inliers], dir_w[inliers])
        for _ in range(iterations):
            h, g, _ = _corner_normal_equations(pose, *args)
            offset = np.r_[pose[:2] - guess[:2], geometry.wrap_angle(pose[2] - guess[2])]
            step = np.linalg.solve(h + hp, -(g + hp @ offset))
            pose = pose + step
            if np.max(np.abs(step)) < 1e-8:
                break
        h, _, chi2 = _corner_normal_equations(pose, *args)
        excess = chi2 - bound[inliers]
        if not inliers.any() or excess.max(initial=0.0) <= 0:
            break
        inliers[np.flatnonzero(inliers)[np.argmax(excess)]] = False
    pose[2] = geometry.wrap_angle(pose[2])
    return CornerMatch(pose, local_information(h, pose[2]), inliers)


# --------------------------------------------------------------------------- the frontend


class CornerFrontend:
    """Scan corners matched to the global corner list; landmark observations of matched corners."""

    class Config(Section):
        """Corner frontend options: extraction, corner list, matching, information, gate."""

        extraction: CornerExtractionConfig = CornerExtractionConfig()
        merge_radius: float = Field(0.25, gt=0, description="m; a corner this close to a listed one is that one")
        match_radius: float = Field(0.4, gt=0, description="m; association radius at the odometry guess")
        min_observations: int = Field(2, ge=1, description="sightings before a listed corner is matched")
        tentative_scans: int = Field(30, ge=1, description="scans a corner with fewer sightings is kept")
        rebuild_every: int = Field(16, gt=0, description="appends before the KD-tree is rebuilt")
        max_count: int = Field(50, gt=0, description="sightings weighting a corner's running mean at most")
        max_angle_deg: float = Field(30.0, gt=0, description="bisectors of one corner differ by less than this")
        use_direction: bool = Field(False, description="the corners' bisectors also constrain the heading")
        sigma_corner: float = Field(0.05, gt=0, description="m; std of an observed corner against its listed one")
        sigma_direction_deg: float = Field(1.0, gt=0, description="std added to a bisector's own (arm fit) std")
        max_correction_xy: MaxCorrectionXY = 0.5
        max_correction_theta_deg: MaxCorrectionThetaDeg = 15.0
        motion: MotionNoise = MotionNoise()
        max_pose_sigma_xy: float = Field(0.5, gt=0, description="m; the pose uncertainty between matches stops here")
        max_pose_sigma_theta_deg: float = Field(10.0, gt=0, description="... and here")
        min_sigma_xy: MinSigmaXY = 0.005
        min_sigma_theta_deg: MinSigmaThetaDeg = 0.1
        max_sigma_xy: MaxSigmaXY = 1.0
        max_sigma_theta_deg: MaxSigmaThetaDeg = 20.0
        landmarks: bool = Field(True, description="return matched corners as landmark observations")
        landmark_sigma: float = Field(0.2, gt=0, description="m; std of a landmark observation (range, and across)")
        gate: SimilarityGate.Config = SimilarityGate.Config(min_confidence=0.66)
        calibration: HeadingCalibration.Config = HeadingCalibration.Config()

    def __init__(self, config: Config | None = None):
        self.config = cfg = config or self.Config()
        self.map = CornerMap(cfg.merge_radius, cfg.rebuild_every, cfg.max_count, cfg.max_angle_deg)
        self.pose = np.zeros(3)
        self.events: Counter[str] = Counter()
        self.gate = SimilarityGate(cfg.gate)
        self.gate.events = self.events
        self.cov = np.zeros((3, 3))  # uncertainty of self.pose against the corner list, local frame
        self._before = (self.pose, self.cov)  # pose and covariance before the last scan
        self._last_delta: np.ndarray | None = None
        self._cov_cap = np.array([cfg.max_pose_sigma_xy, cfg.max_pose_sigma_xy,
                                  np.deg2rad(cfg.max_pose_sigma_theta_deg)])
        self._min_sigma, self._max_sigma = sigma_bounds(cfg)
        self._previous: np.ndarray | None = None
        self._index = 0
        self.calibration = HeadingCalibration(cfg.calibration)

    def process(self, scan: Scan, odom_delta) -> FrontendResult:
        """Match the scan's corners to the corner list, starting from the odometry guess.

        The pose against the corner list carries a covariance: odometry grows
        it (``motion``), a match shrinks it; the predicted covariance is the
        prior of the match, so noisy corners move a well-known pose little.
        """
        odom_delta = self.calibration.correct(odom_delta)
        base, base_cov, motion = self.pose, self.cov, odom_delta
        if odometry_spike(self._last_delta, odom_delta):  # bridge the outlier odometry of the last scan
            self.events["odometry spike bridged"] += 1
            base, base_cov = self._before
            motion = geometry.compose(self._last_delta, odom_delta)
        self._before, self._last_delta = (self.pose, self.cov), odom_delta
        guess = geometry.compose(base, motion)
        step = self.config.motion.covariance(motion)
        predicted = _capped(geometry.compose_covariance(base_cov, motion, step), self._cov_cap)
        odom_delta = geometry.between(self.pose, guess)  # the odometry estimate of this scan's delta
        ext = self.extract(scan)
        points = scan.points_in_base()
        result, pose, cov = self._odometry(odom_delta, step), guess, predicted
        if self._index > 0:
            matched, match_pose, match_cov = self._match(ext, guess, predicted, step, odom_delta)
            if matched is not None and self.gate.check(self._previous, points, matched, odom_delta) is matched:
                result, pose, cov = matched, match_pose, match_cov
                self.calibration.observe(pose, guess)
        self._commit(pose, cov, ext)
        self._previous = points
        return result

    def extract(self, scan: Scan) -> CornerExtraction:
        """Corners of ``scan`` with points (C, 2) and bisector directions (C,) in the base frame."""
        ext = extract_corners(scan.ranges, scan.angles, scan.range_min, scan.range_max, self.config.extraction)
        mount = geometry.as_pose(scan.sensor_pose)
        return CornerExtraction(ext.index, geometry.transform_points(mount, ext.points), ext.turn,
                                geometry.wrap_angle(ext.direction + mount[2]), ext.direction_var, ext.candidates)

    # ------------------------------------------------------------------ steps

    def _match(self, ext: CornerExtraction, guess, predicted, step, odom_delta):
        """(result, pose, covariance) of a corner match from ``guess``, or (None, ...) after counting why not."""
        cfg = self.config
        corners = ext.points
        if not len(corners):
            return self._fallback("no corners")
        idx, dist = self.map.nearest(geometry.transform_points(guess, corners), cfg.match_radius,
                                     cfg.min_observations, geometry.wrap_angle(ext.direction + guess[2]))
        idx = _unique_matches(idx, dist)
        sel = np.flatnonzero(idx >= 0)
        if not len(sel):
            return self._fallback("no matched corners")
        dirs = {}
        if cfg.use_direction:
            dirs = dict(obs_dir=ext.direction[sel], ref_dir=self.map.direction[idx[sel]],
                        dir_var=ext.direction_var[sel] + np.deg2rad(cfg.sigma_direction_deg) ** 2)
        prior = np.linalg.inv(predicted + 1e-12 * np.eye(3))
        match = match_corners(corners[sel], self.map.xy[idx[sel]], guess, prior, cfg.sigma_corner, **dirs)
        if beyond_correction(guess, match.pose, cfg.max_correction_xy, cfg.max_correction_theta_deg):
            return self._fallback("correction beyond max_correction")
        used = sel[match.inliers]
        if not len(used):
            return self._fallback("no consistent corners")
        odometry = np.linalg.inv(step)
        info = bound_information(match.information + odometry, self._min_sigma, self._max_sigma)
        landmarks = self._landmarks(corners[used], self.map.ids[idx[used]]) if cfg.landmarks else ()
        result = FrontendResult(delta=geometry.between(self.pose, match.pose), information=info,
                                confidence=corner_confidence(len(used)), landmarks=landmarks)
        return result, match.pose, np.linalg.inv(match.information + prior)

    def _landmarks(self, corners: np.ndarray, ids: np.ndarray) -> tuple[LandmarkObservation, ...]:
        """Range-bearing observations of corners (base frame); covariance in (bearing, range) order."""
        s = self.config.landmark_sigma
        rng = np.hypot(corners[:, 0], corners[:, 1])
        bearing = np.arctan2(corners[:, 1], corners[:, 0])
        return tuple(
            LandmarkObservation(int(i), float(r), float(b), np.diag([(s / max(r, s)) ** 2, s**2]))
            for i, r, b in zip(ids, rng, bearing)
        )

    def _commit(self, pose, cov, ext: CornerExtraction) -> None:
        cfg = self.config
        self.pose, self.cov = pose, 0.5 * (cov + cov.T)
        if len(ext.points):
            self.map.update(geometry.transform_points(pose, ext.points), self._index,
                            geometry.wrap_angle(ext.direction + pose[2]))
        if self._index % 25 == 0:
            self.map.prune(self._index, cfg.min_observations, cfg.tentative_scans)
        self._index += 1

    @staticmethod
    def _odometry(odom_delta, step_cov) -> FrontendResult:
        """The odometry delta is the estimate: information of one odometry step, confidence 0."""
        return FrontendResult(delta=odom_delta.copy(), information=np.linalg.inv(step_cov), confidence=0.0)

    def _fallback(self, reason: str):
        self.events[reason] += 1
        log.debug("corners fallback to odometry: %s", reason)
        return None, None, None


def _capped(cov: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """``cov`` with every direction's std at most ``sigma`` (per axis, scaled)."""
    normalised = cov / sigma[:, None] / sigma[None, :]
    vals, vecs = np.linalg.eigh(0.5 * (normalised + normalised.T))
    return (vecs * np.minimum(vals, 1.0)) @ vecs.T * sigma[:, None] * sigma[None, :]


def _unique_matches(idx: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """``idx`` with every entry claimed by several observations kept only for the closest one."""
    out = idx.copy()
    order = np.lexsort((dist, idx))
    dup = np.r_[False, idx[order][1:] == idx[order][:-1]] & (idx[order] >= 0)
    out[order[dup]] = -1
    return out


register_frontend("corners")(CornerFrontend)
