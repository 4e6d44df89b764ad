"""Basic geometric units and vertex landmarks of one scan (Chen & Zhang 2006, sections 4.2 and 4.3.1).

Units are fuzzy triangular prisms around orthogonal least-squares lines (eqs. 2-3); two joined
units give a vertex at the intersection of their lines (eqs. 4-5). Lines are in normal form
``cos(phi) x + sin(phi) y = rho``; lengths in metres, angles in radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slam2d import geometry
from slam2d.types import Scan

__all__ = ["FUZZY_SCALE", "Units", "Vertices", "scan_points", "fit_units", "half_width", "robot_distance",
           "line_intersection", "vertex_from_slopes", "extract_vertices"]

FUZZY_SCALE = 1.0 / (1.0 - np.exp(-0.5))  # eq. 3: triangle half-width per Gaussian std (~2.54)


def scan_points(scan: Scan, min_range: float, max_range: float):
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


def robot_distance(units: Units, robot_xy) -> np.ndarray:
    """Eq. 16: distance (m) from the robot to each unit's line."""
    return np.abs(np.cos(units.phi) * robot_xy[0] + np.sin(units.phi) * robot_xy[1] - units.rho)


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
