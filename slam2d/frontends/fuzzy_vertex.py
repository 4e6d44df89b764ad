"""Fuzzy geometric units and vertex landmarks (Chen & Zhang, 2006).

Chen Dongyue, Zhang Liming, "Fuzzy geometric maps and vertex self-localization
for SLAM", Control Theory & Applications 23(5), 2006. Each scan goes through:

1. Twice classification (section 4.1): a coarse pass in beam order starts a
   new set where a point cannot join the current *collinear set* (every point
   within ``xi`` of the least-squares line through the others); a fine pass
   moves the tail point of Q_i to Q_{i+1} while that lowers its line distance.
2. Basic geometric units (section 4.2, eqs. 2-3): ``G = {begin, end, line, l, n}``
   with the orthogonal least-squares line, the end points projected on it and
   the half-width ``l = sqrt(mse + delta_a^2) / (1 - e^-0.5)``.
3. Vertex landmarks (section 4.3.1, eqs. 4-5): two joined units (end of G_i
   within ``sigma`` of the start of G_{i+1}) give ``M = {o, R, m}`` with ``o``
   the intersection of their lines, ``R = min(l_i, l_{i+1})``, ``m = 1``.
4. Matching and offset (eqs. 6, 9): vertices match when
   ``d(o, o') <= min(R, R')``; the paper's offset is ``V* = sum m (o - o') / sum m``
   (heading from a compass). Without a compass the pose is a weighted 2D
   Kabsch fit (weights ``m``) on >= 2 vertices, translation only on one.
5. Map update (eqs. 10-12 for vertices, 13-21 for units).

Lines are kept in normal form ``n . p = rho`` with ``n = (cos phi, sin phi)``
instead of the paper's slope-intercept ``y = a x + b`` (which fails on
vertical walls); :func:`vertex_from_slopes` is eq. 4 verbatim. Two errata are
read as intended: eq. 21 is ``d12 = (n1 l2 d1 + n2 l1 d2) / (n1 l2 + n2 l1)``
and eq. 20 (as printed it subtracts the distances themselves) is the
n-weighted analogue of eq. 11, ``l12 = (n1 l1 + n2 l2) / (n1 + n2) - |d1 - d2| / 2``.

Additions to the paper, each a config option (``FuzzyVertexFrontend.Config``):
a gap cut in the classification (``max_gap``); a minimum size of a unit; a
minimum angle between a vertex's lines, which must cross near the junction;
the directions of a vertex's two walls (arms), checked on matches and used as
a heading measurement (``arm_heading``); the directions of all units matched
to the unit map by eqs. 13-15 as a heading measurement too, also when no
vertex matched (``wall_heading``; the translation then stays the odometry's
and the scan still counts as a fallback); the heading error's displacement at
each unit added to ``delta_a`` (``heading_lever``); a floor and a cap on
``R`` (eq. 11 only shrinks it); a rigidity check on the matched set; the
odometry prediction fused with the vertex fit by information
(``odometry_prior``), with fits too far from it rejected (``max_mahalanobis``);
the pruning of vertices seen only once; and an online calibration of the
odometry heading (curvature bias and turn scale) from the accepted fits
(``calibration``, see ``odometry.HeadingCalibration``). With ``heading="translation"``,
``arm_heading``, ``wall_heading``, ``odometry_prior``, ``rigid_check``,
``calibration`` and the gates off, the frontend is the paper's method as printed.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numba import njit
from pydantic import Field

from slam2d import geometry
from slam2d.config import Section
from slam2d.frontends.base import FrontendResult, register_frontend
from slam2d.frontends.common import (
    MaxCorrectionThetaDeg,
    MaxCorrectionXY,
    MaxRange,
    MinRange,
    MinSigmaThetaDeg,
    MinSigmaXY,
    cap_information,
    local_information,
)
from slam2d.frontends.odometry import HeadingCalibration
from slam2d.types import LandmarkObservation, Scan

__all__ = [
    "FUZZY_SCALE",
    "Units",
    "Vertices",
    "FuzzyVertexFrontend",
    "twice_classification",
    "coarse_classification",
    "fine_classification",
    "fit_units",
    "half_width",
    "line_intersection",
    "vertex_from_slopes",
    "extract_vertices",
    "match_vertices",
    "rigid_matches",
    "translation_offset",
    "fit_se2",
    "update_vertices",
    "match_units",
    "fuse_units",
]

FUZZY_SCALE = 1.0 / (1.0 - np.exp(-0.5))  # eq. 3: triangle half-width per Gaussian std (~2.54)


# --------------------------------------------------------------------------- twice classification


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


# --------------------------------------------------------------------------- units


@dataclass(frozen=True, eq=False)
class Units:
    """Basic geometric units (K of them), each a fuzzy triangular prism.

    begin, end: (K, 2) end points projected on the line, m.
    phi, rho: (K,) line ``cos(phi) x + sin(phi) y = rho`` (rad, m).
    l: (K,) half-width (zero membership), m.  n: (K,) number of points.
    mse: (K,) mean squared distance of the points to the line, m^2.
    """

    begin: np.ndarray
    end: np.ndarray
    phi: np.ndarray
    rho: np.ndarray
    l: np.ndarray  # noqa: E741  (the paper's name)
    n: np.ndarray
    mse: np.ndarray

    FIELDS = ("begin", "end", "phi", "rho", "l", "n", "mse")

    def __len__(self) -> int:
        return len(self.phi)

    @property
    def length(self) -> np.ndarray:
        """(K,) m."""
        return np.linalg.norm(self.end - self.begin, axis=1)

    @property
    def mid(self) -> np.ndarray:
        """(K, 2) m."""
        return 0.5 * (self.begin + self.end)

    @property
    def direction_sd(self) -> np.ndarray:
        """(K,) rad: std of the fitted direction, sqrt(12 mse / n) / length."""
        return np.sqrt(12.0 * self.mse / self.n) / np.maximum(self.length, 1e-9)

    @property
    def angle_width(self) -> np.ndarray:
        """(K,) rad: B, the half-width of the direction fuzzy set, atan(2 l / length)."""
        return np.arctan2(2.0 * self.l, self.length)

    def slope_intercept(self) -> tuple[np.ndarray, np.ndarray]:
        """The paper's (a, b) of ``y = a x + b`` (inf for vertical lines)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.sin(self.phi)
            return -np.cos(self.phi) / s, self.rho / s

    def transformed(self, pose) -> Units:
        """The units mapped from the frame of ``pose`` (3,) to its parent frame."""
        pose = geometry.as_pose(pose)
        phi = geometry.wrap_angle(self.phi + pose[2])
        rho = self.rho + np.cos(phi) * pose[0] + np.sin(phi) * pose[1]
        tp = geometry.transform_points
        return Units(tp(pose, self.begin), tp(pose, self.end), phi, rho, self.l.copy(), self.n.copy(), self.mse.copy())

    def select(self, idx) -> Units:
        return Units(*(getattr(self, f)[idx] for f in self.FIELDS))

    def concat(self, other: Units) -> Units:
        return Units(*(np.concatenate([getattr(self, f), getattr(other, f)]) for f in self.FIELDS))

    @staticmethod
    def empty() -> Units:
        z = np.zeros(0)
        return Units(np.zeros((0, 2)), np.zeros((0, 2)), z, z.copy(), z.copy(), z.copy(), z.copy())


