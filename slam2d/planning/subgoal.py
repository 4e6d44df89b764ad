"""Simple Subgoal Graphs (Uras, Koenig & Hernández, ICAPS 2013) on slam2d's grid, numba.

Same graph as :mod:`~slam2d.planning.astar`'s 8-connected A*: axial steps of 1,
diagonal steps of √2, a diagonal needs both side cells free (no corner cutting).

Preprocessing (``build_seconds``, wall time):

- *subgoals* are the free cells at convex obstacle corners: a diagonal neighbour
  is blocked while the two side cells shared with it are free (the cells a
  shortest path bends around);
- *edges* join subgoals that are direct-h-reachable: one reaches the other by a
  path that moves diagonally, then straight (its length is the octile distance)
  and passes no other subgoal. They are found from each subgoal by the paper's
  clearance scan: walk each diagonal while its moves are allowed; from every
  cell on it scan the two straight lines of that quadrant, each no farther than
  the previous line reached (so the scanned region is a free staircase), and
  stop every line and the diagonal at the first subgoal. A table of axial
  clearances (free non-subgoal cells before the next blocked cell or subgoal,
  int32, 4 a cell) makes each line one look-up. Edges are stored both ways
  (CSR), the cost of an edge is the octile distance.

A query scans from the start and the goal the same way (start and goal join
the graph as extra nodes; one that is a subgoal is that node). When the
start's scan meets the goal, the octile distance is the answer without search;
otherwise A* (octile heuristic, consistent here; a node whose f equals its
parent's is expanded next from a stack) runs over the graph. The subgoal path is refined into
cells, each edge diagonal first then straight from whichever end that path
was found (it is free by construction), so the result is
:class:`~slam2d.planning.astar.PlanResult` with A*'s optimal length.
Costmaps are not supported: a non-zero ``cost`` layer raises ValueError.
"""

from __future__ import annotations

import time

import numpy as np
from numba import njit

from slam2d.planning.astar import (
    _DC,
    _DR,
    SQRT2,
    PlanResult,
    _pop,
    _sift_up,
    endpoint_problem,
    move_mask,
)
from slam2d.planning.base import register_planner
from slam2d.planning.grid import PlanningGrid

__all__ = ["SubgoalGraph", "subgoal_mask"]


def subgoal_mask(free: np.ndarray) -> np.ndarray:
    """(H, W) bool: free cells with a blocked diagonal neighbour whose two shared side cells are free."""
    f = np.pad(np.asarray(free, dtype=bool), 1)
    h, w = f.shape
    core = f[1:-1, 1:-1]
    out = np.zeros_like(core)
    for dr in (-1, 1):
        for dc in (-1, 1):
            out |= (f[1 + dr : h - 1 + dr, 1:-1] & f[1:-1, 1 + dc : w - 1 + dc]
                    & ~f[1 + dr : h - 1 + dr, 1 + dc : w - 1 + dc])  # fmt: skip
    return core & out


@njit(cache=True)
def _clearances(free, sgid, h, w, dr_of, dc_of):
    """((h + 2) (w + 2), 4) int32: per free padded cell and axial move (astar.py's order), the free
    non-subgoal cells passed before a blocked cell or a subgoal."""
    width = w + 2
    clear = np.zeros(((h + 2) * width, 4), np.int32)
    for k in range(4):
        dr = dr_of[k]
        dc = dc_of[k]
        step = dr * width + dc
        r_first, r_last, r_inc = (h, 0, -1) if dr > 0 else (1, h + 1, 1)
        c_first, c_last, c_inc = (w, 0, -1) if dc > 0 else (1, w + 1, 1)
        for r in range(r_first, r_last, r_inc):
            for c in range(c_first, c_last, c_inc):
                n = r * width + c
                m = n + step
                if free[n] != 0 and free[m] != 0 and sgid[m] < 0:
                    clear[n, k] = clear[m, k] + 1
    return clear


@njit(inline="always")
def _line(clear, sgid, x, xr, xc, k, step, dr, dc, mx, gr, gc, out, m):
    """The straight line from ``x`` = (xr, xc) by move ``k`` = (dr, dc): at most ``mx`` free non-subgoal
    cells, then a subgoal (recorded in ``out``) or the goal at ``mx + 1`` at the farthest. Returns
    (free cells passed, m, whether the goal (gr, gc) is on it)."""
    c = clear[x, k]
    p = min(c, mx)
    if c <= mx:
        y = x + (c + 1) * step
        if sgid[y] >= 0:
            out[m] = y
            m += 1
    if dr == 0:
        q = (gc - xc) * dc
        met = gr == xr and 1 <= q <= p + 1
    else:
        q = (gr - xr) * dr
        met = gc == xc and 1 <= q <= p + 1
    return p, m, met


