"""HPA*: hierarchical path-finding over square clusters of the grid.

HPA* (Botea, Müller, Schaeffer, "Near optimal hierarchical path-finding",
J. Game Development 1(1), 2004):

- the grid is cut into ``cluster_size`` square clusters (the last row and
  column of clusters may be smaller);
- an *entrance* is a maximal run of free cell pairs straddling the border of
  two adjacent clusters; a run shorter than ``two_transitions_from`` (6 in the
  paper) gets one transition in its middle, a longer one two, at its ends;
- each transition gives two abstract nodes (one cell on each side) joined by
  an inter-edge of one step; nodes of the same cluster are joined by
  intra-edges whose cost is the shortest path inside the cluster (Dijkstra
  bounded to the cluster, numba);
- the abstract graph is built once per map (``build_seconds``) and reused. A
  query connects start and goal to the nodes of their clusters (bounded
  Dijkstra), runs A* on the abstract graph (numba, octile heuristic), refines
  each abstract edge with A* bounded to its cluster, and optionally smooths
  the path (:func:`~slam2d.planning.smoothing.smooth_octile`). When start and
  goal clusters coincide or touch, an A* bounded to the two clusters gives a
  direct start-goal edge as well (short queries then avoid the detour
  through transition cells).

The abstraction is complete: every border crossing lies in an entrance whose
cells are connected along the border, so an existing path is always found.

The room-graph planner is :mod:`~slam2d.planning.room_graph`.
"""

from __future__ import annotations

import time

import numpy as np
from numba import njit

from slam2d.planning.astar import (
    AStar,
    PlanResult,
    SearchBuffers,
    _search,
    endpoint_problem,
    path_cost,
    path_length,
)
from slam2d.planning.base import register_planner
from slam2d.planning.graph_search import _abstract_search, _trace_from, _trace_ids
from slam2d.planning.grid import PlanningGrid
from slam2d.planning.smoothing import smooth_octile

__all__ = ["HPAStar", "entrances"]


# ---------------------------------------------------------------- HPA* build


