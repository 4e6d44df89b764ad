"""Hierarchical grid planners: HPA* over square clusters, and a room-graph planner.

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

Room-graph planner (the thesis' hierarchical A*, over a topological map):
regions of a segmentation are the nodes and portals the transitions of a
region graph (``slam2d.mapping.topological.region_graph``). The region route
is an A* over the *portals* (one node per region-graph edge; two portals of
the same region are joined at the distance of their centres; start and goal
join the portals of their regions), then a crossing cell is chosen on each
portal, and A* runs inside one region at a time (the grid masked to that
region plus its two portals) and the pieces are stitched. If a piece fails
(a region that does not connect its portals), the search falls back to the
corridor of all regions on the route, then to the whole grid.
"""

from __future__ import annotations

import math
import time

import numpy as np
from numba import njit

from slam2d.planning.astar import (
    SQRT2,
    AStar,
    PlanResult,
    SearchBuffers,
    _octile,
    _pop,
    _search,
    _sift_up,
    endpoint_problem,
    path_cost,
    path_length,
)
from slam2d.planning.base import register_planner
from slam2d.planning.grid import PlanningGrid
from slam2d.planning.smoothing import smooth_octile

__all__ = ["HPAStar", "RoomGraphPlanner", "entrances"]


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
def _relax(v, ng, hv, g, parent, state, hk, hg, hn, hpos, stamp, u, size):
    """Offer ``v`` the cost ``ng`` through ``u``; returns the new heap size (state as in ``_search``)."""
    sv = state[v]
    if sv == 2 * stamp + 1:
        return size
    if sv < 2 * stamp:
        state[v] = 2 * stamp
        g[v] = ng
        parent[v] = u
        _sift_up(hk, hg, hn, hpos, size, ng + hv, ng, v)
        return size + 1
    if ng < g[v] - 1e-12:
        g[v] = ng
        parent[v] = u
        _sift_up(hk, hg, hn, hpos, hpos[v], ng + hv, ng, v)
    return size


@njit(cache=True)
def _abstract_search(indptr, nbr, wt, node_r, node_c, s_nodes, s_w, goal_w, direct, sr, sc, gr, gc,
                     g, parent, state, hk, hg, hn, hpos, stamp):  # fmt: skip
    """A* on the abstract graph; start = node n, goal = node n + 1. Returns (found, expanded)."""
    n = node_r.shape[0]
    S = n
    T = n + 1
    state[S] = 2 * stamp
    g[S] = 0.0
    parent[S] = -1
    _sift_up(hk, hg, hn, hpos, 0, _octile(sr, sc, gr, gc, True), 0.0, S)
    size = 1
    expanded = 0
    while size > 0:
        u, size = _pop(hk, hg, hn, hpos, size)
        state[u] = 2 * stamp + 1
        expanded += 1
        if u == T:
            return True, expanded
        gu = g[u]
        if u == S:
            for i in range(s_nodes.shape[0]):
                v = s_nodes[i]
                if s_w[i] < np.inf:
                    hv = _octile(node_r[v], node_c[v], gr, gc, True)
                    size = _relax(v, gu + s_w[i], hv, g, parent, state, hk, hg, hn, hpos, stamp, u, size)
            if direct < np.inf:
                size = _relax(T, gu + direct, 0.0, g, parent, state, hk, hg, hn, hpos, stamp, u, size)
            continue
        for i in range(indptr[u], indptr[u + 1]):
            v = nbr[i]
            hv = _octile(node_r[v], node_c[v], gr, gc, True)
            size = _relax(v, gu + wt[i], hv, g, parent, state, hk, hg, hn, hpos, stamp, u, size)
        if goal_w[u] < np.inf:
            size = _relax(T, gu + goal_w[u], 0.0, g, parent, state, hk, hg, hn, hpos, stamp, u, size)
    return False, expanded


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


