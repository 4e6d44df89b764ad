"""Plan on a map file: grid path, shortcut, time-optimal trajectory (:func:`plan_on_map`), and many
seeded queries against A* (:func:`plan_queries`). ``slam2d plan`` writes their results."""

from __future__ import annotations

import time
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image
from scipy import ndimage

from slam2d.errors import InputError, check_inside, not_a_file
from slam2d.planning.astar import AStar, PlanResult, check_path, path_length
from slam2d.planning.base import GLOBAL_PLANNERS
from slam2d.planning.grid import PlanningGrid, load_grid
from slam2d.planning.smoothing import shortcut
from slam2d.planning.timing import TimedPath, TrajectoryLimits, time_parametrize
from slam2d.segmentation.config import SegmentationConfig
from slam2d.segmentation.rooms import segment_free

__all__ = ["MapPlan", "plan_on_map", "plan_queries", "make_planner", "planner_name", "room_labels", "NoPathError"]

@dataclass(frozen=True, eq=False)
class MapPlan:
    """One query planned on a map: the map's grid, the grid inflated by the robot radius (``free``),
    the grid search's result, the shortcut ``waypoints`` (N, 2) m and the ``timed`` trajectory (both
    None without a path), the start and goal (x, y) m, and the metrics."""

    grid: PlanningGrid
    free: PlanningGrid
    result: PlanResult
    waypoints: np.ndarray | None
    timed: TimedPath | None
    start: np.ndarray
    goal: np.ndarray
    metrics: dict


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
    seg = segmentation or SegmentationConfig(method="morphological")
    labels, _ = segment_free(np.flipud(grid.free), grid.resolution, seg.method, seg.similarity, seg.params, seed)
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
            raise InputError(path, not_a_file(path) or "labels file not found")
        labels = _read_labels(path)
    labels = np.asarray(labels)
    if labels.shape != shape:
        raise InputError("labels", f"shape {labels.shape} differs from the map {shape}")
    _check_orientation(labels, grid, "labels")
    return labels


def _check_orientation(labels: np.ndarray, grid: PlanningGrid, name: str) -> None:
    """InputError when ``labels`` fit the map only upside down: more than a fifth of their rooms' cells
    blocked, and under half as many once flipped (a label image read in the other row convention)."""
    def blocked(lab):
        rooms = lab > 0
        return float((rooms & ~grid.free).sum() / max(rooms.sum(), 1))

    as_given, flipped = blocked(labels), blocked(labels[::-1])
    if as_given > 0.2 and flipped < 0.5 * as_given:
        raise InputError(name, f"the room labels fit the map only upside down ({100 * as_given:.0f} % of their "
                         f"cells blocked, {100 * flipped:.0f} % flipped): grid rows go up in y, a labels.png has "
                         "row 0 at the top")


def _read_labels(path: Path) -> np.ndarray:
    """A label image (``.png``, row 0 the top, flipped to rows going up) or a ``.npy`` array."""
    try:
        if path.suffix.lower() != ".png":
            return np.load(path, allow_pickle=False)
        with Image.open(path) as im:
            return np.flipud(np.asarray(im).astype(np.int32))
    except Exception as err:  # PIL and numpy raise many types for a file that is not what it says
        raise InputError(path, f"not a readable label image or .npy array ({str(err)[:120]})") from None


def make_planner(grid: PlanningGrid, name: str | None = None, cluster_size: int = 16, labels=None, graph=None,
                 key: str = "hierarchical", corridor: bool = False):
    """The global planner ``name`` (:data:`~slam2d.planning.base.GLOBAL_PLANNERS`; None: A*) on ``grid``.

    A planner that takes room ``labels`` (the room graph) gets them aligned with ``grid`` (rows going
    up): an array, a .npy or a labels.png, by default the morphological segmentation of ``grid``.
    ``cluster_size`` (HPA*) and ``corridor`` (the room graph) go to the planners that take them. ``key``
    names the choice in an error.
    """
    name = planner_name(name, key)
    inputs = {"labels": _labels(labels, grid), "graph": graph} if "labels" in GLOBAL_PLANNERS.takes(name) else {}
    options = GLOBAL_PLANNERS.options_in(name, {"cluster_size": cluster_size, "corridor": corridor})
    return GLOBAL_PLANNERS.create(name, options, grid, **inputs)


def planner_name(name: str | None, key: str = "hierarchical") -> str:
    """The registered name of the global planner ``name`` (None: A*); an InputError naming ``key`` if unknown."""
    GLOBAL_PLANNERS.entry(name or "none", key)
    return GLOBAL_PLANNERS.canonical(name or "none")


def _uses_rooms(name: str | None) -> bool:
    """Whether the planner ``name`` plans over the rooms of a segmentation (it takes room labels)."""
    return "labels" in GLOBAL_PLANNERS.takes(name or "none")


