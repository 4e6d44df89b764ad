"""The submap side of correlative matching: a likelihood field and its max-pooled levels.

A submap's points become a :class:`ProbabilityGrid`: a likelihood field
``exp(-d^2 / 2 sigma^2)`` (d: distance in metres to the nearest cell holding
a submap point; 0 beyond ``FIELD_CUTOFF_SIGMAS`` sigma) on a regular grid, the
points' normals and a k-d tree over them, and, per translational window, a
:class:`Pyramid` of max-pooled levels for branch and bound (``correlative``).
A sided grid also knows the side each surface was seen from.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

__all__ = ["ProbabilityGrid", "Pyramid", "facing_bits", "scatter_normals", "voxel_filter"]

SIGMA_CELLS = 1.0  # std of the likelihood field, in cells
FIELD_CUTOFF_SIGMAS = 4.0  # the field is 0 beyond this many sigma from the submap (exp(-8) = 3e-4)
NORMAL_NEIGHBOURS = 8  # submap points per normal estimate
NORMAL_RADIUS_CELLS = 3.0  # neighbourhood radius of a normal estimate, in cells
SIDE_NEIGHBOURS = 8  # submap points searched for one on the scan's side
SIDES = 16  # sectors of the directions a sided grid tells surfaces apart by (bits of a uint16)
SIDE_REACH = 4  # a surface counts as seen from a point's side if their sectors are at most this many apart (90 deg)


def voxel_filter(points, cell: float) -> np.ndarray:
    """One point (the first) per ``cell`` x ``cell`` square (m) of finite points (M, 2)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    return pts[_voxel_first(pts, cell)]


def _voxel_first(pts: np.ndarray, cell: float, group=None) -> np.ndarray:
    """Indices, in order, of the first finite point of (M, 2) per ``cell`` square (m) and ``group`` (M,) in 0..3."""
    finite = np.flatnonzero(np.isfinite(pts).all(axis=1))
    if len(finite) == 0:
        return finite
    ij = np.floor(pts[finite] / cell).astype(np.int64)
    ij -= ij.min(axis=0)
    key = ij[:, 0] * (ij[:, 1].max() + 1) + ij[:, 1]
    if group is not None:
        key = key * 4 + np.asarray(group, dtype=np.int64)[finite]
    _, first = np.unique(key, return_index=True)
    return finite[np.sort(first)]


@dataclass(frozen=True, eq=False)
class Pyramid:
    """Zero-padded likelihood field and its max-pooled levels, flattened.

    ``levels[k][r * width + c]`` is the maximum of the padded field over rows
    [r, r + 2^k) and columns [c, c + 2^k). ``origin`` (2,) is the corner (m) of
    cell (0, 0); ``window`` the translational half-window in cells it is padded for.
    """

    levels: list[np.ndarray]
    sides: np.ndarray | None  # a sided grid's ``sides`` padded like level 0, flattened
    origin: np.ndarray
    shape: tuple[int, int]
    resolution: float
    window: int
    depth: int


