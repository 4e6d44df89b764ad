"""Goal -> velocity commands: global A* on the inflated map, a local planner, replanning,
recovery, and "unreachable" as a result (the parameters: :mod:`~slam2d.navigation.config`;
a simulated run: :mod:`~slam2d.navigation.drive`).

The map is an argument of every :meth:`Navigator.step` (a known grid now, the live
SLAM grid later). The global path is grid A* (``slam2d.planning.astar``) on the map
inflated by the robot radius (lethal), with a steep cost where the disc would come
within a margin of an obstacle (passages that tight are a last resort, never ruled
out) and a soft cost falling off beyond, so that the path keeps to the middle of passages. The navigator replans
when the map changes under the path, and recovers when the local planner reports
itself blocked for ``blocked_time`` or the remaining path has not shortened by
``progress`` within ``stuck_time``: first a replan with the laser's points put
into the map, then backing off, a replan and a turn towards the new path. After
``max_recoveries`` recoveries without a metre of progress, or when no path
exists on the map (cells blocked for less than ``_SETTLED_S`` count as free if
only they are in the way: they may be a person the live map caught), the goal is unreachable; ``max_time`` bounds every run
(status ``timeout``). Laser points the map does not explain are passed to the
local planner as such (DWA gives them a growing margin: they may move). Every
local planner's command is slowed to the speed that stops at the goal; within
``final_approach`` of it a point controller drives the arc through it and stops on
it (``goal_precision``), then the robot turns to the goal heading if one was given.
"""

from __future__ import annotations

import time as _time

import numpy as np
from pydantic import BaseModel
from scipy import ndimage

from slam2d import geometry
from slam2d.navigation.base import LOCAL_PLANNERS, RECOVERY_BEHAVIOURS, register_recovery
from slam2d.navigation.common import Command, in_robot_frame, point_along, stopping_speed
from slam2d.navigation.config import NavigatorConfig
from slam2d.navigation.maps import free_mask, mark_points, nearest_free, pad_to_reach
from slam2d.planning.astar import AStar
from slam2d.planning.grid import PlanningGrid, around, refresh_clearance
from slam2d.sim.robot import RobotConfig

__all__ = [
    "Navigator",
    "make_local_planner",
    "ACTIVE",
    "REACHED",
    "UNREACHABLE",
    "TIMEOUT",
]

ACTIVE, REACHED, UNREACHABLE, TIMEOUT = "active", "reached", "unreachable", "timeout"
_SNAP = 0.5  # m, farthest a start cell inside the inflation is moved to a free one
_AHEAD = 40  # path points searched ahead of the last nearest one
_EXPLAINED_CELLS = 2  # a laser point this many cells from a blocked map cell is the map's
_SETTLED_S = 3.0  # s; ... if that cell has been blocked this long (a live map also holds people walking)
_EXPLAINING = np.array([(dr, dc) for dr in range(-_EXPLAINED_CELLS, _EXPLAINED_CELLS + 1)
                        for dc in range(-_EXPLAINED_CELLS, _EXPLAINED_CELLS + 1)
                        if abs(dr) + abs(dc) <= _EXPLAINED_CELLS])  # the offsets (rows, cols) of those cells
_FINAL_GAP = 0.01  # m kept between the robot's disc and any point on the final approach
GOAL_PADDING = 1.0  # m of free cells kept around a goal beyond a map whose unknown cells are free
_CREEP = 0.05  # m/s; slower than this, the final approach turns on the spot to a goal more than 0.3 rad off
_STOP_DECEL = 0.9  # of max_accel: the deceleration the stop at the goal is planned with
_TOUCH = 1e-6  # m: with ``touch``, a disc this far within a blocked cell's centre still fits (rounding)


def make_local_planner(name: str, robot: RobotConfig, cfg: NavigatorConfig):
    """The local planner ``name`` (``LOCAL_PLANNERS``) with the section of ``cfg`` of that name (``dwa``,
    ``fsm``; a planner without one: its defaults) and the control period of ``cfg``."""
    section = getattr(cfg, name, None)
    options = LOCAL_PLANNERS.resolve_options(name, section if isinstance(section, BaseModel) else None,
                                             f"navigation.options.{name}")  # fmt: skip
    if options is not None and "period" in type(options).model_fields:
        options = options.model_copy(update={"period": cfg.period})
    return LOCAL_PLANNERS.create(name, options, robot)


