"""``slam2d plan``: a planned path with its timing and figures, or seeded queries against A*, written
as a results folder: ``path.png`` (the map with the grid path, the shortcut polyline and the
trajectory), ``velocity.png`` (speed, yaw rate and acceleration over time), ``trajectory.csv`` (t, x,
y, vx, vy, speed, omega) and ``metrics.json``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from slam2d import config as config_mod
from slam2d.errors import InputError
from slam2d.paths import resolve_data_path
from slam2d.planning.astar import PlanResult
from slam2d.planning.query import MapPlan, NoPathError, plan_on_map, plan_queries
from slam2d.planning.timing import TimedPath, plot_profile
from slam2d.runs.results import json_text, results_folder

__all__ = ["run_plan", "write_plan"]


def run_plan(cfg, quiet: bool = False) -> Path:
    """Run a :class:`~slam2d.planning.config.PlanConfig` into a new results folder under
    ``cfg.output.root``; return the folder. One query (start, goal): the path, its timing and figures
    (NoPathError when there is none, leaving no folder); ``queries`` > 0: :func:`plan_queries`."""
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
            planned = plan_on_map(map_path, p.start, p.goal, hierarchy, p.robot_radius, p.limits, p.cluster_size,
                                  labels, cfg.resolution, cfg.segmentation, cfg.seed, p.corridor)
            metrics = write_plan(planned, work, cfg.output.figures)
            if not metrics["found"]:
                raise NoPathError(metrics.get("reason") or "unknown")
    return published[0]


def write_plan(plan: MapPlan, out: Path, figures: bool = True) -> dict:
    """trajectory.csv, velocity.png and path.png (``figures``) and metrics.json of ``plan`` into ``out``;
    return the metrics written (the plan's, with the files named)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    metrics = dict(plan.metrics)
    if plan.timed is not None:
        _write_trajectory(out / "trajectory.csv", plan.timed)
        if figures:
            plot_profile(plan.timed, out / "velocity.png")
    if figures:
        _plot_path(plan.grid, plan.free, plan.result, plan.waypoints, plan.timed, plan.start, plan.goal,
                   out / "path.png", metrics["planner"], path_title(plan.result, metrics.get("length_m")))
    names = {"metrics": "metrics.json", **({"path": "path.png"} if figures else {})}
    if plan.timed is not None:
        names.update(trajectory="trajectory.csv", **({"velocity": "velocity.png"} if figures else {}))
    metrics["files"] = names
    (out / "metrics.json").write_text(json_text(metrics))
    return metrics


def _write_trajectory(path: Path, timed: TimedPath) -> None:
    data = np.column_stack([timed.t, timed.xy, timed.velocity, timed.speed, timed.omega])
    header = "t_s,x_m,y_m,vx_mps,vy_mps,speed_mps,omega_rps"
    np.savetxt(path, data, delimiter=",", fmt="%.6f", header=header, comments="")


def path_title(result: PlanResult, length_m: float | None) -> str:
    """The title of path.png: the shortened path's length (the metric ``length_m``, what ``slam2d plan``
    prints), the grid path's, nodes expanded and planning time; or why there is no path."""
    if not result.found:
        return result.reason
    return (f"{length_m:.2f} m (grid path {result.length_m:.2f} m), {result.expanded} nodes, "
            f"{1e3 * result.seconds:.1f} ms")


def _plot_path(grid, free, result: PlanResult, waypoints, timed, start, goal, path: Path, planner: str,
               title: str) -> str:
    """The map (black blocked, grey inflation margin, white free) with the paths and end points, under
    ``title``; return the title drawn."""
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
    ax.set_title(title, fontsize="small")
    fig.savefig(path, bbox_inches="tight")
    return ax.get_title()
