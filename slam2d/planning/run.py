"""Plan on a map file: grid path, shortcut, time-optimal trajectory, figures and metrics.

``plan_on_map`` is the library side of ``slam2d plan MAP --start x,y --goal x,y``.
It writes into ``out_dir``: ``path.png`` (the map with the grid path, the
shortcut polyline and the trajectory), ``velocity.png`` (speed, yaw rate and
acceleration over time), ``trajectory.csv`` (t, x, y, vx, vy, speed, omega)
and ``metrics.json``; it returns the metrics as a dict.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from slam2d.errors import InputError
from slam2d.runs.results import json_text
from slam2d.planning.astar import AStar, PlanResult, path_length
from slam2d.planning.grid import PlanningGrid, load_grid
from slam2d.planning.smoothing import shortcut
from slam2d.planning.timing import TimedPath, TrajectoryLimits, plot_profile, time_parametrize

__all__ = ["plan_on_map", "plan_queries", "make_planner", "run_plan", "room_labels", "NoPathError", "PLANNERS"]

PLANNERS = ("hpa", "rooms")
"""Values of ``hierarchical``: HPA* over square clusters, or the room-graph planner."""


def _point(value, name: str) -> np.ndarray:
    p = np.asarray(value, dtype=np.float64).ravel()
    if p.shape != (2,) or not np.isfinite(p).all():
        raise InputError(name, f"expected a point (x, y) in m, got {value!r}")
    return p


class NoPathError(Exception):
    """The planner found no path for the one query asked (its reason is the message)."""


def room_labels(grid: PlanningGrid, segmentation=None, seed: int = 0) -> np.ndarray:
    """Room labels (H, W) aligned with ``grid`` (rows going up): the map segmented as ``slam2d segment``
    would (row 0 the top) by ``segmentation`` (a SegmentationConfig; None: morphological)."""
    from slam2d.segmentation.config import SegmentationConfig
    from slam2d.segmentation.rooms import segment_free

    seg = segmentation or SegmentationConfig(method="morphological")
    params = {"seed": seed, **seg.params} if seg.method == "spectral" else seg.params
    labels, _ = segment_free(np.flipud(grid.free), grid.resolution, seg.method, seg.similarity, params)
    return np.ascontiguousarray(labels[::-1])


def _labels(labels, grid: PlanningGrid, segmentation=None, seed: int = 0) -> np.ndarray:
    """Room labels aligned with ``grid`` (rows going up): an array, a .npy, the
    ``labels.png`` of ``slam2d segment`` (row 0 the top), or, if None, the map's
    segmentation by ``segmentation`` (see :func:`room_labels`)."""
    if labels is None:
        return room_labels(grid, segmentation, seed)
    shape = grid.shape
    if isinstance(labels, (str, Path)):
        path = Path(labels)
        if not path.is_file():
            raise InputError(path, "labels file not found")
        labels = _read_labels(path)
    labels = np.asarray(labels)
    if labels.shape != shape:
        raise InputError("labels", f"shape {labels.shape} differs from the map {shape}")
    return labels


def _read_labels(path: Path) -> np.ndarray:
    """A label image (``.png``, row 0 the top, flipped to rows going up) or a ``.npy`` array."""
    try:
        if path.suffix.lower() != ".png":
            return np.load(path, allow_pickle=False)
        from PIL import Image

        with Image.open(path) as im:
            return np.flipud(np.asarray(im).astype(np.int32))
    except Exception as err:  # PIL and numpy raise many types for a file that is not what it says
        raise InputError(path, f"not a readable label image or .npy array ({str(err)[:120]})") from None


def make_planner(grid: PlanningGrid, hierarchical: str | None = None, cluster_size: int = 16, labels=None, graph=None):
    """A* (``None``), HPA* (``"hpa"``) or the room-graph planner (``"rooms"``) on ``grid``.

    The room-graph planner takes ``labels`` (H, W) int aligned with ``grid``
    (rows going up), by default the morphological segmentation of ``grid``.
    """
    if hierarchical is None:
        return AStar(grid)
    if hierarchical == "hpa":
        from slam2d.planning.hierarchical import HPAStar

        return HPAStar(grid, cluster_size)
    if hierarchical == "rooms":
        from slam2d.planning.hierarchical import RoomGraphPlanner

        return RoomGraphPlanner(grid, _labels(labels, grid), graph)
    raise InputError("hierarchical", f"expected one of {', '.join(PLANNERS)} or none, got {hierarchical!r}")


def plan_on_map(
    map_path,
    start,
    goal,
    hierarchical: str | None = None,
    out_dir="results/plan",
    robot_radius: float = 0.2,
    limits: TrajectoryLimits | None = None,
    cluster_size: int = 16,
    labels=None,
    resolution: float | None = None,
    segmentation=None,
    seed: int = 0,
    figures: bool = True,
) -> dict:
    """Plan from ``start`` to ``goal`` (x, y) m on a map and write figures and metrics.

    ``map_path``: map_server ``.yaml``, Moving AI ``.map`` or a floor-plan
    image (``resolution`` m/px, default 0.05). Obstacles are inflated by
    ``robot_radius`` m. ``hierarchical``: None (A*), ``"hpa"`` or ``"rooms"``
    (``labels``: a region image aligned with the map's rows going up, or
    None for the map's segmentation by ``segmentation``, a SegmentationConfig, default
    morphological, run on the map before inflation; ``seed`` for spectral). ``figures``:
    write path.png and velocity.png. Returns the metrics dict
    (``found`` False with a ``reason`` when there is no path).
    """
    t_all = time.perf_counter()
    limits = limits or TrajectoryLimits()
    start, goal = _point(start, "start"), _point(goal, "goal")
    if not 0 <= robot_radius < np.inf:
        raise InputError("robot_radius", f"must be a finite number >= 0 m, got {robot_radius}")
    grid = load_grid(map_path, resolution=resolution)
    free = grid.inflated(robot_radius)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    if hierarchical == "rooms":
        labels = _labels(labels, grid, segmentation, seed)  # segment the map itself, not the inflated free space
    planner = make_planner(free, hierarchical, cluster_size, labels)
    build_s = time.perf_counter() - t0
    result = planner.plan(free.world_to_cell(start), free.world_to_cell(goal))
    metrics = {
        "map": str(map_path),
        "planner": hierarchical or "astar",
        "found": result.found,
        "reason": result.reason,
        "start": start.tolist(),
        "goal": goal.tolist(),
        "robot_radius_m": robot_radius,
        "resolution_m": grid.resolution,
        "build_ms": 1e3 * build_s,
        "plan_ms": 1e3 * result.seconds,
        "nodes_expanded": result.expanded,
        **({"rooms": planner.graph.number_of_nodes()} if hierarchical == "rooms" else {}),
        "limits": limits.model_dump(),
    }
    timed = waypoints = None
    if result.found:
        t0 = time.perf_counter()
        waypoints = free.cell_to_world(shortcut(free.free, result.path))
        metrics["smoothing_ms"] = 1e3 * (time.perf_counter() - t0)
        t0 = time.perf_counter()
        timed = time_parametrize(waypoints, limits, spacing=max(0.1, grid.resolution))
        metrics["timing_ms"] = 1e3 * (time.perf_counter() - t0)
        metrics.update(
            grid_length_m=result.length_m,
            length_m=path_length(waypoints),
            waypoints=len(waypoints),
            trajectory_length_m=timed.length,
            duration_s=timed.duration,
            max_speed_mps=float(timed.speed.max()),
            max_yaw_rate_rps=float(np.abs(timed.omega).max()),
            spline_deviation_m=timed.max_deviation,
        )
        _write_trajectory(out / "trajectory.csv", timed)
        if figures:
            plot_profile(timed, out / "velocity.png")
    if figures:
        _plot_path(grid, free, result, waypoints, timed, start, goal, out / "path.png", metrics["planner"])
    metrics["total_ms"] = 1e3 * (time.perf_counter() - t_all)
    names = {"metrics": "metrics.json", **({"path": "path.png"} if figures else {})}
    if timed is not None:
        names.update(trajectory="trajectory.csv", **({"velocity": "velocity.png"} if figures else {}))
    metrics["files"] = {k: f for k, f in names.items()}
    (out / "metrics.json").write_text(json_text(metrics))
    return metrics


def run_plan(cfg) -> Path:
    """Run a :class:`~slam2d.planning.config.PlanConfig` into a new results folder under
    ``cfg.output.root``; return the folder. One query (start, goal): the path, its timing and figures
    (NoPathError when there is none, leaving no folder); ``queries`` > 0: :func:`plan_queries`."""
    from slam2d import config as config_mod
    from slam2d.datasets.registry import resolve_data_path
    from slam2d.runs.results import results_folder

    p = cfg.planning
    if cfg.map is None:
        raise InputError("map", "no map given (map: FILE in the config, or slam2d plan MAP)")
    if p.queries == 0 and p.start is None:
        raise InputError("planning.start", "give start and goal (--start x,y --goal x,y), or planning.queries > 0")
    map_path = resolve_data_path(cfg.map, key="map")
    labels = resolve_data_path(p.labels, key="planning.labels") if p.labels else None
    hierarchy = None if p.hierarchy == "none" else p.hierarchy
    name = cfg.name or f"plan-{map_path.stem}" + (f"-{hierarchy}" if hierarchy else "")
    with results_folder(cfg.output.root, name) as (work, published):
        (work / "config.yaml").write_text(config_mod.dump(cfg))
        if p.queries:
            metrics = plan_queries(map_path, cfg, labels)
            (work / "metrics.json").write_text(json_text(metrics))
        else:
            metrics = plan_on_map(map_path, p.start, p.goal, hierarchy, work, p.robot_radius, p.limits,
                                  p.cluster_size, labels, cfg.resolution, cfg.segmentation, cfg.seed,
                                  cfg.output.figures)  # fmt: skip
            if not metrics["found"]:
                raise NoPathError(metrics.get("reason") or "unknown")
    return published[0]


def plan_queries(map_path, cfg, labels=None) -> dict:
    """Plan ``cfg.planning.queries`` seeded random start-goal pairs on the map with A* and with the
    configured planner; return the metrics: queries, failures (no path, or an invalid one, where A*
    found one), suboptimality % of the planner's path length over A*'s (mean, max), speed-up (median
    of A* CPU time / the planner's, per query), CPU ms per query (medians), rooms, build and
    segmentation seconds."""
    from slam2d.planning.astar import check_path

    p = cfg.planning
    hierarchy = None if p.hierarchy == "none" else p.hierarchy
    grid = load_grid(map_path, resolution=cfg.resolution)
    free = grid.inflated(p.robot_radius)
    t0 = time.perf_counter()
    if hierarchy == "rooms":
        labels = _labels(labels, grid, cfg.segmentation, cfg.seed)
    segmentation_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    planner = make_planner(free, hierarchy, p.cluster_size, labels)
    build_s = time.perf_counter() - t0
    astar = AStar(free)
    queries = sample_queries(free, astar, p.queries, p.min_distance, cfg.seed, Path(map_path).stem)
    sub, speedups, ref_ms, own_ms, failures = [], [], [], [], 0
    for n, (s, g) in enumerate(queries):
        if n == 0:  # compiled and cached outside the timings
            astar.plan(s, g), planner.plan(s, g)
        ref, ref_s = _cpu_timed(astar.plan, s, g)
        got, own_s = _cpu_timed(planner.plan, s, g)
        if not got.found or check_path(free.free, got.path) or (got.path[0] != s).any() or (got.path[-1] != g).any():
            failures += 1
            continue
        sub.append(100.0 * (got.length_m / ref.length_m - 1.0))
        speedups.append(ref_s / max(own_s, 1e-9))
        ref_ms.append(1e3 * ref_s)
        own_ms.append(1e3 * own_s)
    stat = (lambda f, v: float(f(v)) if len(v) else None)  # noqa: E731
    return {
        "map": str(map_path), "planner": hierarchy or "astar", "queries": len(queries), "failures": failures,
        "mean_subopt_pct": stat(np.mean, sub), "max_subopt_pct": stat(np.max, sub),
        "median_speedup": stat(np.median, speedups), "astar_ms_median": stat(np.median, ref_ms),
        "planner_ms_median": stat(np.median, own_ms),
        "min_query_m": stat(np.min, [np.hypot(*(s - g)) * grid.resolution for s, g in queries]),
        **({"rooms": planner.graph.number_of_nodes(), "segmentation_s": segmentation_s} if hierarchy == "rooms"
           else {}),
        "build_s": build_s, "robot_radius_m": p.robot_radius, "resolution_m": grid.resolution,
    }  # fmt: skip


def sample_queries(grid: PlanningGrid, astar: AStar, n: int, min_dist_m: float, seed: int, name: str):
    """Up to ``n`` (start, goal) cell pairs that A* connects, preferably >= ``min_dist_m`` apart, drawn
    from the largest 8-connected free component; the seed is mixed with ``name`` (the map), so each map
    keeps its queries in any subset of maps. Too few far pairs: the longest near ones fill up."""
    import zlib

    from scipy import ndimage

    rng = np.random.default_rng([seed, zlib.crc32(name.encode())])
    comp, k = ndimage.label(grid.free, structure=np.ones((3, 3)))
    if k == 0:
        return []
    cells = np.argwhere(comp == np.argmax(np.bincount(comp.ravel())[1:]) + 1)
    far, near = [], []
    min_cells = min_dist_m / grid.resolution
    for _ in range(50 * n):
        if len(far) >= n or len(cells) < 2:
            break
        s, g = cells[rng.choice(len(cells), 2, replace=False)]
        d = float(np.hypot(*(s - g)))
        if d < min_cells and len(near) >= n:
            continue
        if astar.plan(s, g).found:
            (far if d >= min_cells else near).append((d, s, g))
    near.sort(key=lambda q: -q[0])
    return [(s, g) for _, s, g in (far + near)[:n]]


def _cpu_timed(fn, *args):
    """(result, process CPU seconds) of ``fn(*args)``."""
    t0 = time.process_time()
    out = fn(*args)
    return out, time.process_time() - t0


def _write_trajectory(path: Path, timed: TimedPath) -> None:
    data = np.column_stack([timed.t, timed.xy, timed.velocity, timed.speed, timed.omega])
    header = "t_s,x_m,y_m,vx_mps,vy_mps,speed_mps,omega_rps"
    np.savetxt(path, data, delimiter=",", fmt="%.6f", header=header, comments="")


def _plot_path(grid, free, result: PlanResult, waypoints, timed, start, goal, path: Path, planner: str) -> None:
    """The map (black blocked, grey inflation margin, white free) with the paths and end points."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    x0, x1, y0, y1 = grid.extent
    aspect = (y1 - y0) / max(x1 - x0, 1e-9)
    fig = Figure(figsize=(8.0, float(np.clip(8.0 * aspect, 3.0, 16.0))), dpi=150)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    shade = np.where(free.free, 1.0, np.where(grid.free, 0.75, 0.0))
    ax.imshow(shade, cmap="gray", vmin=0.0, vmax=1.0, origin="lower", extent=grid.extent, interpolation="nearest")
    if result.found:
        cells = grid.cell_to_world(result.path)
        ax.plot(cells[:, 0], cells[:, 1], color="tab:orange", linewidth=0.8, label=f"grid path ({planner})")
        ax.plot(waypoints[:, 0], waypoints[:, 1], "o-", color="tab:blue", markersize=2.5, linewidth=1.0,
                label="shortcut")  # fmt: skip
        ax.plot(timed.xy[:, 0], timed.xy[:, 1], color="tab:green", linewidth=1.0, label="trajectory")
    ax.plot(*start, "s", color="tab:green", markersize=6, label="start")
    ax.plot(*goal, "*", color="tab:red", markersize=9, label="goal")
    ax.legend(loc="best", fontsize="small")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal")
    if result.found:
        title = f"{result.length_m:.2f} m, {result.expanded} nodes, {1e3 * result.seconds:.1f} ms"
    else:
        title = result.reason
    ax.set_title(title, fontsize="small")
    fig.savefig(path, bbox_inches="tight")