@register_recovery("backoff")
class BackOffRecovery:
    """Replan with the laser's points in the map and turn to the path; from the second recovery in a row
    on, back off ``backoff`` m first if the rear is clear."""

    def manoeuvres(self, navigator, level: int, pose, points) -> list[str]:
        back = level >= 2 and navigator.rear_clear(points)
        return ["back", "replan", "turn"] if back else ["replan", "turn"]


class Navigator:
    """Drives towards ``goal`` (x, y[, theta]) with :meth:`step`; ``status`` is ``active``,
    ``reached``, ``unreachable`` or ``timeout`` (``reason`` says why)."""

    def __init__(self, goal, robot: RobotConfig | None = None, config: NavigatorConfig | None = None):
        self.robot, self.cfg = robot or RobotConfig(), config or NavigatorConfig()
        self.goal = np.asarray(goal, dtype=np.float64).reshape(-1)
        if self.goal.shape not in ((2,), (3,)) or not np.isfinite(self.goal).all():
            raise ValueError(f"goal must be finite (x, y) or (x, y, theta), got {goal}")
        self.local = make_local_planner(self.cfg.planner, self.robot, self.cfg)
        self.recovery = RECOVERY_BEHAVIOURS.create(self.cfg.recovery)
        self.status, self.reason = ACTIVE, ""
        self.path: np.ndarray | None = None
        self.paths: list[np.ndarray] = []
        self.replans = self.recoveries = 0
        self.planner_seconds: list[float] = []
        self.events: list[tuple[float, str, str]] = []  # (time s, "replan" / "recovery", why)
        self._raw = self._grid = self._cost = None
        self._cell_blocked_at = None  # (H, W) time (s) each cell of ``_raw`` became blocked; inf: free
        self._now, self._clear = 0.0, None  # _clear: the map's clearance (H, W) m, capped
        self._index, self._level, self._arrived = 0, 0, False
        self._best = (np.inf, 0.0)  # (remaining path m, time)
        self._level_mark = np.inf  # remaining path m at the first recovery of a run of them
        self._blocked_since = None
        self._stand_in = False  # the path ends at a free cell near a goal the map blocks (see _goal_cell)
        self._manoeuvre: list[list] = []
        self._layer = None  # (H, W) bool on ``_raw``: cells of the obstacle layer (``step``'s obstacles)
        self._look = None  # the depth camera's start-up sweep
        if (cam := self.cfg.depth_camera).enabled and cam.look_around:  # open3d: imported only with a camera
            from slam2d.navigation.depth_layer import LookAround

            self._look = LookAround(cam, self.robot.max_turn_rate, self.robot.max_turn_accel, self.cfg.period)

    # map and plan --------------------------------------------------------

    def update_map(self, map_grid, now: float | None = None) -> bool:
        """Take the current map at time ``now`` (s; default: the last step's); True when it
        differs from the last one (re-inflated then).

        The free mask is compared at every call, so a map updated in place counts as changed.
        The cells of the first map are settled; a cell blocked later counts as explaining laser
        points only once it has stayed blocked ``_SETTLED_S`` (see :meth:`unmapped`).
        """
        self._now = self._now if now is None else float(now)
        free, res, origin = free_mask(map_grid, self.cfg.unknown_free)
        if self.cfg.unknown_free:  # a map being built may not reach the goal yet: beyond it is unknown, so free
            free, origin = pad_to_reach(free, res, origin, self.goal[:2], GOAL_PADDING)
        same_frame = self._raw is not None and (res, tuple(origin)) == (self._raw.resolution, self._raw.origin)
        same_frame = same_frame and self._raw.free.shape == free.shape
        changed = free != self._raw.free if same_frame else None
        if same_frame and not changed.any():
            return False
        new = PlanningGrid(np.array(free, dtype=bool), res, origin)  # a copy: the source may change
        if same_frame:  # the layers only near the changed cells
            near = refresh_clearance(self._clear, new.free, changed, res, self._clear_cap)
            self._grid.free[near], self._cost[near] = self._layers(self._clear[near])
            self._cell_blocked_at[changed] = np.where(new.free[changed], np.inf, self._now)
        else:
            self._clear = np.minimum(new.clearance(), self._clear_cap)
            self._cell_blocked_at = self._block_times(new)
            fits, self._cost = self._layers(self._clear)
            self._grid = PlanningGrid(fits, res, origin)
        self._raw = new
        return True

    def _block_times(self, new: PlanningGrid) -> np.ndarray:
        """Time (s) each blocked cell of ``new`` became blocked (-inf for the first map's), inf where free."""
        since = np.where(new.free, np.inf, -np.inf if self._raw is None else self._now)
        if self._raw is None or self._raw.resolution != new.resolution:
            return since
        old = np.full(new.free.shape, np.inf)
        shift = np.rint((np.subtract(self._raw.origin, new.origin)) / new.resolution).astype(int)[::-1]  # rows, cols
        lo, hi = np.maximum(shift, 0), np.minimum(shift + self._raw.free.shape, new.free.shape)
        if np.all(hi > lo):
            old[lo[0]:hi[0], lo[1]:hi[1]] = self._cell_blocked_at[lo[0] - shift[0]:hi[0] - shift[0],
                                                                lo[1] - shift[1]:hi[1] - shift[1]]
        return np.where(new.free, np.inf, np.minimum(since, old))

    def unmapped(self, pose, points) -> np.ndarray:
        """Which laser ``points`` (M, 2) (robot frame) lie in no blocked cell of the map: none within
        ``_EXPLAINED_CELLS`` (4-connected steps) has been blocked for ``_SETTLED_S``; points outside the
        map count as mapped."""
        cells = self._raw.world_to_cell(geometry.transform_points(pose, points))
        inside = self._raw.in_bounds(cells)
        blocked_at = around(self._cell_blocked_at, cells[inside, 0], cells[inside, 1], _EXPLAINING, np.inf)
        out = np.zeros(len(points), dtype=bool)
        out[inside] = ~(blocked_at <= self._now - _SETTLED_S).any(axis=1)
        if self._layer is not None:  # the obstacle layer's cells hold things that stay
            out[inside] &= ~self._layer[cells[inside, 0], cells[inside, 1]]
        return out

    @property
    def _clear_cap(self) -> float:
        """m: the clearance beyond which a cell is free and costs nothing."""
        return self.robot.radius + self.cfg.inflation_margin + self.cfg.wall_distance

    def _inflate(self, raw: PlanningGrid) -> tuple[PlanningGrid, np.ndarray]:
        """(The cells where the robot's disc fits, the A* cost layer (H, W)) of ``raw`` (see ``_layers``)."""
        fits, cost = self._layers(raw.clearance())
        return PlanningGrid(fits, raw.resolution, raw.origin), cost

    def _layers(self, clear: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(Where the robot's disc fits, the A* cost) of cells with clearance ``clear`` (m): ``wall_weight``
        where the disc comes within ``inflation_margin`` of a blocked cell, rising by up to ``tight_weight``
        as it comes closer (through a tight gap, its middle), falling linearly to 0 over ``wall_distance`` beyond.
        The disc fits where it keeps off every blocked cell's centre, or with ``touch`` where it reaches one."""
        c = self.cfg
        gap = clear - self.robot.radius
        beyond = gap - c.inflation_margin  # m between the disc + margin and the nearest blocked cell centre
        tight = np.clip(-beyond / c.inflation_margin, 0.0, 1.0) if c.inflation_margin > 0 else 0.0
        cost = c.wall_weight * np.clip(1.0 - beyond / c.wall_distance, 0.0, 1.0) + c.tight_weight * tight
        return (gap > -_TOUCH) if c.touch else (gap > 0), cost

    def plan(self, pose, points_world=None, unmapped=None) -> str:
        """Plans from ``pose`` (3,) to the goal, with ``points_world`` (P, 2) blocked if given;
        '' on success, else why not. Points flagged ``unmapped`` (P,) are first kept clear by the
        local planner's extra reach for things that may move; failing that, by the inflation
        only; failing that, the plan is on the map alone."""
        tries = []
        if points_world is not None and len(points_world):
            marked, cost = self._inflate(mark_points(self._raw, points_world))
            tries.append((marked, cost))
            if unmapped is not None and np.any(unmapped):
                tries.insert(0, (self._keep_clear(marked, points_world[np.asarray(unmapped, dtype=bool)]), cost))
        for grid, cost in tries:
            if not self._plan_on(grid, cost, pose):
                return ""
        why = self._plan_on(self._grid, self._cost, pose)
        lately = np.isfinite(self._cell_blocked_at) & (self._cell_blocked_at > self._now - _SETTLED_S)
        if why and lately.any():  # cells blocked lately may be a person mapped in passing (a door they stand in)
            unsettled = PlanningGrid(self._raw.free | lately, self._raw.resolution, self._raw.origin)
            if not self._plan_on(*self._inflate(unsettled), pose):
                return ""
        return why

    def _keep_clear(self, grid: PlanningGrid, points) -> PlanningGrid:
        """``grid`` with every cell within radius + margin + the DWA's ``obstacle_reach`` of ``points`` blocked."""
        near = np.ones(grid.shape, dtype=bool)
        cells = grid.world_to_cell(points)
        cells = cells[grid.in_bounds(cells)]
        near[cells[:, 0], cells[:, 1]] = False
        clear = self.robot.radius + self.cfg.inflation_margin + self.cfg.dwa.obstacle_reach
        far = ndimage.distance_transform_edt(near) * grid.resolution > clear
        return PlanningGrid(grid.free & far, grid.resolution, grid.origin)

    def _plan_on(self, grid: PlanningGrid, cost: np.ndarray, pose) -> str:
        goal = self._goal_cell(grid)
        if goal is None:
            return f"goal ({self.goal[0]:.2f}, {self.goal[1]:.2f}) is blocked or within the robot radius of an obstacle"
        start = nearest_free(grid, pose[:2], _SNAP)
        if start is None:
            return f"no free cell within {_SNAP} m of the robot at ({pose[0]:.2f}, {pose[1]:.2f})"
        result = AStar(grid, 8, cost).plan(start, goal)
        if not result.found:
            return f"no path: {result.reason}"
        path = np.vstack([pose[:2], grid.cell_to_world(result.path)[1:-1], self.goal[:2]])
        self.path, self._index = path, 0
        self.paths.append(path)
        self.local.reset()
        self._best = (np.inf, self._best[1])
        return ""

    def _goal_cell(self, grid: PlanningGrid):
        """The goal's cell, or, when only the margin is in the way (the robot's disc fits there),
        the nearest free cell within the margin; when the goal has no room for the robot, None, or on
        a map being built the nearest free cell within ``blocked_goal_reach`` (``_stand_in`` set)."""
        cell = grid.world_to_cell(self.goal[:2])
        self._stand_in = False
        if grid.is_free(cell):
            return cell
        raw = self._raw
        rc = raw.world_to_cell(self.goal[:2])
        if not raw.in_bounds(rc) or self._clear[rc[0], rc[1]] < self.robot.radius:
            if not self.cfg.unknown_free:
                return None
            # a map being built: what blocks the goal may be a person mapped in passing; drive to the
            # nearest free cell, where the laser sees the goal again (replanned at every new map)
            self._stand_in = True
            return nearest_free(grid, self.goal[:2], self.cfg.blocked_goal_reach)
        return nearest_free(grid, self.goal[:2], self.cfg.inflation_margin + 2 * grid.resolution)

    def optimal_length(self, start) -> float:
        """Length (m) of the shortest grid path from ``start`` (x, y) to the goal on the map inflated by the radius."""
        result = AStar(self._grid).plan_world(np.asarray(start)[:2], self.goal[:2])
        return result.length_m if result.found else np.inf

    def _path_blocked(self) -> bool:
        """Whether the path ahead crosses a blocked cell of the inflated map."""
        ahead = self.path[self._index + 1 : -1]
        return len(ahead) > 0 and not self._grid.is_free(self._grid.world_to_cell(ahead)).all()

    # the control step -----------------------------------------------------

    def step(self, pose, velocity, points, map_grid, now: float, obstacles=None) -> Command:
        """Command (v, w) for the robot at ``pose`` (3,) moving at ``velocity`` (v, w), seeing laser
        ``points`` (M, 2) in its frame, on ``map_grid`` at time ``now`` (s). ``obstacles`` (K, 2), world
        frame, are an obstacle layer's (e.g. a depth camera's, :mod:`~slam2d.navigation.depth_layer`):
        their cells are blocked in the map and the local planner sees them as points that stay."""
        pose, velocity = np.asarray(pose, dtype=np.float64), np.asarray(velocity, dtype=np.float64)
        points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if self.status != ACTIVE:
            return Command(0.0, 0.0, state=self.status)
        if now > self.cfg.max_time:
            return self._finish(TIMEOUT, f"time budget of {self.cfg.max_time:g} s used up")
        if obstacles is not None:
            obstacles = np.asarray(obstacles, dtype=np.float64).reshape(-1, 2)
            free, res, origin = free_mask(map_grid, self.cfg.unknown_free)
            map_grid = mark_points(PlanningGrid(free, res, origin), obstacles)
            points = np.vstack([points, in_robot_frame(pose, obstacles)])
        changed = self.update_map(map_grid, now)
        self._layer = None if obstacles is None else self._cells_of(obstacles)
        if self.path is None or (changed and (self._stand_in or self._path_blocked())):
            if self.path is not None:
                self._log(now, "replan", "the goal is blocked in the map" if self._stand_in else
                          "the new map blocks the path")
            if why := self.plan(pose):
                return self._finish(UNREACHABLE, why)
        if self._look is not None and (cmd := self._look_command(pose, velocity, now)) is not None:
            return cmd
        if self._at_goal(pose, velocity):
            return self._goal_command(pose, velocity)
        if self._manoeuvre:
            return self._manoeuvre_command(pose, points, now)
        if (cmd := self._final_command(pose, velocity, points, self.unmapped(pose, points))) is not None:
            return cmd
        self._track(pose)
        if np.hypot(*(pose[:2] - self.path[self._index])) > self.cfg.off_path:
            self._log(now, "replan", "off the path")
            if why := self.plan(pose):
                return self._finish(UNREACHABLE, why)
        if self._no_progress(pose, now):
            return self._recover(pose, points, now)
        t0 = _time.perf_counter()
        cmd = self.local.command(pose, velocity, points, self.path[self._index :], self.unmapped(pose, points))
        self.planner_seconds.append(_time.perf_counter() - t0)
        cmd = self._goal_speed(cmd, pose, velocity)
        if cmd.blocked:
            self._blocked_since = now if self._blocked_since is None else self._blocked_since
            if now - self._blocked_since >= self.cfg.blocked_time:
                return self._recover(pose, points, now)
        else:
            self._blocked_since = None
        return cmd

    def _look_command(self, pose, velocity, now: float) -> Command | None:
        """The depth camera's start-up sweep (:class:`LookAround`), ending facing the path; None once done."""
        ahead = in_robot_frame(pose, point_along(self.path[self._index :], 0.5))
        if self._look.left is None:
            self.events.append((float(now), "look around", "sweep the depth camera before driving off"))
        return self._look.command(pose, velocity, float(np.arctan2(ahead[1], ahead[0])))

    def _cells_of(self, xy) -> np.ndarray:
        """(H, W) bool on the map: the cells of world points ``xy`` (K, 2)."""
        mask = np.zeros(self._raw.shape, dtype=bool)
        cells = self._raw.world_to_cell(xy)
        cells = cells[self._raw.in_bounds(cells)]
        mask[cells[:, 0], cells[:, 1]] = True
        return mask

    def _log(self, now: float, kind: str, why: str) -> None:
        """Counts a replan and records ``(time s, kind, why)`` in ``events``."""
        self.replans += kind == "replan"
        self.events.append((float(now), kind, why))

    def _finish(self, status: str, reason: str) -> Command:
        self.status, self.reason = status, reason
        return Command(0.0, 0.0, status != REACHED, status)

    def _track(self, pose) -> None:
        """Moves the nearest path index forward (never back) to the point nearest the robot."""
        window = self.path[self._index : self._index + _AHEAD]
        self._index += int(np.argmin(np.hypot(*(window - pose[:2]).T)))

    def _remaining(self, pose) -> float:
        """Path length (m) left from the robot, via the nearest path point."""
        rest = self.path[self._index :]
        along = float(np.linalg.norm(np.diff(rest, axis=0), axis=1).sum()) if len(rest) > 1 else 0.0
        return along + float(np.hypot(*(pose[:2] - rest[0])))

    def _no_progress(self, pose, now: float) -> bool:
        """True when the remaining path has not shortened by ``progress`` within ``stuck_time``."""
        left = self._remaining(pose)
        if left < self._level_mark - 1.0:
            self._level, self._level_mark = 0, np.inf
        if left < self._best[0] - self.cfg.progress or self._best[0] == np.inf:
            self._best = (left, now)
            return False
        return now - self._best[1] > self.cfg.stuck_time

    # goal -------------------------------------------------------------------

    def _at_goal(self, pose, velocity) -> bool:
        """Arrived: within ``goal_precision`` of the goal, or within ``goal_tolerance`` with the goal abeam or
        behind (driving on would not bring the robot closer). Once arrived the robot brakes; if it then stands
        outside the tolerance (or is pushed off by more than twice it), it approaches again."""
        d = float(np.hypot(*(pose[:2] - self.goal[:2])))
        ahead = float(in_robot_frame(pose, self.goal[:2])[0])
        tol = self.cfg.goal_tolerance
        if d <= self.cfg.goal_precision or (d <= tol and ahead <= 0.0):
            self._arrived = True
        elif d > 2 * tol + 0.02 or (d > tol and np.abs(velocity).max() < 1e-3):
            self._arrived = False
        return self._arrived

    def _goal_command(self, pose, velocity) -> Command:
        """Stop, turn to within half the yaw tolerance of the goal heading if there is one, report reached."""
        if len(self.goal) == 3:
            err = float(geometry.wrap_angle(self.goal[2] - pose[2]))
            if abs(err) > self.cfg.yaw_tolerance / 2:
                brake = np.sqrt(self.robot.max_turn_accel * abs(err))  # stops within err at half the accel
                w = min(self.robot.max_turn_rate, brake, max(2.0 * abs(err), 0.1))
                return Command(0.0, float(np.sign(err) * w), False, "align")
        if np.abs(velocity).max() < 1e-3:  # stopped within the tolerance (else _at_goal approaches again)
            return self._finish(REACHED, "goal reached")
        return Command(0.0, 0.0, False, "stop")

    def _final_command(self, pose, velocity, points, unmapped) -> Command | None:
        """Within ``final_approach`` of the goal and with no laser point within the robot's radius
        (+ 1 cm; + the DWA's margin and obstacle reach for ``unmapped`` points, which may move; + the arc's
        bulge) of the straight line to it, drive at it on the arc from the heading through it at the speed
        that stops on it (:func:`stopping_speed`), so that the robot neither stops short nor coasts past;
        turn on the spot first while it is more than 0.3 rad off and the robot is slow, or once it is
        behind. This also lets the robot reach goals closer to a wall than the local planner's margin. With
        a point that near, within ``goal_tolerance`` is arrived."""
        d = float(np.hypot(*(pose[:2] - self.goal[:2])))
        if d > self.cfg.final_approach:
            return None
        goal = in_robot_frame(pose, self.goal[:2])
        bearing = float(np.arctan2(goal[1], goal[0]))
        bulge = 0.5 * d * np.tan(min(abs(bearing), 1.0) / 2)  # m between the arc and the chord, at most
        keep = self.robot.radius + _FINAL_GAP + bulge + unmapped * (self.cfg.dwa.margin + self.cfg.dwa.obstacle_reach)
        if len(points) and (_segment_distance(points, goal) < keep).any():
            if d <= self.cfg.goal_tolerance:  # the local planner places the robot no closer: arrived
                self._arrived = True
                return self._goal_command(pose, velocity)
            return None
        if abs(bearing) >= np.pi / 2 or (abs(bearing) > 0.3 and abs(float(velocity[0])) < _CREEP):
            return Command(0.0, float(np.clip(2.0 * bearing, -1.0, 1.0)), False, "final turn")
        curvature = 2.0 * np.sin(bearing) / d  # the arc from the heading through the goal
        arc = d * bearing / np.sin(bearing) if abs(bearing) > 1e-9 else d
        v = min(self._stopping_speed(arc, velocity), 0.5 * self.robot.max_turn_rate / max(abs(curvature), 1e-9))
        return Command(float(v), float(v * curvature), False, "final approach")

    def _stopping_speed(self, distance: float, velocity) -> float:
        """m/s: the speed from which the robot, at ``velocity`` now, stops after ``distance`` m (``_STOP_DECEL``)."""
        return stopping_speed(distance, float(velocity[0]), _STOP_DECEL * self.robot.max_accel, self.cfg.period)

    def _goal_speed(self, cmd: Command, pose, velocity) -> Command:
        """``cmd`` slowed on its arc to the speed that stops at the goal, along the path or straight on, whichever
        is shorter (a band cuts the path's corners; its staircase and its lagging nearest point overstate it),
        whatever the local planner plans for its stop: the final approach takes over at a speed it can stop
        from, and a planner that drives the last centimetres itself stops there too."""
        d = float(np.hypot(*(pose[:2] - self.goal[:2])))
        top = self._stopping_speed(min(d, self._remaining(pose)), velocity)
        if cmd.v <= top:
            return cmd
        return Command(top, cmd.w * top / cmd.v, cmd.blocked, cmd.state)

    # recovery ---------------------------------------------------------------

    def _recover(self, pose, points, now: float) -> Command:
        """Next recovery: the manoeuvres of the recovery behaviour (``recovery``) at this level."""
        self._level += 1
        self.recoveries += 1
        self._log(now, "recovery", f"level {self._level}")
        self._blocked_since = None
        self._level_mark = min(self._level_mark, self._remaining(pose))
        if self._level > self.cfg.max_recoveries:
            why = f"recovery exhausted ({self.cfg.max_recoveries} attempts without progress)"
            return self._finish(UNREACHABLE, why)
        for kind in self.recovery.manoeuvres(self, self._level, pose, points):
            self._manoeuvre.append([kind, pose[:2].copy() if kind == "back" else None, now])
        self._best = (np.inf, now)
        return Command(0.0, 0.0, False, "recover")

    def rear_clear(self, points) -> bool:
        """No laser point in the strip the robot sweeps backing off ``backoff`` m, as wide as the disc
        + the DWA's margin, or, wedged closer than that, as wide as the gap it has (backing off
        brings it no closer to anything)."""
        gap = float(np.hypot(*points.T).min()) - 1e-3 if len(points) else np.inf
        r = max(self.robot.radius, min(self.robot.radius + self.cfg.dwa.margin, gap))
        behind = (points[:, 0] < 0) & (points[:, 0] > -(self.cfg.backoff + r)) & (np.abs(points[:, 1]) < r)
        return self.cfg.backoff > 0 and not behind.any()

    def _manoeuvre_command(self, pose, points, now: float) -> Command:
        kind, data, since = self._manoeuvre[0]
        if kind == "back":
            if np.hypot(*(pose[:2] - data)) < self.cfg.backoff and now - since < 4.0 and self.rear_clear(points):
                return Command(-0.2, 0.0, False, "back off")
        elif kind == "replan":
            self._log(now, "replan", "recovery, with the laser's points in the map")
            near = np.hypot(*points.T) < self.cfg.mark_range
            marked = geometry.transform_points(pose, points[near])
            if why := self.plan(pose, marked, self.unmapped(pose, points)[near]):
                return self._finish(UNREACHABLE, why)
        elif kind == "turn":
            carrot = in_robot_frame(pose, point_along(self.path[self._index :], self.cfg.dwa.lookahead))
            err = float(np.arctan2(carrot[1], carrot[0]))
            if abs(err) > 0.3 and now - since < 4.0:
                return Command(0.0, float(np.clip(2.0 * err, -1.5, 1.5)), False, "turn to path")
        self._manoeuvre.pop(0)
        if self._manoeuvre:
            self._manoeuvre[0][2] = now
        return Command(0.0, 0.0, False, kind)


def _segment_distance(points: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Distances (M,) m from points (M, 2) to the segment from the origin to ``end`` (2,)."""
    ee = float(end @ end)
    u = np.clip(points @ end / ee, 0.0, 1.0) if ee > 0 else np.zeros(len(points))
    return np.hypot(*(points - u[:, None] * end).T)
