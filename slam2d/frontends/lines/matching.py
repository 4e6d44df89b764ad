"""Association of observed segments with map lines, and the base pose from matched line normals.

Pairs qualify by normal angle, distance and overlap; the pose is solved by Cauchy-weighted
Gauss-Newton on distance and angle residuals plus the odometry prior, from the odometry guess
and, when a histogram of normal-angle differences disagrees, also from the heading it finds.
Poses are (x, y, theta) (m, m, rad); informations over (x, y, theta).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import Field

from slam2d import geometry
from slam2d.config import Section
from slam2d.frontends.common import (
    MaxCorrectionThetaDeg,
    MaxCorrectionXY,
    local_information,
)
from slam2d.frontends.lines.segments import Segments

__all__ = ["LineMatchConfig", "LineMatch", "associate", "heading_correction", "match_lines"]


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