@njit(cache=True)
def _trace_ids(parent, t):
    n = 0
    v = t
    while v != -1:
        n += 1
        v = parent[v]
    out = np.empty(n, np.int64)
    v = t
    for i in range(n - 1, -1, -1):
        out[i] = v
        v = parent[v]
    return out


# ---------------------------------------------------------------- room graph


def _default_region_graph(labels: np.ndarray, grid: PlanningGrid):
    """``slam2d.mapping.topological.region_graph`` of ``labels`` (rows of the grid go up)."""
    try:
        from slam2d.mapping.topological import region_graph
    except ImportError as err:
        raise ImportError(
            "RoomGraphPlanner needs a region graph: pass graph=... or provide "
            f"slam2d.mapping.topological.region_graph ({err})"
        ) from None
    return region_graph(labels, grid.resolution, grid.origin, row0_top=False)


class RoomGraphPlanner:
    """Region route over a topological map, then A* inside the route's regions only.

    ``labels`` (H, W) int region of each cell; ``graph`` a networkx region
    graph (nodes = region labels; edges carry ``portal``, a list of (row, col)
    cells), by default ``region_graph(labels, resolution)``. Free cells
    without a region in the graph join the nearest region. ``smooth`` applies
    :func:`~slam2d.planning.smoothing.smooth_octile` to the stitched path
    (8-connected grids only).

    The route search runs on the portal graph: one node per portal (at the
    mean of its free cells), two portals of one region joined at their octile
    distance, the grid distance across an empty room.
    """

    def __init__(self, grid: PlanningGrid | np.ndarray, labels: np.ndarray, graph=None, connectivity: int = 8,
                 cost: np.ndarray | None = None, smooth: bool = True):  # fmt: skip
        t0 = time.perf_counter()
        self.low = AStar(grid, connectivity, cost)
        self.grid = self.low.grid
        labels = np.asarray(labels)
        if labels.shape != self.grid.shape:
            raise ValueError(f"labels shape {labels.shape} differs from the grid {self.grid.shape}")
        if graph is None:
            graph = _default_region_graph(labels, self.grid)
        self.graph = graph
        self.smooth = smooth and connectivity == 8
        self._assign_regions(labels)
        self._portals()
        self._portal_graph()
        self.build_seconds = time.perf_counter() - t0

    def _assign_regions(self, labels: np.ndarray) -> None:
        from scipy import ndimage

        names = list(self.graph.nodes)
        self.region_ids = {r: i for i, r in enumerate(names)}
        keys = np.array(names)
        known = np.isin(labels, keys)
        if not known.any():
            raise ValueError("no cell carries a label of the region graph")
        region = np.full(labels.shape, -1, np.int64)
        sorter = np.argsort(keys)
        region[known] = sorter[np.searchsorted(keys, labels[known], sorter=sorter)]
        free = self.grid.free
        if (free & ~known).any():
            _, (ri, ci) = ndimage.distance_transform_edt(~known, return_indices=True)
            region = np.where(free & ~known, region[ri, ci], region)
        region[~free] = -1
        self.region = region
        r, c = np.nonzero(free)
        order = np.argsort(region[r, c], kind="stable")
        self.region_cells = ((r[order] + 1) * self.low.width + c[order] + 1).astype(np.int64)
        self.region_offsets = np.searchsorted(region[r, c][order], np.arange(len(names) + 1)).astype(np.int64)

    def _portals(self) -> None:
        """Portal cells (free ones only) in CSR form, padded indices; centres in padded (row, col)."""
        free = self.grid.free
        h, w = free.shape
        regions, cells_list = [], []
        for a, b, data in self.graph.edges(data=True):
            cells = np.asarray(data.get("portal", ()), dtype=np.int64).reshape(-1, 2)
            inside = (cells[:, 0] >= 0) & (cells[:, 0] < h) & (cells[:, 1] >= 0) & (cells[:, 1] < w)
            cells = cells[inside]
            cells = cells[free[cells[:, 0], cells[:, 1]]]
            ia, ib = self.region_ids[a], self.region_ids[b]
            if a == b or not _traversable(cells, self.region, ia, ib, free):
                continue  # closed by the robot radius, a corner-only contact, or a self-loop
            regions.append((ia, ib))
            cells_list.append(cells)
        self.portal_regions = np.array(regions, dtype=np.int64).reshape(-1, 2)
        sizes = np.array([len(c) for c in cells_list], dtype=np.int64)
        self.portal_ptr = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        rc = np.concatenate(cells_list) if cells_list else np.zeros((0, 2), np.int64)
        self.portal_cells = ((rc[:, 0] + 1) * self.low.width + rc[:, 1] + 1).astype(np.int64)
        centres = np.add.reduceat(rc + 1.0, self.portal_ptr[:-1], axis=0) / sizes[:, None] if len(sizes) else rc * 1.0
        self.portal_r = np.ascontiguousarray(centres[:, 0], dtype=np.float64)
        self.portal_c = np.ascontiguousarray(centres[:, 1], dtype=np.float64)

    def _portal_graph(self) -> None:
        """CSR graph over portals: two portals of one region joined at their octile distance."""
        n_regions = len(self.region_ids)
        pr = self.portal_regions
        ids = np.concatenate([np.arange(len(pr)), np.arange(len(pr))])
        owner = np.concatenate([pr[:, 0], pr[:, 1]])
        order = np.argsort(owner, kind="stable")
        self.rp_ptr = np.searchsorted(owner[order], np.arange(n_regions + 1)).astype(np.int64)
        self.rp = ids[order].astype(np.int64)  # portals of region k: rp[rp_ptr[k]:rp_ptr[k + 1]]
        us, vs = [], []
        for k in range(n_regions):
            ports = self.rp[self.rp_ptr[k] : self.rp_ptr[k + 1]]
            i, j = np.triu_indices(len(ports), 1)
            us.append(ports[i])
            vs.append(ports[j])
        u = np.concatenate(us) if us else np.zeros(0, np.int64)
        v = np.concatenate(vs) if vs else np.zeros(0, np.int64)
        w = _octile_np(self.portal_r[u], self.portal_c[u], self.portal_r[v], self.portal_c[v])
        src, dst, wt = np.concatenate([u, v]), np.concatenate([v, u]), np.concatenate([w, w])
        order = np.argsort(src, kind="stable")
        n = len(pr)
        self.pg_indptr = np.concatenate([[0], np.cumsum(np.bincount(src, minlength=n))]).astype(np.int64)
        self.pg_nbr = dst[order].astype(np.int64)
        self.pg_wt = wt[order].astype(np.float64)
        self.pbuf = SearchBuffers(n + 2)
        self.goal_w = np.full(n, np.inf)

    # -- route
    def _route(self, start, goal, rs: int, rg: int):
        """(portal ids, region of each stitched piece) or None when the region graph has no route."""
        if rs == rg:
            return np.zeros(0, np.int64), [rs]
        sr, sc = int(start[0]) + 1, int(start[1]) + 1
        gr, gc = int(goal[0]) + 1, int(goal[1]) + 1
        s_nodes = self.rp[self.rp_ptr[rs] : self.rp_ptr[rs + 1]]
        g_nodes = self.rp[self.rp_ptr[rg] : self.rp_ptr[rg + 1]]
        s_w = _octile_np(sr, sc, self.portal_r[s_nodes], self.portal_c[s_nodes])
        self.goal_w[g_nodes] = _octile_np(self.portal_r[g_nodes], self.portal_c[g_nodes], gr, gc)
        b = self.pbuf
        found, self.route_expanded = _abstract_search(
            self.pg_indptr, self.pg_nbr, self.pg_wt, self.portal_r, self.portal_c, s_nodes, s_w, self.goal_w,
            np.inf, sr, sc, gr, gc, *b.arrays(), b.next_stamp(),
        )  # fmt: skip
        self.goal_w[g_nodes] = np.inf
        if not found:
            return None
        ports = _trace_ids(b.parent, len(self.portal_r) + 1)[1:-1]
        pieces = [rs]
        pr = self.portal_regions
        for p, q in zip(ports[:-1], ports[1:]):
            shared = set(pr[p].tolist()) & set(pr[q].tolist())
            if len(shared) > 1:
                shared.discard(pieces[-1])
            pieces.append(min(shared))
        pieces.append(rg)
        return ports, pieces

    def _mark(self, pieces, ports) -> int:
        """Mark the cells of regions ``pieces`` and portals ``ports`` with a fresh zone stamp."""
        b = self.low.buf
        z = b.next_zone()
        for r in pieces:
            b.zone[self.region_cells[self.region_offsets[r] : self.region_offsets[r + 1]]] = z
        for p in ports:
            b.zone[self.portal_cells[self.portal_ptr[p] : self.portal_ptr[p + 1]]] = z
        return z

    def plan(self, start, goal) -> PlanResult:
        """Path between (row, col) cells; found=False with a reason when there is none."""
        t0 = time.perf_counter()
        res = self.grid.resolution
        for cell, which in ((start, "start"), (goal, "goal")):
            why = endpoint_problem(self.grid.free, cell, which)
            if why:
                return PlanResult.failure(why, 0, time.perf_counter() - t0, res)
        lo = self.low
        rs, rg = int(self.region[start[0], start[1]]), int(self.region[goal[0], goal[1]])
        s, t = lo.index(start), lo.index(goal)
        self.route_expanded = 0
        route = self._route(start, goal, rs, rg)
        expanded, mode, cells = 0, "regions", None
        if route is not None:
            ports, pieces = route
            b = lo.buf
            h, w = self.grid.shape
            zfirst = b.reserve_zone(len(pieces) + 1)
            cells, expanded, _, ok = _stitch(
                lo.moves, b.zone, zfirst, lo.cost_p, lo.use_cost, lo.width, lo.connectivity == 8, h, w, s, t,
                ports, np.asarray(pieces, np.int64), self.portal_ptr, self.portal_cells, self.portal_r,
                self.portal_c, self.region_offsets, self.region_cells,
                *b.arrays(), b.reserve(len(pieces) + 1),
            )  # fmt: skip
            if not ok:
                mode = "corridor"
                found, e = lo.search(s, t, zstamp=self._mark(pieces, ports))
                expanded += e
                cells = _trace_from(b.parent, s, t, lo.width) if found else None
        if cells is None:
            mode = "grid"
            found, e = lo.search(s, t)
            expanded += e
            if not found:
                return PlanResult.failure(
                    f"goal {tuple(int(v) for v in goal)} is unreachable from start {tuple(int(v) for v in start)}",
                    expanded + self.route_expanded, time.perf_counter() - t0, res, mode=mode,
                )  # fmt: skip
            cells = _trace_from(lo.buf.parent, s, t, lo.width)
        rows = cells // lo.width
        path = np.stack([rows - 1, cells - rows * lo.width - 1], axis=1)
        raw_length = path_length(path)
        if self.smooth:
            b = lo.buf
            path = smooth_octile(self.grid.free, path, buffers=(lo.free_p, lo.width, b.mark, b.hpos, b.next_stamp()))
        info = {"mode": mode, "regions": len(route[1]) if route else 0, "route_expanded": int(self.route_expanded),
                "raw_length": raw_length}  # fmt: skip
        return PlanResult(path, path_length(path), int(expanded + self.route_expanded), time.perf_counter() - t0,
                          True, "", path_cost(path, lo.cost), res, info)  # fmt: skip


