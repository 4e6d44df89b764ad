"""``slam2d navigate``: one closed-loop run as an experiment — a config in, a results folder out.

The simulated robot (``dataset.simulator`` world, laser and odometry models)
drives from ``navigation.start`` to ``navigation.goal``. With
``navigation.slam`` the navigator sees only what online SLAM gives it (the
same frontend, pose graph and grid as ``slam2d run``: the estimate of the
latest scan and the live grid, unknown cells free for planning); without, the
true pose and the world's map. The folder holds the resolved config, the true
and estimated trajectories (TUM), the map with the plans and the drive, the
velocity profile, an animation of the run and ``metrics.json``.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import Field

from slam2d import config as config_mod
from slam2d.config import ExperimentConfig
from slam2d.datasets.simulator import route_start
from slam2d.errors import InputError, check_inside
from slam2d.evaluation.trajectory import write_tum
from slam2d.geometry import wrap_angle
from slam2d.localization import KnownMap
from slam2d.localization.base import LOCALIZERS
from slam2d.navigation import Navigator, run_navigation, world_grid
from slam2d.navigation.config import navigator_config
from slam2d.runs.results import json_text, progress_bar, results_folder
from slam2d.sim import Robot
from slam2d.sim.objects3d import furnish, objects_from_config
from slam2d.sim.obstacles import scatter_wanderers
from slam2d.sim.robot import RobotConfig
from slam2d.sim.world import load_world
from slam2d.slam import OnlineSlam
from slam2d.types import Trajectory

log = logging.getLogger(__name__)


GIF_FRAMES = 120  # frames of the animation at most
GIF_FPS = 10


class NavigateConfig(ExperimentConfig):
    """An experiment config run by ``slam2d navigate``: its ``navigation`` section drives the robot
    (the type tells a sweep which command runs its variants)."""

    name: str = Field("navigate", description="results folder name: no '/' or '\\', no leading '.'")


def run_navigate(cfg: ExperimentConfig, quiet: bool = False) -> Path:
    """Run ``cfg``'s navigation; return the results folder."""
    goal = cfg.navigation.goal
    if goal is None:  # before any folder is made
        raise InputError("navigation.goal", "a goal is needed: --goal x,y or navigation.goal in the config")
    with results_folder(cfg.output.root, cfg.name) as (work, published):
        log.info("slam2d navigate '%s' to %s -> %s", cfg.name, goal, cfg.output.root)
        total = navigator_config(cfg.navigation.options, cfg.navigation.slam).max_time
        with progress_bar("navigating (simulated s)", total, quiet) as advance:
            metrics = _navigate_into(cfg, work, advance)
        log.info("%s in %.1f s simulated (%.1f s wall): %s", metrics["status"], metrics["time"],
                 metrics["wall_s"], metrics["reason"])  # fmt: skip
    return published[0]


def _navigate_into(cfg: ExperimentConfig, out: Path, progress=None) -> dict[str, Any]:
    (out / "config.yaml").write_text(config_mod.dump(cfg))
    run = simulate(cfg, progress)
    _write_trajectories(out, run.result, run.estimate)
    if cfg.output.figures:
        _figures(out, run.world, run.result, run.estimate, run.grid, np.asarray(cfg.navigation.goal, float),
                 run.recorder, cfg.navigation.animation)  # fmt: skip
    (out / "metrics.json").write_text(json_text(run.metrics))
    return run.metrics


@dataclass
class NavigationRun:
    """What :func:`simulate` returns: the world, the navigator's result, the pose it drove on
    (``estimate``, (N, 3)), SLAM's final grid (or None), the recorder and the metrics."""

    world: Any
    result: Any
    estimate: np.ndarray
    grid: Any
    recorder: Any
    metrics: dict[str, Any]


