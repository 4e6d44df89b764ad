"""The grids views of pockets are scored on: the hidden cells (unknown, no known cell within
one cell) among walls closed over their small gaps (:func:`pocket_state`), with obstacles' unknown
faces opaque (:func:`opaque_faces`) and the outside left to the frontiers (:func:`without_outside`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from slam2d.exploration.frontiers import shallow_entries
from slam2d.exploration.gridops import FREE, OCCUPIED, UNKNOWN

__all__ = ["pocket_state", "without_outside", "opaque_faces"]


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