@njit(cache=True)
def _scan(clear, moves, sgid, width, s, goal, out, dr_of, dc_of):
    """The subgoals direct-h-reachable from padded cell ``s`` (module docstring) into ``out``, as
    padded cells; returns (their number, whether ``goal`` (-1: none) lies in the scanned region)."""
    m = 0
    met = False
    big = 1 << 40
    sr = s // width
    sc = s - sr * width
    gr = goal // width if goal >= 0 else -(1 << 40)
    gc = goal - gr * width if goal >= 0 else -(1 << 40)
    cl = np.empty(4, np.int64)
    for k in range(4):
        dr = dr_of[k]
        dc = dc_of[k]
        cl[k], m, hit = _line(clear, sgid, s, sr, sc, k, dr * width + dc, dr, dc, big, gr, gc, out, m)
        met = met or hit
    for k in range(4, 8):
        dr = dr_of[k]
        dc = dc_of[k]
        kv = 0 if dr < 0 else 1
        kh = 2 if dc < 0 else 3
        mv = cl[kv]
        mh = cl[kh]
        step = dr * width + dc
        x = s
        xr = sr
        xc = sc
        while (moves[x] >> k) & 1:
            x += step
            xr += dr
            xc += dc
            if x == goal:
                met = True
            if sgid[x] >= 0:
                out[m] = x
                m += 1
                break
            mv, m, hit = _line(clear, sgid, x, xr, xc, kv, dr * width, dr, 0, mv, gr, gc, out, m)
            met = met or hit
            mh, m, hit = _line(clear, sgid, x, xr, xc, kh, dc, 0, dc, mh, gr, gc, out, m)
            met = met or hit
    return m, met


@njit(cache=True)
def _all_edges(clear, moves, sgid, cells, width, out, dr_of, dc_of):
    """(src, dst) subgoal ids of every scan from every subgoal (one direction each)."""
    src = np.empty(16 * len(cells) + 16, np.int64)
    dst = np.empty_like(src)
    n = 0
    for i in range(len(cells)):
        m, _ = _scan(clear, moves, sgid, width, cells[i], -1, out, dr_of, dc_of)
        if n + m > len(src):
            grow = max(2 * len(src), n + m)
            src2 = np.empty(grow, np.int64)
            dst2 = np.empty(grow, np.int64)
            src2[:n] = src[:n]
            dst2[:n] = dst[:n]
            src, dst = src2, dst2
        for j in range(m):
            src[n] = i
            dst[n] = sgid[out[j]]
            n += 1
    return src[:n], dst[:n]


@njit(inline="always")
def _oct(ar, ac, br, bc):
    dy = abs(ar - br)
    dx = abs(ac - bc)
    return dx + dy + (SQRT2 - 2.0) * min(dx, dy)


