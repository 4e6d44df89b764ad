"""A global tour over subspaces with local coverage, in the manner of TARE (Cao et al., RSS 2021) and FUEL
(Zhou et al., RA-L 2021).

Global layer: the known space is split into square subspaces of ``cell`` m (a coarse grid fixed in the world);
a subspace holding frontier cells is a tour node, represented by the reachable goal of the frontier region
with most cells in it. The open tour from the robot over the nodes is solved by OR-tools' routing solver
(path-cheapest-arc, then local search), the travel costs geodesic distances on a coarse copy of the
traversable grid (a cell per ``COARSE`` m); it is warm-started from the previous decision's order (the nodes
still open kept in that order, new ones inserted where they cost least), so each map update refines the tour
rather than rebuilding it (FUEL's incremental refinement). Local layer: in the tour's first subspace,
viewpoints (reachable cells every ``spacing`` m) are chosen by greedy set cover of its frontier cells, a
viewpoint covering the frontier cells in line of sight within ``view_range`` m (rays over free cells); the
viewpoints are ordered into an open path from the robot that ends at the next subspace's node (the local tour
joins the global one), and the robot drives to the first. Two rules against leaving pieces behind: a subspace
once within ``horizon`` m of path from the robot is begun, and the begun subspaces are toured before the others
(TARE's local horizon, finished before the robot leaves it); the frontier cells a viewpoint reached was chosen to
see and did not clear are no target any more (the tour would send the robot to look at them again and again).
"""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
from numba import njit

from slam2d.exploration.gridops import FREE
from slam2d.exploration.paths import Paths, as_paths

SCALE = 100  # the solver's integer costs: cm
COARSE = 0.2  # m: cell of the coarse grid the travel costs between subspaces are measured on
FAR = 10**9  # cost of an arc no path takes
LEAVE = 1e4  # m added to an arc from a subspace not begun into a begun one (the begun ones first)


def solve_open_tour(cost: np.ndarray, end: int | None = None, initial=None, time_ms: float = 50.0) -> list[int]:
    """The order of the nodes 1..N-1 on a short open path from node 0 over all of them (OR-tools routing),
    ending at ``end`` when given (then not in the order returned); ``cost`` (N, N) m, inf for no way;
    ``initial``: an order of (some of) the nodes to start the local search from (the others inserted where
    they cost least); ``time_ms`` bounds the search."""
    from ortools.constraint_solver import pywrapcp, routing_enums_pb2

    cost = np.asarray(cost, dtype=np.float64)
    n = len(cost)
    inner = [k for k in range(1, n) if k != end]
    if len(inner) <= 1:
        return inner
    if end is None:  # a free end: a dummy last node reached from every node at no cost
        c = np.zeros((n + 1, n + 1))
        c[:n, :n] = cost
        end = n
    else:
        c = cost.copy()
    c[:, 0] = 0.0  # nothing returns to the start
    arcs = np.where(np.isfinite(c), np.rint(np.minimum(c, FAR / SCALE) * SCALE), FAR).astype(np.int64)
    manager = pywrapcp.RoutingIndexManager(len(c), 1, [0], [end])
    routing = pywrapcp.RoutingModel(manager)
    rows = arcs.tolist()
    transit = routing.RegisterTransitMatrix(rows)
    routing.SetArcCostEvaluatorOfAllVehicles(transit)
    params = pywrapcp.DefaultRoutingSearchParameters()
    params.first_solution_strategy = routing_enums_pb2.FirstSolutionStrategy.PATH_CHEAPEST_ARC
    params.local_search_metaheuristic = routing_enums_pb2.LocalSearchMetaheuristic.GREEDY_DESCENT
    params.time_limit.FromMilliseconds(max(1, int(time_ms)))
    solution = None
    if initial is not None:
        start = cheapest_insertion(cost, [k for k in initial if k in set(inner)], inner, end if end < n else None)
        routing.CloseModelWithParameters(params)
        warm = routing.ReadAssignmentFromRoutes([[manager.NodeToIndex(k) for k in start]], True)  # indices, not nodes
        if warm is not None:
            solution = routing.SolveFromAssignmentWithParameters(warm, params)
    if solution is None:
        solution = routing.SolveWithParameters(params)
    if solution is None:
        return greedy_order(cost, inner)
    order, index = [], routing.Start(0)
    while not routing.IsEnd(index):
        node = manager.IndexToNode(index)
        if node != 0:
            order.append(node)
        index = solution.Value(routing.NextVar(index))
    return order


