"""The timed elastic band's factors (:mod:`slam2d.navigation.teb`): residuals over the whole band as numba
kernels with analytic Jacobians, and the GTSAM factor that wraps them."""

from __future__ import annotations

import math

import gtsam
import numpy as np
from numba import njit

__all__ = ["T", "X", "acceleration_residual", "band_factor", "kinematics_residual", "obstacle_residual", "segments",
           "stacked", "time_residual", "velocity_residual", "via_residual"]  # fmt: skip


# --- factors: vectorised over the band, with analytic Jacobians ----------------------------------------------
#
# Each kind of factor is a residual over the whole band, a numba kernel (the band is small: numpy's per-call
# cost would dominate); ``band_factor`` makes one gtsam.CustomFactor of a residual, and the planner stacks all
# kinds into one, so that an evaluation of the graph costs a single Python callback. A residual takes the poses P (n, 3) (x, y, theta; m, rad) and
# intervals dts (n - 1,) s and returns the error (E,) and its derivatives over the world (x, y, theta) of
# every pose (E, n, 3) and over every interval (E, n - 1).


@njit(cache=True, nogil=True)
def segments(P, dts):
    """Speeds of the band's segments: v (m/s, signed by the heading of the segment's first pose) and w (rad/s),
    each (n - 1,), and their gradients (n - 1, 7) over (x_a, y_a, theta_a, x_b, y_b, theta_b, dt) of each."""
    m = len(dts)
    v, w = np.empty(m), np.empty(m)
    gv, gw = np.zeros((m, 7)), np.zeros((m, 7))
    for i in range(m):
        dx, dy, dt = P[i + 1, 0] - P[i, 0], P[i + 1, 1] - P[i, 1], dts[i]
        dist = math.hypot(dx, dy)
        sign = 1.0 if dx * math.cos(P[i, 2]) + dy * math.sin(P[i, 2]) >= 0 else -1.0
        turn = (P[i + 1, 2] - P[i, 2] + math.pi) % (2 * math.pi) - math.pi
        v[i], w[i] = sign * dist / dt, turn / dt
        if dist > 1e-12:
            ux, uy = sign * dx / (dist * dt), sign * dy / (dist * dt)
            gv[i, 0], gv[i, 1], gv[i, 3], gv[i, 4] = -ux, -uy, ux, uy
        gv[i, 6] = -v[i] / dt
        gw[i, 2], gw[i, 5], gw[i, 6] = -1.0 / dt, 1.0 / dt, -w[i] / dt
    return v, w, gv, gw


@njit(cache=True, nogil=True)
def _excess(x, lo, hi):
    """How far ``x`` lies outside [lo, hi] (>= 0) and its derivative."""
    if x > hi:
        return x - hi, 1.0
    if x < lo:
        return lo - x, -1.0
    return 0.0, 0.0


@njit(cache=True, nogil=True)
def _spread(dP, ddt, row, i, g, scale):
    """Adds ``scale`` x the segment-``i`` gradient ``g`` (7,) to row ``row`` of the derivatives."""
    for k in range(3):
        dP[row, i, k] += scale * g[k]
        dP[row, i + 1, k] += scale * g[3 + k]
    ddt[row, i] += scale * g[6]


@njit(cache=True, nogil=True)
def via_residual(P, dts, index, vias, tube):
    """Pulls the positions of poses ``index`` (V,) to within ``tube`` m of the via-points ``vias`` (V, 2) m: error
    (2 V,) m, the x offsets, then the y offsets, each shortened by ``tube`` along the offset (0 inside it)."""
    q = len(index)
    e, dP, ddt = np.zeros(2 * q), np.zeros((2 * q, len(P), 3)), np.zeros((2 * q, len(dts)))
    for k in range(q):
        r = np.array([P[index[k], 0] - vias[k, 0], P[index[k], 1] - vias[k, 1]])
        d = math.hypot(r[0], r[1])
        if d <= tube:
            continue
        f = 1.0 - tube / d
        for a in range(2):
            e[a * q + k] = f * r[a]
            for b in range(2):
                dP[a * q + k, index[k], b] = (f if a == b else 0.0) + tube * r[a] * r[b] / d**3
    return e, dP, ddt