def plan_on_map(
    map_path,
    start,
    goal,
    hierarchical: str | None = None,
    robot_radius: float = 0.2,
    limits: TrajectoryLimits | None = None,
    cluster_size: int = 16,
    labels=None,
    resolution: float | None = None,
    segmentation=None,
    seed: int = 0,
    corridor: bool = False,
) -> MapPlan:
    """Plan from ``start`` to ``goal`` (x, y) m on a map: grid path, shortcut, time-optimal trajectory.

    ``map_path``: map_server ``.yaml``, Moving AI ``.map`` or a floor-plan
    image (``resolution`` m/px, default 0.05). Obstacles are inflated by
    ``robot_radius`` m. ``hierarchical``: a global planner's name (None: A*; ``"hpa"``, ``"rooms"``)
    (``labels``: a region image aligned with the map's rows going up, or
    None for the map's segmentation by ``segmentation``, a SegmentationConfig, default
    morphological, run on the map before inflation; ``seed`` for spectral; ``corridor``: the room graph's one
    A* over the route's rooms, see :class:`~slam2d.planning.room_graph.RoomGraphPlanner`). The metrics say
    ``found`` False with a ``reason`` when there is no path.
    """
    t_all = time.perf_counter()
    limits = limits or TrajectoryLimits()
    start, goal = _point(start, "start"), _point(goal, "goal")
    if not 0 <= robot_radius < np.inf:
        raise InputError("robot_radius", f"must be a finite number >= 0 m, got {robot_radius}")
    grid = load_grid(map_path, resolution=resolution)
    check_inside("start", start, grid.extent)
    check_inside("goal", goal, grid.extent)
    free = grid.inflated(robot_radius)
    t0 = time.perf_counter()
    name = planner_name(hierarchical)
    if _uses_rooms(name):
        labels = _labels(labels, grid, segmentation, seed)  # segment the map itself, not the inflated free space
    planner = make_planner(free, name, cluster_size, labels, corridor=corridor)
    build_s = time.perf_counter() - t0
    result = planner.plan(free.world_to_cell(start), free.world_to_cell(goal))
    metrics = {
        "map": str(map_path),
        "planner": name,
        "found": result.found,
        "reason": result.reason,
        "start": start.tolist(),
        "goal": goal.tolist(),
        "robot_radius_m": robot_radius,
        "resolution_m": grid.resolution,
        "build_ms": 1e3 * build_s,
        "plan_ms": 1e3 * result.seconds,
        "nodes_expanded": result.expanded,
        **({"rooms": planner.graph.number_of_nodes()} if _uses_rooms(name) else {}),
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
    metrics["total_ms"] = 1e3 * (time.perf_counter() - t_all)
    return MapPlan(grid, free, result, waypoints, timed, start, goal, metrics)


def plan_queries(map_path, cfg, labels=None) -> dict:
    """Plan ``cfg.planning.queries`` seeded random start-goal pairs on the map with A* and with the
    configured planner; return the metrics: queries, failures (no path, or an invalid one, where A*
    found one), suboptimality % of the planner's path length over A*'s (mean, max), speed-up (median
    of A* CPU time / the planner's, per query), CPU ms per query (medians), rooms, build and
    segmentation seconds."""
    p = cfg.planning
    hierarchy = planner_name(p.hierarchy, "planning.hierarchy")
    grid = load_grid(map_path, resolution=cfg.resolution)
    free = grid.inflated(p.robot_radius)
    t0 = time.perf_counter()
    if _uses_rooms(hierarchy):
        labels = _labels(labels, grid, cfg.segmentation, cfg.seed)
    segmentation_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    planner = make_planner(free, hierarchy, p.cluster_size, labels, key="planning.hierarchy", corridor=p.corridor)
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
        "map": str(map_path), "planner": hierarchy, "queries": len(queries), "failures": failures,
        "mean_subopt_pct": stat(np.mean, sub), "max_subopt_pct": stat(np.max, sub),
        "median_speedup": stat(np.median, speedups), "astar_ms_median": stat(np.median, ref_ms),
        "planner_ms_median": stat(np.median, own_ms),
        "min_query_m": stat(np.min, [np.hypot(*(s - g)) * grid.resolution for s, g in queries]),
        **({"rooms": planner.graph.number_of_nodes(), "segmentation_s": segmentation_s} if _uses_rooms(hierarchy)
           else {}),
        "build_s": build_s, "robot_radius_m": p.robot_radius, "resolution_m": grid.resolution,
    }  # fmt: skip


def sample_queries(grid: PlanningGrid, astar: AStar, n: int, min_dist_m: float, seed: int, name: str):
    """Up to ``n`` (start, goal) cell pairs that A* connects, preferably >= ``min_dist_m`` apart, drawn
    from the largest 8-connected free component; the seed is mixed with ``name`` (the map), so each map
    keeps its queries in any subset of maps. Too few far pairs: the longest near ones fill up."""
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