def half_width(residuals, delta_a: float) -> float:
    """Eq. 3: l = sqrt(sum d_i^2 / n + delta_a^2) / (1 - e^-0.5), m.

    ``residuals`` are the distances (m) of the unit's points to its line,
    ``delta_a`` the mean dead-reckoning position error (m).
    """
    d = np.asarray(residuals, dtype=np.float64)
    return float(FUZZY_SCALE * np.sqrt(np.mean(d**2) + delta_a**2))


def _set_lines(xy: np.ndarray, starts: np.ndarray, sizes: np.ndarray):
    """Orthogonal least-squares lines (phi, rho) of consecutive point sets (eq. 2), vectorised."""
    sums = np.add.reduceat(np.column_stack([xy, xy**2, xy[:, 0] * xy[:, 1]]), starts, axis=0)
    mean = sums[:, :2] / sizes[:, None]
    cxx = sums[:, 2] / sizes - mean[:, 0] ** 2
    cyy = sums[:, 3] / sizes - mean[:, 1] ** 2
    cxy = sums[:, 4] / sizes - mean[:, 0] * mean[:, 1]
    t = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy)
    phi = t + np.pi / 2
    rho = np.cos(phi) * mean[:, 0] + np.sin(phi) * mean[:, 1]
    flip = rho < 0  # normals point away from the origin (the robot)
    return geometry.wrap_angle(np.where(flip, phi + np.pi, phi)), np.abs(rho)


