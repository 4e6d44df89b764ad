"""Grid A*: 4- or 8-connected, octile heuristic, no corner cutting, numba inner loop.

Moves: 4 axial steps of length 1 and (8-connected) 4 diagonal steps of length
√2; a diagonal needs both side cells free (no corner cutting), as in the
Moving AI benchmarks. An optional cost layer ``c >= 0`` (H, W) makes a step
``u -> v`` cost ``len * (1 + (c[u] + c[v]) / 2)``; the octile (8) or Manhattan
(4) heuristic stays admissible and consistent because the layer never lowers
a step below its length.

The search keeps flat arrays over the padded grid (one blocked cell of border,
so neighbours need no bounds checks): a bit mask of the allowed moves of each
cell (computed once per grid), ``g``, ``parent``, a ``state`` stamp
(reached / expanded in this query), and an indexed binary heap whose slots
hold (f, g, node) inline (``hk``, ``hg``, ``hn``; ``hpos`` maps a node to its
slot) for decrease-key. Stamps make the buffers reusable across queries
without clearing. The goal is accepted when popped, not when pushed; among equal ``f``
the node with the larger ``g`` is popped first.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from slam2d.planning.base import register_planner
from slam2d.planning.grid import PlanningGrid

__all__ = ["PlanResult", "AStar", "astar", "path_length", "path_cost", "check_path", "endpoint_problem", "SQRT2"]

SQRT2 = math.sqrt(2.0)
_EPS_F = 1e-9  # f values closer than this are ties (broken toward larger g)

# Axial moves first, then diagonals (row step, col step).
_DR = np.array([-1, 1, 0, 0, -1, -1, 1, 1], dtype=np.int64)
_DC = np.array([0, 0, -1, 1, -1, 1, -1, 1], dtype=np.int64)


@dataclass(eq=False)
class PlanResult:
    """A planned grid path.

    ``path`` (L, 2) int64 (row, col) cells from start to goal (empty when not
    found); ``length`` geometric length in cells (sum of step lengths);
    ``cost`` the search cost (= length without a cost layer); ``expanded``
    nodes popped; ``seconds`` wall time; ``reason`` why nothing was found;
    ``info`` planner-specific figures.
    """

    path: np.ndarray
    length: float
    expanded: int
    seconds: float
    found: bool
    reason: str = ""
    cost: float = math.inf
    resolution: float = 1.0
    info: dict = field(default_factory=dict)

    @property
    def length_m(self) -> float:
        """Path length in m."""
        return self.length * self.resolution

    @classmethod
    def failure(cls, reason: str, expanded: int = 0, seconds: float = 0.0, resolution: float = 1.0, **info):
        """A not-found result with its reason."""
        return cls(np.zeros((0, 2), np.int64), math.inf, expanded, seconds, False, reason, math.inf, resolution, info)


def path_length(path) -> float:
    """Sum of Euclidean step lengths of a (L, 2) path (cells or m)."""
    p = np.asarray(path, dtype=np.float64)
    if len(p) < 2:
        return 0.0
    d = np.diff(p, axis=0)
    return float(np.hypot(d[:, 0], d[:, 1]).sum())


def path_cost(path, cost: np.ndarray | None = None) -> float:
    """Search cost of a (L, 2) grid path: step lengths times ``1 + (c_u + c_v) / 2``."""
    p = np.asarray(path, dtype=np.int64).reshape(-1, 2)
    if len(p) < 2:
        return 0.0
    d = np.diff(p, axis=0)
    step = np.hypot(d[:, 0], d[:, 1])
    if cost is None:
        return float(step.sum())
    c = np.asarray(cost, dtype=np.float64)[p[:, 0], p[:, 1]]
    return float((step * (1.0 + 0.5 * (c[:-1] + c[1:]))).sum())


def check_path(free: np.ndarray, path, connectivity: int = 8) -> str:
    """Why a grid path is invalid ('' when valid): bounds, blocked cells, gaps, cut corners."""
    free = np.asarray(free, dtype=bool)
    p = np.asarray(path, dtype=np.int64).reshape(-1, 2)
    if len(p) == 0:
        return "empty path"
    h, w = free.shape
    inside = (p[:, 0] >= 0) & (p[:, 0] < h) & (p[:, 1] >= 0) & (p[:, 1] < w)
    if not inside.all():
        return f"cell {tuple(p[~inside][0])} outside the grid"
    if not free[p[:, 0], p[:, 1]].all():
        return f"cell {tuple(p[~free[p[:, 0], p[:, 1]]][0])} is blocked"
    d = np.diff(p, axis=0)
    ad = np.abs(d)
    bad = (ad.max(axis=1) != 1) if connectivity == 8 else (ad.sum(axis=1) != 1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        return f"step {i} from {tuple(p[i])} to {tuple(p[i + 1])} is not a single move"
    diag = (ad[:, 0] == 1) & (ad[:, 1] == 1)
    a = p[:-1][diag]
    dd = d[diag]
    cut = ~(free[a[:, 0] + dd[:, 0], a[:, 1]] & free[a[:, 0], a[:, 1] + dd[:, 1]])
    if cut.any():
        i = int(np.flatnonzero(diag)[np.flatnonzero(cut)[0]])
        return f"diagonal step {i} from {tuple(p[i])} to {tuple(p[i + 1])} cuts a corner"
    return ""


# ---------------------------------------------------------------- numba kernel


@njit(inline="always")
def _less(fa, ga, fb, gb):
    if fa < fb - _EPS_F:
        return True
    if fa > fb + _EPS_F:
        return False
    return ga > gb


@njit(cache=True)
def _sift_up(hk, hg, hn, hpos, i, fk, gk, node):
    """Place ``node`` with key (fk, gk) at heap slot ``i`` or above."""
    while i > 0:
        p = (i - 1) >> 1
        if not _less(fk, gk, hk[p], hg[p]):
            break
        hk[i] = hk[p]
        hg[i] = hg[p]
        hn[i] = hn[p]
        hpos[hn[i]] = i
        i = p
    hk[i] = fk
    hg[i] = gk
    hn[i] = node
    hpos[node] = i


@njit(cache=True)
def _pop(hk, hg, hn, hpos, size):
    """Remove the heap root; returns (node, new size)."""
    top = hn[0]
    size -= 1
    if size > 0:
        fk = hk[size]
        gk = hg[size]
        node = hn[size]
        i = 0
        while True:
            c = 2 * i + 1
            if c >= size:
                break
            if c + 1 < size and _less(hk[c + 1], hg[c + 1], hk[c], hg[c]):
                c += 1
            if not _less(hk[c], hg[c], fk, gk):
                break
            hk[i] = hk[c]
            hg[i] = hg[c]
            hn[i] = hn[c]
            hpos[hn[i]] = i
            i = c
        hk[i] = fk
        hg[i] = gk
        hn[i] = node
        hpos[node] = i
    return top, size


@njit(inline="always")
def _octile(vr, vc, tr, tc, conn8):
    dy = abs(vr - tr)
    dx = abs(vc - tc)
    if conn8:
        return dx + dy + (SQRT2 - 2.0) * min(dx, dy)
    return float(dx + dy)


def move_mask(free: np.ndarray) -> np.ndarray:
    """Allowed moves of every padded cell: bit k set when move k (``_DR``, ``_DC``) from a free
    cell reaches a free cell (and, for a diagonal, both side cells are free). Flat uint8."""
    f = np.pad(np.asarray(free, dtype=bool), 2)  # one extra ring so every shift stays in bounds
    h, w = f.shape
    core = f[1:-1, 1:-1]
    out = np.zeros((h - 2, w - 2), np.uint8)
    for k in range(8):
        dr, dc = int(_DR[k]), int(_DC[k])
        ok = core & f[1 + dr : h - 1 + dr, 1 + dc : w - 1 + dc]
        if dr and dc:
            ok &= f[1 + dr : h - 1 + dr, 1 : w - 1] & f[1 : h - 1, 1 + dc : w - 1 + dc]
        out |= ok.astype(np.uint8) << k
    return out.ravel()


@njit(cache=True)
def _search(moves, zone, zstamp, cost, use_cost, width, s, t, conn8, r0, r1, c0, c1,
            g, parent, state, hk, hg, hn, hpos, stamp):  # fmt: skip
    """A* from padded index ``s`` to ``t`` (Dijkstra over the window when ``t < 0``).

    ``moves`` is :func:`move_mask` of the grid (free target, free diagonal
    sides). Cells must also lie inside rows ``r0..r1`` and cols ``c0..c1``
    (padded, inclusive; pass 0 for ``r0`` to skip the test) and, when
    ``zstamp != 0``, be marked ``zone == zstamp`` (diagonal side cells need
    only be free).
    ``state[v]`` is ``2 stamp`` once ``v`` is reached, ``2 stamp + 1`` once
    expanded (older values are smaller). Returns (found, nodes expanded).
    """
    reached = 2 * stamp
    done = reached + 1
    bounded = r0 > 0
    use_h = t >= 0
    tr = t // width if use_h else 0
    tc = t - tr * width if use_h else 0
    state[s] = reached
    g[s] = 0.0
    parent[s] = -1
    sr = s // width
    _sift_up(hk, hg, hn, hpos, 0, _octile(sr, s - sr * width, tr, tc, conn8) if use_h else 0.0, 0.0, s)
    size = 1
    expanded = 0
    nk = 8 if conn8 else 4
    while size > 0:
        u, size = _pop(hk, hg, hn, hpos, size)
        state[u] = done
        expanded += 1
        if u == t:
            return True, expanded
        ur = u // width
        uc = u - ur * width
        gu = g[u]
        cu = cost[u] if use_cost else 0.0
        mv = moves[u]
        for k in range(nk):
            if not (mv >> k) & 1:
                continue
            dr = _DR[k]
            dc = _DC[k]
            v = u + dr * width + dc
            sv = state[v]
            if sv == done:
                continue
            vr = ur + dr
            vc = uc + dc
            if bounded and (vr < r0 or vr > r1 or vc < c0 or vc > c1):
                continue
            if zstamp != 0 and zone[v] != zstamp:
                continue
            step = SQRT2 if k >= 4 else 1.0
            if use_cost:
                step *= 1.0 + 0.5 * (cu + cost[v])
            ng = gu + step
            if sv < reached:
                state[v] = reached
                g[v] = ng
                parent[v] = u
                hv = _octile(vr, vc, tr, tc, conn8) if use_h else 0.0
                _sift_up(hk, hg, hn, hpos, size, ng + hv, ng, v)
                size += 1
            elif ng < g[v] - 1e-12:
                i = hpos[v]
                hv = hk[i] - g[v]
                g[v] = ng
                parent[v] = u
                _sift_up(hk, hg, hn, hpos, i, ng + hv, ng, v)
    return False, expanded


@njit(cache=True)
def _trace(parent, t, width):
    """(L, 2) unpadded (row, col) cells from the search root to ``t``, and their length (cells)."""
    n = 0
    v = t
    while v != -1:
        n += 1
        v = parent[v]
    out = np.empty((n, 2), np.int64)
    length = 0.0
    v = t
    i = n - 1
    while v != -1:
        r = v // width
        out[i, 0] = r - 1
        out[i, 1] = v - r * width - 1
        p = parent[v]
        if p != -1:
            d = abs(v - p)
            length += 1.0 if d == 1 or d == width else SQRT2
        v = p
        i -= 1
    return out, length


# ---------------------------------------------------------------- planner


class SearchBuffers:
    """Flat search arrays for ``n`` cells (or graph nodes), reused across queries via stamps.

    ``state`` holds ``2 stamp`` (reached) / ``2 stamp + 1`` (expanded) of the
    search with that stamp; ``zone`` marks cells allowed in a masked search;
    ``mark`` is scratch for path post-processing.
    """

    LIMIT = 2**30 - 2

    def __init__(self, n: int):
        self.g = np.zeros(n, np.float64)
        self.parent = np.full(n, -1, np.int32)
        self.state = np.zeros(n, np.int32)
        self.hk = np.zeros(n, np.float64)  # heap slots: f, g, node
        self.hg = np.zeros(n, np.float64)
        self.hn = np.zeros(n, np.int32)
        self.hpos = np.zeros(n, np.int32)  # node -> heap slot
        self.zone = np.zeros(n, np.int32)
        self.mark = np.zeros(n, np.int32)
        self.stamp = 0
        self.zstamp = 0

    def arrays(self):
        """The kernel's buffer arguments: g, parent, state, hk, hg, hn, hpos."""
        return self.g, self.parent, self.state, self.hk, self.hg, self.hn, self.hpos

    def reserve(self, k: int) -> int:
        """Reserve ``k`` consecutive stamps for a kernel that increments its own; returns the last used."""
        if self.stamp + k >= self.LIMIT:
            self.state[:] = 0
            self.mark[:] = 0
            self.stamp = 0
        first = self.stamp
        self.stamp += k
        return first

    def next_stamp(self) -> int:
        """A fresh search stamp (clears the arrays on wrap-around)."""
        return self.reserve(1) + 1

    def reserve_zone(self, k: int) -> int:
        """Reserve ``k`` consecutive zone stamps; returns the last one used before them."""
        if self.zstamp + k >= self.LIMIT:
            self.zone[:] = 0
            self.zstamp = 0
        first = self.zstamp
        self.zstamp += k
        return first

    def next_zone(self) -> int:
        """A fresh zone stamp for marking allowed cells."""
        return self.reserve_zone(1) + 1


