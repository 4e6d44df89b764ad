"""A simulated navigation run: :func:`run_navigation` has a
:class:`~slam2d.navigation.navigator.Navigator` drive a :class:`slam2d.sim.Robot` to a goal and
measures the run (:class:`NavigationResult`, :func:`clearance`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from slam2d import geometry
from slam2d.navigation.config import NavigatorConfig
from slam2d.navigation.depth_layer import ObstacleLayer
from slam2d.navigation.navigator import ACTIVE, REACHED, TIMEOUT, Navigator
from slam2d.sim.depth import DepthCamera

__all__ = ["NavigationResult", "clearance", "run_navigation"]


@dataclass(eq=False)
class NavigationResult:
    """One navigation run: ``success``, ``status`` (reached / unreachable / timeout), ``reason``,
    ``time`` (s), ``path_length`` travelled and ``optimal_length`` of the grid path (m),
    ``collisions`` (contact events), ``min_clearance`` (m between the robot's disc and walls or
    obstacles), ``replans``, ``recoveries``, ``goal_error`` (m) and ``heading_error`` (rad) at the
    end, the true ``trajectory`` (N, 3), ``commands`` (N - 1, 2), ``stamps`` (N,) s, the planned
    ``paths``, the local planner's mean ``planner_hz``, the median and 95th percentile of its calls
    ``planner_ms`` (wall-clock ms) and the navigator's ``events``
    (time s, "replan" / "recovery", why)."""

    success: bool
    status: str
    reason: str
    time: float
    path_length: float
    optimal_length: float
    collisions: int
    min_clearance: float
    replans: int
    recoveries: int
    goal_error: float
    heading_error: float
    trajectory: np.ndarray
    commands: np.ndarray
    stamps: np.ndarray
    paths: list = field(default_factory=list)
    planner_hz: float = float("nan")
    planner_ms: tuple[float, float] = (float("nan"), float("nan"))  # median, 95th percentile of a call (wall)
    steps: int = 0
    events: list = field(default_factory=list)
    object_collisions: int = 0  # contact events with 3D objects (``world.objects``) at the body's height

    @property
    def length_ratio(self) -> float:
        """Travelled path length over the optimal grid path length."""
        return self.path_length / self.optimal_length if self.optimal_length > 0 else float("nan")

    def metrics(self) -> dict:
        """The scalar fields (for metrics.json)."""
        keys = ("success", "status", "reason", "time", "path_length", "optimal_length", "collisions", "min_clearance",
                "replans", "recoveries", "goal_error", "heading_error", "planner_hz", "steps",
                "object_collisions")  # fmt: skip
        return {k: getattr(self, k) for k in keys} | {"length_ratio": self.length_ratio,
                                                      "planner_ms_median": self.planner_ms[0],
                                                      "planner_ms_p95": self.planner_ms[1]}  # fmt: skip


HOLD_TURN = 0.5  # rad/s: turning in place while the pose source holds

def clearance(world, robot) -> float:
    """Distance (m) between the robot's disc and the nearest wall, world bound or moving obstacle."""
    x, y = robot.pose[:2]
    (x0, y0), (x1, y1) = world.bounds
    d = min(float(world.distance(robot.pose[:2])[0]), x - x0, x1 - x, y - y0, y1 - y)
    centres, radii = robot.obstacle_circles()
    if len(radii):
        d = min(d, float((np.hypot(centres[:, 0] - x, centres[:, 1] - y) - radii).min()))
    return d - robot.cfg.radius


