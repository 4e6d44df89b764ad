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
  stop every line and the diagonal at the first subgoal. Edges are stored both
  ways (CSR), the cost of an edge is the octile distance.

A query scans from the start and the goal the same way (start and goal join
the graph as extra nodes; one that is a subgoal is that node), links the start
to the goal directly when the start's scan meets it, and runs A* (octile
heuristic, consistent here) over the graph. The subgoal path is refined into
cells, each edge diagonal first then straight from whichever end that path
was found (it is free by construction), so the result is
:class:`~slam2d.planning.astar.PlanResult` with A*'s optimal length.
Costmaps are not supported: a non-zero ``cost`` layer raises ValueError.
"""

from __future__ import annotations

import time

import numpy as np
from numba import njit

from slam2d.planning.astar import _DC, _DR, PlanResult, SearchBuffers, _octile, _pop, _sift_up, \
    endpoint_problem, move_mask  # fmt: skip
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


@njit(inline="always")
def _line(free, sgid, x, step, mx, goal, out, m):
    """Scan the straight line from ``x`` by ``step``: at most ``mx`` free non-subgoal cells, then a
    subgoal (or the goal) at ``mx + 1`` at the farthest. Returns (free cells passed, m, goal met)."""
    p = 0
    y = x
    met = False
    while p <= mx:
        y += step
        if y == goal:
            met = True
        if free[y] == 0:
            break
        if sgid[y] >= 0:
            out[m] = y
            m += 1
            break
        if p == mx:
            break
        p += 1
    return p, m, met


@njit(cache=True)
def _scan(free, moves, sgid, width, s, goal, out, dr_of, dc_of):
    """The subgoals direct-h-reachable from padded cell ``s`` (module docstring) into ``out``, as
    padded cells; returns (their number, whether ``goal`` lies in the scanned region)."""
    m = 0
    met = False
    big = 1 << 40
    clear = np.empty(4, np.int64)
    for k in range(4):
        c, m, hit = _line(free, sgid, s, dr_of[k] * width + dc_of[k], big, goal, out, m)
        clear[k] = c
        met = met or hit
    for k in range(4, 8):
        dr = dr_of[k]
        dc = dc_of[k]
        kv = 0 if dr < 0 else 1
        kh = 2 if dc < 0 else 3
        mv = clear[kv]
        mh = clear[kh]
        step = dr * width + dc
        x = s
        while (moves[x] >> k) & 1:
            x += step
            if x == goal:
                met = True
            if sgid[x] >= 0:
                out[m] = x
                m += 1
                break
            mv, m, hit = _line(free, sgid, x, dr * width, mv, goal, out, m)
            met = met or hit
            mh, m, hit = _line(free, sgid, x, dc, mh, goal, out, m)
            met = met or hit
    return m, met


@njit(cache=True)
def _all_edges(free, moves, sgid, cells, width, out, dr_of, dc_of):
    """(src, dst) subgoal ids of every scan from every subgoal (one direction each)."""
    src = np.empty(16 * len(cells) + 16, np.int64)
    dst = np.empty_like(src)
    n = 0
    for i in range(len(cells)):
        m, _ = _scan(free, moves, sgid, width, cells[i], -1, out, dr_of, dc_of)
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
def _cost(a, b, width):
    ar = a // width
    br = b // width
    return _octile(ar, a - ar * width, br, b - br * width, True)


@njit(cache=True)
def _astar(indptr, nbr, cell, n_sub, width, s_node, t_node, s_list, ns, direct, goal_mark, stamp,
           g, parent, state, hk, hg, hn, hpos):  # fmt: skip
    """A* over the subgoal graph plus the start and goal nodes (``cell[node]`` padded cells); the
    start's links are ``s_list[:ns]`` when it is no subgoal, ``direct`` links it to the goal, and
    ``goal_mark[u] == stamp`` links subgoal ``u`` to the goal. Returns (found, nodes expanded)."""
    reached = 2 * stamp
    t = cell[t_node]
    tr = t // width
    tc = t - tr * width
    state[s_node] = reached
    g[s_node] = 0.0
    parent[s_node] = -1
    _sift_up(hk, hg, hn, hpos, 0, _cost(cell[s_node], t, width), 0.0, s_node)
    size = 1
    expanded = 0
    while size > 0:
        u, size = _pop(hk, hg, hn, hpos, size)
        state[u] = reached + 1
        expanded += 1
        if u == t_node:
            return True, expanded
        cu = cell[u]
        gu = g[u]
        if u < n_sub:
            lo, hi, src = indptr[u], indptr[u + 1], nbr
        else:
            lo, hi, src = 0, ns, s_list
        extra = (u == s_node and direct) or (u < n_sub and goal_mark[u] == stamp)
        for j in range(lo, hi + (1 if extra else 0)):
            v = src[j] if j < hi else t_node
            sv = state[v]
            if sv == reached + 1:
                continue
            cv = cell[v]
            ng = gu + _cost(cu, cv, width)
            if sv < reached:
                state[v] = reached
                g[v] = ng
                parent[v] = u
                vr = cv // width
                _sift_up(hk, hg, hn, hpos, size, ng + _octile(vr, cv - vr * width, tr, tc, True), ng, v)
                size += 1
            elif ng < g[v] - 1e-12:
                i = hpos[v]
                _sift_up(hk, hg, hn, hpos, i, ng + hk[i] - g[v], ng, v)
                g[v] = ng
                parent[v] = u
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
def _write_segment(a, b, width, out, i, forward):
    """Write the cells after ``a`` up to ``b`` (diagonal first from ``a``) into ``out`` from row ``i``
    on (or, ``forward`` False, the same cells from ``b`` back to ``a`` excluded). Returns the next row."""
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
    if not forward:
        out[i + n - 1, 0] = br - 1
        out[i + n - 1, 1] = bc - 1
    return i + n


@njit(cache=True)
def _refine(free, moves, width, parent, cell, t_node):
    """(L, 2) unpadded cells from the root to ``t_node``, the path's length and number of nodes."""
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
        chain[j] = cell[v]
        v = parent[v]
    out = np.empty((cells, 2), np.int64)
    r = chain[0] // width
    out[0, 0] = r - 1
    out[0, 1] = chain[0] - r * width - 1
    i = 1
    length = 0.0
    for j in range(nodes):
        a = chain[j]
        b = chain[j + 1]
        length += _cost(a, b, width)
        if _diag_first_ok(free, moves, width, a, b):
            i = _write_segment(a, b, width, out, i, True)
        else:  # found from b: diagonal first from b, written backwards
            i = _write_segment(b, a, width, out, i, False)
    return out, length, nodes + 1


