"""Grid path planning on the Moving AI benchmarks: correctness, speed against peers, hierarchy.

1. Correctness: slam2d's A* (8-connected, diagonal √2, no corner cutting) on
   every scenario of every map; its length must equal the scenario's optimal
   length (relative tolerance 1e-5) and its path must be valid.
2. Speed, on the same sampled scenarios and in the same run: slam2d A* (planner
   built once per map), ``networkx.astar_path`` on the same 8-connected grid
   graph (same no-corner-cutting edges and weights, octile heuristic, graph
   built once), scikit-image ``route_through_array`` (per call, as a user
   calls it) and a prebuilt ``MCP_Geometric.find_costs`` (Dijkstra; both let
   diagonals cut corners, so their lengths may be shorter than optimal).
   Each method runs over all sampled queries in turn.
3. Hierarchy on ``16room_000``: HPA* at several cluster sizes, raw and smoothed,
   and the room-graph planner on a morphological room segmentation (stitched per
   room, or one A* over the route's rooms: ``corridor``), against
   A* on the same queries: suboptimality and per-query speed-up, over all
   scenarios and over the long ones (the upper quarter of the buckets).

Times are medians per query of process CPU time (``time.process_time``; all
methods are single-threaded, and CPU time stays meaningful on a shared
machine), numba compilation excluded (one warm-up query per planner); graph
and abstraction build times are wall-clock.

    nice .venv/bin/python benchmarks/planning_movingai.py [--data DIR] [--maps arena den312d 16room_000]
        [--sample 50] [--clusters 8 10 16 32] [--long 0.75] [--seed 0]
"""

from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path

import networkx as nx
import numpy as np

from slam2d.planning.astar import SQRT2, AStar, check_path
from slam2d.planning.grid import load_movingai_map, load_scenarios
from slam2d.planning.hierarchical import HPAStar
from slam2d.planning.room_graph import RoomGraphPlanner

DEFAULT_DATA = Path(os.environ.get("SLAM2D_DATA", Path(__file__).resolve().parents[1] / ".." / "shared" / "datasets"))
MAPS = ("arena", "den312d", "16room_000")
REL_TOL = 1e-5


def table(header: list[str], rows: list[list]) -> str:
    """A Markdown table."""
    fmt = [[f"{v:.3g}" if isinstance(v, float) else str(v) for v in r] for r in rows]
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in fmt])


def grid_graph(free: np.ndarray) -> nx.Graph:
    """8-connected networkx graph of the free cells: axial weight 1, diagonal √2 when both sides are free."""
    g = nx.Graph()
    r, c = np.nonzero(free)
    g.add_nodes_from(zip(r.tolist(), c.tolist()))
    h, w = free.shape
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        a = free[: h - dr, max(-dc, 0) : w - max(dc, 0)]
        b = free[dr:, max(dc, 0) : w + min(dc, 0)]
        ok = a & b
        if dr and dc:
            ok &= free[dr:, max(-dc, 0) : w - max(dc, 0)] & free[: h - dr, max(dc, 0) : w + min(dc, 0)]
        rr, cc = np.nonzero(ok)
        cc = cc + max(-dc, 0)
        wt = SQRT2 if dr and dc else 1.0
        g.add_weighted_edges_from(zip(zip(rr.tolist(), cc.tolist()), zip((rr + dr).tolist(), (cc + dc).tolist()),
                                      [wt] * len(rr)))  # fmt: skip
    return g


def octile(a, b) -> float:
    dy, dx = abs(a[0] - b[0]), abs(a[1] - b[1])
    return dx + dy + (SQRT2 - 2.0) * min(dx, dy)


def timed(fn, *args):
    """(result, CPU seconds) of ``fn(*args)``: process CPU time, robust on a shared machine."""
    t0 = time.process_time()
    out = fn(*args)
    return out, time.process_time() - t0