@register_planner("hpa")
def hpa_planner(grid: PlanningGrid | np.ndarray, cluster_size: int = 16) -> HPAStar:
    """HPA*: A* over the entrances of square clusters of ``cluster_size`` cells, refined inside them."""
    return HPAStar(grid, cluster_size)


@register_planner("rooms", takes=("labels", "graph"))
def room_planner(grid: PlanningGrid | np.ndarray, labels: np.ndarray, graph=None) -> RoomGraphPlanner:
    """A route over the rooms' graph (a room segmentation's ``labels``), then A* inside the route's rooms."""
    return RoomGraphPlanner(grid, labels, graph)


def _traversable(cells: np.ndarray, region: np.ndarray, ia: int, ib: int, free: np.ndarray) -> bool:
    """Whether one move (no corner cutting) leads from a portal cell of region ``ia`` to one of ``ib``."""
    own = region[cells[:, 0], cells[:, 1]]
    a, b = cells[own == ia], cells[own == ib]
    if len(a) == 0 or len(b) == 0:
        return False
    d = np.abs(a[:, None, :] - b[None, :, :])
    if ((d[..., 0] + d[..., 1]) == 1).any():
        return True
    i, j = np.nonzero((d[..., 0] == 1) & (d[..., 1] == 1))
    return bool((free[a[i, 0], b[j, 1]] & free[b[j, 0], a[i, 1]]).any())


