"""Room-graph planning on spectral segmentations: which similarity measure plans best.

On the rooms/ floor plans (Bormann et al. ICRA 2016 maps, 0.05 m/px), each
spectral similarity measure (hausdorff, nearest_neighbour, feature_points,
visibility) segments the map; the room-graph planner
(:class:`~slam2d.planning.hierarchical.RoomGraphPlanner`) built on those rooms
is compared with A* on the same grid and queries. The morphological
segmentation (the default of ``slam2d plan --hierarchical rooms``) is the
reference row.

As ``slam2d.planning.run.plan_on_map``: the map is segmented before
inflation, both planners run on the grid inflated by the robot radius
(0.2 m). Segmentations are in image orientation (row 0 the top) and are
flipped to the planning grid (rows going up).

Queries: random seeded pairs of free cells (seed mixed with the map name, so a
subset of maps keeps its queries) at least ``--min-dist`` m apart in a straight
line and connected by A*. Times are process CPU seconds per query (numba
compiled beforehand); speed-up is the median over queries of A* / room-graph
time. Build (region graph + portals) and segmentation times are wall seconds.
The CSV's ``aligned_pct`` is the share of cells where "labelled" equals "free
in the planning grid" (a check of the flip). Failures: room-graph found
nothing where A* did, or returned an invalid path (``check_path``, wrong end
points).

    nice .venv/bin/python benchmarks/planning_rooms_similarity.py [--maps office_a ...] [--queries 40]
        [--seed 0] [--min-dist 10] [--out results/planning_rooms_similarity.csv]
"""

from __future__ import annotations

import argparse
import csv
import os
import time
import zlib
from pathlib import Path

import numpy as np
from scipy import ndimage

from slam2d.planning.astar import AStar, check_path
from slam2d.planning.grid import load_floor_plan as load_grid
from slam2d.planning.hierarchical import RoomGraphPlanner
from slam2d.segmentation.baselines import morphological
from slam2d.segmentation.evaluate import load_floor_plan as load_free
from slam2d.segmentation.spectral import segment_spectral

ROOT = Path(os.environ.get("SLAM2D_DATA", Path(__file__).resolve().parents[1] / ".." / "shared" / "datasets"))
MAPS = ["Freiburg52_scan", "Freiburg79_scan", "lab_b_scan", "lab_c_scan", "lab_d_scan", "lab_ipa",
        "office_a", "office_b", "office_c", "office_d"]
SIMILARITIES = ("hausdorff", "nearest_neighbour", "feature_points", "visibility")
BASELINE = "morphological"
ROBOT_RADIUS = 0.2


def cpu_timed(fn, *args):
    """(result, process CPU seconds) of ``fn(*args)``."""
    t0 = time.process_time()
    out = fn(*args)
    return out, time.process_time() - t0


def sample_queries(grid, astar: AStar, n: int, min_dist_m: float, seed: int, name: str):
    """Up to ``n`` (start, goal) cell pairs that A* connects, preferably >= ``min_dist_m`` apart.

    Candidates come from the largest 8-connected free component; if too few
    are far enough apart, the longest of the rest fill up.
    """
    rng = np.random.default_rng([seed, zlib.crc32(name.encode())])
    comp, k = ndimage.label(grid.free, structure=np.ones((3, 3)))
    if k == 0:
        return []
    big = np.argmax(np.bincount(comp.ravel())[1:]) + 1
    cells = np.argwhere(comp == big)
    far, near = [], []
    min_cells = min_dist_m / grid.resolution
    for _ in range(50 * n):
        if len(far) >= n:
            break
        s, g = cells[rng.choice(len(cells), 2, replace=False)]
        d = float(np.hypot(*(s - g)))
        if d < min_cells and len(near) >= n:
            continue
        r = astar.plan(s, g)
        if r.found:
            (far if d >= min_cells else near).append((d, s, g, r))
    near.sort(key=lambda q: -q[0])
    return [(s, g) for _, s, g, _ in (far + near)[:n]]


def segment(method: str, free_img: np.ndarray, grid, res: float):
    """Labels aligned with ``grid`` (rows going up), segmentation wall seconds, k (or '')."""
    t0 = time.perf_counter()
    if method == BASELINE:  # as plan_on_map: on the (flipped) planning grid itself
        labels = morphological(grid.free, grid.resolution)
        return labels, time.perf_counter() - t0, ""
    r = segment_spectral(free_img, res, similarity=method)
    return np.flipud(r.labels), time.perf_counter() - t0, r.k


def run_map(name: str, methods, n_queries: int, seed: int, min_dist: float) -> list[dict]:
    path = ROOT / "rooms" / f"{name}.png"
    free_img, res = load_free(path)
    grid = load_grid(path, resolution=res)
    if not np.array_equal(np.flipud(free_img), grid.free):
        raise RuntimeError(f"{name}: segmentation and planning masks are not flips of each other")
    plan_grid = grid.inflated(ROBOT_RADIUS)
    astar = AStar(plan_grid)
    queries = sample_queries(plan_grid, astar, n_queries, min_dist, seed, name)
    base = [cpu_timed(astar.plan, s, g) for s, g in queries]
    ref_len = np.array([r.length_m for r, _ in base])
    ref_s = np.array([dt for _, dt in base])
    dist_m = np.array([np.hypot(*(s - g)) * res for s, g in queries])
    rows = []
    for method in methods:
        labels, seg_s, k = segment(method, free_img, grid, res)
        aligned = 100.0 * float(((labels > 0) == grid.free).mean())  # ~100 when labels and grid line up
        planner = RoomGraphPlanner(plan_grid, labels)
        if queries:
            planner.plan(*queries[0])  # warm caches (and numba on the first map)
        sub, secs, speedups, fails = [], [], [], 0
        for (s, g), ref, ref_dt in zip(queries, ref_len, ref_s):
            r, dt = cpu_timed(planner.plan, s, g)
            bad = (not r.found or check_path(plan_grid.free, r.path) or (r.path[0] != s).any()
                   or (r.path[-1] != g).any())  # fmt: skip
            if bad:
                fails += 1
                continue
            sub.append(100.0 * (r.length_m / ref - 1.0))
            secs.append(dt)
            speedups.append(ref_dt / max(dt, 1e-9))
        rows.append(dict(
            map=name, method=method, k=k, rooms=planner.graph.number_of_nodes(),
            portals=planner.graph.number_of_edges(), aligned_pct=round(aligned, 2),
            seg_s=round(seg_s, 3), build_s=round(planner.build_seconds, 4), queries=len(queries),
            min_query_m=round(float(dist_m.min()), 2) if len(dist_m) else "",
            failures=fails, sub=sub, secs=secs, speedups=speedups, ref_s=ref_s,
        ))
    return rows


