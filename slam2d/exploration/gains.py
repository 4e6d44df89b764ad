"""The information gains' rays kept between decisions (:class:`RayRecords`).

A point's gain and the unknown cells its rays meet (in the order met) depend only on the hidden-cell grid within
the rays' reach of it and on the grid's frame: a point's record is kept from one grid to the next unless a cell
within that reach changed, and the shares (:func:`~slam2d.exploration.gridops.shared_gain`) are summed from the
records, kept or cast anew: the same numbers, bit for bit, as casting every point's rays again.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from slam2d.exploration.gridops import (
    GridView,
    _aim_point,
    _buckets,
    _cells_near,
    _grid_units,
    _trace,
)

__all__ = ["RayRecords"]

TILE = 8  # cells: the changed cells are binned in squares this wide to find the records they touch


@njit(cache=True)
def _record(state, gxy, n_rays, max_t, unknown, mark):
    """Rays from each point (P, 2) grid units, aimed as ``_cast`` aims them: the unknown cells each counts (P,),
    and what its rays met in order (``_trace``'s record: flat cell index, -1 a step beyond the map), point p's from
    ``first[p]`` to ``first[p + 1]``. ``mark`` (H, W) int32, all 0 (and so again after)."""
    n = gxy.shape[0]
    seers = np.zeros((1, 1), dtype=np.int32)
    need = np.ones(n_rays, dtype=np.bool_)
    size = int(np.ceil(max_t + 1.0))
    cells, starts, nbc = _buckets(unknown, state.shape, size)
    most = n_rays * (2 * int(np.ceil(max_t)) + 4)  # steps of a point's rays at most
    ev, n_ev = np.empty(most, dtype=np.int64), 0
    own, first = np.zeros(n), np.zeros(n + 1, dtype=np.int64)
    for p in range(n):
        _aim_point(state, gxy[p, 0], gxy[p, 1], n_rays, max_t, cells, starts, size, nbc, need)
        if n_ev + most > ev.shape[0]:
            grown = np.empty(2 * ev.shape[0], dtype=np.int64)
            grown[:n_ev] = ev[:n_ev]
            ev = grown
        own[p], n_ev = _trace(state, gxy[p, 0], gxy[p, 1], n_rays, max_t, need, mark, p + 1, seers, ev, n_ev)
        first[p + 1] = n_ev
    flat = mark.ravel()
    for k in range(n_ev):
        if ev[k] >= 0:
            flat[ev[k]] = 0
    return own, ev[:n_ev], first


@njit(cache=True)
def _shares(ev, first, seers):
    """Each point's share (P,) of the unknown cells its record ``ev`` (``first``) holds, ``seers`` (H·W,) int32 all 0
    (and so again after): a cell met by k of the points counts 1/k, a step beyond the map 1 (summed in the order
    met, as ``_cast``)."""
    for k in range(first[-1]):
        if ev[k] >= 0:
            seers[ev[k]] += 1
    n = first.shape[0] - 1
    shares = np.zeros(n)
    for p in range(n):
        total = 0.0
        for k in range(first[p], first[p + 1]):
            total += 1.0 if ev[k] < 0 else 1.0 / seers[ev[k]]
        shares[p] = total
    for k in range(first[-1]):
        if ev[k] >= 0:
            seers[ev[k]] = 0
    return shares


@njit(cache=True)
def _changed_tiles(a, b, tile):
    """The squares of ``tile`` cells (H // tile + 1, W // tile + 1) bool holding a cell where the grids ``a`` and
    ``b`` (H, W) differ, and whether any does: one pass, no list of the changed cells."""
    h, w = a.shape
    out = np.zeros((h // tile + 1, w // tile + 1), dtype=np.bool_)
    any_changed = False
    for r in range(h):
        for c in range(w):
            if a[r, c] != b[r, c]:
                out[r // tile, c // tile] = any_changed = True
    return out, any_changed


class RayRecords:
    """The rays' records of the points asked for on successive hidden-cell grids of one map: :meth:`update` with each
    new grid drops the records a changed cell is within reach of (all of them when the frame changed, and those not
    asked for on the last grid anything was asked on: the grids of the goal's checks between two decisions keep
    the points of the first); :meth:`gains` and :meth:`shared` cast only the points without a record."""

    def __init__(self):
        self._state = self._frame = None
        self._kept: dict = {}  # (gx, gy, max_t, rays) -> (gain, record)
        self._used: set = set()  # the points asked for on the current grid
        self._asked: set = set()  # those of the last grid anything was asked on

    def update(self, view: GridView) -> None:
        """A new hidden-cell grid ``view`` (its ``state`` is kept, not copied: not to be changed after)."""
        frame = view.shape, view.resolution, tuple(np.asarray(view.origin, dtype=float))
        if self._used:  # grids nothing was asked on (the goal's checks between decisions) drop no record
            self._asked = self._used
        kept = {key: self._kept[key] for key in self._asked if key in self._kept} if frame == self._frame else {}
        if kept:
            tiles, changed = _changed_tiles(self._state, view.state, TILE)
            if changed:
                for key in list(kept):
                    gx, gy, max_t, _ = key
                    reach = max_t + 2.0  # a ray stops before max_t: its cells lie within max_t + 1 of the point
                    r0, r1 = max(int((gy - reach) // TILE), 0), max(int((gy + reach) // TILE) + 1, 0)
                    c0, c1 = max(int((gx - reach) // TILE), 0), max(int((gx + reach) // TILE) + 1, 0)
                    if tiles[r0:r1, c0:c1].any():
                        del kept[key]
        if frame != self._frame:
            self._mark = np.zeros(view.shape, dtype=np.int32)  # all 0 between calls
        self._state, self._frame, self._kept, self._used = view.state, frame, kept, set()

    def _records(self, view: GridView, points, max_range: float, rays: int, unknown):
        """The gains (P,) and the records (``ev``, ``first``) of ``points`` (P, 2) m on the grid of the last update."""
        gxy = _grid_units(view, points)
        max_t = float(max_range) / view.resolution
        keys = [(float(x), float(y), max_t, int(rays)) for x, y in gxy]
        new = {key: i for i, key in enumerate(keys) if key not in self._kept}
        if new:
            at = gxy[list(new.values())]
            own, ev, first = _record(np.ascontiguousarray(view.state), np.ascontiguousarray(at), int(rays), max_t,
                                     _cells_near(view, at, max_range, unknown), self._mark)  # fmt: skip
            for j, key in enumerate(new):
                self._kept[key] = own[j], ev[first[j] : first[j + 1]].copy()
        self._used.update(keys)
        records = [self._kept[key] for key in keys]
        first = np.concatenate([[0], np.cumsum([len(r[1]) for r in records])]).astype(np.int64)
        ev = np.concatenate([r[1] for r in records]) if records else np.zeros(0, dtype=np.int64)
        return np.array([r[0] for r in records], dtype=np.float64), ev, first

    def gains(self, view: GridView, points, max_range: float, rays: int, unknown) -> np.ndarray:
        """:func:`~slam2d.exploration.gridops.information_gain` (P,) of ``points`` (P, 2) m on ``view`` (the grid of
        the last update); ``unknown``: its ``unknown_cells``."""
        return self._records(view, points, max_range, rays, unknown)[0]

    def shared(self, view: GridView, points, max_range: float, rays: int, unknown) -> tuple[np.ndarray, np.ndarray]:
        """:func:`~slam2d.exploration.gridops.shared_gain` (gains (P,), shares (P,)) of ``points`` (P, 2) m on
        ``view`` (the grid of the last update); ``unknown``: its ``unknown_cells``."""
        own, ev, first = self._records(view, points, max_range, rays, unknown)
        return own, _shares(ev, first, self._mark.ravel())
