"""Vertex matching and the pose offset (Chen & Zhang 2006, eqs. 6 and 9), and unit matching (eqs. 13-15).

Vertices match when ``d(o, o') <= min(R, R')``; the pose is the paper's mean offset (eq. 9) or a
weighted 2D Kabsch fit. Units match by line angle, robot distance and intersecting prisms.
Lengths in metres, angles in radians.
"""

from __future__ import annotations

import numpy as np

from slam2d import geometry
from slam2d.frontends.fuzzy_vertex.extraction import Units, Vertices, robot_distance

__all__ = ["arm_differences", "match_vertices", "rigid_matches", "translation_offset", "fit_se2", "match_units"]


def arm_differences(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Arm directions a - b (rad, (P, 2)) of vertex pairs, with b's arms in the order that fits best."""
    same = geometry.wrap_angle(a - b)
    swapped = geometry.wrap_angle(a - b[:, ::-1])
    better = np.abs(swapped).max(axis=1) < np.abs(same).max(axis=1)
    return np.where(better[:, None], swapped, same)


def _arm_error(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Largest arm-direction difference (rad) of vertex pairs (P, 2) x (P, 2), either arm order."""
    return np.abs(arm_differences(a, b)).max(axis=1)


def match_vertices(local: Vertices, mapped: Vertices, max_arm_error: float | None = None):
    """Eq. 6 matches ``d(o, o') <= min(R, R')`` between two vertex sets in one frame.

    Each vertex takes at most one partner, nearest first. ``max_arm_error``
    (rad) also requires the walls of the two vertices to point the same ways.
    Returns indices (S,) into ``local`` and (S,) into ``mapped``.
    """
    if len(local) == 0 or len(mapped) == 0:
        return np.zeros(0, int), np.zeros(0, int)
    d = np.linalg.norm(local.o[:, None] - mapped.o[None], axis=-1)  # (L, G)
    ok = d <= np.minimum(local.R[:, None], mapped.R[None])
    li, gj = np.nonzero(ok)
    if max_arm_error is not None and len(li):
        keep = _arm_error(local.arms[li], mapped.arms[gj]) <= max_arm_error
        li, gj = li[keep], gj[keep]
    order = np.argsort(d[li, gj], kind="stable")
    li, gj = li[order], gj[order]
    _, first = np.unique(li, return_index=True)  # nearest partner of each local vertex
    li, gj = li[np.sort(first)], gj[np.sort(first)]
    _, first = np.unique(gj, return_index=True)  # and each mapped vertex used once
    first = np.sort(first)
    return li[first], gj[first]


def rigid_matches(local_o, mapped_o, tol, weight=None) -> np.ndarray:
    """Mask (S,) of matches whose pairwise distances agree within tol_i + tol_j (m) in both frames.

    The match breaking most pairs (ties: the smallest ``weight``) is dropped
    until the rest agree.
    """
    p, q = np.asarray(local_o, float), np.asarray(mapped_o, float)
    keep = np.ones(len(p), bool)
    if len(p) < 2:
        return keep
    w = np.zeros(len(p)) if weight is None else np.asarray(weight, float)
    d = np.abs(np.linalg.norm(p[:, None] - p[None], axis=-1) - np.linalg.norm(q[:, None] - q[None], axis=-1))
    bad = d > np.asarray(tol)[:, None] + np.asarray(tol)[None]
    while True:
        count = (bad & keep[None]).sum(1) * keep
        if count.max() == 0:
            return keep
        worst = np.flatnonzero(count == count.max())
        keep[worst[np.argmin(w[worst])]] = False


def translation_offset(global_o, local_o, m) -> np.ndarray:
    """Eq. 9: V* = sum m_i (o_i - o'_i) / sum m_i, the m-weighted mean offset (2,), m."""
    g, q, w = np.asarray(global_o, float), np.asarray(local_o, float), np.asarray(m, float)
    return (w[:, None] * (g - q)).sum(0) / w.sum()


def fit_se2(local, target, w) -> np.ndarray:
    """Pose (3,) minimising sum w_i |pose * local_i - target_i|^2 (weighted 2D Kabsch / Umeyama).

    ``local`` (S, 2) in the robot frame, ``target`` (S, 2) in the map, ``w``
    (S,) weights; S >= 2 points that are not all the same.
    """
    p, q, w = np.asarray(local, float), np.asarray(target, float), np.asarray(w, float)
    pm, qm = (w[:, None] * p).sum(0) / w.sum(), (w[:, None] * q).sum(0) / w.sum()
    a, b = p - pm, q - qm
    s = (w * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])).sum()
    c = (w * (a * b).sum(1)).sum()
    theta = np.arctan2(s, c)
    t = qm - geometry.rotation(theta) @ pm
    return np.array([t[0], t[1], theta])


def _point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances from points p (..., 2) to segments a-b (..., 2), broadcast."""
    e = b - a
    ee = np.maximum((e * e).sum(-1), 1e-18)
    u = np.clip(((p - a) * e).sum(-1) / ee, 0.0, 1.0)
    return np.linalg.norm(p - a - u[..., None] * e, axis=-1)


def _segments_distance(a0, a1, b0, b1) -> np.ndarray:
    """Shortest distances between segments a0-a1 and b0-b1 (..., 2); 0 where they cross."""

    def cross(u, v):
        return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]

    da, db = a1 - a0, b1 - b0
    crossing = (cross(da, b0 - a0) * cross(da, b1 - a0) < 0) & (cross(db, a0 - b0) * cross(db, a1 - b0) < 0)
    d = np.minimum.reduce(
        [
            _point_segment_distance(a0, b0, b1),
            _point_segment_distance(a1, b0, b1),
            _point_segment_distance(b0, a0, a1),
            _point_segment_distance(b1, a0, a1),
        ]
    )
    return np.where(crossing, 0.0, d)


def _line_angle_difference(phi1, phi2) -> np.ndarray:
    """Angle (rad, in [0, pi/2]) between undirected lines of normal angles phi1, phi2."""
    return np.abs((np.asarray(phi1) - phi2 + np.pi / 2) % np.pi - np.pi / 2)


def match_units(local: Units, mapped: Units, robot_xy):
    """Eqs. 13-15: pairs with line angle < min(B1, B2), |d1 - d2| < min(l1, l2) and
    intersecting prisms (segment distance <= l1 + l2); one partner each, best |d1 - d2| first.

    Both unit sets are in the map frame; ``robot_xy`` (2,) m. Returns index arrays (S,), (S,).
    """
    if len(local) == 0 or len(mapped) == 0:
        return np.zeros(0, int), np.zeros(0, int)
    xr = np.asarray(robot_xy, float)[:2]
    angle = _line_angle_difference(local.phi[:, None], mapped.phi[None])
    ok = angle < np.minimum(local.angle_width[:, None], mapped.angle_width[None])
    dd = np.abs(robot_distance(local, xr)[:, None] - robot_distance(mapped, xr)[None])
    ok &= dd < np.minimum(local.l[:, None], mapped.l[None])
    li, gj = np.nonzero(ok)
    if len(li) == 0:
        return li, gj
    gap = _segments_distance(local.begin[li], local.end[li], mapped.begin[gj], mapped.end[gj])
    keep = gap <= local.l[li] + mapped.l[gj]
    li, gj = li[keep], gj[keep]
    order = np.argsort(dd[li, gj], kind="stable")
    li, gj = li[order], gj[order]
    _, first = np.unique(li, return_index=True)
    li, gj = li[np.sort(first)], gj[np.sort(first)]
    _, first = np.unique(gj, return_index=True)
    first = np.sort(first)
    return li[first], gj[first]
