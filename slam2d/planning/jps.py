"""Jump Point Search (Harabor & Grastien, AAAI 2011) on slam2d's grid, numba inner loop.

Same graph as :mod:`~slam2d.planning.astar`'s 8-connected A*: axial steps of 1,
diagonal steps of √2, a diagonal needs both side cells free (no corner
cutting). JPS prunes the symmetric paths of that graph and searches only
*jump points*; its paths have A*'s optimal length (they may differ among equal
length paths). The pruning rules are the no-corner-cutting variant (Harabor &
Grastien, ICAPS 2014; warthog's ``jps``):

- arriving diagonally in ``(dr, dc)``, the successor directions are
  ``(dr, 0)``, ``(0, dc)`` and ``(dr, dc)``: a diagonal move has no forced
  neighbours when it may not cut corners;
- arriving straight in ``d`` at cell ``n``, the side ``s`` (perpendicular) is
  *forced* when ``n + s`` is free and ``n - d + s`` blocked; then ``s`` and
  ``d + s`` are successor directions beside ``d``;
- a straight jump steps until the next move is not allowed (no successor), the
  goal, or a cell with a forced side; a diagonal jump steps until the next move
  is not allowed, the goal, or a cell from which a straight jump in ``(dr, 0)``
  or ``(0, dc)`` finds a jump point.

Two refinements of Harabor & Grastien (ICAPS 2014): straight jumps scan 64
cells a word (:mod:`~slam2d.planning.bitlines`), and a diagonal scan does not
queue the diagonal jump points it passes but the straight jump points (and the
goal) seen from them, with the scan's origin as parent; so an edge runs
diagonally first, then straight, costs the octile distance, and no row is
scanned twice. A successor whose f equals its parent's is expanded next from a
stack, without the heap (A*'s order up to ties). The returned path lists every
cell. JPS+ (:mod:`~slam2d.planning.jps_plus`) shares the search, its jumps
looked up in a table (and its diagonal jump points queued: a look-up is cheap).

Costmaps are not supported: a non-zero ``cost`` layer raises ValueError (the
pruning assumes uniform step costs; plan with ``astar``). JPS is 8-connected only.
"""

from __future__ import annotations

import time

import numpy as np
from numba import njit

from slam2d.planning.astar import (
    _DC,
    _DR,
    _EPS_F,
    SQRT2,
    PlanResult,
    SearchBuffers,
    _octile,
    _pop,
    _sift_up,
    endpoint_problem,
    move_mask,
)
from slam2d.planning.base import register_planner
from slam2d.planning.bitlines import _scan_line, bit_lines
from slam2d.planning.grid import PlanningGrid

__all__ = ["JPS", "jps"]

# Moves in astar.py's order: 0 up, 1 down, 2 left, 3 right (rows -/+, cols -/+), then diagonals
# 4 (-1, -1), 5 (-1, +1), 6 (+1, -1), 7 (+1, +1).


@njit(inline="always")
def _sign(x):
    return (x > 0) - (x < 0)


@njit(inline="always")
def _vert(dr):
    """Move index of the axial step (dr, 0)."""
    return 0 if dr < 0 else 1


@njit(inline="always")
def _horiz(dc):
    """Move index of the axial step (0, dc)."""
    return 2 if dc < 0 else 3


@njit(inline="always")
def _diag(dr, dc):
    """Move index of the diagonal step (dr, dc)."""
    return 4 + (2 if dr > 0 else 0) + (1 if dc > 0 else 0)


@njit(inline="always")
def _forced(free, width, v, dr, dc):
    """Whether cell ``v`` reached by the straight step (dr, dc) has a forced side."""
    if dr != 0:
        b = v - dr * width
        return (free[v - 1] != 0 and free[b - 1] == 0) or (free[v + 1] != 0 and free[b + 1] == 0)
    a = v - width
    c = v + width
    return (free[a] != 0 and free[a - dc] == 0) or (free[c] != 0 and free[c - dc] == 0)


@njit(cache=True)
def _successor_dirs(moves, free, width, u, kin, dr_of, dc_of):
    """Bit mask of the move indices to jump in from ``u`` reached by move ``kin`` (-1: the start)."""
    if kin < 0:
        return np.int64(moves[u])
    dr = dr_of[kin]
    dc = dc_of[kin]
    if dr != 0 and dc != 0:
        m = (1 << _vert(dr)) | (1 << _horiz(dc)) | (1 << _diag(dr, dc))
    elif dr != 0:
        m = 1 << _vert(dr)
        b = u - dr * width
        for s in (-1, 1):
            if free[u + s] != 0 and free[b + s] == 0:
                m |= (1 << _horiz(s)) | (1 << _diag(dr, s))
    else:
        m = 1 << _horiz(dc)
        for s in (-1, 1):
            if free[u + s * width] != 0 and free[u + s * width - dc] == 0:
                m |= (1 << _vert(s)) | (1 << _diag(s, dc))
    return m & np.int64(moves[u])