class ProbabilityGrid:
    """Likelihood field of submap points (M, 2) in the submap frame (m).

    resolution: cell size (m); sigma: field std (m), default one cell.
    Keeps the points (voxel-filtered at half a cell), a k-d tree over them
    and their normals for refinement and scoring.

    views: optional unit vectors (M, 2) from each point towards the place it was
    seen from. With them the normals face that side, and the search, the
    refinement, the covariance (and ``score`` given an origin) pair a scan point
    only with surfaces seen from the scan's side: the two faces of a thick wall,
    one in the submap and one in the scan, would otherwise match a wall's
    thickness off. Points seen from different quadrants keep one point each per voxel.
    """

    def __init__(self, points, resolution: float = 0.05, sigma: float | None = None, views=None):
        if not resolution > 0:
            raise ValueError(f"resolution must be > 0 m, got {resolution}")
        points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if views is not None:
            views = np.asarray(views, dtype=np.float64).reshape(-1, 2)
            if len(views) != len(points):
                raise ValueError(f"views must be (M, 2) like the points, got {views.shape} for {points.shape}")
            quadrant = (views[:, 0] < 0).astype(np.int64) * 2 + (views[:, 1] < 0)
            keep = _voxel_first(points, resolution / 2, quadrant)
            views = views[keep]
        else:
            keep = _voxel_first(points, resolution / 2)
        pts = points[keep]
        if len(pts) == 0:
            raise ValueError("a probability grid needs at least one finite submap point")
        self.resolution = float(resolution)
        self.sigma = float(sigma if sigma is not None else SIGMA_CELLS * resolution)
        margin = 3.0 * self.sigma + resolution
        self.origin = pts.min(axis=0) - margin
        cells = np.floor((pts - self.origin) / resolution).astype(np.int64)
        nx, ny = np.floor((pts.max(axis=0) + margin - self.origin) / resolution).astype(np.int64) + 1
        self.points = pts
        self.tree = cKDTree(pts)
        self.normals, self.has_normal, spread = scatter_normals(self.tree, pts, NORMAL_RADIUS_CELLS * resolution)
        self.facing = None  # (M, 2): the side each point's surface was seen from (a sided grid)
        bits = None
        if views is not None:  # normals face the side each point was seen from
            self.normals *= np.where(np.einsum("ij,ij->i", self.normals, views) < 0, -1.0, 1.0)[:, None]
            self.facing = np.where(spread[:, None], self.normals, views)  # a lone point faces its view
            bits = np.left_shift(1, _sector(np.arctan2(self.facing[:, 1], self.facing[:, 0]))).astype(np.uint16)
        # sides: (ny, nx) uint16 of a sided grid, bit k set where a surface facing sector k is within the field's reach
        self.field, self.sides = _likelihood_field(cells, (int(ny), int(nx)), self.sigma / resolution, bits)
        self._pyramids: dict[tuple[int, int], Pyramid] = {}

    def __repr__(self) -> str:
        ny, nx = self.field.shape
        return f"ProbabilityGrid({len(self.points)} points, {nx} x {ny} cells of {self.resolution:g} m)"

    def pyramid(self, window: int, depth: int) -> Pyramid:
        """The padded, pooled levels for a half-window of ``window`` cells (cached)."""
        key = (window, depth)
        if key not in self._pyramids:
            self._pyramids[key] = self._build_pyramid(window, depth)
        return self._pyramids[key]

    def _build_pyramid(self, window: int, depth: int) -> Pyramid:
        pad = 2 * window + 2 ** (depth + 1) + 2
        levels = _pooled_levels(self.field, depth, pad)
        sides = None
        if self.sides is not None:
            sides = np.zeros(levels.shape[1:], np.uint16)
            sides[pad:pad + self.sides.shape[0], pad:pad + self.sides.shape[1]] = self.sides
            sides = sides.ravel()
        return Pyramid(
            levels=[lv.ravel() for lv in levels],
            sides=sides,
            origin=self.origin - pad * self.resolution,
            shape=levels.shape[1:],
            resolution=self.resolution,
            window=window,
            depth=depth,
        )

    def score(self, points_in_submap, origin=None) -> float:
        """Mean likelihood in [0, 1] of points (N, 2) given in the submap frame (exact distances);
        with ``origin`` (2,), where they were seen from, of a sided grid: surfaces on their side only."""
        pts = np.asarray(points_in_submap, dtype=np.float64).reshape(-1, 2)
        if len(pts) == 0:
            return 0.0
        d, _ = self.nearest(pts, 5.0 * self.sigma, origin)
        return float(np.mean(np.exp(-0.5 * (np.minimum(d, 1e3) / self.sigma) ** 2)))

    def nearest(self, pts: np.ndarray, max_dist: float, origin=None) -> tuple[np.ndarray, np.ndarray]:
        """Distance (N,) (m; inf beyond ``max_dist``) and index (N,) of each point's nearest submap
        point; with ``origin`` (2,) on a sided grid, the nearest whose surface faces ``origin``'s side."""
        if origin is None or self.facing is None:
            return self.tree.query(pts, distance_upper_bound=max_dist)
        k = min(SIDE_NEIGHBOURS, len(self.points))
        d, j = self.tree.query(pts, k=k, distance_upper_bound=max_dist)
        d, j = d.reshape(len(pts), k), j.reshape(len(pts), k)
        found = np.isfinite(d)
        jj = np.minimum(j, len(self.points) - 1)
        facing = np.einsum("nkc,nkc->nk", self.facing[jj], (np.asarray(origin, dtype=np.float64) - pts)[:, None, :])
        other_side = found & (facing < 0)
        d = np.where(other_side, np.inf, d)
        first = np.argmin(d, axis=1)
        rows = np.arange(len(pts))
        return d[rows, first], j[rows, first]