@njit(cache=True)
def _astar(indptr, nbr, wgt, nr, nc, n_sub, s_node, t_node, s_list, ns, direct, goal_mark, stamp,
           g, parent, state, hk, hg, hn, hpos, stack, fwd):  # fmt: skip
    """A* over the subgoal graph (arcs ``nbr`` of cost ``|wgt|``, CSR; negative when the arc's cells
    run diagonally first from its head, not its tail) plus the start and goal nodes
    (node ``i`` at padded row ``nr[i]``, column ``nc[i]``); the start's links are ``s_list[:ns]`` when
    it is no subgoal, ``direct`` links it to the goal, and ``goal_mark[u] == stamp`` links subgoal ``u``
    to the goal. A node whose f equals its parent's is expanded next from ``stack``, without the heap
    (as in jps.py). ``fwd[v]`` is 1 when the cells from ``parent[v]`` to ``v`` run diagonally first
    from ``parent[v]``, 0 when from ``v``. Returns (found, nodes expanded)."""
    reached = 2 * stamp
    tr = nr[t_node]
    tc = nc[t_node]
    state[s_node] = reached
    g[s_node] = 0.0
    parent[s_node] = -1
    _sift_up(hk, hg, hn, hpos, 0, _oct(nr[s_node], nc[s_node], tr, tc), 0.0, s_node)
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
        if u == t_node:
            return True, expanded
        ur = nr[u]
        uc = nc[u]
        gu = g[u]
        fu = gu + _oct(ur, uc, tr, tc)
        sub = u < n_sub
        lo, hi = (indptr[u], indptr[u + 1]) if sub else (0, ns)
        extra = (u == s_node and direct) or (sub and goal_mark[u] == stamp)
        for j in range(lo, hi + (1 if extra else 0)):
            if j < hi:
                v = nbr[j] if sub else s_list[j]
                if state[v] == reached + 1:
                    continue
                ng = gu + (abs(wgt[j]) if sub else _oct(ur, uc, nr[v], nc[v]))
            else:
                v = t_node
                ng = gu + _oct(ur, uc, tr, tc)
            sv = state[v]
            if sv < reached:
                state[v] = reached
                g[v] = ng
                parent[v] = u
                fwd[v] = (wgt[j] > 0 if sub else True) if j < hi else False  # goal links: from the goal
                fv = ng + _oct(nr[v], nc[v], tr, tc)
                if fv <= fu + 1e-9:  # f does not grow: next, without the heap
                    hpos[v] = -1
                    stack[top] = v
                    top += 1
                else:
                    _sift_up(hk, hg, hn, hpos, size, fv, ng, v)
                    size += 1
            elif sv == reached and ng < g[v] - 1e-12:
                i = hpos[v]
                if i >= 0:
                    _sift_up(hk, hg, hn, hpos, i, ng + hk[i] - g[v], ng, v)
                g[v] = ng
                parent[v] = u
                fwd[v] = (wgt[j] > 0 if sub else True) if j < hi else False
    return False, expanded


@njit(inline="always")
def _sign(x):
    return (x > 0) - (x < 0)


@njit(cache=True)
def _diag_first_ok(free, moves, width, a, b):
    """Whether the path from padded ``a`` to ``b`` moving diagonally first, then straight, is free."""
    ar = a // width
    ac = a - ar * width
    br = b // width
    bc = b - br * width
    sr = _sign(br - ar)
    sc = _sign(bc - ac)
    nd = min(abs(br - ar), abs(bc - ac))
    k = 4 + (2 if sr > 0 else 0) + (1 if sc > 0 else 0)
    x = a
    for _ in range(nd):
        if not (moves[x] >> k) & 1:
            return False
        x += sr * width + sc
    step = sr * width if abs(br - ar) > abs(bc - ac) else sc
    while x != b:
        x += step
        if free[x] == 0:
            return False
    return True


@njit(cache=True)
def _diag_first_all(free, moves, width, a, b):
    """:func:`_diag_first_ok` of every pair ``a[i]``, ``b[i]`` (bool)."""
    ok = np.empty(len(a), np.bool_)
    for i in range(len(a)):
        ok[i] = _diag_first_ok(free, moves, width, a[i], b[i])
    return ok


@njit(cache=True)
def _write_segment(a, b, width, out, i, forward):
    """Write the cells after ``a`` up to ``b`` (diagonal first from ``a``) into ``out`` from row ``i``
    on (or, ``forward`` False, those cells reversed: ``b`` left out, ``a`` written last). Returns the
    next row."""
    ar = a // width
    ac = a - ar * width
    br = b // width
    bc = b - br * width
    n = max(abs(br - ar), abs(bc - ac))
    r, c = ar, ac
    for j in range(n):
        dr = br - r
        dc = bc - c
        if dr != 0 and dc != 0:
            r += _sign(dr)
            c += _sign(dc)
        elif dr != 0:
            r += _sign(dr)
        else:
            c += _sign(dc)
        row = i + j if forward else i + n - 2 - j  # backwards: b's side first; a itself is not written
        if forward or j < n - 1:
            out[row, 0] = r - 1
            out[row, 1] = c - 1
    if not forward:  # the walk's origin ``a`` ends the written cells
        out[i + n - 1, 0] = ar - 1
        out[i + n - 1, 1] = ac - 1
    return i + n


