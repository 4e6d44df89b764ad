"""Corners of one scan from the range derivative, checked by the straightness and turn of their two arms.

See the package docstring for the method (Tian 2016, sections 2.3.2 and 4.2.1). Ranges and
points are in metres, angles in radians (config angles in degrees).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import Field

from slam2d.config import Section
from slam2d.frontends.common import MaxRange, MinRange

__all__ = ["CornerExtractionConfig", "CornerExtraction", "extract_corners"]


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
