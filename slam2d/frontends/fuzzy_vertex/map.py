"""The global vertex and unit maps and their updates (Chen & Zhang 2006, eqs. 10-12 and 17-21).

Everything is in the map frame; lengths in metres, angles in radians.
"""

from __future__ import annotations

import numpy as np

from slam2d import geometry
from slam2d.frontends.fuzzy_vertex.extraction import Units, Vertices, robot_distance
from slam2d.frontends.fuzzy_vertex.matching import arm_differences, match_units

__all__ = ["update_vertices", "fuse_units", "VertexMap", "UnitMap"]


def update_vertices(o, R, m, o_new, R_new, min_radius: float = 0.0):
    """Eqs. 10-12 for matched pairs: o <- (m o + o'') / (m + 1),
    R <- (R + R'' - d(o, o'')) / 2 (floored at ``min_radius``), m <- m + 1."""
    o, o_new = np.asarray(o, float), np.asarray(o_new, float)
    m = np.asarray(m, float)
    d = np.linalg.norm(o - o_new, axis=-1)
    o_out = (m[..., None] * o + o_new) / (m[..., None] + 1.0)
    r_out = np.maximum((np.asarray(R, float) + R_new - d) / 2.0, min_radius)
    return o_out, r_out, m + 1.0


def fuse_units(u1: Units, u2: Units, robot_xy, min_width: float = 0.0) -> Units:
    """Eqs. 17-21: fuse matched units u1[k] with u2[k] (same length, map frame) seen from ``robot_xy``.

    n12 = n1 + n2; direction and robot distance are weighted means (weights
    n1 B2, n2 B1 and n1 l2, n2 l1); l12 = (n1 l1 + n2 l2) / (n1 + n2) - |d1 - d2| / 2
    (floored at ``min_width``); the end points are the outermost projections
    of the four end points on the fused line.
    """
    xr = np.asarray(robot_xy, float)[:2]
    n1, n2, l1, l2 = u1.n, u2.n, u1.l, u2.l
    b1, b2 = u1.angle_width, u2.angle_width
    d1, d2 = robot_distance(u1, xr), robot_distance(u2, xr)
    # eq. 18 on directions modulo pi (the paper's arctan a)
    dphi = (u2.phi - u1.phi + np.pi / 2) % np.pi - np.pi / 2
    w1, w2 = n1 * b2, n2 * b1
    phi = u1.phi + w2 * dphi / np.maximum(w1 + w2, 1e-18)
    d12 = (n1 * l2 * d1 + n2 * l1 * d2) / np.maximum(n1 * l2 + n2 * l1, 1e-18)  # eq. 21
    normal = np.column_stack([np.cos(phi), np.sin(phi)])
    side = np.sign(np.einsum("ki,ki->k", normal, u1.mid - xr))
    side = np.where(side == 0, 1.0, side)
    normal *= side[:, None]
    phi = np.arctan2(normal[:, 1], normal[:, 0])
    rho = normal @ xr + d12  # eq. 19: the fused line at distance d12 from the robot
    l12 = np.maximum((n1 * l1 + n2 * l2) / (n1 + n2) - np.abs(d1 - d2) / 2.0, min_width)  # eq. 20
    t = np.column_stack([-normal[:, 1], normal[:, 0]])
    ends = np.stack([u1.begin, u1.end, u2.begin, u2.end], 1)  # (K, 4, 2)
    s = np.einsum("kpi,ki->kp", ends, t)
    base = rho[:, None] * normal
    begin = base + s.min(1)[:, None] * t
    end = base + s.max(1)[:, None] * t
    # keep the first unit's orientation (begin -> end)
    flip = np.einsum("ki,ki->k", end - begin, u1.end - u1.begin) < 0
    begin, end = np.where(flip[:, None], end, begin), np.where(flip[:, None], begin, end)
    mse = (n1 * u1.mse + n2 * u2.mse) / (n1 + n2)
    return Units(begin, end, phi, rho, l12, n1 + n2, mse)


class VertexMap:
    """Global vertices with stable ids; never-reobserved ones are pruned."""

    def __init__(self) -> None:
        self.v = Vertices.empty()
        self.ids = np.zeros(0, np.int64)
        self.last_seen = np.zeros(0, np.int64)
        self.next_id = 0

    def __len__(self) -> int:
        return len(self.ids)

    def near(self, xy, radius: float) -> np.ndarray:
        """Indices of vertices within ``radius`` m of ``xy``."""
        return np.flatnonzero(np.linalg.norm(self.v.o - xy, axis=1) <= radius)

    def update(self, idx, obs: Vertices, step: int, min_radius: float) -> None:
        """Eqs. 10-12 on vertices ``idx`` with observations ``obs`` (map frame); arms averaged too."""
        v = self.v
        o, r, m = update_vertices(v.o[idx], v.R[idx], v.m[idx], obs.o, obs.R, min_radius)
        arms = v.arms[idx]
        turn = arm_differences(obs.arms, arms)
        v.arms[idx] = geometry.wrap_angle(arms + turn / (v.m[idx][:, None] + 1.0))
        v.o[idx], v.R[idx], v.m[idx] = o, r, m
        self.last_seen[idx] = step

    def add(self, obs: Vertices, step: int) -> np.ndarray:
        """Append ``obs`` (map frame); returns their new ids."""
        ids = np.arange(self.next_id, self.next_id + len(obs))
        self.next_id += len(obs)
        self.v = self.v.concat(obs)
        self.ids = np.concatenate([self.ids, ids])
        self.last_seen = np.concatenate([self.last_seen, np.full(len(obs), step)])
        return ids

    def prune(self, step: int, after: int) -> None:
        """Drop vertices seen once and not again within ``after`` scans."""
        keep = (self.v.m > 1) | (step - self.last_seen <= after)
        if keep.all():
            return
        self.v = self.v.select(keep)
        self.ids, self.last_seen = self.ids[keep], self.last_seen[keep]


class UnitMap:
    """Global units in the map frame, matched and fused by eqs. 13-21."""

    def __init__(self, min_width: float = 0.0) -> None:
        self.units = Units.empty()
        self.min_width = min_width

    def __len__(self) -> int:
        return len(self.units)

    def match(self, local: Units, robot_xy) -> tuple[np.ndarray, np.ndarray]:
        """Matches (local idx, map idx) of ``local`` (map frame) seen from ``robot_xy`` (eqs. 13-15)."""
        u = self.units
        if len(local) == 0 or len(u) == 0:
            return np.zeros(0, int), np.zeros(0, int)
        ends = np.concatenate([local.begin, local.end])
        lo, hi = ends.min(0) - local.l.max(), ends.max(0) + local.l.max()
        inside = (np.maximum(u.begin, u.end) >= lo).all(1) & (np.minimum(u.begin, u.end) <= hi).all(1)
        near = np.flatnonzero(inside)  # map units whose box meets the scan's
        li, gk = match_units(local, u.select(near), robot_xy)
        return li, near[gk]

    def integrate(self, local: Units, robot_xy) -> tuple[np.ndarray, np.ndarray]:
        """Fuse ``local`` (map frame) into the map; returns the matched (local, map) index pairs."""
        u = self.units
        li, gj = self.match(local, robot_xy)
        if len(li):
            fused = fuse_units(local.select(li), u.select(gj), robot_xy, self.min_width)
            for name in Units.FIELDS:
                getattr(u, name)[gj] = getattr(fused, name)
        rest = np.setdiff1d(np.arange(len(local)), li)
        if len(rest):
            self.units = u.concat(local.select(rest))
        return li, gj