def _octile_np(r0, c0, r1, c1):
    dy = np.abs(np.asarray(r1, np.float64) - r0)
    dx = np.abs(np.asarray(c1, np.float64) - c0)
    return dx + dy + (SQRT2 - 2.0) * np.minimum(dx, dy)


@njit(cache=True)
def _stitch(moves, zone, zstamp, cost, use_cost, width, conn8, h, w, s, t, ports, pieces,
            pptr, pcells, pr, pc, roff, rcells, g, parent, state, hk, hg, hn, hpos, stamp):  # fmt: skip
    """Crossing cells on the route's portals, then A* inside one region (+ its portals) at a time.

    Returns (padded path, expanded, last stamp, ok)."""
    k = ports.shape[0]
    cross = np.empty(k + 2, np.int64)
    cross[0] = s
    cross[k + 1] = t
    prow = s // width
    pcol = s - prow * width
    for i in range(k):
        if i + 1 < k:
            nr = pr[ports[i + 1]]
            nc = pc[ports[i + 1]]
        else:
            nr = t // width
            nc = t - (t // width) * width
        best = np.inf
        bc = pcells[pptr[ports[i]]]
        for j in range(pptr[ports[i]], pptr[ports[i] + 1]):
            cell = pcells[j]
            r = cell // width
            c = cell - r * width
            d = math.hypot(r - prow, c - pcol) + math.hypot(r - nr, c - nc)
            if d < best:
                best = d
                bc = cell
        cross[i + 1] = bc
        prow = bc // width
        pcol = bc - prow * width
    out = np.empty(h * w + 1, np.int64)
    m = 0
    expanded = 0
    for i in range(k + 1):
        zstamp += 1
        reg = pieces[i]
        for j in range(roff[reg], roff[reg + 1]):
            zone[rcells[j]] = zstamp
        for q in (i - 1, i):
            if 0 <= q < k:
                for j in range(pptr[ports[q]], pptr[ports[q] + 1]):
                    zone[pcells[j]] = zstamp
        a = cross[i]
        b = cross[i + 1]
        stamp += 1
        found, e = _search(moves, zone, zstamp, cost, use_cost, width, a, b, conn8, 1, h, 1, w,
                           g, parent, state, hk, hg, hn, hpos, stamp)  # fmt: skip
        expanded += e
        if not found:
            return out[:m], expanded, stamp, False
        n = 1
        v = b
        while v != a:
            n += 1
            v = parent[v]
        first = 0 if i == 0 else 1  # the crossing cell ends the previous piece
        v = b
        for j in range(n - 1, first - 1, -1):
            out[m + j - first] = v
            v = parent[v]
        m += n - first
    return out[:m], expanded, stamp, True


@njit(cache=True)
def _trace_from(parent, s, t, width):
    """Padded cells from ``s`` to ``t`` along parents."""
    n = 1
    v = t
    while v != s:
        n += 1
        v = parent[v]
    out = np.empty(n, np.int64)
    v = t
    for i in range(n - 1, -1, -1):
        out[i] = v
        if i > 0:
            v = parent[v]
    return out