def fit_units(
    points, bounds, delta_a: float = 0.0, min_points: int = 2, min_length: float = 0.0, heading_error: float = 0.0
) -> Units:
    """Units of the point sets ``points[bounds[k]:bounds[k+1]]`` with >= ``min_points`` points.

    ``delta_a`` (m) enters the half-width (eq. 3); with an uncertain heading
    (``heading_error``, rad) the displacement it causes at the unit's middle
    is added to ``delta_a`` in quadrature (0 with a compass, as in the paper).
    Units shorter than ``min_length`` (m) are dropped. Order follows the sets (beam order).
    """
    xy = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    bounds = np.asarray(bounds, dtype=np.int64)
    sizes = np.diff(bounds)
    keep = sizes >= max(min_points, 2)
    if not keep.any():
        return Units.empty()
    pts = xy[bounds[0] : bounds[-1]][np.repeat(keep, sizes)]
    sizes = sizes[keep]
    local_starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    phi, rho = _set_lines(pts, local_starts, sizes)
    normal = np.column_stack([np.cos(phi), np.sin(phi)])
    label = np.repeat(np.arange(len(sizes)), sizes)
    d = np.einsum("pi,pi->p", pts, normal[label]) - rho[label]
    mse = np.add.reduceat(d**2, local_starts) / sizes
    first, last = pts[local_starts], pts[local_starts + sizes - 1]
    begin = first - (np.einsum("ki,ki->k", first, normal) - rho)[:, None] * normal
    end = last - (np.einsum("ki,ki->k", last, normal) - rho)[:, None] * normal
    lever = heading_error * np.linalg.norm(0.5 * (begin + end), axis=1)
    l = FUZZY_SCALE * np.sqrt(mse + delta_a**2 + lever**2)  # noqa: E741  (eq. 3)
    units = Units(begin, end, phi, rho, l, sizes.astype(np.float64), mse)
    return units.select(units.length >= min_length)


# --------------------------------------------------------------------------- vertices


@dataclass(frozen=True, eq=False)
class Vertices:
    """Vertex landmarks (V of them), conoid fuzzy sets ``M = {o, R, m}``.

    o: (V, 2) centre, m.  R: (V,) base radius, m.  m: (V,) times seen.
    arms: (V, 2) directions (rad) of the two walls leaving the vertex.
    arm_sd: (V,) std (rad) of the arm directions, the larger of the two units'.
    """

    o: np.ndarray
    R: np.ndarray
    m: np.ndarray
    arms: np.ndarray
    arm_sd: np.ndarray

    FIELDS = ("o", "R", "m", "arms", "arm_sd")

    def __len__(self) -> int:
        return len(self.R)

    def transformed(self, pose) -> Vertices:
        """The vertices mapped from the frame of ``pose`` (3,) to its parent frame."""
        pose = geometry.as_pose(pose)
        o = geometry.transform_points(pose, self.o)
        return Vertices(o, self.R.copy(), self.m.copy(), geometry.wrap_angle(self.arms + pose[2]), self.arm_sd.copy())

    def select(self, idx) -> Vertices:
        return Vertices(*(getattr(self, f)[idx] for f in self.FIELDS))

    def concat(self, other: Vertices) -> Vertices:
        return Vertices(*(np.concatenate([getattr(self, f), getattr(other, f)]) for f in self.FIELDS))

    @staticmethod
    def empty() -> Vertices:
        return Vertices(np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros((0, 2)), np.zeros(0))


def line_intersection(phi1, rho1, phi2, rho2) -> np.ndarray:
    """Intersections (..., 2) of lines ``cos(phi) x + sin(phi) y = rho``; NaN where parallel."""
    det = np.sin(np.asarray(phi2) - phi1)
    with np.errstate(divide="ignore", invalid="ignore"):
        x = (rho1 * np.sin(phi2) - rho2 * np.sin(phi1)) / det
        y = (rho2 * np.cos(phi1) - rho1 * np.cos(phi2)) / det
    return np.stack([x, y], -1)