def _finish(rows: list[dict]) -> None:
    """Per-map summary fields from the per-query lists."""
    for r in rows:
        sub = np.array(r["sub"])
        r["mean_subopt_pct"] = round(float(sub.mean()), 3) + 0.0 if len(sub) else ""
        r["max_subopt_pct"] = round(float(sub.max()), 3) + 0.0 if len(sub) else ""
        r["median_speedup"] = round(float(np.median(r["speedups"])), 3) if len(r["speedups"]) else ""
        r["astar_ms_median"] = round(1e3 * float(np.median(r["ref_s"])), 4) if len(r["ref_s"]) else ""
        r["rooms_ms_median"] = round(1e3 * float(np.median(r["secs"])), 4) if len(r["secs"]) else ""


def markdown(rows: list[dict], methods) -> str:
    out = ["| segmentation | maps | queries | failures | mean subopt. % | max subopt. % | median speed-up "
           "| median A* ms | median rooms ms | rooms / map | build s / map | segmentation s / map |",
           "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for m in methods:
        rs = [r for r in rows if r["method"] == m]
        sub = np.concatenate([r["sub"] for r in rs]) if rs else np.array([])
        up = np.concatenate([r["speedups"] for r in rs])
        ref = np.concatenate([r["ref_s"] for r in rs])
        secs = np.concatenate([r["secs"] for r in rs])
        label = m if m != BASELINE else f"{m} (reference)"
        f = (lambda v, d=2: f"{round(float(v), d) + 0.0:.{d}f}")  # no "-0.00"
        out.append(
            f"| {label} | {len(rs)} | {sum(r['queries'] for r in rs)} | {sum(r['failures'] for r in rs)} "
            f"| {f(sub.mean()) if len(sub) else '-'} | {f(sub.max()) if len(sub) else '-'} "
            f"| {f(np.median(up)) if len(up) else '-'} | {f(1e3 * np.median(ref), 3) if len(ref) else '-'} "
            f"| {f(1e3 * np.median(secs), 3) if len(secs) else '-'} | {np.mean([r['rooms'] for r in rs]):.1f} "
            f"| {np.mean([r['build_s'] for r in rs]):.3f} | {np.mean([r['seg_s'] for r in rs]):.2f} |"
        )
    return "\n".join(out)


def warm_up() -> None:
    """Compile the numba kernels (A*, room-graph planner, segmentation) outside the timings."""
    free = np.zeros((120, 200), bool)
    free[10:110, 10:95] = True
    free[10:110, 105:190] = True
    free[55:65, 95:105] = True
    from slam2d.planning.grid import PlanningGrid

    grid = PlanningGrid(np.flipud(free), 0.05)
    AStar(grid).plan((20, 20), (100, 180))
    RoomGraphPlanner(grid, morphological(grid.free, 0.05)).plan((20, 20), (100, 180))
    for sim in SIMILARITIES:
        try:
            segment_spectral(free, 0.05, similarity=sim)
        except Exception:  # a toy map may be too small for some settings; compilation is what matters
            pass


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--maps", nargs="+", default=MAPS)
    ap.add_argument("--queries", type=int, default=40)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--min-dist", type=float, default=10.0, help="preferred straight start-goal distance (m)")
    ap.add_argument("--similarity", nargs="+", default=list(SIMILARITIES), choices=SIMILARITIES)
    ap.add_argument("--out", type=Path, default=Path("results/planning_rooms_similarity.csv"))
    a = ap.parse_args()
    methods = [*a.similarity, BASELINE]
    t_all = time.perf_counter()
    warm_up()
    rows = []
    for name in a.maps:
        t0 = time.perf_counter()
        got = run_map(name, methods, a.queries, a.seed, a.min_dist)
        rows += got
        print(f"{name}: {got[0]['queries']} queries (>= {got[0]['min_query_m']} m), "
              + ", ".join(f"{r['method']} {r['rooms']} rooms {r['failures']} fail" for r in got)
              + f" [{time.perf_counter() - t0:.0f} s]", flush=True)
    _finish(rows)
    print()
    print(markdown(rows, methods))
    a.out.parent.mkdir(parents=True, exist_ok=True)
    fields = ["map", "method", "k", "rooms", "portals", "aligned_pct", "queries", "min_query_m", "failures",
              "mean_subopt_pct", "max_subopt_pct", "median_speedup", "astar_ms_median", "rooms_ms_median",
              "build_s", "seg_s"]
    with open(a.out, "w", newline="") as fh:
        w = csv.DictWriter(fh, fields, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    print(f"\nwrote {a.out} ({len(rows)} rows); total {time.perf_counter() - t_all:.0f} s")


if __name__ == "__main__":
    main()