@njit(cache=True, nogil=True)
def obstacle_residual(P, dts, points, grown, near, soft):
    """Keeps poses 1 .. n - 1 clear of the laser ``points`` (M, 2): error (4 (n - 1),) m, how far the distance to
    the nearest point on each pose's left, then on its right, less that point's margin ``grown`` (n, M) m (per
    pose: the extra margin of a point that may move), falls short of ``near`` (radius + margin); then the same
    against ``soft`` (+ inflation)."""
    n, m = len(P), len(P) - 1
    e, dP, ddt = np.zeros(4 * m), np.zeros((4 * m, n, 3)), np.zeros((4 * m, m))
    for i in range(1, n):
        c, s = math.cos(P[i, 2]), math.sin(P[i, 2])
        best = np.array([np.inf, np.inf])
        pick = np.array([-1, -1])
        for j in range(len(points)):
            rx, ry = points[j, 0] - P[i, 0], points[j, 1] - P[i, 1]
            if abs(rx) > soft + grown[i, j] or abs(ry) > soft + grown[i, j]:
                continue
            gap = math.hypot(rx, ry) - grown[i, j]
            side = 0 if c * ry - s * rx > 0 else 1
            if gap < best[side]:
                best[side], pick[side] = gap, j
        for side in range(2):
            if pick[side] < 0:
                continue
            j = pick[side]
            rx, ry = points[j, 0] - P[i, 0], points[j, 1] - P[i, 1]
            d = max(math.hypot(rx, ry), 1e-9)
            for block, bound in ((side, near), (2 + side, soft)):
                if best[side] < bound:
                    row = block * m + i - 1
                    e[row] = bound - best[side]
                    dP[row, i, 0], dP[row, i, 1] = rx / d, ry / d
    return e, dP, ddt


@njit(cache=True, nogil=True)
def velocity_residual(P, dts, v_lo, v_hi, w_max, min_dt):
    """Keeps every segment within [``v_lo``, ``v_hi``] m/s, |w| <= ``w_max`` rad/s and dt >= ``min_dt`` s: error
    (3 (n - 1),), the excess of v (m/s), then of w (rad/s), then how far dt falls short (s)."""
    n, m = len(P), len(dts)
    v, w, gv, gw = segments(P, dts)
    e, dP, ddt = np.zeros(3 * m), np.zeros((3 * m, n, 3)), np.zeros((3 * m, m))
    for i in range(m):
        e[i], d = _excess(v[i], v_lo, v_hi)
        _spread(dP, ddt, i, i, gv[i], d)
        e[m + i], d = _excess(w[i], -w_max, w_max)
        _spread(dP, ddt, m + i, i, gw[i], d)
        e[2 * m + i], d = _excess(dts[i], min_dt, np.inf)
        ddt[2 * m + i, i] = d
    return e, dP, ddt


@njit(cache=True, nogil=True)
def kinematics_residual(P, dts):
    """Non-holonomic kinematics of every segment (pose a, pose b): error (2 (n - 1),) m, the chord's offset from
    the direction both headings share ((cos a + cos b) dy - (sin a + sin b) dx: zero on an arc), then how far
    the chord runs backwards of pose a's heading."""
    n, m = len(P), len(P) - 1
    e, dP, ddt = np.zeros(2 * m), np.zeros((2 * m, n, 3)), np.zeros((2 * m, m))
    for i in range(m):
        dx, dy = P[i + 1, 0] - P[i, 0], P[i + 1, 1] - P[i, 1]
        ca, sa, cb, sb = math.cos(P[i, 2]), math.sin(P[i, 2]), math.cos(P[i + 1, 2]), math.sin(P[i + 1, 2])
        e[i] = (ca + cb) * dy - (sa + sb) * dx
        dP[i, i, 0], dP[i, i, 1], dP[i, i, 2] = sa + sb, -(ca + cb), -sa * dy - ca * dx
        dP[i, i + 1, 0], dP[i, i + 1, 1], dP[i, i + 1, 2] = -(sa + sb), ca + cb, -sb * dy - cb * dx
        e[m + i], d = _excess(ca * dx + sa * dy, 0.0, np.inf)
        dP[m + i, i, 0], dP[m + i, i, 1], dP[m + i, i, 2] = -d * ca, -d * sa, d * (-sa * dx + ca * dy)
        dP[m + i, i + 1, 0], dP[m + i, i + 1, 1] = d * ca, d * sa
    return e, dP, ddt


