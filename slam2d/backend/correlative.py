"""Correlative scan-to-submap matching that survives a poor initial guess.

A submap becomes a :class:`~slam2d.backend.probability_grid.ProbabilityGrid`: a
likelihood field ``exp(-d^2 / 2 sigma^2)`` (d: distance in metres to the nearest cell
holding a submap point; 0 beyond 4 sigma) on a regular grid, plus max-pooled levels
for branch and bound. :func:`match` sweeps every rotation of the angular window (step ``resolution / range``,
Olson 2009, "Real-time correlative scan matching") and searches translations
by branch and bound over the pooled levels (Hess et al. 2016, "Real-time loop
closure in 2D LIDAR SLAM"), one compiled gather per level. The best cell
is then refined by point-to-line Gauss-Newton against the submap points,
whose Hessian gives the covariance.

The score is the mean likelihood of the scan points (decimated to one per
cell) at the matched pose: 1 when every point lies on a submap point, about
0.6 one cell away, 0 far from the submap.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from slam2d import geometry
from slam2d.backend.probability_grid import (
    ProbabilityGrid,
    Pyramid,
    facing_bits,
    voxel_filter,
)

__all__ = ["MatchResult", "match", "angular_step"]

MAX_DEPTH = 4  # pooled levels of branch and bound; top cells are 2^depth cells wide
RANGE_PERCENTILE = 75.0  # range (percentile) for the angular step; farther points move a few cells per step
MIN_RANGE = 1.0  # m; floor of that range, so close-up scans do not get huge angular steps
REFINE_ITERATIONS = 10  # Gauss-Newton steps at most (more only chase correspondence switches)
REFINE_MAX_DIST_CELLS = 4.0  # point-to-line correspondences farther than this are dropped
REFINE_HUBER_CELLS = 0.5  # Huber threshold on point-to-line residuals, in cells
REFINE_REVERT_SCORE = 0.02  # keep the search pose if refinement loses more score than this
REFINE_MAX_STEPS = 3.0  # ... or moves it more than this many cells or angular steps
COV_FLOOR_XY_CELLS = 0.5  # std floor added to the covariance, in cells
COV_FLOOR_THETA = np.deg2rad(0.25)  # rad; std floor added to the covariance


@dataclass(frozen=True, eq=False)
class MatchResult:
    """Outcome of :func:`match`.

    pose: (3,) pose of the scan in the submap frame (m, m, rad).
    score: mean likelihood in [0, 1] of the scan points at ``pose`` (on a sided
      grid too over all surfaces: the sides choose the pose, not the score).
    covariance: (3, 3) of ``pose``.
    search_score: best grid score of branch and bound, before refinement.
    evaluated: number of (rotation, translation) candidates scored.
    runner_up: best grid score more than ``ambiguity_xy`` from the search's
      best translation, when at least ``ambiguity_ratio`` times its score
      (an alternative match: a periodic or featureless place); else 0.
    rival: (3,) pose of that runner-up in the submap frame, or None.
    """

    pose: np.ndarray
    score: float
    covariance: np.ndarray
    search_score: float
    evaluated: int
    runner_up: float = 0.0
    rival: np.ndarray | None = None


def angular_step(points, resolution: float) -> float:
    """Rotation step (rad) that moves a point at the ``RANGE_PERCENTILE`` range by one cell of ``resolution`` m
    (the refinement after the search recovers the finer angle)."""
    r = np.hypot(points[:, 0], points[:, 1])
    far = max(float(np.percentile(r, RANGE_PERCENTILE)), MIN_RANGE) if len(r) else MIN_RANGE
    return float(np.arccos(1.0 - resolution**2 / (2.0 * far**2)))


# --------------------------------------------------------------------------- branch and bound


def _discretise(pyr: Pyramid, points: np.ndarray, start: np.ndarray, thetas: np.ndarray) -> np.ndarray:
    """Flat cell indices (A, N) of the points rotated by each angle (A,) and moved to ``start`` (2,).

    Points that could leave the padded grid anywhere in the window are sent to
    a cell deep in the zero padding: they score 0 for every candidate.
    """
    c, s = np.cos(thetas)[:, None], np.sin(thetas)[:, None]
    x = c * points[:, 0] - s * points[:, 1] + start[0]
    y = s * points[:, 0] + c * points[:, 1] + start[1]
    col = np.floor((x - pyr.origin[0]) / pyr.resolution).astype(np.int64)
    row = np.floor((y - pyr.origin[1]) / pyr.resolution).astype(np.int64)
    w, reach = pyr.window, pyr.window + 2**pyr.depth
    ny, nx = pyr.shape
    inside = (col >= w) & (row >= w) & (col + reach < nx) & (row + reach < ny)
    return np.where(inside, row * nx + col, w * nx + w)


def _scores(level: np.ndarray, flat: np.ndarray, sides, cands: np.ndarray, width: int) -> np.ndarray:
    """Mean of ``level`` over the points of each candidate (C, 3) = (angle index, dx, dy) cells;
    with ``sides`` = (the grid's side bits, the points' facing bits (A, N)), 0 for a point whose
    cell holds no surface seen from its side."""
    if sides is None:
        return _scores_kernel(level, flat, np.ascontiguousarray(cands), width)
    return _sided_scores_kernel(level, flat, np.ascontiguousarray(cands), width, *sides)


@njit(cache=True, nogil=True)
def _scores_kernel(level, flat, cands, width):  # pragma: no cover - compiled
    n_pts = flat.shape[1]
    out = np.empty(cands.shape[0], dtype=np.float64)
    for c in range(cands.shape[0]):
        row = flat[cands[c, 0]]
        shift = cands[c, 2] * width + cands[c, 1]
        total = 0.0
        for i in range(n_pts):
            total += level[row[i] + shift]
        out[c] = total / max(n_pts, 1)
    return out


@njit(cache=True, nogil=True)
def _sided_scores_kernel(level, flat, cands, width, grid_bits, point_bits):  # pragma: no cover - compiled
    n_pts = flat.shape[1]
    out = np.empty(cands.shape[0], dtype=np.float64)
    for c in range(cands.shape[0]):
        row, facing = flat[cands[c, 0]], point_bits[cands[c, 0]]
        shift = cands[c, 2] * width + cands[c, 1]
        total = 0.0
        for i in range(n_pts):
            cell = row[i] + shift
            if grid_bits[cell] & facing[i]:
                total += level[cell]
        out[c] = total / max(n_pts, 1)
    return out


def _children(cands: np.ndarray, level: int, window: int, exclude=None) -> np.ndarray:
    """The four sub-blocks at ``level - 1`` of candidates (C, 3) at ``level``, inside the window
    and not wholly inside the ``exclude`` square (see :func:`_outside`)."""
    h = 2 ** (level - 1)
    steps = np.array([[0, 0, 0], [0, h, 0], [0, 0, h], [0, h, h]], dtype=np.int64)
    kids = (cands[:, None, :] + steps[None]).reshape(-1, 3)
    kids = kids[(kids[:, 1] <= window) & (kids[:, 2] <= window)]
    return kids[_outside(kids, h, exclude)]


def _outside(cands: np.ndarray, size: int, exclude) -> np.ndarray:
    """Mask of blocks (C, 3) of ``size`` cells not wholly inside ``exclude`` = (dx, dy, r) cells,
    the square of half-width r around (dx, dy); all True when ``exclude`` is None."""
    if exclude is None:
        return np.ones(len(cands), dtype=bool)
    bx, by, r = exclude
    inside = (
        (cands[:, 1] >= bx - r) & (cands[:, 1] + size - 1 <= bx + r)
        & (cands[:, 2] >= by - r) & (cands[:, 2] + size - 1 <= by + r)
    )  # fmt: skip
    return ~inside


def _level(pyr: Pyramid, flat: np.ndarray, k: int, facing) -> tuple:
    """``_scores``'s level, indices and sides at level ``k``: sided at level 0 with ``facing`` bits."""
    return pyr.levels[k], flat, (pyr.sides, facing) if k == 0 and facing is not None else None


