"""Correlative scan-to-submap matching that survives a poor initial guess.

A submap becomes a :class:`ProbabilityGrid`: a likelihood field
``exp(-d^2 / 2 sigma^2)`` (d: distance in metres to the nearest cell holding
a submap point; 0 beyond 4 sigma) on a regular grid, plus max-pooled levels
for branch and bound. :func:`match` sweeps every rotation of the angular window (step ``resolution / range``,
Olson 2009, "Real-time correlative scan matching") and searches translations
by branch and bound over the pooled levels (Hess et al. 2016, "Real-time loop
closure in 2D LIDAR SLAM"), one compiled gather per level. The best cell
is then refined by point-to-line Gauss-Newton against the submap points,
whose Hessian gives the covariance.

The score is the mean likelihood of the scan points (decimated to one per
cell) at the matched pose: 1 when every point lies on a submap point, about
0.6 one cell away, 0 far from the submap.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from slam2d import geometry

__all__ = ["ProbabilityGrid", "MatchResult", "match", "voxel_filter", "angular_step"]

SIGMA_CELLS = 1.0  # std of the likelihood field, in cells
FIELD_CUTOFF_SIGMAS = 4.0  # the field is 0 beyond this many sigma from the submap (exp(-8) = 3e-4)
MAX_DEPTH = 4  # pooled levels of branch and bound; top cells are 2^depth cells wide
RANGE_PERCENTILE = 75.0  # range (percentile) for the angular step; farther points move a few cells per step
MIN_RANGE = 1.0  # m; floor of that range, so close-up scans do not get huge angular steps
NORMAL_NEIGHBOURS = 8  # submap points per normal estimate
NORMAL_RADIUS_CELLS = 3.0  # neighbourhood radius of a normal estimate, in cells
REFINE_ITERATIONS = 10  # Gauss-Newton steps at most (more only chase correspondence switches)
REFINE_MAX_DIST_CELLS = 4.0  # point-to-line correspondences farther than this are dropped
REFINE_HUBER_CELLS = 0.5  # Huber threshold on point-to-line residuals, in cells
REFINE_REVERT_SCORE = 0.02  # keep the search pose if refinement loses more score than this
REFINE_MAX_STEPS = 3.0  # ... or moves it more than this many cells or angular steps
COV_FLOOR_XY_CELLS = 0.5  # std floor added to the covariance, in cells
COV_FLOOR_THETA = np.deg2rad(0.25)  # rad; std floor added to the covariance
SIDE_NEIGHBOURS = 8  # submap points searched for one on the scan's side
SIDES = 16  # sectors of the directions a sided grid tells surfaces apart by (bits of a uint16)
SIDE_REACH = 4  # a surface counts as seen from a point's side if their sectors are at most this many apart (90 deg)


@dataclass(frozen=True, eq=False)
class MatchResult:
    """Outcome of :func:`match`.

    pose: (3,) pose of the scan in the submap frame (m, m, rad).
    score: mean likelihood in [0, 1] of the scan points at ``pose`` (on a sided
      grid too over all surfaces: the sides choose the pose, not the score).
    covariance: (3, 3) of ``pose``.
    search_score: best grid score of branch and bound, before refinement.
    evaluated: number of (rotation, translation) candidates scored.
    runner_up: best grid score more than ``ambiguity_xy`` from the search's
      best translation, when at least ``ambiguity_ratio`` times its score
      (an alternative match: a periodic or featureless place); else 0.
    rival: (3,) pose of that runner-up in the submap frame, or None.
    """

    pose: np.ndarray
    score: float
    covariance: np.ndarray
    search_score: float
    evaluated: int
    runner_up: float = 0.0
    rival: np.ndarray | None = None


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


def angular_step(points, resolution: float) -> float:
    """Rotation step (rad) that moves a point at the ``RANGE_PERCENTILE`` range by one cell of ``resolution`` m
    (the refinement after the search recovers the finer angle)."""
    r = np.hypot(points[:, 0], points[:, 1])
    far = max(float(np.percentile(r, RANGE_PERCENTILE)), MIN_RANGE) if len(r) else MIN_RANGE
    return float(np.arccos(1.0 - resolution**2 / (2.0 * far**2)))


# --------------------------------------------------------------------------- the grid


@dataclass(frozen=True, eq=False)
class _Pyramid:
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
        self.normals, self.has_normal, spread = _normals(self.tree, pts, NORMAL_RADIUS_CELLS * resolution)
        self.facing = None  # (M, 2): the side each point's surface was seen from (a sided grid)
        bits = None
        if views is not None:  # normals face the side each point was seen from
            self.normals *= np.where(np.einsum("ij,ij->i", self.normals, views) < 0, -1.0, 1.0)[:, None]
            self.facing = np.where(spread[:, None], self.normals, views)  # a lone point faces its view
            bits = np.left_shift(1, _sector(np.arctan2(self.facing[:, 1], self.facing[:, 0]))).astype(np.uint16)
        # sides: (ny, nx) uint16 of a sided grid, bit k set where a surface facing sector k is within the field's reach
        self.field, self.sides = _likelihood_field(cells, (int(ny), int(nx)), self.sigma / resolution, bits)
        self._pyramids: dict[tuple[int, int], _Pyramid] = {}

    def __repr__(self) -> str:
        ny, nx = self.field.shape
        return f"ProbabilityGrid({len(self.points)} points, {nx} x {ny} cells of {self.resolution:g} m)"

    def pyramid(self, window: int, depth: int) -> _Pyramid:
        """The padded, pooled levels for a half-window of ``window`` cells (cached)."""
        key = (window, depth)
        if key not in self._pyramids:
            self._pyramids[key] = self._build_pyramid(window, depth)
        return self._pyramids[key]

    def _build_pyramid(self, window: int, depth: int) -> _Pyramid:
        pad = 2 * window + 2 ** (depth + 1) + 2
        levels = _pooled_levels(self.field, depth, pad)
        sides = None
        if self.sides is not None:
            sides = np.zeros(levels.shape[1:], np.uint16)
            sides[pad:pad + self.sides.shape[0], pad:pad + self.sides.shape[1]] = self.sides
            sides = sides.ravel()
        return _Pyramid(
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


def _facing_bits(points: np.ndarray, thetas: np.ndarray) -> np.ndarray:
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


def _normals(tree: cKDTree, pts: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit normals (M, 2) of points from their neighbours' scatter, where they are reliable (M,),
    and where they have any (M,).

    A normal is had with at least 3 neighbours within ``radius`` (m), and reliable
    when they spread along a line (smaller scatter eigenvalue <= 10 % of the larger).
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
    return normals, (count >= 3) & (small <= 0.1 * large), count >= 3


# --------------------------------------------------------------------------- branch and bound


def _discretise(pyr: _Pyramid, points: np.ndarray, start: np.ndarray, thetas: np.ndarray) -> np.ndarray:
    """Flat cell indices (A, N) of the points rotated by each angle (A,) and moved to ``start`` (2,).

    Points that could leave the padded grid anywhere in the window are sent to
    a cell deep in the zero padding: they score 0 for every candidate.
    """
    c, s = np.cos(thetas)[:, None], np.sin(thetas)[:, None]
    x = c * points[:, 0] - s * points[:, 1] + start[0]
    y = s * points[:, 0] + c * points[:, 1] + start[1]
    col = np.floor((x - pyr.origin[0]) / pyr.resolution).astype(np.int64)
    row = np.floor((y - pyr.origin[1]) / pyr.resolution).astype(np.int64)
    w, reach = pyr.window, pyr.window + 2**pyr.depth
    ny, nx = pyr.shape
    inside = (col >= w) & (row >= w) & (col + reach < nx) & (row + reach < ny)
    return np.where(inside, row * nx + col, w * nx + w)


def _scores(level: np.ndarray, flat: np.ndarray, sides, cands: np.ndarray, width: int) -> np.ndarray:
    """Mean of ``level`` over the points of each candidate (C, 3) = (angle index, dx, dy) cells;
    with ``sides`` = (the grid's side bits, the points' facing bits (A, N)), 0 for a point whose
    cell holds no surface seen from its side."""
    if sides is None:
        return _scores_kernel(level, flat, np.ascontiguousarray(cands), width)
    return _sided_scores_kernel(level, flat, np.ascontiguousarray(cands), width, *sides)


@njit(cache=True, nogil=True)
def _scores_kernel(level, flat, cands, width):  # pragma: no cover - compiled
    n_pts = flat.shape[1]
    out = np.empty(cands.shape[0], dtype=np.float64)
    for c in range(cands.shape[0]):
        row = flat[cands[c, 0]]
        shift = cands[c, 2] * width + cands[c, 1]
        total = 0.0
        for i in range(n_pts):
            total += level[row[i] + shift]
        out[c] = total / max(n_pts, 1)
    return out


@njit(cache=True, nogil=True)
def _sided_scores_kernel(level, flat, cands, width, grid_bits, point_bits):  # pragma: no cover - compiled
    n_pts = flat.shape[1]
    out = np.empty(cands.shape[0], dtype=np.float64)
    for c in range(cands.shape[0]):
        row, facing = flat[cands[c, 0]], point_bits[cands[c, 0]]
        shift = cands[c, 2] * width + cands[c, 1]
        total = 0.0
        for i in range(n_pts):
            cell = row[i] + shift
            if grid_bits[cell] & facing[i]:
                total += level[cell]
        out[c] = total / max(n_pts, 1)
    return out


def _children(cands: np.ndarray, level: int, window: int, exclude=None) -> np.ndarray:
    """The four sub-blocks at ``level - 1`` of candidates (C, 3) at ``level``, inside the window
    and not wholly inside the ``exclude`` square (see :func:`_outside`)."""
    h = 2 ** (level - 1)
    steps = np.array([[0, 0, 0], [0, h, 0], [0, 0, h], [0, h, h]], dtype=np.int64)
    kids = (cands[:, None, :] + steps[None]).reshape(-1, 3)
    kids = kids[(kids[:, 1] <= window) & (kids[:, 2] <= window)]
    return kids[_outside(kids, h, exclude)]


def _outside(cands: np.ndarray, size: int, exclude) -> np.ndarray:
    """Mask of blocks (C, 3) of ``size`` cells not wholly inside ``exclude`` = (dx, dy, r) cells,
    the square of half-width r around (dx, dy); all True when ``exclude`` is None."""
    if exclude is None:
        return np.ones(len(cands), dtype=bool)
    bx, by, r = exclude
    inside = (
        (cands[:, 1] >= bx - r) & (cands[:, 1] + size - 1 <= bx + r)
        & (cands[:, 2] >= by - r) & (cands[:, 2] + size - 1 <= by + r)
    )  # fmt: skip
    return ~inside


def _level(pyr: _Pyramid, flat: np.ndarray, k: int, facing) -> tuple:
    """``_scores``'s level, indices and sides at level ``k``: sided at level 0 with ``facing`` bits."""
    return pyr.levels[k], flat, (pyr.sides, facing) if k == 0 and facing is not None else None


