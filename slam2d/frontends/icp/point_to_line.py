"""Point-to-line ICP in 2D: correspondences, robust normal equations and Gauss-Newton, compiled with numba.

Each kernel loops over the 100-400 points of one scan, several times per scan; numpy's
per-call overhead on arrays this small would dominate. Points are (x, y) m, poses
(x, y, theta) (m, m, rad).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from slam2d.frontends.icp.grid import knn

__all__ = ["scan_normals", "fit", "icp_line"]


@njit(cache=True, nogil=True)
def scan_normals(points, line_ratio, max_gap, half_window=2):
    """Unit normals (M, 2) of the scan's local lines; zeros where the beams around a point are no line.

    ``points`` (M, 2) are in beam order. Each point's window is the
    ``2 * half_window + 1`` beams around it (clipped at the ends); it is a line
    when its scatter's eigenvalue ratio is <= ``line_ratio`` and no two
    consecutive beams in it are more than ``max_gap`` m apart (a depth jump).
    """
    m = len(points)
    out = np.zeros((m, 2))
    for i in range(m):
        lo, hi = max(0, i - half_window), min(m, i + half_window + 1)
        if hi - lo < 3:
            continue
        mx, my, gap = 0.0, 0.0, 0.0
        for j in range(lo, hi):
            mx += points[j, 0]
            my += points[j, 1]
            if j > lo:
                gap = max(gap, np.hypot(points[j, 0] - points[j - 1, 0], points[j, 1] - points[j - 1, 1]))
        if gap > max_gap:
            continue
        mx, my = mx / (hi - lo), my / (hi - lo)
        cxx, cyy, cxy = 0.0, 0.0, 0.0
        for j in range(lo, hi):
            dx, dy = points[j, 0] - mx, points[j, 1] - my
            cxx += dx * dx
            cyy += dy * dy
            cxy += dx * dy
        ok, tx, ty = _line_direction(cxx, cyy, cxy, line_ratio)
        if ok:
            out[i, 0], out[i, 1] = -ty, tx
    return out


@njit(cache=True, nogil=True)
def _line_direction(cxx, cyy, cxy, line_ratio):
    """(is a line, tx, ty): unit direction of the largest eigenvector of [[cxx, cxy], [cxy, cyy]].

    A line when the smaller eigenvalue is at most ``line_ratio`` times the larger.
    """
    half = 0.5 * (cxx + cyy)
    disc = np.sqrt(max(half * half - (cxx * cyy - cxy * cxy), 0.0))
    hi, lo = half + disc, half - disc
    if not (hi > 0 and lo <= line_ratio * hi):
        return False, 1.0, 0.0
    ax, ay, bx, by = hi - cyy, cxy, cxy, hi - cxx
    tx, ty = (ax, ay) if ax * ax + ay * ay >= bx * bx + by * by else (bx, by)
    norm = np.sqrt(tx * tx + ty * ty)
    return True, tx / norm, ty / norm


@njit(cache=True, nogil=True)
def _line_fit(map_xy, idx, n, along, line_ratio, out_target, out_omega):
    """Target and weight of one correspondence from its ``n`` nearest map points ``idx``.

    A neighbourhood whose scatter is a line (eigenvalue ratio <= line_ratio, at
    least 3 points) gives target = its mean and weight n n^T + along t t^T;
    otherwise target = the nearest point and weight = identity (point-to-point).
    Returns whether the neighbourhood is a line.
    """
    mx, my = 0.0, 0.0
    for j in range(n):
        mx += map_xy[idx[j], 0]
        my += map_xy[idx[j], 1]
    mx, my = mx / n, my / n
    cxx, cyy, cxy = 0.0, 0.0, 0.0
    for j in range(n):
        dx, dy = map_xy[idx[j], 0] - mx, map_xy[idx[j], 1] - my
        cxx += dx * dx
        cyy += dy * dy
        cxy += dx * dy
    ok, tx, ty = _line_direction(cxx, cyy, cxy, line_ratio)
    if n >= 3 and ok:
        out_omega[0, 0] = ty * ty + along * tx * tx
        out_omega[1, 1] = tx * tx + along * ty * ty
        out_omega[0, 1] = out_omega[1, 0] = (along - 1.0) * tx * ty
        out_target[0], out_target[1] = mx, my
        return True
    out_omega[0, 0], out_omega[1, 1], out_omega[0, 1], out_omega[1, 0] = 1.0, 1.0, 0.0, 0.0
    out_target[0], out_target[1] = map_xy[idx[0], 0], map_xy[idx[0], 1]
    return False


@njit(cache=True, nogil=True)
def _correspond(grid, source, pose, k, radius, along, line_ratio, min_cluster):
    """Correspondences (valid (M,), target (M, 2), omega (M, 2, 2)) of ``source`` moved to ``pose``.

    ``source`` (M, 4) holds points and scan-line normals. The residual is
    across the map's local line where the map neighbourhood is one, else
    across the scan's own line (to the nearest map point) where the scan has
    one there, else point-to-point.
    """
    m = len(source)
    valid = np.zeros(m, np.bool_)
    target = np.zeros((m, 2))
    omega = np.zeros((m, 2, 2))
    idx, d2 = np.empty(k, np.int64), np.empty(k)
    c, s = np.cos(pose[2]), np.sin(pose[2])
    for i in range(m):
        x = pose[0] + c * source[i, 0] - s * source[i, 1]
        y = pose[1] + s * source[i, 0] + c * source[i, 1]
        n = knn(grid, x, y, radius, idx, d2)
        if n == 0:
            continue
        valid[i] = True
        if _line_fit(grid.points, idx, n, along, line_ratio, target[i], omega[i]):
            continue
        if source[i, 2] != 0.0:
            nx = c * source[i, 2] - s * source[i, 3]  # the scan's own line, in the local frame
            ny = s * source[i, 2] + c * source[i, 3]
            omega[i, 0, 0], omega[i, 0, 1], omega[i, 1, 0], omega[i, 1, 1] = nx * nx, nx * ny, nx * ny, ny * ny
        elif n < min_cluster:
            valid[i] = False  # an isolated point: its nearest map point is likely another surface point
    return valid, target, omega


@njit(cache=True, nogil=True)
def _normal_equations(source, pose, valid, target, omega, kernel, inlier_distance=0.0):
    """Robust normal equations of the residuals T(pose) source - target over (x, y, theta).

    Geman-McClure weights w = (kernel^2 / (kernel^2 + e^2))^2, e^2 = r^T omega r.
    Returns H (3, 3), g (3,), sum of w e^2 (m^2), sum of w, and the number of
    residuals with e <= ``inlier_distance`` (m).
    """
    c, s = np.cos(pose[2]), np.sin(pose[2])
    h = np.zeros((3, 3))
    g = np.zeros(3)
    k2, wsq, wsum, inliers = kernel * kernel, 0.0, 0.0, 0
    for i in range(len(source)):
        if not valid[i]:
            continue
        px, py = source[i, 0], source[i, 1]
        jx, jy = -s * px - c * py, c * px - s * py  # d(R p)/d theta
        rx, ry = c * px - s * py + pose[0] - target[i, 0], s * px + c * py + pose[1] - target[i, 1]
        o00, o01, o11 = omega[i, 0, 0], omega[i, 0, 1], omega[i, 1, 1]
        ox, oy = o00 * rx + o01 * ry, o01 * rx + o11 * ry
        e2 = rx * ox + ry * oy
        w = (k2 / (k2 + e2)) ** 2
        qx, qy = o00 * jx + o01 * jy, o01 * jx + o11 * jy
        h[0, 0] += w * o00
        h[0, 1] += w * o01
        h[1, 1] += w * o11
        h[0, 2] += w * qx
        h[1, 2] += w * qy
        h[2, 2] += w * (jx * qx + jy * qy)
        g[0] += w * ox
        g[1] += w * oy
        g[2] += w * (jx * ox + jy * oy)
        wsq += w * e2
        wsum += w
        inliers += e2 <= inlier_distance * inlier_distance
    h[1, 0], h[2, 0], h[2, 1] = h[0, 1], h[0, 2], h[1, 2]
    return h, g, wsq, wsum, inliers


@njit(cache=True, nogil=True)
def fit(grid, source, pose, k, radius, along, line_ratio, min_cluster, kernel, inlier_distance):
    """(matched fraction, H, sum w e^2, sum w) of ``source`` at ``pose``: see ``Fit``."""
    valid, target, omega = _correspond(grid, source, pose, k, radius, along, line_ratio, min_cluster)
    h, _, weighted_sq, weight_sum, inliers = _normal_equations(source, pose, valid, target, omega, kernel,
                                                               inlier_distance)
    return inliers / max(len(source), 1), h, weighted_sq, weight_sum


@njit(cache=True, nogil=True)
def _abs_max(v):
    """max |v_i| of a 3-vector."""
    return max(abs(v[0]), abs(v[1]), abs(v[2]))


@njit(cache=True, nogil=True)
def _solve3(a, b):
    """Solution of the 3x3 system a x = b by the adjugate (a symmetric positive semi-definite)."""
    c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
    c01 = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
    c02 = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
    det = a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02 + 1e-300
    c11 = a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]
    c12 = a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]
    c22 = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    x = np.empty(3)
    x[0] = (c00 * b[0] + c01 * b[1] + c02 * b[2]) / det
    x[1] = (c01 * b[0] + c11 * b[1] + c12 * b[2]) / det
    x[2] = (c02 * b[0] + c12 * b[1] + c22 * b[2]) / det
    return x


@njit(cache=True, nogil=True)
def _gauss_newton(source, pose, valid, target, omega, kernel, guess, prior, iterations, convergence):
    """Gauss-Newton steps with fixed correspondences and the prior ``prior`` (3, 3) on ``pose - guess``.

    Returns the new pose and the size of its total change (max over m and rad).
    """
    out = pose.copy()
    for _ in range(iterations):
        h, g, _, _, _ = _normal_equations(source, out, valid, target, omega, kernel)
        off = out - guess
        off[2] = (off[2] + np.pi) % (2.0 * np.pi) - np.pi
        for i in range(3):
            g[i] += prior[i, 0] * off[0] + prior[i, 1] * off[1] + prior[i, 2] * off[2]
            h[i, i] += 1e-9
        step = _solve3(h + prior, -g)
        out += step
        if _abs_max(step) < convergence:
            break
    return out, _abs_max(out - pose)


@njit(cache=True, nogil=True)
def icp_line(grid, source, start, guess, prior, radius, kernel, k, along, line_ratio,
              min_cluster, iterations, inner, convergence):
    """Point-to-line ICP from ``start``: correspondences re-found each outer iteration.

    Stops when an outer iteration moves the pose less than ``convergence`` or
    returns to where it was two iterations before (cycling between two
    correspondence sets). Returns the pose and whether it is usable.
    """
    pose, before = start.copy(), np.full(3, np.inf)
    for _ in range(iterations):
        valid, target, omega = _correspond(grid, source, pose, k, radius, along, line_ratio,
                                           min_cluster)
        if valid.sum() < 3:
            return pose, False
        new, step = _gauss_newton(source, pose, valid, target, omega, kernel, guess, prior, inner, convergence)
        if not (np.isfinite(new[0]) and np.isfinite(new[1]) and np.isfinite(new[2])):
            return pose, False
        cycling = _abs_max(new - before) < convergence
        before, pose = pose, new
        if step < convergence or cycling:
            break
    pose[2] = (pose[2] + np.pi) % (2.0 * np.pi) - np.pi
    return pose, True