@njit(cache=True, nogil=True)
def _pooled_levels(field, depth, pad):  # pragma: no cover - compiled
    """Levels 0..depth (depth + 1, ny + 2 pad, nx + 2 pad) of ``field`` (ny, nx) zero-padded by ``pad``
    cells: level k holds each cell's max over the 2^k x 2^k cells from it (clipped at the far edges).

    Only the field and the 2^depth cells around it are pooled (farther cells stay 0);
    ``pad`` >= 2^depth.
    """
    ny, nx = field.shape
    reach = 2**depth
    out = np.zeros((depth + 1, ny + 2 * pad, nx + 2 * pad), np.float32)
    out[0, pad:pad + ny, pad:pad + nx] = field
    lo, hgt, wid = pad - reach, ny + 2 * reach, nx + 2 * reach
    rows = np.empty((hgt, wid), np.float32)
    for k in range(1, depth + 1):
        h = 2 ** (k - 1)
        src = out[k - 1, lo:lo + hgt, lo:lo + wid]
        dst = out[k, lo:lo + hgt, lo:lo + wid]
        for i in range(hgt):
            for j in range(wid):
                rows[i, j] = max(src[i, j], src[i, j + h]) if j + h < wid else src[i, j]
        for i in range(hgt):
            for j in range(wid):
                dst[i, j] = max(rows[i, j], rows[i + h, j]) if i + h < hgt else rows[i, j]
    return out


def _sector(angle) -> np.ndarray:
    """Sector (int64) of directions ``angle`` (rad) among ``SIDES``, sector k centred on k * 360 / SIDES deg."""
    return np.floor(np.mod(np.asarray(angle) + np.pi / SIDES, 2 * np.pi) / (2 * np.pi / SIDES)).astype(np.int64) % SIDES


def facing_bits(points: np.ndarray, thetas: np.ndarray) -> np.ndarray:
    """Bits (A, N) uint16 of the surface sectors seen from each point's side: points (N, 2) seen
    from the origin, rotated by each angle (A,); a surface is on the point's side when its normal's
    sector is within ``SIDE_REACH`` of the sector of the point's view (the direction back to the
    origin). Never a surface seen from the other side (normal and view more than 90 deg apart)
    unless the two are within 22.5 deg of perpendicular."""
    s = _sector(np.arctan2(-points[:, 1], -points[:, 0])[None] + np.asarray(thetas)[:, None])
    table = np.zeros(SIDES, np.uint16)
    for d in range(-SIDE_REACH, SIDE_REACH + 1):
        table |= np.left_shift(1, (np.arange(SIDES) + d) % SIDES).astype(np.uint16)
    return table[s]