@njit(inline="always")
def _table_jump(dist, u, k, dr, dc, width, ddr, ddc):
    """JPS+'s jump from ``u`` in move ``k`` = (dr, dc), looked up in ``dist`` (see
    :mod:`~slam2d.planning.jps_plus`); the goal is (ddr, ddc) cells away. Returns (cell or -1, steps)."""
    d = dist[u, k]
    if dr == 0 or dc == 0:
        ahead = ddc * dc if dr == 0 else ddr * dr
        if ahead > 0 and (ddr if dr == 0 else ddc) == 0 and ahead <= abs(d):
            return u + ahead * (dr * width + dc), ahead  # the goal, on the line within reach
    else:
        a = min(ddr * dr, ddc * dc)
        if a > 0 and a <= abs(d):
            return u + a * (dr * width + dc), a  # the target point, in line with the goal
    if d > 0:
        return u + d * (dr * width + dc), d
    return -1, 0


@njit(inline="always")
def _jump_bits(rows, cols, width, u, dr, dc, tr, tc):
    """The jump point reached from ``u`` by straight steps (dr, dc), or -1: :func:`_scan_line` over the
    row bits ``rows`` (padded rows x words) or the column bits ``cols``."""
    ur = u // width
    uc = u - ur * width
    if dr == 0:
        x = _scan_line(rows, ur, uc, dc, tc if tr == ur else -1)
        return ur * width + x if x >= 0 else -1
    y = _scan_line(cols, uc, ur, dr, tr if tc == uc else -1)
    return y * width + uc if y >= 0 else -1


@njit(cache=True)
def _scan_successors(moves, free, rows, cols, width, u, dirs, t, dr_of, dc_of, out_v, out_k):
    """JPS's successors of ``u`` in the moves ``dirs`` (bit mask), by scanning: jump points into
    ``out_v`` with the move reaching them in ``out_k``; returns their number.

    Diagonal jump points are not returned (Harabor & Grastien 2014's pruning of intermediate jump
    points): a diagonal scan returns the straight jump points (and the goal) seen from each of them,
    so an edge runs diagonally first, then straight, and no row is scanned twice."""
    m = 0
    tr = t // width
    tc = t - tr * width
    for k in range(8):
        if not (dirs >> k) & 1:
            continue
        dr = dr_of[k]
        dc = dc_of[k]
        if dr == 0 or dc == 0:
            v = _jump_bits(rows, cols, width, u, dr, dc, tr, tc)
            if v >= 0:
                out_v[m] = v
                out_k[m] = k
                m += 1
            continue
        kv = _vert(dr)
        kh = _horiz(dc)
        step = dr * width + dc
        x = u
        while (moves[x] >> k) & 1:
            x += step
            if x == t:
                out_v[m] = t
                out_k[m] = k
                m += 1
                break
            v = _jump_bits(rows, cols, width, x, dr, 0, tr, tc)
            if v >= 0:
                out_v[m] = v
                out_k[m] = kv
                m += 1
            v = _jump_bits(rows, cols, width, x, 0, dc, tr, tc)
            if v >= 0:
                out_v[m] = v
                out_k[m] = kh
                m += 1
    return m


@njit(cache=True)
def _table_successors(dist, width, u, dirs, tr, tc, dr_of, dc_of, out_v, out_k):
    """JPS+'s successors of ``u`` in the moves ``dirs``, looked up in ``dist`` (:func:`_table_jump`);
    diagonal jump points are returned (a look-up is cheap, and most are never expanded)."""
    m = 0
    ur = u // width
    uc = u - ur * width
    for k in range(8):
        if (dirs >> k) & 1:
            v, _ = _table_jump(dist, u, k, dr_of[k], dc_of[k], width, tr - ur, tc - uc)
            if v >= 0:
                out_v[m] = v
                out_k[m] = k
                m += 1
    return m


