"""SE(2) on numpy arrays: the one place for pose maths.

A pose is ``(x, y, theta)`` (metres, metres, radians) as a float64 array of
shape ``(3,)``; N poses are ``(N, 3)``. Every function broadcasts over leading
dimensions, so ``compose(a, b)`` works for one pose with many or many with many.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "wrap_angle",
    "wrap_scalar",
    "compose",
    "compose_floats",
    "inverse",
    "inverse_floats",
    "between",
    "transform_points",
    "interpolate",
    "rotation",
    "as_pose",
    "adjoint",
    "logmap",
    "compose_covariance",
]


def as_pose(p) -> np.ndarray:
    """Return ``p`` as a float64 array whose last dimension is 3."""
    a = np.asarray(p, dtype=np.float64)
    if a.shape[-1:] != (3,):
        raise ValueError(f"a pose needs 3 values (x, y, theta), got shape {a.shape}")
    return a


def wrap_angle(a):
    """Wrap angles (rad) to [-pi, pi)."""
    return (np.asarray(a, dtype=np.float64) + np.pi) % (2.0 * np.pi) - np.pi


def rotation(theta) -> np.ndarray:
    """2x2 rotation matrices for angles ``theta`` (rad), shape ``(..., 2, 2)``."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def wrap_scalar(a: float) -> float:
    """``wrap_angle`` of one Python float."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def compose_floats(a, b) -> list[float]:
    """:func:`compose` of two poses given as Python floats (x, y, theta), as a list: a tenth of numpy's per-call
    cost."""
    (ax, ay, at), (bx, by, bt) = a, b
    c, s = math.cos(at), math.sin(at)
    return [ax + c * bx - s * by, ay + s * bx + c * by, wrap_scalar(at + bt)]


def inverse_floats(a) -> list[float]:
    """:func:`inverse` of one pose given as Python floats (x, y, theta), as a list."""
    x, y, t = a
    c, s = math.cos(t), math.sin(t)
    return [-c * x - s * y, s * x - c * y, wrap_scalar(-t)]


def compose(a, b) -> np.ndarray:
    """a ⊕ b: pose ``b`` expressed in frame ``a``, mapped to the world frame."""
    a, b = as_pose(a), as_pose(b)
    if a.ndim == 1 and b.ndim == 1:  # one pose: Python floats
        return np.array(compose_floats(a.tolist(), b.tolist()))
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    return np.stack([x, y, wrap_angle(a[..., 2] + b[..., 2])], -1)


def inverse(a) -> np.ndarray:
    """⊖a, so that compose(a, inverse(a)) is the identity."""
    a = as_pose(a)
    if a.ndim == 1:
        return np.array(inverse_floats(a.tolist()))
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = -c * a[..., 0] - s * a[..., 1]
    y = s * a[..., 0] - c * a[..., 1]
    return np.stack([x, y, wrap_angle(-a[..., 2])], -1)


def between(a, b) -> np.ndarray:
    """Relative pose of ``b`` seen from ``a``: ⊖a ⊕ b (as gtsam.Pose2.between)."""
    a, b = as_pose(a), as_pose(b)
    if a.ndim == 1 and b.ndim == 1:
        (ax, ay, at), (bx, by, bt) = a.tolist(), b.tolist()
        c, s = math.cos(at), math.sin(at)
        dx, dy = bx - ax, by - ay
        return np.array([c * dx + s * dy, -s * dx + c * dy, wrap_scalar(bt - at)])
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    dx, dy = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy, wrap_angle(b[..., 2] - a[..., 2])], -1)


def transform_points(pose, points) -> np.ndarray:
    """Map points ``(M, 2)`` from the frame of ``pose`` (3,) to its parent frame."""
    pose = as_pose(pose)
    pts = np.asarray(points, dtype=np.float64)
    c, s = np.cos(pose[2]), np.sin(pose[2])
    out = np.empty_like(pts)
    out[..., 0] = pose[0] + c * pts[..., 0] - s * pts[..., 1]
    out[..., 1] = pose[1] + s * pts[..., 0] + c * pts[..., 1]
    return out


def interpolate(stamps, poses, query) -> np.ndarray:
    """Poses at times ``query`` by linear interpolation of ``(stamps, poses)``.

    ``stamps`` (N,) must be non-decreasing. Translation is interpolated linearly
    and heading along the shortest arc. Queries outside the span are clamped to
    the first or last pose.
    """
    stamps = np.asarray(stamps, dtype=np.float64)
    poses = as_pose(poses)
    q = np.atleast_1d(np.asarray(query, dtype=np.float64))
    if len(stamps) == 0:
        raise ValueError("cannot interpolate an empty trajectory")
    if len(stamps) == 1:
        out = np.repeat(poses[None, 0], len(q), axis=0)
        return out if np.ndim(query) else out[0]
    if not np.ndim(query):  # one stamp (a reader's per-scan call): Python floats
        return _interpolate_one(stamps, poses, float(q[0]))
    i = np.clip(np.searchsorted(stamps, q, side="right") - 1, 0, len(stamps) - 2)
    t0, t1 = stamps[i], stamps[i + 1]
    dt = t1 - t0
    w = np.where(dt > 0, (q - t0) / np.where(dt > 0, dt, 1.0), 0.0)
    w = np.clip(w, 0.0, 1.0)
    p0, p1 = poses[i], poses[i + 1]
    xy = p0[:, :2] + w[:, None] * (p1[:, :2] - p0[:, :2])
    th = wrap_angle(p0[:, 2] + w * wrap_angle(p1[:, 2] - p0[:, 2]))
    out = np.column_stack([xy, th])
    return out if np.ndim(query) else out[0]


def _interpolate_one(stamps: np.ndarray, poses: np.ndarray, q: float) -> np.ndarray:
    """``interpolate`` at one time ``q`` (s); ``stamps`` has at least two entries."""
    i = min(max(int(np.searchsorted(stamps, q, side="right")) - 1, 0), len(stamps) - 2)
    t0, t1 = stamps[i].item(), stamps[i + 1].item()
    w = min(max((q - t0) / (t1 - t0), 0.0), 1.0) if t1 > t0 else 0.0
    (x0, y0, a0), (x1, y1, a1) = poses[i].tolist(), poses[i + 1].tolist()
    return np.array([x0 + w * (x1 - x0), y0 + w * (y1 - y0), wrap_scalar(a0 + w * wrap_scalar(a1 - a0))])


def adjoint(pose) -> np.ndarray:
    """Adjoints (..., 3, 3) of SE(2) poses (..., 3) in (x, y, theta) tangent order, as gtsam.Pose2.AdjointMap."""
    p = as_pose(pose)
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    out = np.zeros(p.shape[:-1] + (3, 3))
    out[..., 0, 0], out[..., 0, 1], out[..., 0, 2] = c, -s, p[..., 1]
    out[..., 1, 0], out[..., 1, 1], out[..., 1, 2] = s, c, -p[..., 0]
    out[..., 2, 2] = 1.0
    return out


def logmap(pose) -> np.ndarray:
    """SE(2) logarithms (..., 3) of poses (..., 3), as gtsam.Pose2.Logmap."""
    p = as_pose(pose)
    x, y, w = p[..., 0], p[..., 1], wrap_angle(p[..., 2])
    c1, s = np.cos(w) - 1.0, np.sin(w)
    small = np.abs(w) < 1e-10
    det = np.where(small, 1.0, c1 * c1 + s * s)
    ux, uy = c1 * x + s * y, -s * x + c1 * y  # R^T t - t
    scale = np.where(small, 0.0, w / det)
    vx, vy = np.where(small, x, -uy * scale), np.where(small, y, ux * scale)  # R(pi/2) (R^T t - t) w / det
    return np.stack([vx, vy, w], -1)


def compose_covariance(cov_a, b, cov_b) -> np.ndarray:
    """Covariance (3, 3) of a ⊕ b in the local frame of the result.

    ``cov_a`` and ``cov_b`` are the covariances of relative poses a and b, each
    in its own local tangent space (gtsam's convention), assumed independent.
    """
    ad = adjoint(inverse(b))
    return ad @ cov_a @ ad.T + cov_b