@njit(cache=True, nogil=True)
def acceleration_residual(P, dts, start, end, a_max, alpha_max):
    """Keeps the change of speed from the robot's velocity ``start`` (v m/s, w rad/s) to the first segment's,
    between consecutive segments and, if ``end`` (2,) is finite, from the last segment's to ``end``, within
    ``a_max`` m/s^2 and ``alpha_max`` rad/s^2: error (2 q,), the excess of the linear accelerations (start,
    pairs, end), then of the angular ones. A segment's speed is its mean, at its middle: the start's change
    is over half the first interval, as the end's over half the last (over the whole interval, the band
    planned twice the acceleration the robot has, and the robot lagged it)."""
    n, m = len(P), len(dts)
    v, w, gv, gw = segments(P, dts)
    closed = np.isfinite(end[0])
    q = m + 1 if closed else m
    e, dP, ddt = np.zeros(2 * q), np.zeros((2 * q, n, 3)), np.zeros((2 * q, m))
    for block in range(2):
        x, g, lim = (v, gv, a_max) if block == 0 else (w, gw, alpha_max)
        base = block * q
        acc = 2 * (x[0] - start[block]) / dts[0]  # from now to the first segment's middle
        e[base], d = _excess(acc, -lim, lim)
        _spread(dP, ddt, base, 0, g[0], 2 * d / dts[0])
        ddt[base, 0] -= d * acc / dts[0]
        for i in range(m - 1):
            total = dts[i] + dts[i + 1]
            acc = 2 * (x[i + 1] - x[i]) / total
            row = base + 1 + i
            e[row], d = _excess(acc, -lim, lim)
            _spread(dP, ddt, row, i, g[i], -2 * d / total)
            _spread(dP, ddt, row, i + 1, g[i + 1], 2 * d / total)
            ddt[row, i] -= d * acc / total
            ddt[row, i + 1] -= d * acc / total
        if closed:
            acc = 2 * (end[block] - x[m - 1]) / dts[m - 1]  # from the last segment's middle to its end
            row = base + q - 1
            e[row], d = _excess(acc, -lim, lim)
            _spread(dP, ddt, row, m - 1, g[m - 1], -2 * d / dts[m - 1])
            ddt[row, m - 1] -= d * acc / dts[m - 1]
    return e, dP, ddt


@njit(cache=True, nogil=True)
def time_residual(P, dts):
    """Pulls every time interval to 0 (the band is time-optimal): error (n - 1,) s."""
    m = len(dts)
    return dts.copy(), np.zeros((m, len(P), 3)), np.eye(m)


def band_factor(n: int, residual, weights, timed: bool) -> gtsam.CustomFactor:
    """The factor over the band's ``n`` poses (and its n - 1 intervals if ``timed``) whose error is
    ``residual(P, dts) -> (e, dP, ddt)`` (see above) weighted by ``weights`` (E,): a pose's derivatives
    turn into its tangent space (``Pose2.retract`` moves the translation in the body frame)."""
    pose_keys, dt_keys = [X(i) for i in range(n)], [T(i) for i in range(n - 1)] if timed else []

    def error(this, values, jacobians):
        P = gtsam.utilities.extractPose2(values)  # (n, 3), in key order: the band's poses
        dts = gtsam.utilities.extractVectors(values, "t")[:, 0]  # (n - 1,), in key order: the band's intervals
        e, dP, ddt = residual(P, np.maximum(dts, 1e-6))
        if jacobians is not None:
            c, s = np.cos(P[:, 2]), np.sin(P[:, 2])
            tangent = np.stack([dP[..., 0] * c + dP[..., 1] * s, -dP[..., 0] * s + dP[..., 1] * c, dP[..., 2]], -1)
            for k in range(n):
                jacobians[k] = np.ascontiguousarray(tangent[:, k, :])
            for k in range(len(dt_keys)):
                jacobians[n + k] = np.ascontiguousarray(ddt[:, k : k + 1])
        return e

    return gtsam.CustomFactor(_sigmas(weights), pose_keys + dt_keys, error)


def stacked(residuals):
    """The residual whose error and derivatives are those of ``residuals`` one after the other."""

    def residual(P, dts):
        parts = [f(P, dts) for f in residuals]
        return tuple(np.concatenate([p[k] for p in parts]) for k in range(3))

    return residual


def _sigmas(weights) -> gtsam.noiseModel.Diagonal:
    """The diagonal noise model whose squared whitened error is the weighted square (weight 0: nearly ignored)."""
    return gtsam.noiseModel.Diagonal.Sigmas(1.0 / np.sqrt(np.maximum(np.atleast_1d(np.asarray(weights, float)), 1e-9)))


def X(i: int) -> int:
    """Key of the band's i-th pose."""
    return gtsam.symbol("x", i)


def T(i: int) -> int:
    """Key of the band's i-th time interval (between poses i and i + 1; a 1-vector, s)."""
    return gtsam.symbol("t", i)