@njit(cache=True)
def _jps(dist, use_table, moves, free, rows, cols, width, s, t, g, parent, state, arrive, hk, hg, hn, hpos, stamp,
         dr_of, dc_of, out_v, out_k, stack):  # fmt: skip
    """JPS from padded index ``s`` to ``t``: the A* of astar.py (same heap, ties and ``state`` stamps)
    over jump points, found by scanning the grid or, with ``use_table``, looked up in JPS+'s ``dist``.
    Successors join their parent by a diagonal then a straight line (edge cost: octile distance);
    ``arrive[v]`` is the move by which ``v`` was reached; ``out_v``, ``out_k`` are scratch for the
    successors of one node. Returns (found, jump points expanded)."""
    reached = 2 * stamp
    tr = t // width
    tc = t - tr * width
    state[s] = reached
    g[s] = 0.0
    parent[s] = -1
    arrive[s] = -1
    sr = s // width
    _sift_up(hk, hg, hn, hpos, 0, _octile(sr, s - sr * width, tr, tc, True), 0.0, s)
    size = 1
    top = 0
    expanded = 0
    while size > 0 or top > 0:
        if top > 0:
            top -= 1
            u = stack[top]
        else:
            u, size = _pop(hk, hg, hn, hpos, size)
        state[u] = reached + 1
        expanded += 1
        if u == t:
            return True, expanded
        ur = u // width
        uc = u - ur * width
        gu = g[u]
        dirs = _successor_dirs(moves, free, width, u, arrive[u], dr_of, dc_of)
        if use_table:
            m = _table_successors(dist, width, u, dirs, tr, tc, dr_of, dc_of, out_v, out_k)
        else:
            m = _scan_successors(moves, free, rows, cols, width, u, dirs, t, dr_of, dc_of, out_v, out_k)
        fu = gu + _octile(ur, uc, tr, tc, True)
        for j in range(m):
            v = out_v[j]
            sv = state[v]
            if sv == reached + 1:
                continue
            vr = v // width
            vc = v - vr * width
            ng = gu + _octile(ur, uc, vr, vc, True)
            if sv < reached:
                state[v] = reached
                g[v] = ng
                parent[v] = u
                arrive[v] = out_k[j]
                hv = _octile(vr, vc, tr, tc, True)
                if ng + hv <= fu + _EPS_F:  # f does not grow: next, without the heap
                    hpos[v] = -1
                    stack[top] = v
                    top += 1
                else:
                    _sift_up(hk, hg, hn, hpos, size, ng + hv, ng, v)
                    size += 1
            elif ng < g[v] - 1e-12:
                i = hpos[v]
                if i >= 0:
                    _sift_up(hk, hg, hn, hpos, i, ng + hk[i] - g[v], ng, v)
                g[v] = ng
                parent[v] = u
                arrive[v] = out_k[j]
    return False, expanded


@njit(cache=True)
def _trace_lines(parent, t, width):
    """(L, 2) unpadded (row, col) cells from the root to ``t`` through the jump points linked by
    ``parent``, every cell of the edges between them (each diagonal first, then straight), their
    length (cells) and the number of jump points."""
    n = 1
    jumps = 1
    v = t
    while parent[v] != -1:
        p = parent[v]
        vr = v // width
        pr = p // width
        n += max(abs(vr - pr), abs((v - vr * width) - (p - pr * width)))
        jumps += 1
        v = p
    out = np.empty((n, 2), np.int64)
    axial = 0
    diagonal = 0
    i = n - 1
    v = t
    r = v // width
    c = v - r * width
    out[i, 0] = r - 1
    out[i, 1] = c - 1
    while parent[v] != -1:
        p = parent[v]
        pr = p // width
        pc = p - pr * width
        while r != pr or c != pc:  # backwards: the straight part first, then the diagonal one
            ar = abs(pr - r)
            ac = abs(pc - c)
            if ar >= ac:
                r += _sign(pr - r)
            if ac >= ar:
                c += _sign(pc - c)
            if ar == ac:
                diagonal += 1
            else:
                axial += 1
            i -= 1
            out[i, 0] = r - 1
            out[i, 1] = c - 1
        v = p
    return out, axial + diagonal * SQRT2, jumps


@njit(cache=True)
def _query(dist, use_table, moves, free, rows, cols, h, w, sr, sc, gr, gc, g, parent, state, arrive, hk, hg, hn,
           hpos, stamp, dr_of, dc_of, out_v, out_k, stack):  # fmt: skip
    """One query between unpadded cells in one call: (code, expanded, path, length, jump points) with
    code 0 found, 1 start unusable, 2 goal unusable, 3 unreachable (path empty unless found)."""
    width = w + 2
    empty = np.zeros((0, 2), np.int64)
    if not (0 <= sr < h and 0 <= sc < w and free[(sr + 1) * width + sc + 1] != 0):
        return 1, 0, empty, np.inf, 0
    if not (0 <= gr < h and 0 <= gc < w and free[(gr + 1) * width + gc + 1] != 0):
        return 2, 0, empty, np.inf, 0
    t = (gr + 1) * width + gc + 1
    found, expanded = _jps(dist, use_table, moves, free, rows, cols, width, (sr + 1) * width + sc + 1, t, g, parent,
                           state, arrive, hk, hg, hn, hpos, stamp, dr_of, dc_of, out_v, out_k, stack)  # fmt: skip
    if not found:
        return 3, expanded, empty, np.inf, 0
    path, length, jumps = _trace_lines(parent, t, width)
    return 0, expanded, path, length, jumps


