"""The grids views of pockets are scored on: the hidden cells (unknown, no known cell within
one cell) among walls closed over their small gaps (:func:`pocket_state`), with obstacles' unknown
faces opaque (:func:`opaque_faces`) and the outside left to the frontiers (:func:`without_outside`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from slam2d.exploration.frontiers import shallow_entries
from slam2d.exploration.gridops import (
    FREE,
    OCCUPIED,
    UNKNOWN,
    GridView,
    cells_of,
    first_seeing,
    inside_polygon,
    reach_table,
    unknown_cells,
    unknown_in_sight,
    unknown_within_reach,
)
from slam2d.exploration.paths import as_paths

__all__ = ["LocalRefresh", "opaque_faces", "pocket_goal", "pocket_state", "without_outside"]

POCKET_SPACING = 0.2  # m between the places tried as views of pockets
POCKET_RAYS = 360  # rays cast from each of them (one a degree, as the laser's beams)


def pocket_state(state: np.ndarray, wall_cells: int, retired: np.ndarray | None = None) -> np.ndarray:
    """The grid the views of pockets are scored on (FREE / OCCUPIED / UNKNOWN, (H, W) int8).

    UNKNOWN: the *hidden* cells — unknown with no known cell within one cell, i.e. what the
    coverage counts as unexplored — except ``retired`` ones (H, W bool). OCCUPIED: occupied cells,
    and the cells in gaps of at most ``wall_cells`` between occupied ones (a wall's cells seen at a
    grazing angle or missed, the corners of a box): rays do not leak through them into the unknown
    space behind walls and inside furniture. FREE: the rest, which rays cross.
    """
    known = state != UNKNOWN
    hidden = ~_within_a_cell(known)  # outside the grid: unknown
    if retired is not None:
        hidden &= ~retired
    closed = _gaps_closed(state == OCCUPIED, wall_cells)
    out = np.full(state.shape, FREE, dtype=np.int8)
    out[hidden] = UNKNOWN
    out[closed] = OCCUPIED
    return out


def _within_a_cell(mask: np.ndarray) -> np.ndarray:
    """Cells (H, W) bool with a set cell of ``mask`` among their 3 x 3 neighbourhood (beyond the grid: unset)."""
    return _window_any(_window_any(mask, 1, 1, False, 0), 1, 1, False, 1)


def _gaps_closed(mask: np.ndarray, gap_cells: int) -> np.ndarray:
    """``mask`` (H, W) bool with its gaps of at most ``gap_cells`` filled: a closing by a square of
    gap_cells + 1 cells (a dilation, then the mirrored erosion; beyond the grid nothing is set)."""
    size = max(1, gap_cells) + 1
    lo, hi = size // 2, size - 1 - size // 2
    grown = np.pad(mask, size)
    for axis in (0, 1):
        grown = _window_any(grown, lo, hi, False, axis)
    for axis in (0, 1):
        grown = ~_window_any(~grown, hi, lo, False, axis)
    return grown[size:-size, size:-size]


def without_outside(scored: np.ndarray, span_cells: int) -> np.ndarray:
    """``scored`` (a ``pocket_state`` grid, (H, W) int8) with the outside FREE: the UNKNOWN cells
    4-connected to the grid's edge, seen through an open end or gaps in the outer wall (the frontiers'
    business). Gaps of up to ``span_cells`` between OCCUPIED cells (a wall's stretch unseen behind
    furniture) are bridged first, so that a pocket behind a desk at the outer wall stays a pocket."""
    from scipy import ndimage

    bridged = _gaps_closed(scored == OCCUPIED, span_cells)
    hidden = np.pad((scored == UNKNOWN) & ~bridged, 1, constant_values=True)  # beyond the grid: outside
    labels, _ = ndimage.label(hidden)
    out = scored.copy()
    out[labels[1:-1, 1:-1] == labels[0, 0]] = FREE
    return out


def opaque_faces(scored: np.ndarray, state: np.ndarray, depth: int = 0) -> np.ndarray:
    """``scored`` (a ``pocket_state`` grid of the map ``state``, both (H, W) int8) with the unknown
    cells on an obstacle's face OCCUPIED: unknown in ``state``, not UNKNOWN in ``scored``, within a cell
    of an OCCUPIED one, or opening a strip of unknown no deeper than ``depth`` cells from a free cell
    (``shallow_entries``). Rays then neither run along a wall's unseen side nor enter a block of walls
    through its unobserved cells or a thick wall through its unseen face."""
    occupied = scored == OCCUPIED
    face = _within_a_cell(occupied)
    if depth > 0:
        face |= shallow_entries(state, depth)
    out = scored.copy()
    out[face & (state == UNKNOWN) & (scored != UNKNOWN) & ~occupied] = OCCUPIED
    return out


@njit(cache=True)
def _window_any(mask, before, after, outside, axis):
    """Whether any cell from ``before`` cells before to ``after`` cells after each cell along ``axis`` is
    set in ``mask`` (H, W) bool; cells beyond the grid count as ``outside``. Running counts, row by row in
    memory order for both axes (per column along axis 0, per row along axis 1)."""
    h, w = mask.shape
    out = np.empty((h, w), dtype=np.bool_)
    if axis == 0:
        count = np.zeros(w, dtype=np.int64)
        for r in range(min(after, h - 1) + 1):
            for c in range(w):
                count[c] += mask[r, c]
        for r in range(h):
            edge = outside and (r - before < 0 or r + after >= h)
            for c in range(w):
                out[r, c] = count[c] > 0 or edge
            if r - before >= 0:
                for c in range(w):
                    count[c] -= mask[r - before, c]
            if r + after + 1 < h:
                for c in range(w):
                    count[c] += mask[r + after + 1, c]
        return out
    for r in range(h):
        count = 0
        for c in range(min(after, w - 1) + 1):
            count += mask[r, c]
        for c in range(w):
            out[r, c] = count > 0 or (outside and (c - before < 0 or c + after >= w))
            if c - before >= 0:
                count -= mask[r, c - before]
            if c + after + 1 < w:
                count += mask[r, c + after + 1]
    return out


class LocalRefresh:
    """``fn`` of (H, W) grids of one-byte cells (int8, uint8, bool) whose every output cell depends only on the
    inputs within ``radius`` cells of it (and on the grid's edge), kept between calls: where the inputs changed since
    the last call (of the same shape), it is recomputed in a box round the changes only, on a window reaching
    ``radius`` beyond it; the same result as ``fn`` on the whole grid."""

    def __init__(self, fn, radius: int):
        self.fn, self.radius = fn, int(radius)
        self._inputs = self._out = None

    def __call__(self, *grids) -> np.ndarray:
        grids = tuple(np.ascontiguousarray(g) for g in grids)
        if any(g.ndim != 2 or g.dtype.itemsize != 1 for g in grids):
            raise TypeError(f"LocalRefresh takes (H, W) grids of one-byte cells, not {[g.dtype.name for g in grids]}")
        last = self._inputs
        if last is None or any(a.shape != b.shape or a.dtype != b.dtype for a, b in zip(last, grids)):
            self._out = self.fn(*grids)
            self._inputs = tuple(g.copy() for g in grids)
            return self._out.copy()
        box = np.array([grids[0].shape[0], 0, grids[0].shape[1], 0])  # rows r0:r1, cols c0:c1 of the changes
        for a, b in zip(last, grids):
            _changed_box(a.view(np.int8), b.view(np.int8), box)
        if box[0] < box[1]:
            lo, hi, shape = box[[0, 2]], box[[1, 3]], np.array(grids[0].shape)
            inner_lo, inner_hi = np.maximum(lo - self.radius, 0), np.minimum(hi + self.radius, shape)
            win_lo, win_hi = np.maximum(lo - 2 * self.radius, 0), np.minimum(hi + 2 * self.radius, shape)
            part = self.fn(*(g[win_lo[0] : win_hi[0], win_lo[1] : win_hi[1]] for g in grids))
            a, b = inner_lo - win_lo, inner_hi - win_lo
            self._out[inner_lo[0] : inner_hi[0], inner_lo[1] : inner_hi[1]] = part[a[0] : b[0], a[1] : b[1]]
            for kept, g in zip(last, grids):  # outside the box the inputs are unchanged
                kept[lo[0] : hi[0], lo[1] : hi[1]] = g[lo[0] : hi[0], lo[1] : hi[1]]
        return self._out.copy()


@njit(cache=True)
def _changed_box(a, b, box):
    """Grow ``box`` [r0, r1, c0, c1] (rows r0:r1, cols c0:c1) to hold every cell where the (H, W) int8 grids ``a``
    and ``b`` differ; each row read from both ends to its first and last change, no temporary grid."""
    h, w = a.shape
    for r in range(h):
        c = 0
        while c < w and a[r, c] == b[r, c]:
            c += 1
        if c == w:
            continue
        e = w - 1
        while a[r, e] == b[r, e]:
            e -= 1
        box[0], box[1] = min(box[0], r), max(box[1], r + 1)
        box[2], box[3] = min(box[2], c), max(box[3], e + 1)


def pocket_goal(explorer, pose, view: GridView, distance):
    """When no frontier (or candidate) is left: the nearest reachable place (sampled every
    POCKET_SPACING m, and every cell along the edge of the space with room for a goal: the views
    along walls and furniture; away from visited and inaccessible goals) that sees at least
    ``pocket_gain`` of hidden cells (``pocket_state``) — pockets whose openings are narrower than a
    frontier region or touch an obstacle (behind furniture, beside a wall), often seen from a few
    places only."""
    distance = as_paths(distance)
    if not distance.reach.any():  # no place to try
        return None
    state = explorer._pocket_state(view)
    if not (state == UNKNOWN).any():
        return None
    k = max(1, round(POCKET_SPACING / view.resolution))
    room = distance.reach
    inner = np.pad(room, 1)
    inner = inner[:-2, 1:-1] & inner[2:, 1:-1] & inner[1:-1, :-2] & inner[1:-1, 2:]
    tried = room & ~inner  # the edge of the room: views along walls and furniture
    tried[::k, ::k] = True
    cells = cells_of(tried & room)
    xy = view.to_world(cells)
    keep = np.ones(len(xy), dtype=bool)
    if explorer.cfg.bounds is not None:
        keep &= inside_polygon(xy, explorer.cfg.bounds)
    avoid = explorer.visited + explorer.inaccessible
    if avoid:
        from scipy.spatial import cKDTree

        keep &= cKDTree(np.array(avoid)).query(xy)[0] >= explorer.cfg.avoid_radius
    scored = GridView(state, view.resolution, view.origin)
    floor = explorer.cfg.pocket_gain / view.resolution**2
    gains, unknown, table = _gains(explorer, view, state)
    keep &= ~(gains[cells[:, 0] * view.shape[1] + cells[:, 1]] < floor)  # counted already and seeing too few
    if floor > 0:  # a place with fewer hidden cells within the rays' reach than the floor sees too few: not scored
        keep[keep] = unknown_within_reach(scored, xy[keep], explorer.cfg.gain_range, table) >= floor
    cells, xy = cells[keep], xy[keep]
    order = np.argsort(distance.lengths(cells), kind="stable")  # lengths only of the places scored
    cells, xy = cells[order], xy[order]
    flat = cells[:, 0] * view.shape[1] + cells[:, 1]
    known = gains[flat]  # each place counted once a pocket grid (the levels of a decision), nearest first
    k = first_seeing(scored, xy, explorer.cfg.gain_range, POCKET_RAYS, floor, known, unknown)
    gains[flat] = known
    if k < 0:
        return None
    seen = unknown_in_sight(scored, xy[k], explorer.cfg.gain_range, POCKET_RAYS)
    targets = view.to_world(np.column_stack(np.nonzero(seen)))
    from slam2d.exploration.explorer import Goal

    return Goal(xy[k], "pocket", score=float(known[k]), targets=targets)


def _gains(explorer, view: GridView, state: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The gains (H·W,) of the places scored on the pocket grid ``state`` (NaN: not yet), its hidden cells
    (K, 2) and its ``reach_table``. A place keeps its gain from the last pocket grid of the same frame unless a
    cell within the rays' reach of it changed since (a place sees nothing farther): a box round the cells that
    changed is scored anew, the rest of the building is not."""
    frame = view.shape, view.resolution, tuple(np.asarray(view.origin, dtype=float))
    last, gains, _, _, last_frame = explorer._gains_of
    if last is not state:
        if last is None or last_frame != frame:
            gains = np.full(state.size, np.nan)
        else:
            changed = cells_of(last != state)
            if len(changed):
                m = int(np.ceil(explorer.cfg.gain_range / view.resolution)) + 2
                lo, hi = np.maximum(changed.min(axis=0) - m, 0), changed.max(axis=0) + m + 1
                gains.reshape(state.shape)[lo[0] : hi[0], lo[1] : hi[1]] = np.nan
        hidden = unknown_cells(GridView(state, 1.0, (0.0, 0.0)))
        explorer._gains_of = state, gains, hidden, reach_table(state), frame
    return explorer._gains_of[1:4]