def run_navigation(world, robot, map_grid, goal, planner: str = "dwa", config: NavigatorConfig | None = None,
                   *, pose_source=None, max_steps: int | None = None, seed: int = 0) -> NavigationResult:  # fmt: skip
    """Drives ``robot`` (a :class:`slam2d.sim.Robot` in ``world``) to ``goal`` (x, y[, theta]).

    ``map_grid`` is a planning or occupancy grid, or a callable ``(StepResult) -> grid``
    asked at every step (a live map). ``pose_source(StepResult) -> pose`` is the pose the
    navigator uses (default: the true pose); while its ``holding()`` (if it has one) is True, the
    robot does not drive to the goal (a localiser that has not claimed its pose): it drives to the
    pose source's ``looking()`` goal if it gives one (a place that tells its hypotheses apart; then
    ``looked()`` is called once that goal is reached or given up), else turns in place. Stops when the goal is reached or
    unreachable, after ``config.max_time`` s of simulated time, or after ``max_steps``. With
    ``config.depth_camera.enabled`` a depth camera (noise seeded by ``seed``) renders the world
    (its 3D objects too) at every step and its obstacle layer goes to the navigator.
    """
    cfg = (config or NavigatorConfig()).model_copy(update={"planner": planner})
    nav = Navigator(goal, robot.cfg, cfg)
    step = robot.step(0.0, 0.0, 0.0)
    start_pose = step.pose.copy()
    poses, commands, stamps = [step.pose], [], [step.scan.stamp]
    collisions, object_hits, in_contact, min_clear = 0, 0, False, clearance(world, robot)
    limit = max_steps if max_steps is not None else int(np.ceil(cfg.max_time / cfg.period)) + 1
    depth = cfg.depth_camera
    camera, layer = (DepthCamera(depth, seed), ObstacleLayer(depth)) if depth.enabled else (None, None)
    holding = getattr(pose_source, "holding", None)
    looking, aside = getattr(pose_source, "looking", None), None
    for _ in range(limit):
        grid = map_grid(step) if callable(map_grid) else map_grid
        pose = step.pose if pose_source is None else pose_source(step)
        points, obstacles = step.scan.points_in_base(), None
        if camera is not None:
            layer.update(pose, camera.render(world, robot.pose, robot.obstacle_circles()), step.scan.stamp, points)
            obstacles = layer.corners()
        if holding is not None and holding():  # the pose is not claimed: do not drive to the goal
            if not nav.events or nav.events[-1][1] != "hold":
                nav.events.append((float(step.scan.stamp), "hold", "localisation not tracking"))
            look = looking() if looking is not None else None
            if look is not None and (aside is None or not np.allclose(aside.goal[:2], look[:2])):
                aside = Navigator(look[:2], robot.cfg, cfg)
                nav.events.append((float(step.scan.stamp), "disambiguate", f"to ({look[0]:.2f}, {look[1]:.2f})"))
            v, w = 0.0, HOLD_TURN  # look round in place ...
            if look is not None:  # ... or drive where the localiser's hypotheses differ
                cmd = aside.step(pose, step.velocity, points, grid, step.scan.stamp, obstacles)
                if aside.status == ACTIVE:
                    v, w = cmd.v, cmd.w
                else:
                    nav.events.append((float(step.scan.stamp), "looked", f"{aside.status}: {aside.reason}"))
                    pose_source.looked()
                    aside = None
        else:
            cmd = nav.step(pose, step.velocity, points, grid, step.scan.stamp, obstacles)
            if nav.status != ACTIVE:
                break
            v, w = cmd.v, cmd.w
        step = robot.step(v, w, cfg.period)
        poses.append(step.pose)
        commands.append((v, w))
        stamps.append(step.scan.stamp)
        collisions += int(step.collision and not in_contact)
        object_hits += int(step.contact == "object" and not in_contact)
        in_contact = step.collision
        min_clear = min(min_clear, clearance(world, robot))
    else:
        nav._finish(TIMEOUT, f"step budget of {limit} steps used up")
    result = _result(nav, start_pose, np.array(poses), np.array(commands).reshape(-1, 2), np.array(stamps),
                     collisions, min_clear)  # fmt: skip
    result.object_collisions = object_hits
    return result


def _result(nav: Navigator, start, traj, commands, stamps, collisions, min_clear) -> NavigationResult:
    end, goal = traj[-1], nav.goal
    heading = float(abs(geometry.wrap_angle(goal[2] - end[2]))) if len(goal) == 3 else 0.0
    seconds = np.asarray(nav.planner_seconds)
    hz = 1.0 / float(seconds.mean()) if len(seconds) else float("nan")
    ms = tuple(1e3 * np.percentile(seconds, [50, 95])) if len(seconds) else (float("nan"),) * 2
    optimal = nav.optimal_length(start) if nav._grid is not None else float("inf")
    return NavigationResult(
        success=nav.status == REACHED, status=nav.status, reason=nav.reason, time=float(stamps[-1] - stamps[0]),
        path_length=float(np.linalg.norm(np.diff(traj[:, :2], axis=0), axis=1).sum()),
        optimal_length=optimal, collisions=collisions, min_clearance=float(min_clear),
        replans=nav.replans, recoveries=nav.recoveries,
        goal_error=float(np.hypot(*(end[:2] - goal[:2]))), heading_error=heading,
        trajectory=traj, commands=commands, stamps=stamps, paths=nav.paths, planner_hz=hz, planner_ms=ms,
        steps=len(commands), events=nav.events,
    )  # fmt: skip
