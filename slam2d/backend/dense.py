"""Point-to-line alignment of one scan against another's local lines, many pairs at once.

A keyframe's scan becomes a :class:`Surface`: its points (base frame, m), a cKDTree over them and
each point's unit normal from the principal axes of its neighbours within ``NORMAL_RADIUS``
(points whose neighbourhood is not a line get no normal and take no part). Aligning a source
scan to a surface (:func:`align_pairs`, many pairs at once) minimises, under a Cauchy kernel, the squared distances
of the source's points to the lines through their nearest surface points; it returns the
relative pose (source frame seen from the surface's), the Gauss-Newton Hessian of those
residuals at the solution (the information of the pose in (x, y, theta) of the source frame,
GTSAM's tangent order) and the share of source points that found a line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from slam2d import geometry
from slam2d.backend.probability_grid import scatter_normals

NORMAL_RADIUS = 0.5  # m: neighbours that fit a point's local line
NORMAL_MIN_NEIGHBOURS = 3  # points (with itself) within NORMAL_RADIUS to fit a line (scatter_normals asks as many)
NORMAL_MAX_FLATNESS = 0.3  # ratio of the neighbourhood's smaller to larger principal spread (a line: ~0)
SIGMA = 0.02  # m: point-to-line noise; the information is the Hessian over SIGMA^2
KERNEL_WIDTH = 0.05  # m: Cauchy kernel width on point-to-line distances
DAMPING = 1e-6  # share of the Hessian's trace on its diagonal: a direction no line constrains does not move
ITERATIONS = 3  # Gauss-Newton steps (each re-associates) per alignment: the graph starts them close


@dataclass(frozen=True)
class Surface:
    """A scan's points (M, 2) m, their unit normals (M, 2) (NaN where no line) and a cKDTree."""

    points: np.ndarray
    normals: np.ndarray
    tree: cKDTree


def surface(points) -> Surface:
    """The :class:`Surface` of ``points`` (M, 2) in one frame (m)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    tree = cKDTree(pts)
    normals = np.full_like(pts, np.nan)
    if len(pts) >= NORMAL_MIN_NEIGHBOURS:
        found, line, _ = scatter_normals(tree, pts, NORMAL_RADIUS, NORMAL_MAX_FLATNESS**2)
        normals[line] = found[line]
    return Surface(pts, normals, tree)


def align_pairs(targets: list[Surface], sources: list[np.ndarray], pairs, relative,
                max_distance: float = 0.3, iterations: int = ITERATIONS):
    """Align every pair at once: ``pairs`` (P, 2) rows (target, source) index ``targets`` and
    ``sources`` (points (M, 2) in their own frames); ``relative`` (P, 3) is each source frame in its
    target's frame to start from. Returns poses (P, 3), information (P, 3, 3) in the source frame's
    tangent (x, y, theta) and the share (P,) of each source's points that found a line."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    x = np.asarray(relative, dtype=np.float64).reshape(-1, 3).copy()
    n_pairs = len(pairs)
    order = np.argsort(pairs[:, 0], kind="stable")
    counts = np.array([len(sources[j]) for j in pairs[order, 1]], dtype=np.int64)
    owner = np.repeat(order, counts)  # pair of each stacked source point
    src = np.vstack([sources[j] for j in pairs[order, 1]]) if n_pairs else np.zeros((0, 2))
    bounds = np.r_[0, np.cumsum(counts)]
    starts = np.flatnonzero(np.r_[True, np.diff(pairs[order, 0]) != 0])  # first of each target's run
    runs = [(int(pairs[order[s], 0]), bounds[s], bounds[e]) for s, e in zip(starts, np.r_[starts[1:], n_pairs])]
    info = np.zeros((n_pairs, 3, 3))
    used = np.zeros(n_pairs)
    for _ in range(iterations):
        c, s = np.cos(x[owner, 2]), np.sin(x[owner, 2])
        rot = np.column_stack([c * src[:, 0] - s * src[:, 1], s * src[:, 0] + c * src[:, 1]])
        moved = rot + x[owner, :2]
        normal = np.full((len(src), 2), np.nan)  # nearest target point's normal and position
        near = np.zeros((len(src), 2))
        for t, a, b in runs:
            dist, idx = targets[t].tree.query(moved[a:b], distance_upper_bound=max_distance)
            hit = np.isfinite(dist)
            normal[a:b][hit] = targets[t].normals[idx[hit]]
            near[a:b][hit] = targets[t].points[idx[hit]]
        k = np.flatnonzero(np.isfinite(normal[:, 0]))
        n, own = normal[k], owner[k]
        r = np.einsum("ij,ij->i", n, moved[k] - near[k])
        jac = np.column_stack([n, n[:, 1] * rot[k, 0] - n[:, 0] * rot[k, 1]])
        w = 1.0 / (1.0 + (r / KERNEL_WIDTH) ** 2)
        h = np.zeros((n_pairs, 3, 3))
        g = np.zeros((n_pairs, 3))
        for u in range(3):
            g[:, u] = np.bincount(own, w * jac[:, u] * r, n_pairs)
            for v in range(u, 3):
                h[:, u, v] = h[:, v, u] = np.bincount(own, w * jac[:, u] * jac[:, v], n_pairs)
        used = np.bincount(own, minlength=n_pairs).astype(float)
        ok = used >= 3
        step = np.zeros((n_pairs, 3))
        damp = DAMPING * np.trace(h[ok], axis1=1, axis2=2)[:, None, None] * np.eye(3)  # a corridor's free direction
        step[ok] = -np.linalg.solve(h[ok] + damp, g[ok][..., None])[..., 0]
        x[:, :2] += step[:, :2]
        x[:, 2] = geometry.wrap_angle(x[:, 2] + step[:, 2])
        info = h
        if np.abs(step[:, :2]).max(initial=0) < 1e-5 and np.abs(step[:, 2]).max(initial=0) < 1e-6:
            break
    c, s = np.cos(x[:, 2]), np.sin(x[:, 2])
    frame = np.zeros((n_pairs, 3, 3))
    frame[:, 0, 0], frame[:, 0, 1], frame[:, 1, 0], frame[:, 1, 1], frame[:, 2, 2] = c, -s, s, c, 1.0
    info = np.transpose(frame, (0, 2, 1)) @ info @ frame / SIGMA**2
    return x, info, used / np.maximum(counts[np.argsort(order)], 1)
