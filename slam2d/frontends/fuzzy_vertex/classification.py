"""Twice classification (Chen & Zhang 2006, section 4.1): scan points in beam order split into collinear sets.

A coarse pass starts a new set where a point cannot join the current collinear set (every
point within ``xi`` m of the least-squares line through the others); a fine pass moves the
tail point of Q_i to Q_{i+1} while that lowers its line distance. The inner loops are
compiled with numba.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["twice_classification", "coarse_classification", "fine_classification"]


@njit(cache=True)
def _sums(xy, s, e):
    """Moments (n, sx, sy, sxx, sxy, syy) of points s..e-1."""
    out = np.zeros(6)
    for j in range(s, e):
        x, y = xy[j, 0], xy[j, 1]
        out[0] += 1.0
        out[1] += x
        out[2] += y
        out[3] += x * x
        out[4] += x * y
        out[5] += y * y
    return out


@njit(cache=True)
def _line(n, sx, sy, sxx, sxy, syy):
    """Orthogonal least-squares line (nx, ny, rho) from point moments."""
    mx, my = sx / n, sy / n
    cxx, cxy, cyy = sxx / n - mx * mx, sxy / n - mx * my, syy / n - my * my
    half = 0.5 * (cxx - cyy)
    low = 0.5 * (cxx + cyy) - np.sqrt(half * half + cxy * cxy)  # smallest eigenvalue
    if cxx >= cyy:  # eigenvector of ``low``, from the better-conditioned row
        nx, ny = cxy, low - cxx
    else:
        nx, ny = low - cyy, cxy
    norm = np.hypot(nx, ny)
    if norm == 0.0:  # isotropic or degenerate: the axis of the smaller spread
        nx, ny, norm = (0.0, 1.0, 1.0) if cxx >= cyy else (1.0, 0.0, 1.0)
    nx, ny = nx / norm, ny / norm
    return nx, ny, nx * mx + ny * my


@njit(cache=True)
def _fit_range(xy, s, e):
    m = _sums(xy, s, e)
    return _line(m[0], m[1], m[2], m[3], m[4], m[5])


@njit(cache=True)
def _distance(xy, j, line):
    return abs(line[0] * xy[j, 0] + line[1] * xy[j, 1] - line[2])


@njit(cache=True)
def _collinear(xy, tol, s, e):
    """Definition 1: every point of s..e-1 within tol of the line through the others."""
    if e - s < 3:
        return True
    m = _sums(xy, s, e)
    for j in range(s, e):
        x, y = xy[j, 0], xy[j, 1]
        line = _line(m[0] - 1.0, m[1] - x, m[2] - y, m[3] - x * x, m[4] - x * y, m[5] - y * y)
        if _distance(xy, j, line) > tol[j]:
            return False
    return True


@njit(cache=True)
def _coarse(xy, tol, max_gap):
    n = xy.shape[0]
    bounds = np.empty(n + 1, np.int64)
    gap_cut = np.zeros(n + 1, np.bool_)
    bounds[0], k, s = 0, 0, 0
    for i in range(1, n):
        jump = max_gap[i] > 0 and np.hypot(xy[i, 0] - xy[i - 1, 0], xy[i, 1] - xy[i - 1, 1]) > max_gap[i]
        if jump or not _collinear(xy, tol, s, i + 1):
            k += 1
            bounds[k], gap_cut[k], s = i, jump, i
    k += 1
    bounds[k] = n
    return bounds[: k + 1], gap_cut[: k + 1]


@njit(cache=True)
def _fine(xy, bounds, gap_cut, max_rounds):
    bounds = bounds.copy()
    for _ in range(max_rounds):
        changed = False
        for i in range(len(bounds) - 2):
            while not gap_cut[i + 1]:
                a, b, c = bounds[i], bounds[i + 1], bounds[i + 2]
                if b - a < 3 or c - b < 2:  # Q_i keeps >= 2 points; Q_{i+1} needs a line
                    break
                tail = b - 1
                d_own = _distance(xy, tail, _fit_range(xy, a, b))
                d_next = _distance(xy, tail, _fit_range(xy, tail, c))
                if d_next >= d_own:
                    break
                bounds[i + 1] = tail
                changed = True
        if not changed:
            break
    return bounds


def _per_point(points: np.ndarray, value) -> np.ndarray:
    return np.broadcast_to(np.asarray(value, dtype=np.float64), (len(points),)).copy()


def coarse_classification(points, xi, max_gap=None) -> tuple[np.ndarray, np.ndarray]:
    """Coarse pass over points (N, 2) in beam order.

    ``xi`` (m, scalar or (N,)) is the collinearity tolerance of each point;
    a point farther than ``max_gap`` (m, scalar or (N,); None: no limit) from
    the previous one starts a new set.
    Returns the set bounds (K + 1,) (set k is ``bounds[k]:bounds[k+1]``) and
    whether each bound is a gap cut (K + 1,).
    """
    xy = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
    if len(xy) == 0:
        return np.zeros(1, np.int64), np.zeros(1, bool)
    gap = _per_point(xy, 0.0 if max_gap is None else max_gap)
    return _coarse(xy, _per_point(xy, xi), gap)


def fine_classification(points, bounds, gap_cut=None, max_rounds: int = 100) -> np.ndarray:
    """Fine pass: move the tail of Q_i into Q_{i+1} while its line distance drops; new bounds."""
    xy = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
    bounds = np.asarray(bounds, dtype=np.int64)
    cuts = np.zeros(len(bounds), bool) if gap_cut is None else np.asarray(gap_cut, bool)
    return _fine(xy, bounds, cuts, max_rounds)


def twice_classification(points, xi, max_gap=None) -> tuple[np.ndarray, np.ndarray]:
    """Coarse then fine pass; returns bounds (K + 1,) and gap cuts (K + 1,)."""
    bounds, cuts = coarse_classification(points, xi, max_gap)
    return fine_classification(points, bounds, cuts), cuts