@njit(cache=True)
def _query(free, moves, sgid, indptr, nbr, cell, n_sub, h, w, sr, sc, gr, gc, out, s_list, goal_mark, stamp,
           g, parent, state, hk, hg, hn, hpos, dr_of, dc_of):  # fmt: skip
    """One query between unpadded cells: (code, expanded, path, length, nodes on the path) with code 0
    found, 1 start unusable, 2 goal unusable, 3 unreachable."""
    width = w + 2
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
    ns, direct = _scan(free, moves, sgid, width, s, t, out, dr_of, dc_of)
    for j in range(ns):
        s_list[j] = sgid[out[j]]
    if t_node == n_sub + 1:
        m, _ = _scan(free, moves, sgid, width, t, -1, out, dr_of, dc_of)
        for j in range(m):
            goal_mark[sgid[out[j]]] = stamp
    found, expanded = _astar(indptr, nbr, cell, n_sub, width, s_node, t_node, s_list, ns, direct, goal_mark, stamp,
                             g, parent, state, hk, hg, hn, hpos)  # fmt: skip
    if not found:
        return 3, expanded, empty, np.inf, 0
    path, length, nodes = _refine(free, moves, width, parent, cell, t_node)
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
        self.sgid = np.full(self.free_p.size, -1, np.int64)
        self.sgid[cells] = np.arange(n)
        self.out = np.zeros(8 * (h + w + 4), np.int64)  # one scan's subgoals: <= 1 a line
        src, dst = _all_edges(self.free_p, self.moves, self.sgid, cells, width, self.out, _DR, _DC)
        key = np.unique(np.concatenate([src * n + dst, dst * n + src]))
        self.nbr = (key % max(n, 1)).astype(np.int64)
        self.indptr = np.searchsorted(key // max(n, 1), np.arange(n + 1)).astype(np.int64)
        self.cell = np.concatenate([cells, np.zeros(2, np.int64)])
        self.subgoals, self.edges = n, len(key) // 2
        self.s_list = np.zeros(len(self.out), np.int64)
        self.buf = SearchBuffers(n + 2)
        self.build_seconds = time.perf_counter() - t0

    def plan(self, start, goal) -> PlanResult:
        """Path between (row, col) cells; found=False with A*'s reasons when there is none."""
        t0 = time.perf_counter()
        b = self.buf
        stamp = b.next_stamp()
        code, expanded, path, length, nodes = _query(
            self.free_p, self.moves, self.sgid, self.indptr, self.nbr, self.cell, self.subgoals, *self.shape,
            int(start[0]), int(start[1]), int(goal[0]), int(goal[1]), self.out, self.s_list, b.mark, stamp,
            b.g, b.parent, b.state, b.hk, b.hg, b.hn, b.hpos, _DR, _DC)  # fmt: skip
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
