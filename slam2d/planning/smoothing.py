"""Path post-processing on the grid (numba): line-of-sight shortcutting and octile straightening.

- :func:`shortcut` keeps the fewest path cells such that each straight segment
  between consecutive kept cells (centre to centre) crosses only free cells.
  The test is the *supercover* of the segment (every cell the segment
  touches, both side cells where it passes exactly through a grid corner;
  Dedu's integer algorithm), so a segment never cuts a blocked corner. The
  result is an any-angle polyline: the zig-zag of equal-cost 8-connected
  moves disappears (an open knight-move corridor gives 2 points).
- :func:`smooth_octile` is the HPA* smoothing of Botea et al. (2004): from
  each path cell, walk straight in the 8 directions and jump to the farthest
  later path cell reached more cheaply than along the path. The result is
  still an 8-connected grid path, never longer in octile length.

Both work on geometric length and ignore any cost layer.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from slam2d.planning.astar import SQRT2, _DC, _DR

__all__ = ["line_of_sight", "supercover", "shortcut", "smooth_octile"]


@njit(cache=True)
def _los(free, y0, x0, y1, x1):
    """Whether every cell of the supercover from (y0, x0) to (y1, x1) is free (both inside)."""
    if not free[y0, x0]:
        return False
    dy = y1 - y0
    dx = x1 - x0
    ystep = 1
    xstep = 1
    if dy < 0:
        ystep = -1
        dy = -dy
    if dx < 0:
        xstep = -1
        dx = -dx
    ddy = 2 * dy
    ddx = 2 * dx
    y = y0
    x = x0
    if ddx >= ddy:
        error = dx
        errorprev = dx
        for _ in range(dx):
            x += xstep
            error += ddy
            if error > ddx:
                y += ystep
                error -= ddx
                if error + errorprev < ddx:
                    if not free[y - ystep, x]:
                        return False
                elif error + errorprev > ddx:
                    if not free[y, x - xstep]:
                        return False
                elif not free[y - ystep, x] or not free[y, x - xstep]:
                    return False
            if not free[y, x]:
                return False
            errorprev = error
    else:
        error = dy
        errorprev = dy
        for _ in range(dy):
            y += ystep
            error += ddx
            if error > ddy:
                x += xstep
                error -= ddy
                if error + errorprev < ddy:
                    if not free[y, x - xstep]:
                        return False
                elif error + errorprev > ddy:
                    if not free[y - ystep, x]:
                        return False
                elif not free[y, x - xstep] or not free[y - ystep, x]:
                    return False
            if not free[y, x]:
                return False
            errorprev = error
    return True


def line_of_sight(free: np.ndarray, a, b) -> bool:
    """Whether the straight segment between the centres of (row, col) cells ``a`` and ``b``
    touches only free cells (supercover; both cells must lie inside the grid)."""
    free = np.asarray(free, dtype=bool)
    h, w = free.shape
    for r, c in (a, b):
        if not (0 <= r < h and 0 <= c < w):
            return False
    return bool(_los(free, int(a[0]), int(a[1]), int(b[0]), int(b[1])))


@njit(cache=True)
def _supercover(y0, x0, y1, x1):
    """Cells (K, 2) of the supercover from (y0, x0) to (y1, x1), in order (as :func:`_los`)."""
    dy = abs(y1 - y0)
    dx = abs(x1 - x0)
    ystep = 1 if y1 >= y0 else -1
    xstep = 1 if x1 >= x0 else -1
    out = np.empty((3 * (dx + dy) + 1, 2), np.int64)
    out[0, 0] = y0
    out[0, 1] = x0
    n = 1
    major, minor = (dx, dy) if dx >= dy else (dy, dx)
    dmaj = 2 * major
    dmin = 2 * minor
    a = x0 if dx >= dy else y0  # major coordinate
    b = y0 if dx >= dy else x0  # minor coordinate
    astep = xstep if dx >= dy else ystep
    bstep = ystep if dx >= dy else xstep
    error = major
    errorprev = major
    for _ in range(major):
        a += astep
        error += dmin
        if error > dmaj:
            b += bstep
            error -= dmaj
            s = error + errorprev
            if s <= dmaj:  # the cell beside, on the minor side
                out[n, 0], out[n, 1] = (b - bstep, a) if dx >= dy else (a, b - bstep)
                n += 1
            if s >= dmaj:  # the cell behind, on the major side
                out[n, 0], out[n, 1] = (b, a - astep) if dx >= dy else (a - astep, b)
                n += 1
        out[n, 0], out[n, 1] = (b, a) if dx >= dy else (a, b)
        n += 1
        errorprev = error
    return out[:n]


def supercover(a, b) -> np.ndarray:
    """(K, 2) (row, col) cells touched by the segment between the centres of cells ``a`` and ``b``."""
    return _supercover(int(a[0]), int(a[1]), int(b[0]), int(b[1]))


@njit(cache=True)
def _shortcut(free, path):
    n = path.shape[0]
    keep = np.zeros(n, np.bool_)
    keep[0] = True
    keep[n - 1] = True
    a = 0
    j = 1
    while j < n - 1:
        if _los(free, path[a, 0], path[a, 1], path[j + 1, 0], path[j + 1, 1]):
            j += 1
        else:
            keep[j] = True
            a = j
            j += 1
    return keep


def shortcut(free: np.ndarray, path) -> np.ndarray:
    """Any-angle shortcut of a (L, 2) grid path: (K, 2) kept cells, first and last included.

    Greedy string pulling: from the last kept cell, extend while the next path
    cell is in line of sight, keep the last visible one. Consecutive path cells
    must be valid moves (8-connected, no corner cutting), which are always in
    line of sight.
    """
    p = np.ascontiguousarray(path, dtype=np.int64).reshape(-1, 2)
    if len(p) <= 2:
        return p.copy()
    return p[_shortcut(np.ascontiguousarray(free, dtype=np.bool_), p)]


@njit(cache=True)
def _smooth_octile(free, width, cells, mark, pos, stamp, max_steps):
    """HPA*-style straightening on the padded flat grid; returns padded cell indices."""
    n = cells.shape[0]
    cum = np.zeros(n)
    for i in range(n):
        mark[cells[i]] = stamp
        pos[cells[i]] = i
        if i > 0:
            d = abs(cells[i] - cells[i - 1])
            cum[i] = cum[i - 1] + (1.0 if d == 1 or d == width else SQRT2)
    out = np.empty(n, np.int64)
    out[0] = cells[0]
    m = 1
    i = 0
    while i < n - 1:
        u = cells[i]
        if pos[u] > i:  # the path comes back to this cell: drop the loop
            i = pos[u]
            continue
        best_j = i + 1
        best_d = -1
        best_k = 0
        for d in range(8):
            dr = _DR[d]
            dc = _DC[d]
            step = dr * width + dc
            length = SQRT2 if d >= 4 else 1.0
            v = u
            k = 0
            while k < max_steps:
                nv = v + step
                if free[nv] == 0:
                    break
                if d >= 4 and (free[v + dr * width] == 0 or free[v + dc] == 0):
                    break
                v = nv
                k += 1
                if mark[v] == stamp:
                    j = pos[v]
                    if j > best_j and k * length < cum[j] - cum[i] - 1e-9:
                        best_j = j
                        best_d = d
                        best_k = k
        if best_d < 0:
            out[m] = cells[i + 1]
            m += 1
        else:
            step = _DR[best_d] * width + _DC[best_d]
            for k in range(1, best_k + 1):
                out[m] = u + k * step
                m += 1
        i = best_j
    return out[:m]


def smooth_octile(free: np.ndarray, path, max_steps: int | None = None, buffers=None) -> np.ndarray:
    """Straighten an 8-connected (L, 2) grid path (Botea et al. 2004); returns an
    8-connected path with octile length <= the input's.

    ``max_steps`` bounds each straight probe (default: the grid's larger side);
    ``buffers`` (padded free, width, mark, pos, stamp) lets a planner reuse arrays.
    """
    p = np.asarray(path, dtype=np.int64).reshape(-1, 2)
    if len(p) <= 2:
        return p.copy()
    free = np.asarray(free, dtype=bool)
    h, w = free.shape
    if buffers is None:
        free_p = np.pad(free, 1).astype(np.uint8).ravel()
        width = w + 2
        mark = np.zeros(free_p.size, np.int32)
        pos = np.zeros(free_p.size, np.int32)
        stamp = 1
    else:
        free_p, width, mark, pos, stamp = buffers
    cells = (p[:, 0] + 1) * width + p[:, 1] + 1
    out = _smooth_octile(free_p, width, cells, mark, pos, stamp, max(h, w) if max_steps is None else max_steps)
    rows = out // width
    return np.stack([rows - 1, out - rows * width - 1], axis=1)