def _greedy(pyr: _Pyramid, flat: np.ndarray, cand: np.ndarray, level: int, exclude=None, facing=None):
    """Descend from ``cand`` at ``level`` to level 0 through the best child: (candidate, score, evaluated)."""
    width, evaluated, score = pyr.shape[1], 0, 0.0
    for k in range(level, 0, -1):
        kids = _children(cand[None], k, pyr.window, exclude)
        if len(kids) == 0:
            return cand, -np.inf, evaluated
        s = _scores(*_level(pyr, flat, k - 1, facing), kids, width)
        evaluated += len(kids)
        cand, score = kids[np.argmax(s)], float(s.max())
    if level == 0:
        score = float(_scores(*_level(pyr, flat, 0, facing), cand[None], width)[0])
        evaluated += 1
    return cand, score, evaluated


def _branch_and_bound(pyr: _Pyramid, flat: np.ndarray, min_score: float, exclude=None, facing=None):
    """Best (angle index, dx, dy) over all angles and the translational window, its score, evaluations.

    Level-synchronous branch and bound: every level's surviving blocks are
    scored in one gather; a block survives while its pooled upper bound beats
    the best exact score so far (found by greedy descents) and ``min_score``.
    ``exclude`` = (dx, dy, r) cells leaves out the translations within r of
    (dx, dy) (the runner-up search); with ``facing`` bits (A, N) of the points,
    level 0 counts only surfaces seen from each point's side (no more than the
    field, so the pooled levels still bound it). The score is -inf when nothing is left.
    """
    w, depth, width = pyr.window, pyr.depth, pyr.shape[1]
    offs = np.arange(-w, w + 1, 2**depth, dtype=np.int64)
    a, dx, dy = np.meshgrid(np.arange(len(flat), dtype=np.int64), offs, offs, indexing="ij")
    cands = np.column_stack([a.ravel(), dx.ravel(), dy.ravel()])
    cands = cands[_outside(cands, 2**depth, exclude)]
    bound = _scores(*_level(pyr, flat, depth, facing), cands, width)
    evaluated = len(cands)
    best, best_score = None, -np.inf
    for k in range(depth, 0, -1):
        if len(cands) == 0:
            break
        c, s, n = _greedy(pyr, flat, cands[np.argmax(bound)], k, exclude, facing)
        evaluated += n
        if s > best_score:
            best, best_score = c, s
        keep = bound > max(best_score, min_score)
        cands = _children(cands[keep], k, w, exclude)
        bound = _scores(*_level(pyr, flat, k - 1, facing), cands, width)
        evaluated += len(cands)
    if len(cands) and (best is None or bound.max() > best_score):
        best, best_score = cands[np.argmax(bound)], float(bound.max())
    return best, best_score, evaluated