def cheapest_insertion(cost: np.ndarray, order: list[int], nodes: list[int], end: int | None = None) -> list[int]:
    """``order`` with the other ``nodes`` each inserted where it lengthens the open path from node 0 (to ``end``)
    least."""
    order = list(order)
    for k in nodes:
        if k in order:
            continue
        path = [0, *order] + ([end] if end is not None else [])
        best, at = np.inf, len(order)
        for i in range(len(path)):
            nxt = path[i + 1] if i + 1 < len(path) else None
            extra = cost[path[i], k] + (cost[k, nxt] - cost[path[i], nxt] if nxt is not None else 0.0)
            if extra < best:
                best, at = extra, i
        order.insert(at, k)
    return order


def greedy_order(cost: np.ndarray, nodes: list[int]) -> list[int]:
    """Nearest next from node 0 over ``nodes``."""
    left, order, cur = list(nodes), [], 0
    while left:
        k = min(left, key=lambda j: cost[cur, j])
        order.append(k)
        left.remove(k)
        cur = k
    return order


def path_length(cost: np.ndarray, order: list[int], end: int | None = None) -> float:
    """Length (m) of the open path 0 → ``order`` (→ ``end``)."""
    path = [0, *order] + ([end] if end is not None else [])
    return float(sum(cost[a, b] for a, b in itertools.pairwise(path)))


# --------------------------------------------------------------------------- local coverage


@njit(cache=True)
def _sees(state, viewpoints, cells, reach):
    """(V, F) bool: frontier cell f is in line of sight of viewpoint v (cells (row, col)) within ``reach`` cells,
    every cell between them free (a line of cells stepped along the longer axis)."""
    out = np.zeros((viewpoints.shape[0], cells.shape[0]), dtype=np.bool_)
    for v in range(viewpoints.shape[0]):
        r0, c0 = viewpoints[v, 0], viewpoints[v, 1]
        for f in range(cells.shape[0]):
            dr, dc = cells[f, 0] - r0, cells[f, 1] - c0
            if dr * dr + dc * dc > reach * reach:
                continue
            n = max(abs(dr), abs(dc))
            clear = True
            for k in range(1, n):
                r = r0 + int(np.floor(dr * k / n + 0.5))
                c = c0 + int(np.floor(dc * k / n + 0.5))
                if state[r, c] != FREE:
                    clear = False
                    break
            out[v, f] = clear
    return out


def coverage_matrix(state: np.ndarray, viewpoints: np.ndarray, cells: np.ndarray, reach_cells: float) -> np.ndarray:
    """Which frontier ``cells`` (F, 2) each of the ``viewpoints`` (V, 2) (row, col) sees (V, F) bool: within
    ``reach_cells`` cells, over free cells (what the laser would see of them)."""
    vp = np.ascontiguousarray(np.asarray(viewpoints, dtype=np.int64).reshape(-1, 2))
    fc = np.ascontiguousarray(np.asarray(cells, dtype=np.int64).reshape(-1, 2))
    return _sees(np.ascontiguousarray(state, dtype=np.int8), vp, fc, float(reach_cells))


def greedy_cover(sees: np.ndarray, cost=None, min_cells: int = 1) -> list[int]:
    """Viewpoints (indices into the rows of ``sees`` (V, F) bool) chosen by greedy set cover: each time the one
    seeing most cells not yet covered (ties: lowest ``cost`` (V,)), until none sees ``min_cells`` more."""
    sees = np.asarray(sees, dtype=bool)
    cost = np.zeros(len(sees)) if cost is None else np.asarray(cost, dtype=np.float64)
    left = np.ones(sees.shape[1], dtype=bool)
    chosen: list[int] = []
    while left.any():
        gain = sees[:, left].sum(axis=1)
        best = int(np.lexsort((cost, -gain))[0])
        if gain[best] < max(min_cells, 1):
            break
        chosen.append(best)
        left &= ~sees[best]
    return chosen


# --------------------------------------------------------------------------- travel costs


def coarse_grid(passable: np.ndarray, k: int) -> np.ndarray:
    """``passable`` (H, W) on cells k times larger (ceil(H / k), ceil(W / k)): passable when one of its cells is."""
    return _coarse_any(np.ascontiguousarray(passable, dtype=np.bool_), int(k))