def endpoint_problem(free: np.ndarray, cell, which: str) -> str:
    """Why ``cell`` cannot be a start or goal ('' when it can)."""
    r, c = (int(v) for v in cell)
    h, w = free.shape
    if not (0 <= r < h and 0 <= c < w):
        return f"{which} cell ({r}, {c}) is outside the {h}x{w} grid"
    if not free[r, c]:
        return f"{which} cell ({r}, {c}) is blocked (an obstacle, unknown, or within the robot radius of one)"
    return ""


class AStar:
    """Reusable grid A* over a :class:`PlanningGrid` (or a bool mask, resolution 1).

    ``connectivity`` 4 or 8; ``cost`` an optional (H, W) layer >= 0 (see the
    module docstring). Buffers are allocated once; each :meth:`plan` reuses them.
    """

    def __init__(self, grid: PlanningGrid | np.ndarray, connectivity: int = 8, cost: np.ndarray | None = None):
        if not isinstance(grid, PlanningGrid):
            grid = PlanningGrid(np.asarray(grid, dtype=bool))
        if connectivity not in (4, 8):
            raise ValueError(f"connectivity must be 4 or 8, got {connectivity}")
        self.grid = grid
        self.connectivity = connectivity
        h, w = grid.shape
        self.shape = (h, w)
        self.width = w + 2
        self.free_p = np.pad(grid.free, 1).astype(np.uint8).ravel()
        self.moves = move_mask(grid.free)
        self.use_cost = cost is not None
        self.cost = None if cost is None else np.asarray(cost, dtype=np.float64)
        self.cost_p = _padded_cost(cost, grid.shape) if cost is not None else np.zeros(1)
        self.buf = SearchBuffers(self.free_p.size)

    def _usable(self, cell) -> bool:
        """Whether a (row, col) cell is inside the grid and free (fast path of endpoint_problem)."""
        r, c = int(cell[0]), int(cell[1])
        return 0 <= r < self.shape[0] and 0 <= c < self.shape[1] and self.free_p[(r + 1) * self.width + c + 1] != 0

    def index(self, cell) -> int:
        """Padded flat index of a (row, col) cell."""
        return (int(cell[0]) + 1) * self.width + int(cell[1]) + 1

    def search(self, s: int, t: int, bounds=None, zstamp: int = 0) -> tuple[bool, int]:
        """Run the kernel between padded indices; (found, expanded). Parents stay in ``buf``."""
        b = self.buf
        r0, r1, c0, c1 = bounds if bounds is not None else (0, 0, 0, 0)
        return _search(self.moves, b.zone, zstamp, self.cost_p, self.use_cost, self.width, s, t,
                       self.connectivity == 8, r0, r1, c0, c1, *b.arrays(), b.next_stamp())  # fmt: skip

    def plan(self, start, goal) -> PlanResult:
        """Path between (row, col) cells; found=False with a reason when there is none."""
        t0 = time.perf_counter()
        res = self.grid.resolution
        if not (self._usable(start) and self._usable(goal)):
            why = endpoint_problem(self.grid.free, start, "start") or endpoint_problem(self.grid.free, goal, "goal")
            return PlanResult.failure(why, 0, time.perf_counter() - t0, res)
        t = self.index(goal)
        found, expanded = self.search(self.index(start), t)
        if not found:
            return PlanResult.failure(
                f"goal {tuple(int(v) for v in goal)} is unreachable from start {tuple(int(v) for v in start)} "
                f"({expanded} cells searched)",
                expanded, time.perf_counter() - t0, res,
            )  # fmt: skip
        path, length = _trace(self.buf.parent, t, self.width)
        cost = float(self.buf.g[t])
        return PlanResult(path, length, expanded, time.perf_counter() - t0, True, "", cost, res)

    def plan_world(self, start_xy, goal_xy) -> PlanResult:
        """Path between world points (x, y) m (their containing cells)."""
        return self.plan(self.grid.world_to_cell(start_xy), self.grid.world_to_cell(goal_xy))


def _padded_cost(cost, shape) -> np.ndarray:
    cost = np.asarray(cost, dtype=np.float64)
    if cost.shape != shape:
        raise ValueError(f"cost layer shape {cost.shape} differs from the grid {shape}")
    if not np.isfinite(cost).all() or (cost < 0).any():
        raise ValueError("cost layer must be finite and >= 0 (keeps the heuristic admissible)")
    return np.pad(cost, 1).ravel()


def astar(grid: PlanningGrid | np.ndarray, start, goal, connectivity: int = 8, cost=None) -> PlanResult:
    """One-off A* between (row, col) cells (allocates buffers; use :class:`AStar` for many queries)."""
    return AStar(grid, connectivity, cost).plan(start, goal)


@register_planner("astar")
def astar_planner(grid: PlanningGrid | np.ndarray) -> AStar:
    """A* on the 8-connected grid, octile heuristic, no corner cutting."""
    return AStar(grid)