def vertex_from_slopes(a1, b1, a2, b2) -> np.ndarray:
    """Eq. 4: intersection of ``y = a1 x + b1`` and ``y = a2 x + b2``."""
    return np.array([(b2 - b1) / (a1 - a2), (a1 * b2 - a2 * b1) / (a1 - a2)])


def _arm_angles(units: Units, idx, o: np.ndarray) -> np.ndarray:
    """Direction (rad) along unit ``idx``'s line from ``o`` towards the unit's middle."""
    phi = units.phi[idx]
    t = np.column_stack([-np.sin(phi), np.cos(phi)])
    sign = np.where(np.einsum("ki,ki->k", t, units.mid[idx] - o) < 0, -1.0, 1.0)
    return np.arctan2(sign * t[:, 1], sign * t[:, 0])


def extract_vertices(units: Units, sigma: float, min_angle: float = 0.0, circular: bool = False) -> Vertices:
    """Vertices of consecutive joined units (eqs. 4-5).

    Units i, i+1 are joined when ``|end_i - begin_{i+1}| <= sigma`` (m). The
    vertex is kept when the lines cross at >= ``min_angle`` (rad) and within
    ``sigma`` of the junction's midpoint. ``circular``: the last unit is
    followed by the first (full-turn scans).
    """
    k = len(units)
    if k < 2:
        return Vertices.empty()
    i = np.arange(k if circular and k > 2 else k - 1)
    j = (i + 1) % k
    junction = 0.5 * (units.end[i] + units.begin[j])
    joined = np.linalg.norm(units.end[i] - units.begin[j], axis=1) <= sigma
    crossing = np.abs(np.sin(units.phi[j] - units.phi[i])) >= np.sin(min_angle)
    o = line_intersection(units.phi[i], units.rho[i], units.phi[j], units.rho[j])
    near = np.linalg.norm(np.nan_to_num(o - junction, nan=np.inf), axis=1) <= sigma
    ok = joined & crossing & near
    i, j, o = i[ok], j[ok], o[ok]
    arms = np.column_stack([_arm_angles(units, i, o), _arm_angles(units, j, o)])
    b = np.maximum(units.direction_sd[i], units.direction_sd[j])
    return Vertices(o, np.minimum(units.l[i], units.l[j]), np.ones(len(i)), arms, b)


# --------------------------------------------------------------------------- matching and the offset