def correctness(data: Path, maps) -> str:
    rows = []
    for name in maps:
        grid = load_movingai_map(data / "movingai" / f"{name}.map")
        sc = load_scenarios(data / "movingai" / f"{name}.map.scen")
        planner = AStar(grid)
        planner.plan(sc.start_cells[0], sc.goal_cells[0])
        bad = invalid = 0
        worst = 0.0
        secs = []
        for s, t, opt in zip(sc.start_cells, sc.goal_cells, sc.optimal):
            r, dt = timed(planner.plan, s, t)
            secs.append(dt)
            err = abs(r.length - opt) / max(opt, 1.0) if r.found else math.inf
            worst = max(worst, err)
            bad += err > REL_TOL
            invalid += bool(not r.found or check_path(grid.free, r.path))
        h, w = grid.shape
        rows.append([name, f"{w}x{h}", len(sc), bad, invalid, f"{worst:.1e}", 1e3 * float(np.median(secs)),
                     float(np.sum(secs))])  # fmt: skip
    return table(["map", "size", "scenarios", "length mismatches", "invalid paths", "max rel. error",
                  "median ms (CPU)", "total s (CPU)"], rows)  # fmt: skip


def speed(data: Path, maps, sample: int, seed: int) -> str:
    from skimage.graph import MCP_Geometric, route_through_array

    rows = []
    for name in maps:
        grid = load_movingai_map(data / "movingai" / f"{name}.map")
        sc = load_scenarios(data / "movingai" / f"{name}.map.scen")
        idx = np.sort(np.random.default_rng(seed).choice(len(sc), min(sample, len(sc)), replace=False))
        planner = AStar(grid)
        planner.plan(sc.start_cells[0], sc.goal_cells[0])
        t0 = time.perf_counter()
        graph = grid_graph(grid.free)
        nx_build = time.perf_counter() - t0
        costs = np.where(grid.free, 1.0, np.inf)
        t0 = time.perf_counter()
        mcp = MCP_Geometric(costs)
        mcp_build = time.perf_counter() - t0
        pairs = [(tuple(sc.start_cells[i].tolist()), tuple(sc.goal_cells[i].tolist()), sc.optimal[i]) for i in idx]
        methods = {
            "ours": lambda s, g: planner.plan(s, g).length,
            "nx": lambda s, g: nx.path_weight(graph, nx.astar_path(graph, s, g, octile, "weight"), "weight"),
            "route": lambda s, g: route_through_array(costs, s, g, True, True)[1],
            "mcp": lambda s, g: mcp.find_costs([s], [g])[0][g],
        }
        t, diff = {}, {}
        for key, fn in methods.items():  # one method at a time over the same queries (warm caches for each)
            runs = [timed(fn, s, g) + (opt,) for s, g, opt in pairs]
            t[key] = [dt for _, dt, _ in runs]
            diff[key] = sum(abs(length - opt) > REL_TOL * max(opt, 1.0) for length, _, opt in runs)
        med = {k: 1e3 * float(np.median(v)) for k, v in t.items()}
        rows.append([name, len(idx), med["ours"], med["nx"], med["route"], med["mcp"], med["nx"] / med["ours"],
                     med["route"] / med["ours"], med["mcp"] / med["ours"], nx_build, mcp_build,
                     f"{diff['ours']} / {diff['nx']} / {diff['route']} / {diff['mcp']}"])  # fmt: skip
    return table(["map", "queries", "slam2d A* ms", "networkx ms", "skimage route ms", "skimage MCP ms",
                  "× vs networkx", "× vs route", "× vs MCP", "nx graph build s", "MCP build s",
                  "length ≠ optimal (slam2d / nx / route / MCP)"], rows)  # fmt: skip


def _room_planner(grid, smooth: bool, corridor: bool = False):
    """Room-graph planner on a morphological segmentation of a Moving AI map (None if unavailable)."""
    try:
        from slam2d.mapping.topological import region_graph
        from slam2d.segmentation.baselines import morphological
    except ImportError:
        return None, "segmentation or topological map not available"
    t0 = time.perf_counter()
    # A Moving AI cell is one unit: rooms of 20-2000 cells², up to 8 erosions (doors of 1-2 cells close).
    labels = morphological(grid.free, 1.0, room_area_min=20.0, room_area_max=2000.0, max_erosion=8.0)
    graph = region_graph(labels, grid.resolution, grid.origin, row0_top=False)
    seg_s = time.perf_counter() - t0
    planner = RoomGraphPlanner(grid, labels, graph, smooth=smooth, corridor=corridor)
    planner.build_seconds += seg_s
    return planner, f"{graph.number_of_nodes()} rooms, {graph.number_of_edges()} portals"