def _greedy(pyr: Pyramid, flat: np.ndarray, cand: np.ndarray, level: int, exclude=None, facing=None):
    """Descend from ``cand`` at ``level`` to level 0 through the best child: (candidate, score, evaluated)."""
    width, evaluated, score = pyr.shape[1], 0, 0.0
    for k in range(level, 0, -1):
        kids = _children(cand[None], k, pyr.window, exclude)
        if len(kids) == 0:
            return cand, -np.inf, evaluated
        s = _scores(*_level(pyr, flat, k - 1, facing), kids, width)
        evaluated += len(kids)
        cand, score = kids[np.argmax(s)], float(s.max())
    if level == 0:
        score = float(_scores(*_level(pyr, flat, 0, facing), cand[None], width)[0])
        evaluated += 1
    return cand, score, evaluated


def _branch_and_bound(pyr: Pyramid, flat: np.ndarray, min_score: float, exclude=None, facing=None):
    """Best (angle index, dx, dy) over all angles and the translational window, its score, evaluations.

    Level-synchronous branch and bound: every level's surviving blocks are
    scored in one gather; a block survives while its pooled upper bound beats
    the best exact score so far (found by greedy descents) and ``min_score``.
    ``exclude`` = (dx, dy, r) cells leaves out the translations within r of
    (dx, dy) (the runner-up search); with ``facing`` bits (A, N) of the points,
    level 0 counts only surfaces seen from each point's side (no more than the
    field, so the pooled levels still bound it). The score is -inf when nothing is left.
    """
    w, depth, width = pyr.window, pyr.depth, pyr.shape[1]
    offs = np.arange(-w, w + 1, 2**depth, dtype=np.int64)
    a, dx, dy = np.meshgrid(np.arange(len(flat), dtype=np.int64), offs, offs, indexing="ij")
    cands = np.column_stack([a.ravel(), dx.ravel(), dy.ravel()])
    cands = cands[_outside(cands, 2**depth, exclude)]
    bound = _scores(*_level(pyr, flat, depth, facing), cands, width)
    evaluated = len(cands)
    best, best_score = None, -np.inf
    for k in range(depth, 0, -1):
        if len(cands) == 0:
            break
        c, s, n = _greedy(pyr, flat, cands[np.argmax(bound)], k, exclude, facing)
        evaluated += n
        if s > best_score:
            best, best_score = c, s
        keep = bound > max(best_score, min_score)
        cands = _children(cands[keep], k, w, exclude)
        bound = _scores(*_level(pyr, flat, k - 1, facing), cands, width)
        evaluated += len(cands)
    if len(cands) and (best is None or bound.max() > best_score):
        best, best_score = cands[np.argmax(bound)], float(bound.max())
    return best, best_score, evaluated


