"""Association of observed corners with listed ones, and the base pose from matched corners.

The pose minimises the point residuals (and optionally the bisector angles) of all pairs plus
the odometry prior by Gauss-Newton, dropping chi-square outliers one at a time. Poses are
(x, y, theta) (m, m, rad); informations over (x, y, theta).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slam2d import geometry
from slam2d.frontends.common import local_information

__all__ = ["CornerMatch", "match_corners", "corner_confidence", "unique_matches"]

CHI2_2DOF_99 = 9.21  # 99% quantile of chi-square with 2 degrees of freedom
CHI2_3DOF_99 = 11.345  # ... with 3


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


def corner_confidence(matched: int) -> float:
    """Thesis confidence of a corner match: 1 corner 0.33, 2 corners 0.66, 3 or more 1.0 (0 for none)."""
    return (0.0, 0.33, 0.66)[matched] if matched < 3 else 1.0


def unique_matches(idx: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """``idx`` with every entry claimed by several observations kept only for the closest one."""
    out = idx.copy()
    order = np.lexsort((dist, idx))
    dup = np.r_[False, idx[order][1:] == idx[order][:-1]] & (idx[order] >= 0)
    out[order[dup]] = -1
    return out
