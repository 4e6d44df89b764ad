"""Grid operations shared by the explorers: cell states of an occupancy grid, geodesic distances,
information gain by ray casting, the three-ray straight-line test and point-in-polygon.

Cells are (row, col) with rows along y, as :class:`~slam2d.types.GridFrame`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from slam2d.exploration.paths import Paths
from slam2d.planning.grid import PlanningGrid, refresh_clearance
from slam2d.segmentation.observations import dda_start, dda_step, raycast_grid

FREE, OCCUPIED, UNKNOWN = 0, 1, 2


@dataclass(eq=False)
class GridView:
    """One snapshot of a map for a decision: ``state`` (H, W) int8 (FREE / OCCUPIED / UNKNOWN),
    ``resolution`` m/cell, ``origin`` (x, y) m of cell (0, 0)'s corner; ``clearance`` (H, W) cells from
    each cell centre to the nearest occupied one (outside the grid counts as occupied), capped at
    ``clearance_cap`` cells, if known (else computed when first needed)."""

    state: np.ndarray
    resolution: float
    origin: tuple[float, float]
    clearance: np.ndarray | None = None
    clearance_cap: float = np.inf

    @classmethod
    def of(cls, grid, free_thresh: float = 0.196, occupied_thresh: float = 0.65) -> GridView:
        """The view of an :class:`~slam2d.mapping.occupancy.OccupancyGrid`."""
        state = np.full(grid.shape, UNKNOWN, dtype=np.int8)
        state[grid.free_mask(free_thresh)] = FREE
        state[grid.occupied_mask(occupied_thresh)] = OCCUPIED
        return cls(state, grid.resolution, grid.origin)

    @property
    def shape(self) -> tuple[int, int]:
        return self.state.shape

    def to_cell(self, xy) -> np.ndarray:
        """Integer (row, col) cells (..., 2) of points (..., 2) m."""
        xy = np.asarray(xy, dtype=np.float64)
        o = np.asarray(self.origin)
        return np.floor((xy[..., ::-1] - o[::-1]) / self.resolution).astype(np.int64)

    def to_world(self, cells) -> np.ndarray:
        """Centres (x, y) m (..., 2) of (row, col) cells (..., 2)."""
        rc = np.asarray(cells, dtype=np.float64)
        return (rc[..., ::-1] + 0.5) * self.resolution + np.asarray(self.origin)

    def inside(self, cells) -> np.ndarray:
        rc = np.asarray(cells)
        h, w = self.shape
        return (rc[..., 0] >= 0) & (rc[..., 0] < h) & (rc[..., 1] >= 0) & (rc[..., 1] < w)

    def traversable(self, radius: float) -> np.ndarray:
        """Known-free cells farther than ``radius`` m from every occupied cell (H, W) bool."""
        cells = radius / self.resolution
        if self.clearance is None or cells >= self.clearance_cap:
            self.clearance, self.clearance_cap = _clearance_cells(self.state != OCCUPIED), np.inf
        return (self.clearance > cells) & (self.state == FREE)

    def roomy(self, radius: float) -> np.ndarray:
        """Known-free cells farther than ``radius`` m from every cell not known free (H, W) bool: where a disc of
        that radius fits on what has been seen."""
        known = self.state == FREE
        return known & (_clearance_cells(known) > radius / self.resolution)


def _clearance_cells(free: np.ndarray) -> np.ndarray:
    return PlanningGrid(free, 1.0, (0.0, 0.0)).clearance()  # in cells: a grid of 1-unit cells


class LiveClearance:
    """The clearance of successive views of one map being built, capped at ``cap`` m: refreshed only
    near the cells whose occupancy changed since the last view (all of it when the grid's frame changed)."""

    def __init__(self, cap: float):
        self.cap = cap
        self._frame = self._occupied = self._clear = None

    def attach(self, view: GridView) -> GridView:
        """``view`` with its ``clearance`` set (a copy of its own)."""
        occupied = view.state == OCCUPIED
        cap = self.cap / view.resolution
        frame = view.shape, view.resolution, tuple(view.origin)
        if frame == self._frame:
            refresh_clearance(self._clear, ~occupied, occupied != self._occupied, 1.0, cap)
        else:
            self._clear = np.minimum(_clearance_cells(~occupied), cap)
        self._frame, self._occupied = frame, occupied
        view.clearance, view.clearance_cap = self._clear.copy(), cap
        return view


# --------------------------------------------------------------------------- geodesic distance


def geodesic(passable: np.ndarray, start_cell, resolution: float, snap_cells: int = 10) -> np.ndarray:
    """Shortest 8-connected path length (m) from ``start_cell`` to every cell over ``passable`` (H, W)
    (no corner cutting); inf where unreachable. A start outside ``passable`` is moved to the nearest
    passable cell within ``snap_cells`` (the rest of that distance added). :class:`~slam2d.exploration.paths.Paths`
    computes only as far as asked."""
    return Paths(passable, start_cell, resolution, snap_cells).dense()


# --------------------------------------------------------------------------- information gain


@njit(cache=True)
def _ray_start(gx, gy, b, n_rays):
    """Ray ``b`` of ``n_rays`` evenly spread from (gx, gy) grid units: its cell (col, row) and traversal state."""
    a = 2.0 * np.pi * b / n_rays
    step_c, step_r, inv_x, inv_y, tmx, tmy = dda_start(gx, gy, np.cos(a), np.sin(a))
    return int(np.floor(gx)), int(np.floor(gy)), step_c, step_r, inv_x, inv_y, tmx, tmy


AIM_ALL_ABOVE = 2  # a point with more unknown cells than this many per ray in its buckets casts every ray instead


@njit(cache=True)
def _buckets(cells, shape, size):
    """``cells`` (K, 2) (row, col) sorted by square buckets of ``size`` cells (row-major), with ``starts``
    (B + 1,): bucket b holds sorted cells starts[b] to starts[b + 1]; and the buckets per row."""
    nbr, nbc = shape[0] // size + 1, shape[1] // size + 1
    key = np.empty(cells.shape[0], dtype=np.int64)
    for k in range(cells.shape[0]):
        key[k] = min(max(cells[k, 0] // size, 0), nbr - 1) * nbc + min(max(cells[k, 1] // size, 0), nbc - 1)
    order = np.argsort(key, kind="mergesort")
    starts = np.zeros(nbr * nbc + 1, dtype=np.int64)
    for k in range(cells.shape[0]):
        starts[key[k] + 1] += 1
    starts = np.cumsum(starts)
    return cells[order], starts, nbc


@njit(cache=True)
def _aim(gx, gy, shape, cells, starts, size, nbc, max_t, need):
    """Set ``need`` (R,) bool for the rays from (gx, gy) grid units that may count a cell within ``max_t``: those
    whose angle lies in the angular span of one of the unknown ``cells`` (``_buckets`` of ``size``: sorted cells,
    ``starts``, ``nbc``) within reach (a ray that enters a cell crosses its square; a cell two or more cells away
    is spanned by the circle round its corners, a little wider), or of a stretch of the grid's edge (of
    ``shape``) within reach (steps beyond it count); all of them from inside an unknown cell, or when more than
    AIM_ALL_ABOVE cells a ray lie in the buckets round the point. The others meet only free cells before an
    occupied one."""
    need[:] = False
    scale = need.shape[0] / (2.0 * np.pi)
    reach = max_t + 1.0
    for side in range(4):  # the edges at x = 0, x = W, y = 0, y = H: the direction to each, the distance
        mid, d = np.pi, gx
        if side == 1:
            mid, d = 0.0, shape[1] - gx
        elif side == 2:
            mid, d = -0.5 * np.pi, gy
        elif side == 3:
            mid, d = 0.5 * np.pi, shape[0] - gy
        if d <= 0.0:
            need[:] = True
            return
        if d < reach:  # the edge's stretch within reach: seen under 2 atan(half its length / d)
            _span(need, mid, -np.arctan2(np.sqrt(reach * reach - d * d), d), scale)
    nbr = (starts.shape[0] - 1) // nbc
    r0, r1 = max(int((gy - reach) // size), 0), min(int((gy + reach) // size), nbr - 1)
    c0, c1 = max(int((gx - reach) // size), 0), min(int((gx + reach) // size), nbc - 1)
    if c0 > c1:
        return
    near = 0
    for br in range(r0, r1 + 1):
        near += starts[br * nbc + c1 + 1] - starts[br * nbc + c0]
    if near > AIM_ALL_ABOVE * need.shape[0]:  # aiming would cost more than casting every ray
        need[:] = True
        return
    for br in range(r0, r1 + 1):
        for k in range(starts[br * nbc + c0], starts[br * nbc + c1 + 1]):
            cx, cy = cells[k, 1] + 0.5 - gx, cells[k, 0] + 0.5 - gy
            d2 = cx * cx + cy * cy
            if d2 > reach * reach:
                continue
            mid = np.arctan2(cy, cx)
            if d2 >= 2.0:  # tan(asin(r / d)) of the corners' circle (r = 0.7071 cells) bounds its half-angle above
                _span(need, mid, -0.70711 / np.sqrt(d2 - 0.5), scale)
                continue
            if abs(cx) <= 0.501 and abs(cy) <= 0.501:
                need[:] = True
                return
            lo = 0.0
            for corner in range(4):
                d = np.arctan2(cy + (corner // 2) - 0.5, cx + (corner % 2) - 0.5) - mid
                lo = min(lo, -abs((d + np.pi) % (2.0 * np.pi) - np.pi))
            _span(need, mid, lo, scale)


@njit(cache=True)
def _span(need, mid, lo, scale):
    """Set the rays of ``need`` (R,) whose angle (ray b at 2 pi b / R) lies within ``mid`` ± |``lo``| rad."""
    n = need.shape[0]
    for b in range(int(np.ceil((mid + lo) * scale - 1e-6)), int(np.floor((mid - lo) * scale + 1e-6)) + 1):
        need[b % n] = True


@njit(cache=True)
def _aim_point(state, gx, gy, n_rays, max_t, cells, starts, size, nbc, need):
    """``need`` for the point (gx, gy): every ray from inside an unknown cell, else ``_aim``'s."""
    c, r = int(np.floor(gx)), int(np.floor(gy))
    if 0 <= r < state.shape[0] and 0 <= c < state.shape[1] and state[r, c] == 2:
        need[:] = True
    else:
        _aim(gx, gy, state.shape, cells, starts, size, nbc, max_t, need)


@njit(cache=True)
def _trace(state, gx, gy, n_rays, max_t, need, mark, token, seers, ev, n_ev):
    """The rays ``need`` marks from (gx, gy), through free and unknown cells until an occupied one: the unknown
    cells not yet marked ``token`` (and steps beyond the map) they meet, counted and marked, and added to ``seers``
    (H, W) when it is a grid. When ``ev`` is not empty, each of them is written to it from ``n_ev`` in the order
    met (the flat index of a cell, -1 for a step beyond the map; ``ev`` has room for ``_steps_at_most``). Returns
    (count, n_ev)."""
    h, w = state.shape
    shared = seers.shape[0] > 1
    record = ev.shape[0] > 0
    total = 0.0
    for b in range(n_rays):
        if not need[b]:
            continue
        c, r, step_c, step_r, inv_x, inv_y, tmx, tmy = _ray_start(gx, gy, b, n_rays)
        t = 0.0
        while t < max_t:
            if r < 0 or c < 0 or r >= h or c >= w:
                total += 1.0  # beyond the map: unknown, no other point's
                if record:
                    ev[n_ev] = -1
                    n_ev += 1
            else:
                s = state[r, c]
                if s == 1:
                    break
                if s == 2 and mark[r, c] != token:
                    mark[r, c] = token
                    total += 1.0
                    if shared:
                        seers[r, c] += 1
                    if record:
                        ev[n_ev] = r * w + c
                        n_ev += 1
            t, tmx, tmy, c, r = dda_step(tmx, tmy, inv_x, inv_y, c, r, step_c, step_r)
    return total, n_ev


@njit(cache=True)
def _cast(state, gxy, n_rays, max_t, rounds, unknown, aimed):
    """Rays from each point (P, 2) grid units through free and unknown cells until an occupied one: ``own`` (P,)
    unknown cells in sight (steps beyond the map counted as unknown), the ``mark`` (H, W) of the last point seeing
    each cell (1-based), and with ``rounds`` = 2 the ``shares`` (P,): a cell seen from k of the points is 1/k (summed
    over what each point's rays met, in the order met). With ``aimed``, only the rays ``_aim_point`` finds aimed at
    one of the ``unknown`` cells (K, 2) (at least the entry cells of unknown space) are cast (the same counts)."""
    h, w = state.shape
    n = gxy.shape[0]
    mark = np.zeros((h, w), dtype=np.int32)
    shared = rounds > 1
    seers = np.zeros((h if shared else 1, w if shared else 1), dtype=np.int32)  # points seeing each cell
    own, shares = np.zeros(n), np.zeros(n)
    need = np.ones(n_rays, dtype=np.bool_)
    size = int(np.ceil(max_t + 1.0))
    cells, starts, nbc = _buckets(unknown, state.shape, size)
    most = n_rays * (2 * int(np.ceil(max_t)) + 4)  # steps of a point's rays at most (two a cell of length, and one)
    ev, n_ev = np.empty(most if shared else 0, dtype=np.int64), 0  # what each point's rays met, in order
    first = np.zeros(n + 1, dtype=np.int64)
    for p in range(n):
        if aimed:
            _aim_point(state, gxy[p, 0], gxy[p, 1], n_rays, max_t, cells, starts, size, nbc, need)
        if shared and n_ev + most > ev.shape[0]:  # room for this point's steps
            grown = np.empty(2 * ev.shape[0], dtype=np.int64)
            grown[:n_ev] = ev[:n_ev]
            ev = grown
        own[p], n_ev = _trace(state, gxy[p, 0], gxy[p, 1], n_rays, max_t, need, mark, p + 1, seers, ev, n_ev)
        first[p + 1] = n_ev
    if shared:  # each cell a point sees shared among the points seeing it
        flat = seers.ravel()
        for p in range(n):
            total = 0.0
            for k in range(first[p], first[p + 1]):
                total += 1.0 if ev[k] < 0 else 1.0 / flat[ev[k]]
            shares[p] = total
    return own, shares, mark


@njit(cache=True)
def _first_seeing(state, gxy, n_rays, max_t, unknown, floor, gains):
    """The first point (P, 2) grid units in order whose ``_cast`` gain is at least ``floor``, or -1; ``gains`` (P,)
    NaN where not counted yet, filled in for the points counted up to it (always aimed)."""
    mark = np.zeros(state.shape, dtype=np.int32)
    seers, nothing = np.zeros((1, 1), dtype=np.int32), np.empty(0, dtype=np.int64)
    need = np.ones(n_rays, dtype=np.bool_)
    size = int(np.ceil(max_t + 1.0))
    cells, starts, nbc = _buckets(unknown, state.shape, size)
    for p in range(gxy.shape[0]):
        if np.isnan(gains[p]):
            _aim_point(state, gxy[p, 0], gxy[p, 1], n_rays, max_t, cells, starts, size, nbc, need)
            gains[p] = _trace(state, gxy[p, 0], gxy[p, 1], n_rays, max_t, need, mark, p + 1, seers, nothing, 0)[0]
        if gains[p] >= floor:
            return p
    return -1


def unknown_cells(view: GridView) -> np.ndarray:
    """The UNKNOWN cells (K, 2) (row, col) of ``view`` a ray enters unknown space by, in raster order: those with a
    FREE 4-neighbour (a ray steps from cell to 4-neighbour and stops at an occupied one, so one that reaches an
    unknown cell from outside the unknown came from a free cell next to it); for :func:`information_gain` called
    on the view many times."""
    return cells_of(entry_mask(view.state))


def cells_of(mask: np.ndarray) -> np.ndarray:
    """``np.argwhere`` of an (H, W) mask: its set cells (K, 2) (row, col) in raster order (a flat listing: 2-D
    ``argwhere`` costs ~25 × more a cell)."""
    return np.column_stack(np.divmod(np.flatnonzero(mask), mask.shape[1]))


def entry_mask(state: np.ndarray) -> np.ndarray:
    """The cells (H, W) bool of :func:`unknown_cells`: UNKNOWN with a FREE 4-neighbour (a function of the cells
    within one of each, for :class:`~slam2d.exploration.pockets.LocalRefresh`)."""
    return _entry_mask(np.ascontiguousarray(state))


@njit(cache=True)
def _entry_mask(state):
    h, w = state.shape
    out = np.zeros((h, w), dtype=np.bool_)
    for r in range(h):
        for c in range(w):
            out[r, c] = state[r, c] == 2 and ((r > 0 and state[r - 1, c] == 0) or (r < h - 1 and state[r + 1, c] == 0)
                                              or (c > 0 and state[r, c - 1] == 0) or (c < w - 1 and state[r, c + 1] == 0))
    return out


def _rays(view: GridView, points, max_range: float, rays: int, rounds: int, unknown=None):
    gxy = _grid_units(view, points)
    return _cast(np.ascontiguousarray(view.state), gxy, int(rays), float(max_range) / view.resolution, rounds,
                 _cells_near(view, gxy, max_range, unknown), True)  # fmt: skip


def _grid_units(view: GridView, points) -> np.ndarray:
    """Points (P, 2) m as (x, y) grid units of ``view``."""
    xy = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    return np.ascontiguousarray((xy - np.asarray(view.origin)) / view.resolution)


def _cells_near(view: GridView, gxy, max_range: float, unknown=None) -> np.ndarray:
    """The ``unknown_cells`` (``unknown`` if known) within the rays' reach of the box round the points (P, 2)
    grid units: the only ones rays can be aimed at."""
    cells = unknown_cells(view) if unknown is None else unknown
    if len(gxy):
        reach = float(max_range) / view.resolution + 2.0
        lo, hi = gxy.min(axis=0)[::-1] - reach, gxy.max(axis=0)[::-1] + reach
        cells = cells[np.all((cells >= lo) & (cells <= hi), axis=1)]
    return np.ascontiguousarray(cells, dtype=np.int64).reshape(-1, 2)


def information_gain(view: GridView, points, max_range: float, rays: int = 180, unknown=None) -> np.ndarray:
    """Unknown cells (P,) visible from each point (P, 2) m within ``max_range`` m: ``rays`` rays cast
    (Amanatides–Woo) through free and unknown cells until an occupied one; ``unknown``: the view's
    ``unknown_cells`` if already known."""
    return _rays(view, points, max_range, rays, 1, unknown)[0]


def shared_gain(view: GridView, points, max_range: float, rays: int = 180, unknown=None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`information_gain` (P,) of each point, and its share (P,) of the unknown cells: a cell seen from k of
    the points counts 1/k to each, so the shares add up to the unknown area all the points see together;
    ``unknown``: the view's ``unknown_cells`` if already known."""
    own, shares, _ = _rays(view, points, max_range, rays, 2, unknown)
    return own, shares


def unknown_in_sight(view: GridView, point, max_range: float, rays: int = 180) -> np.ndarray:
    """The unknown cells (H, W) bool that :func:`information_gain` counts for one point (x, y) m."""
    return _rays(view, point, max_range, rays, 1)[2] == 1


def first_seeing(view: GridView, points, max_range: float, rays: int, floor: float, gains: np.ndarray,
                 unknown=None) -> int:
    """The index of the first of ``points`` (P, 2) m, in their order, whose :func:`information_gain` is at least
    ``floor`` cells, or -1; ``gains`` (P,) NaN where not counted yet, filled in for the points counted (in order,
    up to that one): a search for the nearest place that sees enough counts no place beyond it."""
    gxy = _grid_units(view, points)
    return int(_first_seeing(np.ascontiguousarray(view.state), gxy, int(rays), float(max_range) / view.resolution,
                             _cells_near(view, gxy, max_range, unknown), float(floor), gains))  # fmt: skip


def reach_table(state: np.ndarray) -> np.ndarray:
    """Summed-area table (H + 1, W + 1) of the UNKNOWN cells of ``state`` (H, W) that a ray cast from outside the
    unknown can count: those in a 4-connected block of unknown with a FREE 4-neighbour (a ray steps from cell to
    4-neighbour and stops at an occupied one, so it enters unknown space from a free cell; a block walled in is
    never seen)."""
    from scipy import ndimage

    unknown = state == UNKNOWN
    labels, n = ndimage.label(unknown)
    free = np.pad(state == FREE, 1)
    entry = unknown & (free[:-2, 1:-1] | free[2:, 1:-1] | free[1:-1, :-2] | free[1:-1, 2:])
    seen = np.zeros(n + 1, dtype=bool)
    seen[labels[entry]] = True  # entry cells are unknown: label 0 (known cells) stays unset
    table = np.zeros((state.shape[0] + 1, state.shape[1] + 1), dtype=np.int64)
    np.cumsum(np.cumsum(seen[labels], axis=0), axis=1, out=table[1:, 1:])
    return table


def unknown_within_reach(view: GridView, xy, max_range: float, table: np.ndarray | None = None) -> np.ndarray:
    """An upper bound (P,) on the UNKNOWN cells the rays cast from each point (P, 2) m can count: those of
    ``reach_table`` (``table``, of ``view.state``) in the square of ``max_range`` m and a cell and a half round the
    point; infinite within that of the grid's edge (beyond it counts as unknown) and from an unknown cell."""
    table = reach_table(view.state) if table is None else table
    g = (np.asarray(xy, dtype=np.float64).reshape(-1, 2) - np.asarray(view.origin)) / view.resolution  # (col, row)
    bound = max_range / view.resolution + 1.5
    h, w = view.shape
    out = (g.min(axis=1) < bound) | (g[:, 0] > w - bound) | (g[:, 1] > h - bound)
    at = np.clip(np.floor(g).astype(np.int64), 0, [w - 1, h - 1])
    out |= view.state[at[:, 1], at[:, 0]] == UNKNOWN
    lo = np.clip(np.floor(g - bound).astype(np.int64), 0, [w, h])  # (col, row) of the square's first cell ...
    hi = np.clip(np.floor(g + bound).astype(np.int64) + 1, 0, [w, h])  # ... and one past its last
    count = table[hi[:, 1], hi[:, 0]] - table[lo[:, 1], hi[:, 0]] - table[hi[:, 1], lo[:, 0]] + table[lo[:, 1], lo[:, 0]]
    return np.where(out, np.inf, count)


# --------------------------------------------------------------------------- straight-line reachability


def straight_reachable(blocked: np.ndarray, resolution: float, origin, a, b, width: float) -> bool:
    """Whether ``b`` (x, y) m is straight-line reachable from ``a``: three rays — the two long sides
    and the midline of a box of ``width`` m from ``a`` to ``b`` — cast on the grid (Amanatides–Woo,
    ``raycast_grid``) reach ``b``'s end of the box without meeting a ``blocked`` (H, W) cell."""
    a, b = np.asarray(a, dtype=np.float64)[:2], np.asarray(b, dtype=np.float64)[:2]
    d = b - a
    length = float(np.hypot(*d))
    if length < 1e-9:
        return True
    normal = np.array([-d[1], d[0]]) / length
    starts = a + np.outer([-0.5, 0.0, 0.5], normal * width) + 1e-6 * resolution  # off cell edges: 0·inf in the traversal
    angle = np.full((3, 1), np.arctan2(d[1], d[0]))
    _, hit = raycast_grid(~np.asarray(blocked, dtype=bool), resolution, starts, angle, length, origin)
    return not bool(hit.any())


# --------------------------------------------------------------------------- polygons


def inside_polygon(points, polygon) -> np.ndarray:
    """Even-odd test: which points (P, 2) lie inside ``polygon`` (K, 2) (m)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    poly = np.asarray(polygon, dtype=np.float64)
    x, y = pts[:, :1], pts[:, 1:]
    x0, y0 = poly[:, 0], poly[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    crosses = (y0 > y) != (y1 > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xc = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
    return (crosses & (x < xc)).sum(axis=1) % 2 == 1


def cells_inside_polygon(shape, to_world, polygon) -> np.ndarray:
    """Which cells (H, W) bool of a grid of ``shape`` have their centre inside ``polygon`` (K, 2) m;
    ``to_world`` maps (N, 2) (row, col) cells to their centres (x, y) m."""
    rows, cols = np.indices(shape)
    return inside_polygon(to_world(np.column_stack([rows.ravel(), cols.ravel()])), polygon).reshape(shape)


# --------------------------------------------------------------------------- visibility


@njit(cache=True)
def _mark_visible(free, gxy, n_rays, max_t, seen):
    h, w = free.shape
    for p in range(gxy.shape[0]):
        gx, gy = gxy[p, 0], gxy[p, 1]
        for b in range(n_rays):
            c, r, step_c, step_r, inv_x, inv_y, tmx, tmy = _ray_start(gx, gy, b, n_rays)
            t = 0.0
            while t < max_t and 0 <= r < h and 0 <= c < w and free[r, c]:
                seen[r, c] = True
                t, tmx, tmy, c, r = dda_step(tmx, tmy, inv_x, inv_y, c, r, step_c, step_r)


def visible_from(free: np.ndarray, resolution: float, origins, max_range: float, rays: int = 720) -> np.ndarray:
    """Free cells (H, W) bool that a ray from one of ``origins`` (P, 2) (cells, continuous (x, y) = (col, row))
    reaches within ``max_range`` m through free cells (Amanatides–Woo)."""
    seen = np.zeros(free.shape, dtype=np.bool_)
    gxy = np.ascontiguousarray(np.asarray(origins, dtype=np.float64).reshape(-1, 2))
    _mark_visible(np.ascontiguousarray(free, dtype=np.bool_), gxy, int(rays), float(max_range) / resolution, seen)
    return seen