@njit(cache=True)
def _coarse_any(passable, k):
    h, w = passable.shape
    out = np.zeros((-(-h // k), -(-w // k)), dtype=np.bool_)
    for r in range(h):
        row = out[r // k]
        for cc in range(out.shape[1]):
            row[cc] |= passable[r, cc * k : min(cc * k + k, w)].any()
    return out


# --------------------------------------------------------------------------- the strategy


class TourPlanner:
    """The ``tour`` strategy's state between decisions: the previous global order (by subspace) and the
    subspaces' travel-cost rows on the coarse grid."""

    def __init__(self):
        self.order: list[tuple[int, int]] = []  # the previous global tour, by subspace
        self._rows: dict = {}  # rep cell -> (its coarse distances, settled as far as asked; decision measured at)
        self._coarse_frame = None
        self.begun: set = set()  # subspaces once within the horizon
        self.decisions = 0

    def choose(self, explorer, pose, view, distance):
        from slam2d.exploration.explorer import Goal

        cfg = explorer.cfg.tour
        self.decisions += 1
        found = _unviewed(view, explorer.frontiers(pose, view, distance), explorer.viewed)
        if not found:
            return None
        keys, goals, paths, members = _subspaces(view, found, cfg.cell, distance)
        cost = self._costs(explorer, view, pose, goals, paths)
        order = self._global_order(keys, cost, cfg.solver_ms, cfg.horizon)
        first = order[0]
        nxt = goals[order[1]] if len(order) > 1 else None
        cells = members[first]
        if len(cells) > cfg.max_cells:
            cells = cells[np.linspace(0, len(cells) - 1, cfg.max_cells).astype(int)]
        goal, targets = self._local_goal(explorer, view, distance, pose, cells, nxt)
        if goal is None:  # no viewpoint sees its frontier: the subspace's own goal
            return Goal(goals[first].copy(), "frontier", score=float(paths[first]))
        return Goal(goal, "viewpoint", score=float(len(targets)), targets=targets)

    def _costs(self, explorer, view, pose, goals, path) -> np.ndarray:
        """Travel costs (K + 1, K + 1) m between the robot (0) and the subspaces' goals: the robot's grid
        path, between goals the geodesic on the coarse grid (each goal's row kept ``refresh`` decisions), at
        least the straight line and the difference of the robot's paths."""
        pts = np.vstack([pose[:2], goals])
        d = np.concatenate([[0.0], path])
        low = np.maximum(np.hypot(*(pts[:, None] - pts[None]).transpose(2, 0, 1)), np.abs(d[:, None] - d))
        between = self._coarse(explorer, view, view.to_cell(goals))
        cost = low.copy()
        cost[1:, 1:] = np.where(np.isfinite(between), np.maximum(between, low[1:, 1:]), low[1:, 1:])
        cost[0, 1:] = path
        return cost

    def _coarse(self, explorer, view, cells) -> np.ndarray:
        """Geodesic distances (K, K) m between ``cells`` (K, 2) on the coarse grid of the cells keeping the robot's
        radius from obstacles; inf where no way is found."""
        k = max(1, round(COARSE / view.resolution))
        frame = view.shape, view.resolution, tuple(np.asarray(view.origin, dtype=float))
        if frame != self._coarse_frame:
            self._rows, self._coarse_frame = {}, frame
        at = np.asarray(cells, dtype=np.int64) // k
        out = np.empty((len(at), len(at)))
        refresh, coarse = explorer.cfg.tour.refresh, None
        for i, cell in enumerate(at):
            key = tuple(cell)
            row = self._rows.get(key)
            if row is None or self.decisions - row[1] >= refresh:
                if coarse is None:  # made only when a row is measured
                    coarse = coarse_grid(view.traversable(explorer.radius), k)
                row = Paths(coarse, cell, view.resolution * k, snap_cells=2), self.decisions
                self._rows[key] = row
            out[i] = row[0].lengths(at)  # the search resumed only as far as these cells
        return np.minimum(out, out.T)

    def _global_order(self, keys, cost, solver_ms, horizon) -> list[int]:
        """Indices of the subspaces in tour order, warm-started from the previous decision's order. A subspace once
        within ``horizon`` m of path from the robot is *begun*, and the begun subspaces are toured before the others
        (TARE's local horizon, finished before the robot leaves it; a begun subspace left for the end of the tour is
        a trip back once the tour has grown the other way): an arc from one not begun to a begun one costs
        ``LEAVE`` m more."""
        index = {key: i for i, key in enumerate(keys)}
        previous = [index[key] + 1 for key in self.order if key in index]
        self.begun |= {keys[k - 1] for k in range(1, len(cost)) if cost[0, k] <= horizon}
        near = np.array([False] + [key in self.begun for key in keys])
        if near.any() and not near[1:].all():
            cost = cost.copy()
            cost[np.ix_(np.flatnonzero(~near)[1:], near)] += LEAVE  # not from the robot (node 0)
        order = [k - 1 for k in solve_open_tour(cost, initial=previous, time_ms=solver_ms)]
        self.order = [keys[i] for i in order]
        return order

    def _local_goal(self, explorer, view, distance, pose, cells, nxt):
        """The first viewpoint (x, y) m of the local tour covering frontier ``cells`` (F, 2), and the frontier
        cells it sees (K, 2) m; (None, None) when no viewpoint sees any."""
        cfg, res = explorer.cfg.tour, view.resolution
        reach = cfg.view_range / res
        step = max(1, round(cfg.spacing / res))
        lo = np.maximum(cells.min(axis=0) - int(reach), 0)
        hi = np.minimum(cells.max(axis=0) + int(reach) + 1, view.shape)
        distance = as_paths(distance)
        rows, cols = np.nonzero(distance.reach[lo[0] : hi[0] : step, lo[1] : hi[1] : step])
        if len(rows) == 0:
            return None, None
        cand = np.column_stack([rows, cols]) * step + lo
        xy = view.to_world(cand)
        avoid = explorer.visited + explorer.inaccessible
        if avoid:
            keep = np.hypot(*(xy[:, None] - np.array(avoid)[None]).transpose(2, 0, 1)).min(axis=1) >= explorer.cfg.avoid_radius
            cand, xy = cand[keep], xy[keep]
        if len(cand) == 0:
            return None, None
        sees = coverage_matrix(view.state, cand, cells, reach)
        path = distance.lengths(cand)
        chosen = greedy_cover(sees, path, int(np.ceil(cfg.min_cover / res)))
        if not chosen:
            return None, None
        pts = np.vstack([pose[:2], xy[chosen]] + ([nxt[None]] if nxt is not None else []))
        d = np.concatenate([[0.0], path[chosen]] + ([[np.inf]] if nxt is not None else []))
        cost = np.hypot(*(pts[:, None] - pts[None]).transpose(2, 0, 1))
        cost[0, 1 : 1 + len(chosen)] = path[chosen]
        fin = np.isfinite(d)
        cost[np.ix_(fin, fin)] = np.maximum(cost[np.ix_(fin, fin)], np.abs(d[fin, None] - d[fin]))
        end = len(pts) - 1 if nxt is not None else None
        first = chosen[solve_open_tour(cost, end=end, time_ms=cfg.solver_ms)[0] - 1] if len(chosen) > 1 else chosen[0]
        return xy[first].copy(), view.to_world(cells[sees[first]])


def _unviewed(view, found: list, viewed: np.ndarray) -> list:
    """The frontier regions ``found`` without the cells ``viewed`` (K, 2) m (frontier cells a viewpoint reached was
    chosen to see and did not clear: the map keeps them frontier from there, another viewpoint would not fare
    better); a region with none left is dropped."""
    if len(viewed) == 0:
        return found
    mask = np.zeros(view.shape, dtype=bool)
    cells = view.to_cell(viewed)
    cells = cells[view.inside(cells)]
    mask[cells[:, 0], cells[:, 1]] = True
    out = []
    for f in found:
        keep = ~mask[f.cells[:, 0], f.cells[:, 1]]
        if keep.all():
            out.append(f)
        elif keep.any():
            out.append(replace(f, cells=f.cells[keep], size=int(keep.sum())))
    return out


def _subspaces(view, found, cell: float, distance: np.ndarray):
    """The subspaces (squares of ``cell`` m fixed in the world) holding frontier cells of the regions ``found``:
    their keys [(i, j)], goals (K, 2) m (the reachable frontier cell nearest the centre of the subspace's frontier
    cells, else the goal of the region with most cells in it), path lengths (K,) m to them, and the frontier
    cells [(F, 2)] of each."""
    cells = np.concatenate([f.cells for f in found])
    region = np.repeat(np.arange(len(found)), [len(f.cells) for f in found])
    ij = np.floor(view.to_world(cells) / cell).astype(np.int64)
    keys, inv = np.unique(ij, axis=0, return_inverse=True)
    inv = inv.ravel()
    distance = as_paths(distance)
    goals, paths, members, ends = np.empty((len(keys), 2)), np.empty(len(keys)), [], []
    order = np.argsort(inv, kind="stable")  # each subspace's cells in their order in ``cells``
    bounds = np.concatenate([[0], np.cumsum(np.bincount(inv, minlength=len(keys)))])
    reach = distance.reach[cells[:, 0], cells[:, 1]]
    for k in range(len(keys)):
        at = order[bounds[k] : bounds[k + 1]]
        mine, ok = cells[at], reach[at]
        if ok.any():
            own = mine[ok]
            best = own[np.argmin(np.hypot(*(own - mine.mean(axis=0)).T))]
            goals[k] = view.to_world(best)
            ends.append((k, best))
        else:
            f = found[int(np.argmax(np.bincount(region[at], minlength=len(found))))]
            goals[k], paths[k] = f.goal, f.path
        members.append(mine)
    if ends:
        paths[[k for k, _ in ends]] = distance.lengths(np.array([b for _, b in ends]))
    return [tuple(int(v) for v in key) for key in keys], goals, paths, members
