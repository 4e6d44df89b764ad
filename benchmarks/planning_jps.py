"""JPS, JPS+ and Simple Subgoal Graphs (SSG) against slam2d's A* on the Moving AI maps and floor plans.

1. Correctness: every Moving AI scenario and every floor-plan query planned by
   JPS, JPS+ and SSG; a mismatch is a length differing from A*'s (and, on Moving AI,
   from the scenario's optimal length) by more than 1e-5 relative, or an invalid
   path (blocked cell, cut corner, wrong ends).
2. Speed on long queries (optimal length >= ``--min-length`` cells, default
   100): per query, A*'s CPU time over the planner's; the median of these
   ratios per map and over all long queries of a data set. Moving AI: up to
   ``--sample`` long scenarios per map (seeded). Floor plans (rooms/, 0.05 m
   per pixel, obstacles inflated by ``--radius`` m as ``slam2d plan`` does):
   ``--queries`` seeded start-goal pairs per map at least ``--min-length``
   cells apart in a straight line (so their paths are long too).
3. Preprocessing: JPS+ table build and SSG graph build (wall-clock, best of 3,
   numba compiled beforehand), the table's size, the graph's subgoals and
   (undirected) edges, beside the map's size: the rebuild a changed map costs.

Times are process CPU time (``time.process_time``), the best of ``--repeat``
runs of each query; the planners take turns query by query (the machine's load
changes alike for all); each planner is built and warmed up (compiled) on the
map before timing. A*, JPS, JPS+ and SSG are
all single-threaded numba called from Python, so each query includes the same
few microseconds of call overhead.

    nice .venv/bin/python benchmarks/planning_jps.py [--data DIR] [--maps ...] [--plans ...]
        [--sample 100] [--queries 40] [--min-length 100] [--radius 0.2] [--repeat 3] [--seed 0]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from slam2d.planning.astar import AStar, check_path
from slam2d.planning.grid import load_grid, load_movingai_map, load_scenarios
from slam2d.planning.jps import JPS
from slam2d.planning.jps_plus import JPSPlus
from slam2d.planning.query import sample_queries
from slam2d.planning.subgoal import SubgoalGraph

DEFAULT_DATA = Path(os.environ.get("SLAM2D_DATA", Path(__file__).resolve().parents[1] / ".." / "shared" / "datasets"))
MAPS = ("arena", "den312d", "16room_000")
PLANS = ("Freiburg52_scan", "Freiburg79_scan", "lab_a_scan", "lab_b_scan", "lab_c_scan", "lab_d_scan", "lab_ipa",
         "office_a", "office_b", "office_c", "office_d")  # fmt: skip
REL_TOL = 1e-5
FAST = ("JPS", "JPS+", "SSG")  # compared with A*


def table(header: list[str], rows: list[list]) -> str:
    """A Markdown table."""
    fmt = [[f"{v:.3g}" if isinstance(v, float) else str(v) for v in r] for r in rows]
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in fmt])


def best_cpu(fn, s, g, repeat: int):
    """(result, best process CPU seconds of ``repeat`` runs) of ``fn(s, g)``."""
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.process_time()
        out = fn(s, g)
        best = min(best, time.process_time() - t0)
    return out, best


def build_seconds(cls, free: np.ndarray, repeat: int = 3) -> float:
    """Best wall time of building JPS+ (grid arrays, jump distances) or SSG (subgoals, edges) on ``free``."""
    return min(cls(free).build_seconds for _ in range(repeat))


def mismatches(grid, planners, pairs, optimal=None) -> dict:
    """Per planner name: queries whose length differs from A*'s (or ``optimal``) beyond REL_TOL or
    whose path is invalid."""
    astar = planners["A*"]
    bad = dict.fromkeys(planners, 0)
    for i, (s, g) in enumerate(pairs):
        ref = astar.plan(s, g).length if optimal is None else optimal[i]
        for name, p in planners.items():
            r = p.plan(s, g)
            wrong = not r.found or abs(r.length - ref) > REL_TOL * max(ref, 1.0)
            wrong = wrong or bool(check_path(grid.free, r.path)) or (r.path[0] != s).any() or (r.path[-1] != g).any()
            bad[name] += bool(wrong)
    return bad


def speed(planners, pairs, repeat: int) -> tuple[dict, dict]:
    """Per planner name: (L,) best CPU seconds of each query and (L,) nodes expanded (cells for A*, jump
    points for JPS and JPS+, graph nodes for SSG); the planners take turns on each query (so a change of
    load on the shared machine hits all of them alike)."""
    for p in planners.values():
        p.plan(*pairs[0])  # compiled and cached outside the timings
    secs = {name: np.zeros(len(pairs)) for name in planners}
    expanded = {name: np.zeros(len(pairs)) for name in planners}
    for i, (s, g) in enumerate(pairs):
        for name, p in planners.items():
            r, secs[name][i] = best_cpu(p.plan, s, g, repeat)
            expanded[name][i] = r.expanded
    return secs, expanded


def med(values):
    """The median as a float, or a dash when there are no values."""
    return float(np.median(values)) if len(values) else "–"


def run_map(name, grid, check_pairs, long_pairs, optimal, repeat):
    """One row of figures for a map, and the per-query speed-ups of JPS, JPS+ and SSG."""
    planners = {"A*": AStar(grid), "JPS": JPS(grid), "JPS+": JPSPlus(grid), "SSG": SubgoalGraph(grid)}
    bad = mismatches(grid, planners, check_pairs, optimal)
    t, e = speed(planners, long_pairs, repeat) if long_pairs else (None, None)
    up = {k: t["A*"] / np.maximum(t[k], 1e-9) if t else [] for k in FAST}
    h, w = grid.shape
    ssg = planners["SSG"]
    ms = [med(1e3 * t[k]) if t else "–" for k in ("A*", *FAST)]
    ex = " / ".join(f"{med(e[k]):.0f}" for k in ("A*", *FAST)) if e else "–"
    row = [name, f"{w}x{h}", len(check_pairs), " / ".join(str(bad[k]) for k in FAST), len(long_pairs), *ms, ex,
           *(med(up[k]) for k in FAST), 1e3 * build_seconds(JPSPlus, grid.free),
           planners["JPS+"].table_bytes / 2**20, 1e3 * build_seconds(SubgoalGraph, grid.free),
           f"{ssg.subgoals} / {ssg.edges}"]  # fmt: skip
    return row, up


HEADER = ["map", "size", "checked", "mismatches JPS / JPS+ / SSG", "long queries", "A* ms", "JPS ms", "JPS+ ms",
          "SSG ms", "expanded A* / JPS / JPS+ / SSG", "JPS speed-up", "JPS+ speed-up", "SSG speed-up",
          "JPS+ build ms", "table MB", "SSG build ms", "subgoals / edges"]  # fmt: skip


def movingai(data: Path, maps, sample: int, min_length: float, repeat: int, seed: int):
    rows, ups = [], {k: [] for k in FAST}
    for name in maps:
        grid = load_movingai_map(data / "movingai" / f"{name}.map")
        sc = load_scenarios(data / "movingai" / f"{name}.map.scen")
        pairs = list(zip(sc.start_cells, sc.goal_cells))
        long = np.flatnonzero(sc.optimal >= min_length)
        rng = np.random.default_rng(seed)
        pick = np.sort(rng.choice(long, min(sample, len(long)), replace=False)) if len(long) else long
        row, up = run_map(name, grid, pairs, [pairs[i] for i in pick], sc.optimal, repeat)
        rows.append(row)
        for k, pooled in ups.items():
            pooled.extend(up[k])
        print(f"  {name} done", flush=True)
    return rows, ups


def floor_plans(data: Path, plans, queries: int, min_length: float, radius: float, repeat: int, seed: int):
    rows, ups = [], {k: [] for k in FAST}
    for name in plans:
        grid = load_grid(data / "rooms" / f"{name}.png", resolution=0.05).inflated(radius)
        pairs = sample_queries(grid, AStar(grid), queries, min_length * grid.resolution, seed, name)
        pairs = [(s, g) for s, g in pairs if np.hypot(*(s - g)) >= min_length]
        row, up = run_map(name, grid, pairs, pairs, None, repeat)
        rows.append(row)
        for k, pooled in ups.items():
            pooled.extend(up[k])
        print(f"  {name} done", flush=True)
    return rows, ups


def summary(label: str, ups: dict) -> str:
    n = len(ups["JPS"])
    if not n:
        return f"{label}: no long queries"
    meds = ", ".join(f"{k} {np.median(ups[k]):.1f}x" for k in FAST)
    quart = "; ".join(f"{k} {np.percentile(ups[k], 25):.1f}-{np.percentile(ups[k], 75):.1f}x" for k in ("JPS+", "SSG"))
    return f"{label}: {n} long queries, median speed-up over A*: {meds} (quartiles {quart})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="dataset root holding movingai/ and rooms/")
    ap.add_argument("--maps", nargs="*", default=list(MAPS), help="Moving AI maps")
    ap.add_argument("--plans", nargs="*", default=list(PLANS), help="floor plans of rooms/")
    ap.add_argument("--sample", type=int, default=100, help="long scenarios timed per Moving AI map")
    ap.add_argument("--queries", type=int, default=40, help="queries per floor plan")
    ap.add_argument("--min-length", type=float, default=100.0, help="long query: optimal length >= this, cells")
    ap.add_argument("--radius", type=float, default=0.2, help="floor plans: robot radius, m")
    ap.add_argument("--repeat", type=int, default=3, help="runs per query; the best CPU time counts")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    if args.maps:
        rows, ups = movingai(args.data, args.maps, args.sample, args.min_length, args.repeat, args.seed)
        print("## Moving AI (every scenario checked; long ones timed)\n\n" + table(HEADER, rows) + "\n\n"
              + summary("Moving AI", ups), "\n", flush=True)  # fmt: skip
    if args.plans:
        rows, ups = floor_plans(args.data, args.plans, args.queries, args.min_length, args.radius, args.repeat,
                                args.seed)  # fmt: skip
        print(f"## Floor plans (0.05 m/px, inflated by {args.radius} m; lengths checked against A*)\n\n"
              + table(HEADER, rows) + "\n\n" + summary("Floor plans", ups), flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