def _runs_to_transitions(pairs: np.ndarray, block: int, two_from: int) -> tuple[np.ndarray, np.ndarray]:
    """Transitions along axis 0 of ``pairs`` (n, borders) bool, runs cut at multiples of ``block``.

    Returns (position along the border, border index) of every transition.
    """
    n = pairs.shape[0]
    idx = np.arange(n)[:, None]
    prev = np.zeros_like(pairs)
    prev[1:] = pairs[:-1]
    prev &= idx % block != 0
    nxt = np.zeros_like(pairs)
    nxt[:-1] = pairs[1:]
    nxt &= (idx + 1) % block != 0
    sk, sa = np.nonzero((pairs & ~prev).T)  # border-major order: starts and ends pair up
    _, eb = np.nonzero((pairs & ~nxt).T)
    single = (eb - sa + 1) < two_from
    pos = np.concatenate([(sa + eb)[single] // 2, sa[~single], eb[~single]])
    border = np.concatenate([sk[single], sk[~single], sk[~single]])
    return pos, border


def entrances(free: np.ndarray, cluster_size: int, two_transitions_from: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """Transition cell pairs of HPA*: two (T, 2) (row, col) arrays, ``a`` and ``b`` adjacent
    across a cluster border (``a`` on the lower-index side)."""
    free = np.asarray(free, dtype=bool)
    h, w = free.shape
    c = cluster_size
    xs = np.arange(c - 1, w - 1, c)
    ys = np.arange(c - 1, h - 1, c)
    rows, kx = _runs_to_transitions(free[:, xs] & free[:, xs + 1], c, two_transitions_from)
    cols, ky = _runs_to_transitions((free[ys, :] & free[ys + 1, :]).T, c, two_transitions_from)
    a = np.concatenate([np.stack([rows, xs[kx]], 1), np.stack([ys[ky], cols], 1)]).reshape(-1, 2)
    b = np.concatenate([np.stack([rows, xs[kx] + 1], 1), np.stack([ys[ky] + 1, cols], 1)]).reshape(-1, 2)
    return a.astype(np.int64), b.astype(np.int64)


@njit(inline="always")
def _cluster_bounds(cl, csize, ncols, h, w):
    ci = cl // ncols
    cj = cl - ci * ncols
    return ci * csize + 1, min((ci + 1) * csize, h), cj * csize + 1, min((cj + 1) * csize, w)


@njit(cache=True)
def _cluster_of(p, width, csize, ncols):
    r = p // width - 1
    c = p - (r + 1) * width - 1
    return (r // csize) * ncols + c // csize


@njit(cache=True)
def _intra_edges(moves, zone, cost, use_cost, width, conn8, csize, ncols, h, w, cells, offsets,
                 g, parent, state, hk, hg, hn, hpos, stamp):  # fmt: skip
    """Intra-cluster edges (u, v, cost) between nodes of each cluster; ``cells`` sorted by cluster."""
    m = 0
    for cl in range(offsets.shape[0] - 1):
        k = offsets[cl + 1] - offsets[cl]
        m += k * (k - 1) // 2
    eu = np.empty(m, np.int64)
    ev = np.empty(m, np.int64)
    ew = np.empty(m, np.float64)
    m = 0
    expanded = 0
    for cl in range(offsets.shape[0] - 1):
        lo = offsets[cl]
        hi = offsets[cl + 1]
        if hi - lo < 2:
            continue
        r0, r1, c0, c1 = _cluster_bounds(cl, csize, ncols, h, w)
        for a in range(lo, hi - 1):
            stamp += 1
            _, e = _search(moves, zone, 0, cost, use_cost, width, cells[a], -1, conn8, r0, r1, c0, c1,
                           g, parent, state, hk, hg, hn, hpos, stamp)  # fmt: skip
            expanded += e
            for b in range(a + 1, hi):
                if state[cells[b]] == 2 * stamp + 1:
                    eu[m] = a
                    ev[m] = b
                    ew[m] = g[cells[b]]
                    m += 1
    return eu[:m], ev[:m], ew[:m], stamp, expanded


@njit(cache=True)
def _connect(moves, zone, cost, use_cost, width, conn8, csize, ncols, h, w, src, cells, lo, hi, other,
             g, parent, state, hk, hg, hn, hpos, stamp):  # fmt: skip
    """Bounded Dijkstra from ``src`` in its cluster: costs to nodes ``lo..hi`` (inf if cut off)
    and to cell ``other`` (inf if outside the cluster or unreachable); nodes expanded."""
    cl = _cluster_of(src, width, csize, ncols)
    r0, r1, c0, c1 = _cluster_bounds(cl, csize, ncols, h, w)
    _, e = _search(moves, zone, 0, cost, use_cost, width, src, -1, conn8, r0, r1, c0, c1,
                   g, parent, state, hk, hg, hn, hpos, stamp)  # fmt: skip
    out = np.full(hi - lo, np.inf)
    for i in range(lo, hi):
        if state[cells[i]] == 2 * stamp + 1:
            out[i - lo] = g[cells[i]]
    direct = g[other] if state[other] == 2 * stamp + 1 else np.inf
    return out, direct, e


@njit(cache=True)
def _refine(moves, zone, cost, use_cost, width, conn8, csize, ncols, h, w, cells,
            g, parent, state, hk, hg, hn, hpos, stamp):  # fmt: skip
    """Concrete path through the padded cells ``cells`` (consecutive ones share a cluster or
    are adjacent). Returns (padded path, expanded, last stamp, ok)."""
    k = cells.shape[0]
    out = np.empty(k + (k - 1) * csize * csize, np.int64)
    out[0] = cells[0]
    m = 1
    expanded = 0
    for i in range(k - 1):
        a = cells[i]
        b = cells[i + 1]
        if a == b:
            continue
        cl = _cluster_of(a, width, csize, ncols)
        if cl != _cluster_of(b, width, csize, ncols):
            out[m] = b
            m += 1
            continue
        r0, r1, c0, c1 = _cluster_bounds(cl, csize, ncols, h, w)
        stamp += 1
        found, e = _search(moves, zone, 0, cost, use_cost, width, a, b, conn8, r0, r1, c0, c1,
                           g, parent, state, hk, hg, hn, hpos, stamp)  # fmt: skip
        expanded += e
        if not found:
            return out[:m], expanded, stamp, False
        n = 0
        v = b
        while v != a:
            n += 1
            v = parent[v]
        v = b
        for j in range(n - 1, -1, -1):
            out[m + j] = v
            v = parent[v]
        m += n
    return out[:m], expanded, stamp, True


class HPAStar:
    """HPA* planner: abstract graph built once per grid, reused by every :meth:`plan`.

    ``cluster_size`` cells per cluster side; ``two_transitions_from`` entrance
    width from which an entrance gets two transitions (paper: 6); ``smooth``
    applies :func:`~slam2d.planning.smoothing.smooth_octile` to each path
    (8-connected grids only).
    Figures of the abstraction: ``build_seconds``, ``n_nodes``, ``n_edges``.
    """

    def __init__(self, grid: PlanningGrid | np.ndarray, cluster_size: int = 16, connectivity: int = 8,
                 cost: np.ndarray | None = None, two_transitions_from: int = 6, smooth: bool = True):  # fmt: skip
        if cluster_size < 2:
            raise ValueError(f"cluster_size must be >= 2, got {cluster_size}")
        self.low = AStar(grid, connectivity, cost)
        self.grid = self.low.grid
        self.cluster_size = int(cluster_size)
        self.two_transitions_from = int(two_transitions_from)
        self.smooth = smooth and connectivity == 8
        t0 = time.perf_counter()
        self._build()
        self.build_seconds = time.perf_counter() - t0

    # -- build
    def _kernel_args(self):
        lo = self.low
        h, w = self.grid.shape
        return (lo.moves, lo.buf.zone, lo.cost_p, lo.use_cost, lo.width, lo.connectivity == 8,
                self.cluster_size, self.ncols, h, w)  # fmt: skip

    def _buffers(self):
        return self.low.buf.arrays()

    def _build(self) -> None:
        lo = self.low
        h, w = self.grid.shape
        c = self.cluster_size
        self.ncols = -(-w // c)
        self.nclusters = (-(-h // c)) * self.ncols
        a, b = entrances(self.grid.free, c, self.two_transitions_from)
        pa = (a[:, 0] + 1) * lo.width + a[:, 1] + 1
        pb = (b[:, 0] + 1) * lo.width + b[:, 1] + 1
        cells, inverse = np.unique(np.concatenate([pa, pb]), return_inverse=True)
        rows = cells // lo.width - 1
        cols = cells - (rows + 1) * lo.width - 1
        cluster = (rows // c) * self.ncols + cols // c
        order = np.argsort(cluster, kind="stable")
        rank = np.empty_like(order)
        rank[order] = np.arange(len(order))
        self.node_cell = cells[order]
        self.node_r = rows[order]
        self.node_c = cols[order]
        self.offsets = np.searchsorted(cluster[order], np.arange(self.nclusters + 1)).astype(np.int64)
        iu = rank[inverse[: len(pa)]]
        iv = rank[inverse[len(pa) :]]
        iw = np.ones(len(iu))
        if lo.use_cost:
            iw = 1.0 + 0.5 * (lo.cost[a[:, 0], a[:, 1]] + lo.cost[b[:, 0], b[:, 1]])
        first = lo.buf.reserve(len(self.node_cell) + 1)
        eu, ev, ew, _, self.build_expanded = _intra_edges(
            *self._kernel_args(), self.node_cell, self.offsets, *self._buffers(), first
        )
        self._csr(np.concatenate([iu, eu]), np.concatenate([iv, ev]), np.concatenate([iw, ew]))
        n = len(self.node_cell)
        self.abuf = SearchBuffers(n + 2)
        self.goal_w = np.full(n, np.inf)

    def _csr(self, u, v, wt) -> None:
        src = np.concatenate([u, v])
        dst = np.concatenate([v, u])
        w = np.concatenate([wt, wt])
        order = np.argsort(src, kind="stable")
        n = len(self.node_cell)
        self.indptr = np.concatenate([[0], np.cumsum(np.bincount(src, minlength=n))]).astype(np.int64)
        self.nbr = dst[order].astype(np.int64)
        self.wt = w[order]
        self.n_nodes = n
        self.n_edges = len(u)

    # -- query
    def plan(self, start, goal) -> PlanResult:
        """Path between (row, col) cells; found=False with a reason when there is none."""
        t0 = time.perf_counter()
        res = self.grid.resolution
        for cell, which in ((start, "start"), (goal, "goal")):
            why = endpoint_problem(self.grid.free, cell, which)
            if why:
                return PlanResult.failure(why, 0, time.perf_counter() - t0, res)
        lo = self.low
        s, t = lo.index(start), lo.index(goal)
        k = self._kernel_args()
        cs = int((int(start[0]) // self.cluster_size) * self.ncols + int(start[1]) // self.cluster_size)
        cg = int((int(goal[0]) // self.cluster_size) * self.ncols + int(goal[1]) // self.cluster_size)
        s_lo, s_hi = self.offsets[cs], self.offsets[cs + 1]
        g_lo, g_hi = self.offsets[cg], self.offsets[cg + 1]
        s_w, direct, e1 = _connect(*k, s, self.node_cell, s_lo, s_hi, t, *self._buffers(), lo.buf.next_stamp())
        g_w, _, e2 = _connect(*k, t, self.node_cell, g_lo, g_hi, s, *self._buffers(), lo.buf.next_stamp())
        local, e_local = self._local(start, goal, s, t)
        if local is not None:
            direct = min(direct, local[1])
        self.goal_w[g_lo:g_hi] = g_w
        ab = self.abuf
        found, e3 = _abstract_search(
            self.indptr, self.nbr, self.wt, self.node_r, self.node_c, np.arange(s_lo, s_hi), s_w, self.goal_w,
            direct, int(start[0]), int(start[1]), int(goal[0]), int(goal[1]),
            *ab.arrays(), ab.next_stamp(),
        )  # fmt: skip
        self.goal_w[g_lo:g_hi] = np.inf
        expanded = e1 + e2 + e3 + e_local
        if not found:
            return PlanResult.failure(
                f"goal {tuple(int(v) for v in goal)} is unreachable from start {tuple(int(v) for v in start)}",
                expanded, time.perf_counter() - t0, res, abstract_expanded=e3,
            )  # fmt: skip
        route = self._abstract_route(s, t)
        if len(route) == 2 and local is not None and local[1] <= direct:
            cells, e4, ok = local[0], 0, True  # the direct path through the neighbouring clusters
        else:
            first = lo.buf.reserve(len(route) + 1)
            cells, e4, _, ok = _refine(*k, route, *self._buffers(), first)
        expanded += e4
        if not ok:  # cannot happen on a consistent abstraction; say so rather than fail silently
            return PlanResult.failure("internal error: an abstract edge could not be refined", expanded,
                                      time.perf_counter() - t0, res)  # fmt: skip
        rows = cells // lo.width
        path = np.stack([rows - 1, cells - rows * lo.width - 1], axis=1)
        raw_length = path_length(path)
        if self.smooth:
            b = lo.buf
            path = smooth_octile(self.grid.free, path, buffers=(lo.free_p, lo.width, b.mark, b.hpos, b.next_stamp()))
        info = {"abstract_expanded": int(e3), "abstract_nodes": int(len(route)), "raw_length": raw_length}
        return PlanResult(path, path_length(path), int(expanded), time.perf_counter() - t0, True, "",
                          path_cost(path, lo.cost), res, info)  # fmt: skip

    def _local(self, start, goal, s: int, t: int):
        """When start and goal clusters touch (or coincide): A* bounded to their bounding box.

        Returns ((padded path, cost) or None, expanded). Its cost becomes the
        direct start-goal edge of the abstract search, which removes HPA*'s
        detours through transitions on short queries.
        """
        c = self.cluster_size
        ci, cj = int(start[0]) // c, int(start[1]) // c
        gi, gj = int(goal[0]) // c, int(goal[1]) // c
        if abs(ci - gi) > 1 or abs(cj - gj) > 1:
            return None, 0
        h, w = self.grid.shape
        r0, r1 = min(ci, gi) * c + 1, min((max(ci, gi) + 1) * c, h)
        c0, c1 = min(cj, gj) * c + 1, min((max(cj, gj) + 1) * c, w)
        bounds = (r0, r1, c0, c1)
        found, e = self.low.search(s, t, bounds=bounds)
        if not found:
            return None, e
        return (_trace_from(self.low.buf.parent, s, t, self.low.width), float(self.low.buf.g[t])), e

    def _abstract_route(self, s: int, t: int) -> np.ndarray:
        """Padded cells: start, abstract nodes, goal."""
        n = self.n_nodes
        ids = _trace_ids(self.abuf.parent, n + 1)
        cells = np.empty(len(ids), np.int64)
        inner = ids[1:-1]
        cells[1:-1] = self.node_cell[inner]
        cells[0], cells[-1] = s, t
        return cells


@register_planner("hpa")
def hpa_planner(grid: PlanningGrid | np.ndarray, cluster_size: int = 16) -> HPAStar:
    """HPA*: A* over the entrances of square clusters of ``cluster_size`` cells, refined inside them."""
    return HPAStar(grid, cluster_size)