def _likelihood_field(cells: np.ndarray, shape: tuple[int, int], sigma_cells: float, bits=None):
    """exp(-d^2 / 2 sigma^2) on a grid of ``shape`` (d: distance to the nearest occupied cell
    ``cells`` (M, 2) = (col, row)), cut to 0 beyond ``FIELD_CUTOFF_SIGMAS`` sigma; and with ``bits``
    (M,) uint16 of the cells' points, the grid of the bits OR-ed over the field's reach of each
    (else None)."""
    r = int(np.ceil(FIELD_CUTOFF_SIGMAS * sigma_cells))
    off = np.arange(-r, r + 1)
    d2 = (off[:, None] ** 2 + off[None, :] ** 2) / sigma_cells**2
    kernel = np.where(d2 <= FIELD_CUTOFF_SIGMAS**2, np.exp(-0.5 * d2), 0.0).astype(np.float32)
    flat = cells[:, 1] * shape[1] + cells[:, 0]
    if bits is None:
        flat, cell_bits = np.unique(flat), np.zeros(0, np.uint16)
    else:  # one entry per cell, its points' bits OR-ed
        order = np.argsort(flat, kind="stable")
        flat, first = np.unique(flat[order], return_index=True)
        cell_bits = np.bitwise_or.reduceat(np.asarray(bits, np.uint16)[order], first)
    field, sides = _splat_max(flat // shape[1], flat % shape[1], shape[0], shape[1], kernel, cell_bits)
    return field, (sides if bits is not None else None)


@njit(cache=True, nogil=True)
def _splat_max(rows, cols, ny, nx, kernel, bits):  # pragma: no cover - compiled
    """Grid (ny, nx) holding, per cell, the max of ``kernel`` centred on each (row, col), and with
    ``bits`` (P,) (else empty) the grid of the bits OR-ed over each kernel's support (else 0 x 0)."""
    field = np.zeros((ny, nx), dtype=np.float32)
    sided = bits.shape[0] > 0
    sy, sx = (ny, nx) if sided else (0, 0)
    sides = np.zeros((sy, sx), dtype=np.uint16)
    r = kernel.shape[0] // 2
    for p in range(len(rows)):
        for dy in range(-r, r + 1):
            y = rows[p] + dy
            if y < 0 or y >= ny:
                continue
            for dx in range(-r, r + 1):
                x = cols[p] + dx
                if 0 <= x < nx:
                    k = kernel[dy + r, dx + r]
                    if k > field[y, x]:
                        field[y, x] = k
                    if sided and k > 0:
                        sides[y, x] |= bits[p]
    return field, sides


def scatter_normals(tree: cKDTree, pts: np.ndarray, radius: float,
                    flatness: float = 0.1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit normals (M, 2) of points from their neighbours' scatter, where they are reliable (M,),
    and where they have any (M,).

    A normal is had with at least 3 of the ``NORMAL_NEIGHBOURS`` nearest within ``radius`` (m), and
    reliable when they spread along a line (smaller scatter eigenvalue <= ``flatness`` times the larger).
    """
    k = min(NORMAL_NEIGHBOURS, len(pts))
    d, j = tree.query(pts, k=k, distance_upper_bound=radius)
    d, j = d.reshape(len(pts), k), j.reshape(len(pts), k)
    ok = np.isfinite(d)
    count = ok.sum(axis=1)
    nb = pts[np.minimum(j, len(pts) - 1)]
    mean = (nb * ok[..., None]).sum(axis=1) / np.maximum(count, 1)[:, None]
    dx, dy = ((nb - mean[:, None]) * ok[..., None]).transpose(2, 0, 1)
    sxx, syy, sxy = (dx * dx).sum(1), (dy * dy).sum(1), (dx * dy).sum(1)
    along = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)  # direction of the larger eigenvalue
    half_gap = np.hypot(0.5 * (sxx - syy), sxy)
    small, large = 0.5 * (sxx + syy) - half_gap, 0.5 * (sxx + syy) + half_gap
    normals = np.column_stack([-np.sin(along), np.cos(along)])
    return normals, (count >= 3) & (small <= flatness * large), count >= 3
