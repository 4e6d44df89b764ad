"""Room-graph planner: the thesis' hierarchical A*, over a topological map.

Regions of a segmentation are the nodes and portals the transitions of a
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
    _search,
    endpoint_problem,
    path_cost,
    path_length,
)
from slam2d.planning.base import register_planner
from slam2d.planning.graph_search import _abstract_search, _trace_from, _trace_ids
from slam2d.planning.grid import PlanningGrid
from slam2d.planning.smoothing import smooth_octile

__all__ = ["RoomGraphPlanner"]

CORRIDOR_RINGS = 3  # regions around the route that the corridor search may also cross (portals away)


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

    ``corridor``: instead of stitching one A* per room, one A* over the union of the route's rooms, the
    rooms next to them and the portals among those: the shortest path there, so a detour is only what
    leaving them would save (slower: the search spans the whole corridor).
    """

    def __init__(self, grid: PlanningGrid | np.ndarray, labels: np.ndarray, graph=None, connectivity: int = 8,
                 cost: np.ndarray | None = None, smooth: bool = True, corridor: bool = False):  # fmt: skip
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
        self.corridor = corridor
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

    def _widened(self, pieces) -> tuple[np.ndarray, np.ndarray]:
        """The route's regions with every region up to ``CORRIDOR_RINGS`` portals from one of them, and the
        portals among those."""
        pr, regions = self.portal_regions, np.asarray(pieces)
        for _ in range(CORRIDOR_RINGS):
            regions = np.union1d(regions, pr[np.isin(pr, regions).any(axis=1)].ravel())
        return regions, np.flatnonzero(np.isin(pr, regions).all(axis=1))

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
        if route is not None and self.corridor:
            mode = "corridor"
            found, expanded = lo.search(s, t, zstamp=self._mark(*self._widened(route[1])))
            cells = _trace_from(lo.buf.parent, s, t, lo.width) if found else None
        elif route is not None:
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


@register_planner("rooms", takes=("labels", "graph"))
def room_planner(grid: PlanningGrid | np.ndarray, labels: np.ndarray, graph=None,
                 corridor: bool = False) -> RoomGraphPlanner:  # fmt: skip
    """A route over the rooms' graph (a room segmentation's ``labels``), then A* inside the route's rooms
    (``corridor``: one A* over all of them, the shortest path inside the rooms crossed)."""
    return RoomGraphPlanner(grid, labels, graph, corridor=corridor)


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