# --------------------------------------------------------------------------- refinement


def _point_to_line(grid: ProbabilityGrid, points: np.ndarray, pose: np.ndarray, max_dist: float):
    """Residuals (K,), Jacobian (K, 3) w.r.t. (x, y, theta) and Huber weights (K,) at ``pose``."""
    q = geometry.transform_points(pose, points)
    d, j = grid.nearest(q, max_dist, pose[:2])
    ok = np.isfinite(d)
    ok[ok] = grid.has_normal[j[ok]]
    j, q, p = j[ok], q[ok], points[ok]
    n = grid.normals[j]
    r = np.einsum("ki,ki->k", n, q - grid.points[j])
    c, s = np.cos(pose[2]), np.sin(pose[2])
    dqx, dqy = -s * p[:, 0] - c * p[:, 1], c * p[:, 0] - s * p[:, 1]
    jac = np.column_stack([n[:, 0], n[:, 1], n[:, 0] * dqx + n[:, 1] * dqy])
    k = REFINE_HUBER_CELLS * grid.resolution
    weights = np.minimum(1.0, k / np.maximum(np.abs(r), 1e-12))
    return r, jac, weights


def _refine(grid: ProbabilityGrid, points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Gauss-Newton point-to-line refinement of ``pose`` (3,) against the submap points."""
    max_dist = REFINE_MAX_DIST_CELLS * grid.resolution
    pose = pose.copy()
    for _ in range(REFINE_ITERATIONS):
        r, jac, wgt = _point_to_line(grid, points, pose, max_dist)
        if len(r) < 3:
            break
        h = jac.T @ (wgt[:, None] * jac)
        g = jac.T @ (wgt * r)
        damping = 1e-6 * np.trace(h) + 1e-12
        step = -np.linalg.solve(h + damping * np.eye(3), g)
        pose += step
        if np.hypot(step[0], step[1]) < 1e-5 and abs(step[2]) < 1e-6:
            break
    pose[2] = geometry.wrap_angle(pose[2])
    return pose


def _covariance(grid: ProbabilityGrid, points: np.ndarray, pose: np.ndarray, window: np.ndarray) -> np.ndarray:
    """Covariance (3, 3) of ``pose`` (m^2, rad^2) from the point-to-line fit.

    (J^T W J / sigma^2 + diag(1 / window^2))^-1 plus a floor: sigma is the
    residual std (at least a tenth of a cell); the window (3,) prior (m, m, rad)
    bounds the variance along directions the scan does not constrain, as in a
    featureless corridor.
    """
    res = grid.resolution
    floor = np.diag([(COV_FLOOR_XY_CELLS * res) ** 2] * 2 + [COV_FLOOR_THETA**2])
    info = np.diag(1.0 / np.asarray(window, dtype=np.float64) ** 2)
    r, jac, wgt = _point_to_line(grid, points, pose, REFINE_MAX_DIST_CELLS * res)
    if len(r) > 3:
        sigma2 = max(float(np.sum(wgt * r**2) / (np.sum(wgt) - 3)), (0.1 * res) ** 2)
        info = info + jac.T @ (wgt[:, None] * jac) / sigma2
    cov = np.linalg.inv(info)
    return 0.5 * (cov + cov.T) + floor


# --------------------------------------------------------------------------- matching


def match(
    grid: ProbabilityGrid,
    points,
    initial,
    window_xy: float,
    window_theta: float,
    *,
    min_score: float = 0.0,
    depth: int | None = None,
    ambiguity_xy: float = 0.0,
    ambiguity_ratio: float = 0.9,
    prior_window=None,
) -> MatchResult:
    """Match scan points (N, 2) in the scan's base frame against ``grid``.

    initial: (3,) guess of the scan's pose in the submap frame; the search
    covers +-``window_xy`` m in x and y and +-``window_theta`` rad around it.
    min_score: prune blocks whose bound is below it (a faster search when the
    caller rejects lower scores anyway; the result may then be a greedy one
    below ``min_score``). depth: pooled levels (default: enough for the window,
    at most ``MAX_DEPTH``). ambiguity_xy: m; when > 0, also search for the
    runner-up outside this distance of the best (see ``MatchResult.runner_up``)
    when the best's grid score reaches ``min_score``. prior_window: (3,) m, m,
    rad bounding the covariance where the scan constrains nothing (default:
    the search window).
    """
    initial = geometry.as_pose(initial).reshape(3)
    pts = voxel_filter(points, grid.resolution)
    if len(pts) == 0:
        raise ValueError("match needs at least one finite scan point")
    found, step, search_score, evaluated, runner_up, rival = _search(
        grid, pts, initial, window_xy, window_theta, min_score, depth, ambiguity_xy, ambiguity_ratio
    )
    pose = _polish(grid, pts, found, step)
    score = grid.score(geometry.transform_points(pose, pts))  # on every surface, as a blind grid scores it
    window = [window_xy, window_xy, window_theta] if prior_window is None else prior_window
    cov = _covariance(grid, pts, pose, np.asarray(window, dtype=np.float64))
    return MatchResult(pose, score, cov, search_score, evaluated, runner_up, rival)


def _search(grid, pts, initial, window_xy, window_theta, min_score, depth, ambiguity_xy, ambiguity_ratio):
    """Branch and bound around ``initial``: best pose (3,), angular step (rad), its grid score,
    evaluations, and the runner-up score and pose (see ``match``)."""
    res = grid.resolution
    window = int(np.ceil(window_xy / res - 1e-9))
    if depth is None:
        depth = int(min(MAX_DEPTH, max(0, np.ceil(np.log2(2 * window + 1)) - 1)))
    step = angular_step(pts, res)
    n_steps = int(np.ceil(window_theta / step - 1e-9))
    thetas = initial[2] + step * np.arange(-n_steps, n_steps + 1)
    pyr = grid.pyramid(window, depth)
    flat = _discretise(pyr, pts, initial[:2], thetas)
    facing = None if pyr.sides is None else facing_bits(pts, thetas)
    best, score, evaluated = _branch_and_bound(pyr, flat, min_score, facing=facing)

    def pose_of(cand):
        return np.array([*(initial[:2] + res * cand[1:]), geometry.wrap_angle(thetas[cand[0]])])

    runner_up, rival = 0.0, None
    if ambiguity_xy > 0 and score >= min_score:  # below min_score the caller rejects the match anyway
        floor = ambiguity_ratio * score
        exclude = (int(best[1]), int(best[2]), int(np.ceil(ambiguity_xy / res - 1e-9)))
        other, second, n = _branch_and_bound(pyr, flat, floor, exclude, facing)
        evaluated += n
        if second >= floor:
            runner_up, rival = second, pose_of(other)
    return pose_of(best), step, score, evaluated, runner_up, rival


def _polish(grid: ProbabilityGrid, pts: np.ndarray, found: np.ndarray, step: float) -> np.ndarray:
    """Refined pose; the search pose if refinement loses (exact, sided) score, or strays without
    gaining any (the search's cells and view sectors only approximate the sides: where it still
    paired a wall's two faces, refinement moves the pose by the wall's thickness)."""
    refined = _refine(grid, pts, found)
    score = grid.score(geometry.transform_points(refined, pts), refined[:2])
    found_score = grid.score(geometry.transform_points(found, pts), found[:2])
    moved = geometry.between(found, refined)
    limit = REFINE_MAX_STEPS * np.array([grid.resolution, step])
    strayed = np.hypot(moved[0], moved[1]) > limit[0] or abs(moved[2]) > limit[1]
    if (strayed and score <= found_score) or score < found_score - REFINE_REVERT_SCORE:
        return found
    return refined