@njit(cache=True)
def _refine(width, parent, fwd, cell, t_node):
    """(L, 2) unpadded cells from the root to ``t_node`` (each edge diagonal first from the end
    ``fwd`` names, see :func:`_astar`), the path's length and number of nodes."""
    nodes = 0
    cells = 1
    v = t_node
    while parent[v] != -1:
        a = cell[parent[v]]
        b = cell[v]
        ar = a // width
        br = b // width
        cells += max(abs(ar - br), abs((a - ar * width) - (b - br * width)))
        nodes += 1
        v = parent[v]
    chain = np.empty(nodes + 1, np.int64)
    v = t_node
    for j in range(nodes, -1, -1):
        chain[j] = v
        v = parent[v]
    out = np.empty((cells, 2), np.int64)
    r = cell[chain[0]] // width
    out[0, 0] = r - 1
    out[0, 1] = cell[chain[0]] - r * width - 1
    i = 1
    length = 0.0
    for j in range(nodes):
        a = cell[chain[j]]
        b = cell[chain[j + 1]]
        length += _oct(a // width, a % width, b // width, b % width)
        if fwd[chain[j + 1]]:
            i = _write_segment(a, b, width, out, i, True)
        else:  # found from b: diagonal first from b, written backwards
            i = _write_segment(b, a, width, out, i, False)
    return out, length, nodes + 1


@njit(cache=True)
def _query(maps, clear, gi, wgt, n_sub, n_arcs, h, w, sr, sc, gr, gc, scratch, fbuf, ibuf, stamp):
    """One query between unpadded cells: (code, expanded, path, length, nodes on the path) with code 0
    found, 1 start unusable, 2 goal unusable, 3 unreachable. Few arguments (a call's overhead grows with
    them): ``maps`` rows free, moves; ``gi`` sgid, indptr, arcs, node cells, rows, columns in a row;
    ``scratch`` rows: one scan's cells, the start's links; ``fbuf`` rows g, heap f, heap g; ``ibuf``
    rows parent, state, heap node, heap slot, goal marks, stack, edge sides."""
    width = w + 2
    free = maps[0]
    moves = maps[1]
    npad = free.size
    sgid = gi[:npad]
    indptr = gi[npad : npad + n_sub + 1]
    o = npad + n_sub + 1
    nbr = gi[o : o + n_arcs]
    o += n_arcs
    cell = gi[o : o + n_sub + 2]
    nr = gi[o + n_sub + 2 : o + 2 * (n_sub + 2)]
    nc = gi[o + 2 * (n_sub + 2) : o + 3 * (n_sub + 2)]
    out = scratch[0]
    s_list = scratch[1]
    empty = np.zeros((0, 2), np.int64)
    if not (0 <= sr < h and 0 <= sc < w and free[(sr + 1) * width + sc + 1] != 0):
        return 1, 0, empty, np.inf, 0
    if not (0 <= gr < h and 0 <= gc < w and free[(gr + 1) * width + gc + 1] != 0):
        return 2, 0, empty, np.inf, 0
    s = (sr + 1) * width + sc + 1
    t = (gr + 1) * width + gc + 1
    if s == t:
        path = np.empty((1, 2), np.int64)
        path[0, 0] = sr
        path[0, 1] = sc
        return 0, 0, path, 0.0, 1
    s_node = sgid[s] if sgid[s] >= 0 else n_sub
    t_node = sgid[t] if sgid[t] >= 0 else n_sub + 1
    cell[n_sub] = s
    cell[n_sub + 1] = t
    nr[n_sub], nc[n_sub] = sr + 1, sc + 1
    nr[n_sub + 1], nc[n_sub + 1] = gr + 1, gc + 1
    goal_mark = ibuf[4]
    ns, direct = _scan(clear, moves, sgid, width, s, t, out, _DR, _DC)
    for j in range(ns):
        s_list[j] = sgid[out[j]]
    parent = ibuf[0]
    if direct:  # the octile distance: a shortest path, no search needed
        parent[s_node] = -1
        parent[t_node] = s_node
        ibuf[6, t_node] = 1
        path, length, nodes = _refine(width, parent, ibuf[6], cell, t_node)
        return 0, 1, path, length, nodes
    if t_node == n_sub + 1:
        m, _ = _scan(clear, moves, sgid, width, t, -1, out, _DR, _DC)
        for j in range(m):
            goal_mark[sgid[out[j]]] = stamp
    found, expanded = _astar(indptr, nbr, wgt, nr, nc, n_sub, s_node, t_node, s_list, ns, direct, goal_mark, stamp,
                             fbuf[0], parent, ibuf[1], fbuf[1], fbuf[2], ibuf[2], ibuf[3], ibuf[5],
                             ibuf[6])  # fmt: skip
    if not found:
        return 3, expanded, empty, np.inf, 0
    path, length, nodes = _refine(width, parent, ibuf[6], cell, t_node)
    return 0, expanded, path, length, nodes


class SubgoalGraph:
    """Simple Subgoal Graph over a :class:`PlanningGrid` (or a bool mask, resolution 1): A*'s moves and
    optimal lengths (8-connected, no corner cutting). Built once (``build_seconds`` wall time,
    ``subgoals``, ``edges`` undirected); ``expanded`` counts graph nodes. ``cost``: None or all zero."""

    name = "SSG"

    def __init__(self, grid: PlanningGrid | np.ndarray, cost: np.ndarray | None = None):
        t0 = time.perf_counter()
        if not isinstance(grid, PlanningGrid):
            grid = PlanningGrid(np.asarray(grid, dtype=bool))
        if cost is not None and np.any(np.asarray(cost) != 0):
            raise ValueError(f"{self.name} needs uniform step costs: a non-zero cost layer breaks its edges "
                             "(plan with the 'astar' planner on a costmap)")  # fmt: skip
        self.grid = grid
        h, w = grid.shape
        self.shape = (h, w)
        self.width = width = w + 2
        self.free_p = np.pad(grid.free, 1).astype(np.uint8).ravel()
        self.moves = move_mask(grid.free)
        sub = np.pad(subgoal_mask(grid.free), 1).ravel()
        cells = np.flatnonzero(sub).astype(np.int64)
        n = len(cells)
        sgid = np.full(self.free_p.size, -1, np.int64)
        sgid[cells] = np.arange(n)
        out = np.zeros(8 * (h + w + 4), np.int64)  # one scan's subgoals: <= 1 a line
        self.clear = _clearances(self.free_p, sgid, h, w, _DR, _DC)
        src, dst = _all_edges(self.clear, self.moves, sgid, cells, width, out, _DR, _DC)
        key = np.unique(np.concatenate([src * n + dst, dst * n + src]))
        nbr = key % max(n, 1)
        indptr = np.searchsorted(key // max(n, 1), np.arange(n + 1))
        cell = np.concatenate([cells, [0, 0]])
        tail, head = cells[key // max(n, 1)], cells[nbr]
        ok = _diag_first_all(self.free_p, self.moves, width, tail, head)  # else: diagonal first from the head
        dy, dx = np.abs(tail // width - head // width), np.abs(tail % width - head % width)
        self.wgt = np.where(ok, 1.0, -1.0) * (dx + dy + (SQRT2 - 2.0) * np.minimum(dx, dy))
        self.subgoals, self.edges, self.arcs = n, len(key) // 2, len(key)
        self.gi = np.concatenate([sgid, indptr, nbr, cell, cell // width, cell % width]).astype(np.int64)
        self.maps = np.stack([self.free_p, self.moves])
        self.scratch = np.zeros((2, len(out)), np.int64)
        self.fbuf = np.zeros((3, n + 2), np.float64)
        self.ibuf = np.zeros((7, n + 2), np.int32)
        self.stamp = 0
        self.build_seconds = time.perf_counter() - t0

    def plan(self, start, goal) -> PlanResult:
        """Path between (row, col) cells; found=False with A*'s reasons when there is none."""
        t0 = time.perf_counter()
        self.stamp += 1
        if self.stamp >= 2**30 - 2:  # stamps wrap around: clear the states and goal marks
            self.ibuf[1:] = 0
            self.stamp = 1
        code, expanded, path, length, nodes = _query(
            self.maps, self.clear, self.gi, self.wgt, self.subgoals, self.arcs, *self.shape, int(start[0]),
            int(start[1]), int(goal[0]), int(goal[1]), self.scratch, self.fbuf, self.ibuf, self.stamp)
        if code == 0:
            return PlanResult(path, length, expanded, time.perf_counter() - t0, True, "", length,
                              self.grid.resolution, {"subgoals": nodes})  # fmt: skip
        if code == 3:
            why = (f"goal {tuple(int(v) for v in goal)} is unreachable from start {tuple(int(v) for v in start)} "
                   f"({expanded} graph nodes searched)")  # fmt: skip
        else:
            why = endpoint_problem(self.grid.free, start, "start") or endpoint_problem(self.grid.free, goal, "goal")
        return PlanResult.failure(why, expanded, time.perf_counter() - t0, self.grid.resolution)

    def plan_world(self, start_xy, goal_xy) -> PlanResult:
        """Path between world points (x, y) m (their containing cells)."""
        return self.plan(self.grid.world_to_cell(start_xy), self.grid.world_to_cell(goal_xy))


@register_planner("subgoal")
def subgoal_planner(grid: PlanningGrid | np.ndarray) -> SubgoalGraph:
    """Simple Subgoal Graph: A*'s optimal lengths (8-connected, no corner cutting) over corner subgoals."""
    return SubgoalGraph(grid)