def simulate(cfg: ExperimentConfig, progress=None) -> NavigationRun:
    """One closed-loop run of ``cfg`` (no files written); ``progress(seconds)``, if given, is told the
    simulated time at every step."""

    t0 = time.perf_counter()
    nav, sim = cfg.navigation, cfg.dataset.simulator
    if nav.goal is None:
        raise InputError("navigation.goal", "a goal is needed: --goal x,y or navigation.goal in the config")
    if nav.slam and nav.localization != "none":
        raise InputError("navigation.localization", "localises on the world's map: needs navigation.slam: false")
    world = load_world(sim.world, sim.resolution)
    start = np.asarray(nav.start if nav.start is not None else route_start(sim.world), float)
    goal = np.asarray(nav.goal, float)
    (x0, y0), (x1, y1) = world.bounds
    check_inside("navigation.start", start, (x0, x1, y0, y1), f"the world '{sim.world}'")
    check_inside("navigation.goal", goal, (x0, x1, y0, y1), f"the world '{sim.world}'")
    options = navigator_config(nav.options, nav.slam)
    rng = np.random.default_rng(cfg.seed)
    keep = (np.array([start[:2], goal[:2]]), np.array([1.0, 1.0]))
    world = _with_objects(world, sim, options, start, goal, keep, cfg.seed)
    people = scatter_wanderers(world, nav.people, rng, speed=nav.people_speed, keep_clear=keep)
    robot = Robot(world, start, RobotConfig(laser=sim.laser, odometry=sim.odometry), obstacles=people, seed=cfg.seed)
    truth = world_grid(world)
    record = _Recorder(robot, progress)
    online = None
    if nav.slam:

        online = OnlineSlam(cfg)
        map_grid, pose_source = record.wrap(online), lambda step: online.pose
    else:
        map_grid, pose_source = record.wrap(None, truth), _localizer(nav, world, start, robot, cfg.seed)
    result = run_navigation(world, robot, map_grid, goal, nav.planner, options, pose_source=pose_source,
                            seed=cfg.seed)  # fmt: skip
    wall = time.perf_counter() - t0
    reference = Navigator(goal, robot.cfg, options)
    reference.update_map(truth)
    optimal = reference.optimal_length(start)
    estimates = record.estimates if nav.slam else getattr(pose_source, "estimates", None)
    estimate = np.array(estimates) if estimates is not None else result.trajectory
    metrics = {
        **result.metrics(),
        "optimal_length": optimal,
        "length_ratio": result.path_length / optimal if optimal > 0 else float("nan"),
        "planner": nav.planner,
        "slam": nav.slam,
        "localization": nav.localization,
        "people": nav.people,
        "wall_s": wall,
        "real_time_factor": result.time / wall if wall > 0 else float("nan"),
        **_pose_errors(estimate, result.trajectory),
        **_stop_errors(estimate, result.trajectory, goal),
    }
    return NavigationRun(world, result, estimate, online.grid if online else None, record, metrics)


def _with_objects(world, sim, options, start, goal, keep, seed: int):
    """``world`` with the 3D objects of ``sim.objects`` (scattered by ``seed``, clear of ``keep`` circles, near
    the shortest path from ``start`` to ``goal`` if asked); ``world`` itself without any."""
    spec = sim.objects
    if not (spec.items or spec.file or spec.boxes or spec.tables or spec.chairs or spec.shelves):
        return world
    along = None
    if spec.along_path:
        reference = Navigator(goal, RobotConfig(), options.model_copy(update={"unknown_free": False}))
        reference.update_map(world_grid(world))
        along = reference.path if not reference.plan(start) else None
    objects = objects_from_config(spec, world, np.random.default_rng([seed, 3]), keep_clear=keep, along=along)
    return furnish(world, objects, sim.laser.height)


class _Recorder:
    """Feeds each step's scan to online SLAM (once) and keeps the estimates and the people's positions."""

    def __init__(self, robot, progress=None):
        self.robot = robot
        self.progress = progress
        self.estimates: list[np.ndarray] = []
        self.people: list[np.ndarray] = []

    def wrap(self, online, fixed=None):
        """The ``map_grid`` callable for :func:`run_navigation`."""

        def map_grid(step):
            if self.progress is not None:
                self.progress(step.scan.stamp)
            self.people.append(np.array([o.centre for o in self.robot.obstacles]).reshape(-1, 2))
            if online is None:
                return fixed
            online.add(step.scan)
            self.estimates.append(online.pose.copy())
            return online.grid

        return map_grid


def _localizer(nav, world, start, robot, seed: int):
    """The pose source of the localiser ``navigation.localization`` names in the world's map, or None
    (``none``: the true pose)."""
    if nav.localization == "none":
        return None
    return LOCALIZERS.create(nav.localization, None, KnownMap.from_world(world), start,
                             range_max=robot.cfg.laser.range_max, seed=seed)