# --------------------------------------------------------------------------- refinement


def _point_to_line(grid: ProbabilityGrid, points: np.ndarray, pose: np.ndarray, max_dist: float):
    """Residuals (K,), Jacobian (K, 3) w.r.t. (x, y, theta) and Huber weights (K,) at ``pose``."""
    q = geometry.transform_points(pose, points)
    d, j = grid.nearest(q, max_dist, pose[:2])
    ok = np.isfinite(d)
    ok[ok] = grid.has_normal[j[ok]]
    j, q, p = j[ok], q[ok], points[ok]
    n = grid.normals[j]
    r = np.einsum("ki,ki->k", n, q - grid.points[j])
    c, s = np.cos(pose[2]), np.sin(pose[2])
    dqx, dqy = -s * p[:, 0] - c * p[:, 1], c * p[:, 0] - s * p[:, 1]
    jac = np.column_stack([n[:, 0], n[:, 1], n[:, 0] * dqx + n[:, 1] * dqy])
    k = REFINE_HUBER_CELLS * grid.resolution
    weights = np.minimum(1.0, k / np.maximum(np.abs(r), 1e-12))
    return r, jac, weights


def _refine(grid: ProbabilityGrid, points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Gauss-Newton point-to-line refinement of ``pose`` (3,) against the submap points."""
    max_dist = REFINE_MAX_DIST_CELLS * grid.resolution
    pose = pose.copy()
    for _ in range(REFINE_ITERATIONS):
        r, jac, wgt = _point_to_line(grid, points, pose, max_dist)
        if len(r) < 3:
            break
        h = jac.T @ (wgt[:, None] * jac)
        g = jac.T @ (wgt * r)
        damping = 1e-6 * np.trace(h) + 1e-12
        step = -np.linalg.solve(h + damping * np.eye(3), g)
        pose += step
        if np.hypot(step[0], step[1]) < 1e-5 and abs(step[2]) < 1e-6:
            break
    pose[2] = geometry.wrap_angle(pose[2])
    return pose


def _covariance(grid: ProbabilityGrid, points: np.ndarray, pose: np.ndarray, window: np.ndarray) -> np.ndarray:
    """Covariance (3, 3) of ``pose`` (m^2, rad^2) from the point-to-line fit.

    (J^T W J / sigma^2 + diag(1 / window^2))^-1 plus a floor: sigma is the
    residual std (at least a tenth of a cell); the window (3,) prior (m, m, rad)
    bounds the variance along directions the scan does not constrain, as in a
    featureless corridor.
    """
    res = grid.resolution
    floor = np.diag([(COV_FLOOR_XY_CELLS * res) ** 2] * 2 + [COV_FLOOR_THETA**2])
    info = np.diag(1.0 / np.asarray(window, dtype=np.float64) ** 2)
    r, jac, wgt = _point_to_line(grid, points, pose, REFINE_MAX_DIST_CELLS * res)
    if len(r) > 3:
        sigma2 = max(float(np.sum(wgt * r**2) / (np.sum(wgt) - 3)), (0.1 * res) ** 2)
        info = info + jac.T @ (wgt[:, None] * jac) / sigma2
    cov = np.linalg.inv(info)
    return 0.5 * (cov + cov.T) + floor


# --------------------------------------------------------------------------- matching


def match(
    grid: ProbabilityGrid,
    points,
    initial,
    window_xy: float,
    window_theta: float,
    *,
    min_score: float = 0.0,
    depth: int | None = None,
    ambiguity_xy: float = 0.0,
    ambiguity_ratio: float = 0.9,
    prior_window=None,
) -> MatchResult:
    """Match scan points (N, 2) in the scan's base frame against ``grid``.

    initial: (3,) guess of the scan's pose in the submap frame; the search
    covers +-``window_xy`` m in x and y and +-``window_theta`` rad around it.
    min_score: prune blocks whose bound is below it (a faster search when the
    caller rejects lower scores anyway; the result may then be a greedy one
    below ``min_score``). depth: pooled levels (default: enough for the window,
    at most ``MAX_DEPTH``). ambiguity_xy: m; when > 0, also search for the
    runner-up outside this distance of the best (see ``MatchResult.runner_up``)
    when the best's grid score reaches ``min_score``. prior_window: (3,) m, m,
    rad bounding the covariance where the scan constrains nothing (default:
    the search window).
    """
    initial = geometry.as_pose(initial).reshape(3)
    pts = voxel_filter(points, grid.resolution)
    if len(pts) == 0:
        raise ValueError("match needs at least one finite scan point")
    found, step, search_score, evaluated, runner_up, rival = _search(
        grid, pts, initial, window_xy, window_theta, min_score, depth, ambiguity_xy, ambiguity_ratio
    )
    pose = _polish(grid, pts, found, step)
    score = grid.score(geometry.transform_points(pose, pts))  # on every surface, as a blind grid scores it
    window = [window_xy, window_xy, window_theta] if prior_window is None else prior_window
    cov = _covariance(grid, pts, pose, np.asarray(window, dtype=np.float64))
    return MatchResult(pose, score, cov, search_score, evaluated, runner_up, rival)


def _search(grid, pts, initial, window_xy, window_theta, min_score, depth, ambiguity_xy, ambiguity_ratio):
    """Branch and bound around ``initial``: best pose (3,), angular step (rad), its grid score,
    evaluations, and the runner-up score and pose (see ``match``)."""
    res = grid.resolution
    window = int(np.ceil(window_xy / res - 1e-9))
    if depth is None:
        depth = int(min(MAX_DEPTH, max(0, np.ceil(np.log2(2 * window + 1)) - 1)))
    step = angular_step(pts, res)
    n_steps = int(np.ceil(window_theta / step - 1e-9))
    thetas = initial[2] + step * np.arange(-n_steps, n_steps + 1)
    pyr = grid.pyramid(window, depth)
    flat = _discretise(pyr, pts, initial[:2], thetas)
    facing = None if pyr.sides is None else _facing_bits(pts, thetas)
    best, score, evaluated = _branch_and_bound(pyr, flat, min_score, facing=facing)

    def pose_of(cand):
        return np.array([*(initial[:2] + res * cand[1:]), geometry.wrap_angle(thetas[cand[0]])])

    runner_up, rival = 0.0, None
    if ambiguity_xy > 0 and score >= min_score:  # below min_score the caller rejects the match anyway
        floor = ambiguity_ratio * score
        exclude = (int(best[1]), int(best[2]), int(np.ceil(ambiguity_xy / res - 1e-9)))
        other, second, n = _branch_and_bound(pyr, flat, floor, exclude, facing)
        evaluated += n
        if second >= floor:
            runner_up, rival = second, pose_of(other)
    return pose_of(best), step, score, evaluated, runner_up, rival


def _polish(grid: ProbabilityGrid, pts: np.ndarray, found: np.ndarray, step: float) -> np.ndarray:
    """Refined pose; the search pose if refinement loses (exact, sided) score, or strays without
    gaining any (the search's cells and view sectors only approximate the sides: where it still
    paired a wall's two faces, refinement moves the pose by the wall's thickness)."""
    refined = _refine(grid, pts, found)
    score = grid.score(geometry.transform_points(refined, pts), refined[:2])
    found_score = grid.score(geometry.transform_points(found, pts), found[:2])
    moved = geometry.between(found, refined)
    limit = REFINE_MAX_STEPS * np.array([grid.resolution, step])
    strayed = np.hypot(moved[0], moved[1]) > limit[0] or abs(moved[2]) > limit[1]
    if (strayed and score <= found_score) or score < found_score - REFINE_REVERT_SCORE:
        return found
    return refined