# ---------------------------------------------------------------- planner

class JPS:
    """Reusable Jump Point Search over a :class:`PlanningGrid` (or a bool mask, resolution 1).

    The same moves and optimal lengths as :class:`~slam2d.planning.astar.AStar` (8-connected, no corner
    cutting). ``cost``: None or an all-zero layer; a non-zero layer raises ValueError (use A*). Buffers
    are allocated once; ``expanded`` counts jump points, ``info['jump_points']`` those on the path.
    """

    name = "JPS"

    def __init__(self, grid: PlanningGrid | np.ndarray, cost: np.ndarray | None = None):
        if not isinstance(grid, PlanningGrid):
            grid = PlanningGrid(np.asarray(grid, dtype=bool))
        if cost is not None and np.any(np.asarray(cost) != 0):
            raise ValueError(f"{self.name} needs uniform step costs: a non-zero cost layer breaks its pruning "
                             "(plan with the 'astar' planner on a costmap)")  # fmt: skip
        self.grid = grid
        h, w = grid.shape
        self.shape = (h, w)
        self.width = w + 2
        self.free_p = np.pad(grid.free, 1).astype(np.uint8).ravel()
        self.moves = move_mask(grid.free)
        padded = np.pad(grid.free, 1)
        self.rows, self.cols = bit_lines(padded), bit_lines(padded.T)
        self.buf = SearchBuffers(self.free_p.size)
        self.out_v = np.zeros(4 * (h + w + 4), np.int64)  # one node's successors: <= 2 per diagonal step
        self.out_k = np.zeros(4 * (h + w + 4), np.int64)
        self.stack = np.zeros(self.free_p.size, np.int32)  # reached nodes whose f equals their parent's
        b = self.buf
        self._buffers = (b.g, b.parent, b.state, b.mark, b.hk, b.hg, b.hn, b.hpos)  # mark: the arrival moves
        self.table = np.zeros((1, 8), np.int16)  # JPS+'s jump distances (unused here)
        self.use_table = False

    def _maps(self) -> tuple:
        """The kernels' map arguments: jump table, whether to use it, moves, free cells, row and column bits."""
        return self.table, self.use_table, self.moves, self.free_p, self.rows, self.cols

    def index(self, cell) -> int:
        """Padded flat index of a (row, col) cell."""
        return (int(cell[0]) + 1) * self.width + int(cell[1]) + 1

    def search(self, s: int, t: int) -> tuple[bool, int]:
        """Run the kernel between padded indices; (found, jump points expanded). Parents stay in ``buf``."""
        return _jps(*self._maps(), self.width, s, t, *self._buffers, self.buf.next_stamp(), _DR, _DC, self.out_v,
                    self.out_k, self.stack)  # fmt: skip

    def plan(self, start, goal) -> PlanResult:
        """Path between (row, col) cells; found=False with A*'s reasons when there is none."""
        t0 = time.perf_counter()
        code, expanded, path, length, jumps = _query(
            *self._maps(), *self.shape, int(start[0]), int(start[1]), int(goal[0]), int(goal[1]), *self._buffers,
            self.buf.next_stamp(), _DR, _DC, self.out_v, self.out_k, self.stack)  # fmt: skip
        if code == 0:
            return PlanResult(path, length, expanded, time.perf_counter() - t0, True, "", length,
                              self.grid.resolution, {"jump_points": jumps})  # fmt: skip
        if code == 3:
            why = (f"goal {tuple(int(v) for v in goal)} is unreachable from start {tuple(int(v) for v in start)} "
                   f"({expanded} jump points searched)")  # fmt: skip
        else:
            why = endpoint_problem(self.grid.free, start, "start") or endpoint_problem(self.grid.free, goal, "goal")
        return PlanResult.failure(why, expanded, time.perf_counter() - t0, self.grid.resolution)

    def plan_world(self, start_xy, goal_xy) -> PlanResult:
        """Path between world points (x, y) m (their containing cells)."""
        return self.plan(self.grid.world_to_cell(start_xy), self.grid.world_to_cell(goal_xy))


def jps(grid: PlanningGrid | np.ndarray, start, goal) -> PlanResult:
    """One-off JPS between (row, col) cells (allocates buffers; use :class:`JPS` for many queries)."""
    return JPS(grid).plan(start, goal)


@register_planner("jps")
def jps_planner(grid: PlanningGrid | np.ndarray) -> JPS:
    """Jump Point Search: A*'s optimal lengths (8-connected, no corner cutting), searching jump points only."""
    return JPS(grid)