def _pose_errors(estimate: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """Position error (m) of the pose the navigator used: RMSE over the run and at the end."""
    n = min(len(estimate), len(truth))
    err = np.hypot(*(estimate[:n, :2] - truth[:n, :2]).T)
    return {"pose_rmse": float(np.sqrt(np.mean(err**2))), "pose_error_end": float(err[-1])}


def _stop_errors(estimate: np.ndarray, truth: np.ndarray, goal: np.ndarray) -> dict[str, float]:
    """The goal error split at the stop: ``stop_control_error`` (m), the pose driven on (the estimate) to the goal,
    which is the navigator's; ``stop_pose_error`` (m, rad: ``stop_heading_pose_error``), the estimate against the
    true pose, which is the localisation's; ``goal_error`` (true pose to goal) is at most their sum."""
    n = min(len(estimate), len(truth))
    est, true = estimate[n - 1], truth[n - 1]
    return {"stop_control_error": float(np.hypot(*(est[:2] - goal[:2]))),
            "stop_pose_error": float(np.hypot(*(est[:2] - true[:2]))),
            "stop_heading_pose_error": float(abs(wrap_angle(est[2] - true[2])))}


def _write_trajectories(out: Path, result, estimate: np.ndarray) -> None:

    write_tum(out / "ground_truth.tum", Trajectory(result.stamps, result.trajectory))
    n = min(len(estimate), len(result.stamps))
    write_tum(out / "trajectory.tum", Trajectory(result.stamps[:n], estimate[:n]))


def _figures(out: Path, world, result, estimate, grid, goal, record, animation: bool) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 6))
    _draw_map(ax, world, grid)
    for path in result.paths:
        ax.plot(*np.asarray(path)[:, :2].T, color="tab:green", lw=0.8, alpha=0.6)
    ax.plot(*result.trajectory[:, :2].T, color="tab:blue", lw=1.2, label="true")
    ax.plot(*estimate[:, :2].T, color="tab:orange", lw=1.0, ls="--", label="estimate")
    ax.plot(*goal[:2], "r*", ms=12, label="goal")
    ax.set_title(f"{result.status}: {result.time:.1f} s, {result.path_length:.1f} m, {result.collisions} collisions")
    ax.legend(loc="upper right", fontsize=8)
    fig.savefig(out / "map.png", dpi=120, bbox_inches="tight")
    plt.close(fig)
    _velocity_figure(out, result, plt)
    if animation:
        _animation(out, world, result, record, goal, plt)


def _draw_map(ax, world, grid) -> None:
    """The SLAM grid (if any) under the world's walls, equal axes in metres."""
    if grid is not None:
        x0, x1, y0, y1 = grid.extent
        ax.imshow(1.0 - grid.probability(), cmap="gray", origin="lower", extent=(x0, x1, y0, y1), vmin=0, vmax=1)
    for seg in world.segments:
        ax.plot(*seg.T, color="0.3", lw=0.6)
    for ring in world.objects.footprints() if world.objects is not None else ():  # 3D objects: every part
        ax.fill(*ring.T, color="tab:brown", alpha=0.35, lw=0)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def _velocity_figure(out: Path, result, plt) -> None:
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 4), sharex=True)
    t = result.stamps[1 : len(result.commands) + 1] - result.stamps[0]
    a1.plot(t, result.commands[:, 0])
    a1.set_ylabel("v (m/s)")
    a2.plot(t, result.commands[:, 1])
    a2.set_ylabel("ω (rad/s)")
    a2.set_xlabel("t (s)")
    fig.savefig(out / "velocity.png", dpi=110, bbox_inches="tight")
    plt.close(fig)


def _animation(out: Path, world, result, record, goal, plt) -> None:
    """run.gif: the robot, the people and the drive so far, at most GIF_FRAMES frames."""
    from matplotlib.animation import FuncAnimation, PillowWriter
    from matplotlib.patches import Circle

    traj = result.trajectory
    frames = np.unique(np.linspace(0, len(traj) - 1, min(GIF_FRAMES, len(traj))).astype(int))
    fig, ax = plt.subplots(figsize=(6, 4.5))
    _draw_map(ax, world, None)
    ax.plot(*goal[:2], "r*", ms=10)
    (drive,) = ax.plot([], [], color="tab:blue", lw=1.2)
    body = ax.add_patch(Circle((0, 0), 0.2, color="tab:blue"))
    people = [ax.add_patch(Circle((0, 0), 0.25, color="tab:red", alpha=0.7)) for _ in range(
        len(record.people[0]) if record.people else 0)]  # fmt: skip

    def draw(k):
        drive.set_data(traj[: k + 1, 0], traj[: k + 1, 1])
        body.center = traj[k, :2]
        if record.people:
            for disc, c in zip(people, record.people[min(k, len(record.people) - 1)]):
                disc.center = c
        ax.set_title(f"t = {result.stamps[k] - result.stamps[0]:.1f} s")
        return [drive, body, *people]

    FuncAnimation(fig, draw, frames=frames, blit=False).save(out / "run.gif", writer=PillowWriter(fps=GIF_FPS))
    plt.close(fig)
