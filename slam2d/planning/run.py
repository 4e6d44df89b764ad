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
from slam2d.experiment import json_text
from slam2d.planning.astar import AStar, PlanResult, path_length
from slam2d.planning.grid import PlanningGrid, load_grid
from slam2d.planning.smoothing import shortcut
from slam2d.planning.timing import TimedPath, TrajectoryLimits, plot_profile, time_parametrize

__all__ = ["plan_on_map", "make_planner", "PLANNERS"]

PLANNERS = ("hpa", "rooms")
"""Values of ``hierarchical``: HPA* over square clusters, or the room-graph planner."""


def _point(value, name: str) -> np.ndarray:
    p = np.asarray(value, dtype=np.float64).ravel()
    if p.shape != (2,) or not np.isfinite(p).all():
        raise InputError(name, f"expected a point (x, y) in m, got {value!r}")
    return p


def _labels(labels, grid: PlanningGrid) -> np.ndarray:
    """Room labels aligned with ``grid`` (rows going up): an array, a .npy, the
    ``labels.png`` of ``slam2d segment`` (row 0 the top), or, if None, a
    morphological segmentation of ``grid``."""
    if labels is None:
        from slam2d.segmentation.baselines import morphological

        return morphological(grid.free, grid.resolution)
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
) -> dict:
    """Plan from ``start`` to ``goal`` (x, y) m on a map and write figures and metrics.

    ``map_path``: map_server ``.yaml``, Moving AI ``.map`` or a floor-plan
    image (``resolution`` m/px, default 0.05). Obstacles are inflated by
    ``robot_radius`` m. ``hierarchical``: None (A*), ``"hpa"`` or ``"rooms"``
    (``labels``: a region image aligned with the map's rows going up, or
    None for the morphological segmentation of the map, which is then run on
    the map before inflation). Returns the metrics dict
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
        labels = _labels(labels, grid)  # segment the map itself, not the inflated free space
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
        plot_profile(timed, out / "velocity.png")
    _plot_path(grid, free, result, waypoints, timed, start, goal, out / "path.png", metrics["planner"])
    metrics["total_ms"] = 1e3 * (time.perf_counter() - t_all)
    names = {"path": "path.png", "metrics": "metrics.json"}
    if timed is not None:
        names.update(velocity="velocity.png", trajectory="trajectory.csv")
    metrics["files"] = {k: f for k, f in names.items()}
    (out / "metrics.json").write_text(json_text(metrics))
    return metrics


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