def _arm_differences(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Arm directions a - b (rad, (P, 2)) of vertex pairs, with b's arms in the order that fits best."""
    same = geometry.wrap_angle(a - b)
    swapped = geometry.wrap_angle(a - b[:, ::-1])
    better = np.abs(swapped).max(axis=1) < np.abs(same).max(axis=1)
    return np.where(better[:, None], swapped, same)


def _arm_error(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Largest arm-direction difference (rad) of vertex pairs (P, 2) x (P, 2), either arm order."""
    return np.abs(_arm_differences(a, b)).max(axis=1)


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


def update_vertices(o, R, m, o_new, R_new, min_radius: float = 0.0):
    """Eqs. 10-12 for matched pairs: o <- (m o + o'') / (m + 1),
    R <- (R + R'' - d(o, o'')) / 2 (floored at ``min_radius``), m <- m + 1."""
    o, o_new = np.asarray(o, float), np.asarray(o_new, float)
    m = np.asarray(m, float)
    d = np.linalg.norm(o - o_new, axis=-1)
    o_out = (m[..., None] * o + o_new) / (m[..., None] + 1.0)
    r_out = np.maximum((np.asarray(R, float) + R_new - d) / 2.0, min_radius)
    return o_out, r_out, m + 1.0


# --------------------------------------------------------------------------- unit matching and fusion


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


def _robot_distance(units: Units, robot_xy) -> np.ndarray:
    """Eq. 16: distance (m) from the robot to each unit's line."""
    return np.abs(np.cos(units.phi) * robot_xy[0] + np.sin(units.phi) * robot_xy[1] - units.rho)


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
    dd = np.abs(_robot_distance(local, xr)[:, None] - _robot_distance(mapped, xr)[None])
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
    d1, d2 = _robot_distance(u1, xr), _robot_distance(u2, xr)
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


# --------------------------------------------------------------------------- global maps


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
        turn = _arm_differences(obs.arms, arms)
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


# --------------------------------------------------------------------------- the frontend


@register_frontend("fuzzy_vertex")
class FuzzyVertexFrontend:
    """Vertex self-localisation on a fuzzy geometric map (Chen & Zhang 2006).

    The frontend keeps the base pose in its own map frame, a global vertex
    map (stable ids) and a global unit map. Each scan's vertices are matched
    to the map from the odometry prediction, the pose is fitted, and the maps
    are updated at the fitted pose. The returned delta is the fitted motion
    since the previous scan; with no vertex matched it is the odometry delta
    (counted in ``events``).
    """

    class Config(Section):
        """Parameters; defaults suit 180-beam 1-degree SICK logs and the simulator."""

        min_range: MinRange = 0.1
        max_range: MaxRange = 30.0
        xi: float = Field(0.05, gt=0, description="m; collinearity tolerance (definition 1)")
        xi_range: float = Field(0.01, ge=0, description="xi added per metre of range (range-proportional noise)")
        max_gap: float | None = Field(0.5, gt=0, description="m; a farther point starts a new set (None: off)")
        max_gap_range: float = Field(0.1, ge=0, description="gap allowance added per metre of range")
        min_unit_points: int = Field(3, ge=2, description="points of a unit")
        min_unit_length: float = Field(0.15, ge=0, description="m; shorter units are dropped")
        sigma: float = Field(0.5, gt=0, description="m; end of G_i to start of G_i+1 for a vertex")
        min_vertex_angle_deg: float = Field(30.0, ge=0, lt=90, description="min angle between a vertex's two lines")
        max_arm_error_deg: float | None = Field(30.0, gt=0, description="matched vertices' walls differ less")
        dead_reckoning_error: float = Field(0.02, gt=0, description="m; delta_a of eq. 3 per scan, at rest")
        dead_reckoning_rel: float = Field(0.1, ge=0, description="delta_a added per metre travelled in the step")
        heading_error_deg: float = Field(0.5, gt=0, description="odometry heading std per scan, at rest")
        heading_rel: float = Field(0.1, ge=0, description="heading std added per radian turned in the step")
        heading_lever: bool = Field(True, description="add the heading error's displacement at each unit to delta_a")
        min_radius: float = Field(0.1, gt=0, description="m; floor of R (eq. 11) and of fused half-widths (eq. 20)")
        max_radius: float = Field(1.0, gt=0, description="m; cap of a new vertex's R")
        heading: Literal["se2", "translation"] = Field(
            "se2", description="se2: weighted Kabsch (>= 2 vertices); translation: eq. 9, heading from odometry/compass"
        )
        arm_heading: bool = Field(True, description="matched vertices' wall directions also measure the heading")
        wall_heading: bool = Field(True, description="units matched to the unit map (eqs. 13-15) measure the heading")
        min_arm_sd_deg: float = Field(1.5, gt=0, description="floor of a wall direction's std")
        odometry_prior: bool = Field(True, description="fuse the vertex fit with the odometry prediction")
        iterations: int = Field(2, ge=1, description="match-and-fit rounds per scan")
        min_matches: int = Field(1, ge=1, description="fewer matched vertices -> odometry fallback")
        rigid_check: bool = Field(True, description="drop matches whose mutual distances disagree between scan and map")
        max_mahalanobis: float | None = Field(
            4.0, gt=0, description="reject a vertex fit this many stds from the odometry prediction (None: off)"
        )
        max_correction_xy: MaxCorrectionXY = 1.0
        max_correction_theta_deg: MaxCorrectionThetaDeg = 15.0
        prune_after: int | None = Field(50, ge=1, description="scans after which a vertex seen once is dropped")
        unit_map: bool = Field(True, description="keep the fused global unit map (eqs. 13-21)")
        min_sigma_xy: MinSigmaXY = 0.005
        min_sigma_theta_deg: MinSigmaThetaDeg = 0.1
        calibration: HeadingCalibration.Config = HeadingCalibration.Config()

    def __init__(self, config: Config | None = None):
        self.config = cfg = config or self.Config()
        self.calibration = HeadingCalibration(cfg.calibration)
        self.pose = np.zeros(3)
        self.vertices = VertexMap()
        self.units = UnitMap(cfg.min_radius)
        self.events: Counter[str] = Counter()
        self.matched_counts: list[int] = []
        self._step = -1

    # ------------------------------------------------------------------ public

    def process(self, scan: Scan, odom_delta: np.ndarray) -> FrontendResult:
        """Localise ``scan`` on the vertex map; ``odom_delta`` (3,) is the base motion since the last scan."""
        cfg = self.config
        self._step += 1
        odom_delta = self.calibration.correct(odom_delta)
        pred = geometry.compose(self.pose, odom_delta)
        delta_a = cfg.dead_reckoning_error + cfg.dead_reckoning_rel * float(np.hypot(*odom_delta[:2]))
        sigma_theta = np.deg2rad(cfg.heading_error_deg) + cfg.heading_rel * abs(float(odom_delta[2]))
        prior = np.diag([delta_a**-2, delta_a**-2, sigma_theta**-2])
        units, local = self.extract(scan, delta_a, sigma_theta if cfg.heading_lever else 0.0)
        if self._step == 0:
            return self._accept(pred, odom_delta, units, local, None, prior)
        walls = self._wall_heading(units, pred) if cfg.wall_heading else None
        pose, info, pairs, gate = self._localise(pred, local, prior, walls)
        if pairs is None:
            self.events["too few vertices matched"] += 1
            if walls is not None:  # odometry translation, heading from the matched walls
                pose, info = _combine(pred, [walls, (pred, prior)])
                if self._diverged(pose, pred, _mahalanobis2(walls[0], pred, walls[1], prior)) is None:
                    return self._accept(pose, odom_delta, units, local, None, info)
            return self._accept(pred, odom_delta, units, local, None, prior)
        reason = self._diverged(pose, pred, gate)
        if reason:
            self.events[reason] += 1
            return self._accept(pred, odom_delta, units, local, None, prior)
        self.calibration.observe(pose, pred)
        return self._accept(pose, odom_delta, units, local, pairs, info)

    def extract(self, scan: Scan, delta_a: float = 0.0, heading_error: float = 0.0) -> tuple[Units, Vertices]:
        """Units and vertices of ``scan`` in the robot base frame (``delta_a`` m, ``heading_error`` rad)."""
        cfg = self.config
        points, ranges, circular = _scan_points(scan, cfg.min_range, cfg.max_range)
        if len(points) < 2:
            return Units.empty(), Vertices.empty()
        gap = None if cfg.max_gap is None else cfg.max_gap + cfg.max_gap_range * ranges
        bounds, _ = twice_classification(points, cfg.xi + cfg.xi_range * ranges, gap)
        units = fit_units(points, bounds, delta_a, cfg.min_unit_points, cfg.min_unit_length, heading_error)
        v = extract_vertices(units, cfg.sigma, np.deg2rad(cfg.min_vertex_angle_deg), circular)
        arm_sd = np.maximum(v.arm_sd, np.deg2rad(cfg.min_arm_sd_deg))
        return units, Vertices(v.o, np.clip(v.R, cfg.min_radius, cfg.max_radius), v.m, v.arms, arm_sd)

    # ------------------------------------------------------------------ steps

    def _wall_heading(self, units: Units, pred):
        """Heading estimate (pose, information) from units matched to the unit map (eqs. 13-15), or None."""
        if len(units) == 0 or len(self.units) == 0:
            return None
        world = units.transformed(pred)
        li, gj = self.units.match(world, pred)
        if len(li) == 0:
            return None
        mapped = self.units.units.select(gj)
        turn = (mapped.phi - world.phi[li] + np.pi / 2) % np.pi - np.pi / 2
        floor = np.deg2rad(self.config.min_arm_sd_deg)
        w = 1.0 / (np.maximum(world.direction_sd[li], floor) ** 2 + np.maximum(mapped.direction_sd, floor) ** 2)
        heading = pred[2] + (w * turn).sum() / w.sum()
        return np.array([pred[0], pred[1], heading]), np.diag([0.0, 0.0, w.sum()])

    def _localise(self, pred, local: Vertices, prior, walls=None):
        """Match and fit ``iterations`` times.

        Returns the pose, its information, the pairs (local idx, map idx) or
        None, and the squared Mahalanobis distance of the vertex fit from the
        odometry prediction.
        """
        cfg = self.config
        if len(local) == 0 or len(self.vertices) == 0:
            return pred, prior, None, 0.0
        reach = float(np.linalg.norm(local.o, axis=1).max()) + cfg.max_radius + cfg.max_correction_xy
        near = self.vertices.near(pred[:2], reach)
        mapped = self.vertices.v.select(near)
        arm_tol = None if cfg.max_arm_error_deg is None else np.deg2rad(cfg.max_arm_error_deg)
        pose, info, pairs, gate = pred, prior, None, 0.0
        for _ in range(cfg.iterations):
            li, gj = match_vertices(local.transformed(pose), mapped, arm_tol)
            if cfg.rigid_check:
                keep = rigid_matches(local.o[li], mapped.o[gj], local.R[li], mapped.m[gj])
                li, gj = li[keep], gj[keep]
            if len(li) < cfg.min_matches:
                pairs = None
                break
            pairs = (li, near[gj])
            pose, info, gate = self._fit(pred, prior, local.select(li), mapped.select(gj), walls)
        return pose, info, pairs, gate

    def _fit(self, pred, prior, local: Vertices, mapped: Vertices, walls=None):
        """Map pose (3,) and its information (3, 3, map frame) from matched vertex pairs.

        The vertex fit (eq. 9, or weighted Kabsch) and, optionally, the wall
        directions and the odometry prior are combined as independent
        estimates, each weighted by its information.
        """
        cfg = self.config
        p, q, m = local.o, mapped.o, mapped.m
        sd = np.minimum(local.R, mapped.R) / FUZZY_SCALE
        w = 1.0 / (sd**2 * (1.0 + 1.0 / m))
        if cfg.heading == "se2" and len(p) >= 2 and np.ptp(p, axis=0).max() > 0:
            fit = fit_se2(p, q, m)
            info = _vertex_information(fit, p, w, rotation=True)
        else:
            v = translation_offset(q, geometry.transform_points(pred, p), m)
            fit = np.array([pred[0] + v[0], pred[1] + v[1], pred[2]])
            info = _vertex_information(fit, p, w, rotation=False)
        estimates = [(fit, info)]
        if cfg.arm_heading:
            turn = _arm_differences(mapped.arms, local.arms + pred[2])  # (S, 2)
            w_arm = 1.0 / (local.arm_sd**2 * (1.0 + 1.0 / m))
            heading = pred[2] + (w_arm[:, None] * turn).sum() / (2.0 * w_arm.sum())
            estimates.append((np.array([pred[0], pred[1], heading]), np.diag([0.0, 0.0, 2.0 * w_arm.sum()])))
        if walls is not None:
            estimates.append(walls)
        fit, fit_info = _combine(pred, estimates)
        gate = _mahalanobis2(fit, pred, fit_info, prior)
        if cfg.odometry_prior:
            return *_combine(pred, [(fit, fit_info), (pred, prior)]), gate
        if fit_info[2, 2] == 0:  # translation only: the heading is the odometry's (or the compass')
            fit_info = fit_info + np.diag([0.0, 0.0, prior[2, 2]])
        return fit, fit_info, gate

    def _diverged(self, pose, pred, gate: float) -> str | None:
        cfg = self.config
        if cfg.max_mahalanobis is not None and gate > cfg.max_mahalanobis**2:
            return "vertex fit inconsistent with odometry"
        if np.hypot(*(pose[:2] - pred[:2])) > cfg.max_correction_xy:
            return "translation correction too large"
        if abs(geometry.wrap_angle(pose[2] - pred[2])) > np.deg2rad(cfg.max_correction_theta_deg):
            return "rotation correction too large"
        return None

    def _accept(self, pose, odom_delta, units: Units, local: Vertices, pairs, info_world) -> FrontendResult:
        """Update the maps at ``pose`` and return the delta from the previous pose."""
        cfg = self.config
        world = local.transformed(pose)
        li = np.zeros(0, int) if pairs is None else pairs[0]
        landmarks: tuple[LandmarkObservation, ...] = ()
        if pairs is not None:
            self.vertices.update(pairs[1], world.select(li), self._step, cfg.min_radius)
            landmarks = _observations(local.select(li), self.vertices.ids[pairs[1]])
        self.vertices.add(world.select(np.setdiff1d(np.arange(len(local)), li)), self._step)
        if cfg.prune_after is not None:
            self.vertices.prune(self._step, cfg.prune_after)
        if cfg.unit_map and len(units):
            self.units.integrate(units.transformed(pose), pose)
        delta = geometry.between(self.pose, pose) if self._step else np.asarray(odom_delta, float).copy()
        self.pose = pose
        matched = len(li)
        self.matched_counts.append(matched)
        info = cap_information(local_information(info_world, pose[2]), cfg.min_sigma_xy,
                               np.deg2rad(cfg.min_sigma_theta_deg))
        return FrontendResult(delta=delta, information=info, confidence=matched / (matched + 1.0), landmarks=landmarks)


# --------------------------------------------------------------------------- helpers


def _scan_points(scan: Scan, min_range: float, max_range: float):
    """Hit points (M, 2) in the base frame in beam order, their ranges (M,), and whether the scan is a full turn.

    A full-turn scan is rotated to start after its widest gap.
    """
    rr = scan.ranges[scan.hit_mask(min_range, max_range)]
    pts = scan.points_in_base(min_range, max_range)
    n = len(scan.angles)
    circular = n > 1 and (scan.angles[-1] - scan.angles[0]) * n / (n - 1) >= 2 * np.pi - 1e-6
    if circular and len(pts) > 2:
        gaps = np.linalg.norm(pts - np.roll(pts, 1, axis=0), axis=1)
        k = int(np.argmax(gaps))
        pts, rr = np.roll(pts, -k, axis=0), np.roll(rr, -k)
    return pts, rr, circular


def _vertex_information(pose, p, w, rotation: bool) -> np.ndarray:
    """Information (3, 3) of a map-frame pose (x, y, theta) from vertices p (S, 2) in the base frame.

    Each vertex gives the residual pose * p - map vertex with isotropic weight w (1/m^2).
    """
    info = np.zeros((3, 3))
    info[0, 0] = info[1, 1] = w.sum()
    if rotation:
        rp = p @ geometry.rotation(pose[2]).T
        lever = np.column_stack([-rp[:, 1], rp[:, 0]])  # d(R p)/d theta
        info[:2, 2] = info[2, :2] = (w[:, None] * lever).sum(0)
        info[2, 2] = (w * (lever**2).sum(1)).sum()
    return info


def _combine(pred, estimates) -> tuple[np.ndarray, np.ndarray]:
    """Information-weighted mean of pose estimates [(pose, info)] in the tangent space at ``pred``."""
    total = sum(info for _, info in estimates)
    rhs = sum(info @ _difference(x, pred) for x, info in estimates)
    step = np.linalg.lstsq(total, rhs, rcond=None)[0]
    return np.array([pred[0] + step[0], pred[1] + step[1], geometry.wrap_angle(pred[2] + step[2])]), total


def _difference(a, b) -> np.ndarray:
    """a - b for poses (3,), the angle wrapped."""
    return np.array([a[0] - b[0], a[1] - b[1], geometry.wrap_angle(a[2] - b[2])])


def _mahalanobis2(fit, pred, fit_info, prior) -> float:
    """Squared Mahalanobis distance of ``fit`` from ``pred``: e^T (I_f^-1 + I_p^-1)^-1 e, I_f may be singular."""
    e = _difference(fit, pred)
    s_inv = fit_info @ np.linalg.solve(fit_info + prior, prior)
    return float(e @ s_inv @ e)


def _observations(local: Vertices, ids) -> tuple[LandmarkObservation, ...]:
    """Range-bearing observations (base frame) of matched vertices; covariance from R, isotropic
    in the plane, in (bearing, range) order (rad^2, m^2)."""
    o = local.o
    rng = np.linalg.norm(o, axis=1)
    bearing = np.arctan2(o[:, 1], o[:, 0])
    sd = local.R / FUZZY_SCALE
    return tuple(
        LandmarkObservation(int(i), float(r), float(b), np.diag([(s / max(r, 1e-3)) ** 2, s**2]))
        for i, r, b, s in zip(ids, rng, bearing, sd)
        if r > 1e-3
    )