def hierarchy(data: Path, clusters, long_frac: float) -> str:
    name = "16room_000"
    grid = load_movingai_map(data / "movingai" / f"{name}.map")
    sc = load_scenarios(data / "movingai" / f"{name}.map.scen")
    astar = AStar(grid)
    astar.plan(sc.start_cells[0], sc.goal_cells[0])
    planners = []
    for c in clusters:
        for smooth in (False, True):
            p = HPAStar(grid, c, smooth=smooth)
            label = f"HPA* {c}x{c}" + (" + smoothing" if smooth else "")
            planners.append((label, p, f"{p.n_nodes} nodes, {p.n_edges} edges"))
    for smooth, corridor in ((False, False), (True, False), (False, True)):
        p, note = _room_planner(grid, smooth, corridor)
        if p is not None:
            planners.append(("room graph" + (" + smoothing" if smooth else "") + (", corridor A*" if corridor else ""),
                             p, note))  # fmt: skip
    for _, p, _ in planners:
        p.plan(sc.start_cells[0], sc.goal_cells[0])
    n = len(sc)
    cells = list(zip(sc.start_cells, sc.goal_cells))
    base = np.array([timed(astar.plan, s, g)[1] for s, g in cells])
    sub = np.zeros((len(planners), n))
    ms = np.zeros((len(planners), n))
    invalid = np.zeros(len(planners), int)
    for k, (_, p, _) in enumerate(planners):  # one planner at a time over all queries
        for i, (s, g) in enumerate(cells):
            r, ms[k, i] = timed(p.plan, s, g)
            sub[k, i] = r.length / sc.optimal[i] - 1.0 if sc.optimal[i] > 0 else 0.0
            invalid[k] += bool(not r.found or check_path(grid.free, r.path) or (r.path[0] != s).any()
                               or (r.path[-1] != g).any())  # fmt: skip
    long = sc.bucket >= long_frac * sc.bucket.max()
    rows = []
    for k, (label, p, note) in enumerate(planners):
        up = base / ms[k]
        rows.append([label, note, p.build_seconds, invalid[k], 100 * sub[k].mean(), 100 * sub[k].max(),
                     100 * sub[k][long].mean(), 100 * sub[k][long].max(), float(np.median(up)),
                     float(np.median(up[long])), 1e3 * float(np.median(ms[k][long]))])  # fmt: skip
    head = (
        f"{name}: {n} scenarios, {int(long.sum())} long (bucket >= {long_frac:.2f} x {sc.bucket.max()}); "
        f"A* median {1e3 * np.median(base):.2f} ms (all), {1e3 * np.median(base[long]):.2f} ms (long)\n\n"
    )
    return head + table(["planner", "abstraction", "build s", "invalid", "subopt. mean %", "subopt. max %",
                         "long: mean %", "long: max %", "speed-up (all)", "speed-up (long)", "long: median ms"],
                        rows)  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="dataset root holding movingai/")
    ap.add_argument("--maps", nargs="+", default=list(MAPS))
    ap.add_argument("--sample", type=int, default=50, help="scenarios per map in the speed comparison")
    ap.add_argument("--clusters", type=int, nargs="+", default=[8, 10, 16, 32], help="HPA* cluster sizes")
    ap.add_argument("--long", type=float, default=0.75, help="long queries: bucket >= this fraction of the largest")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--skip", nargs="*", default=[], choices=["correctness", "speed", "hierarchy"])
    args = ap.parse_args()
    if "correctness" not in args.skip:
        print("## Correctness: A* length vs the scenarios' optimal lengths (rel. tol. 1e-5)\n")
        print(correctness(args.data, args.maps), "\n", flush=True)
    if "speed" not in args.skip:
        print(f"## Speed: median CPU ms per query, {args.sample} sampled scenarios per map (seed {args.seed})\n")
        print(speed(args.data, args.maps, args.sample, args.seed), "\n", flush=True)
    if "hierarchy" not in args.skip:
        print("## Hierarchy: suboptimality and speed-up over A* (per query CPU time, median)\n")
        print(hierarchy(args.data, args.clusters, args.long), flush=True)


if __name__ == "__main__":
    main()
