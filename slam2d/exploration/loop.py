"""Autonomous exploration with SLAM in the loop (:func:`explore`; ``slam2d explore`` writes its results).

The simulated robot starts in ``dataset.simulator.world`` knowing nothing. Online SLAM
(the ICP frontend and pose graph of ``slam2d run``, fed one scan at a time) gives the
pose and the grid; the explorer picks a goal on them (``exploration.strategy``) and a
:class:`~slam2d.navigation.Navigator` drives there, until no goal is left or a limit is
reached. The true pose is used only to score the run (:mod:`slam2d.exploration.coverage`).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from slam2d import geometry
from slam2d.errors import InputError
from slam2d.evaluation.trajectory import ate
from slam2d.exploration.collection import start_up_frozen
from slam2d.exploration.config import ExploreConfig
from slam2d.exploration.coverage import (
    Coverage,
    at_coverage,
    ignored_cells,
    path_repetition,
    reachable_free,
    seeded_start,
    truth_map,
)
from slam2d.exploration.explorer import Explorer, Goal
from slam2d.exploration.gridops import GridView, LiveClearance, geodesic, inside_polygon
from slam2d.exploration.recovery import escape, retrace, way_out
from slam2d.navigation import Navigator
from slam2d.navigation.config import navigator_config
from slam2d.navigation.drive import clearance
from slam2d.navigation.navigator import ACTIVE, REACHED
from slam2d.sim import Robot
from slam2d.sim.robot import RobotConfig
from slam2d.sim.world import load_world
from slam2d.slam import OnlineSlam

log = logging.getLogger(__name__)

WARMUP = 2.0  # s the robot stands still at the start while the grid's first cells become free
POCKET_REACHED = 0.1  # m: a view of a pocket is reached closer than other goals (it may be the only one)
WAY_OUT_REACHED = 0.1  # m: the end of a tight stretch is reached this close (the margin fits within it)
POCKET_DWELL = 1.0  # s standing at a view of a pocket (a log-odds cell needs a few scans to turn free)
ENTRY_MIN = 0.3  # m: a tight goal's way with the safety margin shorter than this is not driven as a leg of its own
TIGHT_MARGIN_WEIGHT = 3.0  # the DWA's margin_weight in a tight stretch: the arcs along its middle


@dataclass(eq=False)
class ExplorationRun:
    """What :func:`explore` returns (no files written)."""

    world: Any
    grid: Any
    truth: np.ndarray  # (N, 3) true poses
    estimate: np.ndarray  # (N, 3) SLAM poses
    stamps: np.ndarray
    explorer: Explorer
    curve: np.ndarray  # (K, 3): time s, distance m, coverage
    snapshots: list = field(default_factory=list)
    goals: list = field(default_factory=list)
    metrics: dict = field(default_factory=dict)


def resolved(cfg: ExploreConfig) -> ExploreConfig:
    """``cfg`` with ``mapping.max_range`` at the laser's range limit when unset: a simulated laser's
    no-return is open space up to the limit, which A-type candidates stand on."""
    if cfg.mapping.max_range is None:
        mapping = cfg.mapping.model_copy(update={"max_range": cfg.dataset.simulator.laser.range_max})
        cfg = cfg.model_copy(update={"mapping": mapping})
    return cfg


# --------------------------------------------------------------------------- the loop


class _Loop:
    """State of one exploration run: robot, SLAM, explorer, the current goal and its navigator."""

    def __init__(self, cfg: ExploreConfig):
        self.cfg, self.ecfg, sim = cfg, cfg.exploration, cfg.dataset.simulator
        self.world = load_world(sim.world, sim.resolution)
        self.truth_free, self.truth_frame = truth_map(self.world)
        start = np.asarray(self.ecfg.start, float) if self.ecfg.start is not None else seeded_start(
            self.world, sim.world, self.truth_free, self.truth_frame, cfg.seed)  # fmt: skip
        if not self.world.free(start[None, :2], 0.2)[0]:
            raise InputError("exploration.start", f"({start[0]:.2f}, {start[1]:.2f}) is not free for the robot")
        if self.ecfg.bounds is not None and not inside_polygon(start[None, :2], self.ecfg.bounds)[0]:
            raise InputError("exploration.bounds", f"the start ({start[0]:.2f}, {start[1]:.2f}) is outside the polygon")
        self.robot = Robot(self.world, start, RobotConfig(laser=sim.laser, odometry=sim.odometry), seed=cfg.seed)
        # the robot as it plans and drives: its disc grown by the safety margin
        self.body = self.robot.cfg.model_copy(update={"radius": self.robot.cfg.radius + self.ecfg.safety_margin})
        # a goal the map comes to block is inaccessible at once: the explorer picks another
        self.options = navigator_config({"max_time": 120.0, "blocked_goal_reach": 0.0, **self.ecfg.options},
                                          True, "exploration.options")  # fmt: skip
        dwa = self.options.dwa
        self.tight_options = self.options.model_copy(update={"touch": True, "dwa": dwa.model_copy(update={
            "margin_weight": max(dwa.margin_weight, TIGHT_MARGIN_WEIGHT)})})  # fmt: skip
        self.ignored = ignored_cells(self.world.unmapped, self.truth_frame, self.truth_free.shape, self.ecfg.bounds)
        # the robot's centre goes where the navigator plans: radius + inflation margin from walls
        self.reachable = reachable_free(self.truth_free, self.truth_frame, start[:2],
                                        self.robot.cfg.radius + self.options.inflation_margin,
                                        sim.laser.range_max, self.ignored)  # fmt: skip
        self.reachable_disc = reachable_free(self.truth_free, self.truth_frame, start[:2], self.robot.cfg.radius,
                                             sim.laser.range_max, self.ignored)  # fmt: skip
        self.slam = OnlineSlam(cfg)
        self.explorer = Explorer(self.ecfg, self.robot.cfg.radius, self.options.inflation_margin,
                                 sim.laser.range_max)  # fmt: skip
        # the explorer asks for room of its radius + the larger of the inflation and the goal clearance
        self.clearance = LiveClearance(self.body.radius + max(self.options.inflation_margin, self.ecfg.goal_clearance)
                                       + 2 * cfg.mapping.resolution)  # fmt: skip
        self.nav = None
        self.goal: Goal | None = None
        self.dwell: float | None = None  # s: until when the robot stands at a view of a pocket
        self.legs: list[np.ndarray] = []
        self.tight_legs: list[bool] = []  # per leg: driven with the robot's own disc (the tight stretch of a goal)
        self.goals: list[dict] = []
        self.replans = self.recoveries = self.escapes = 0
        self.contacts: list = []
        self.escape = None  # (heading rad, start (x, y), start time) while backing out of a tight spot
        self.retrace = None  # (the way back (K, 2) m, start time) while driving out of a trap
        self.retraces = 0

    def view(self) -> GridView:
        m = self.cfg.mapping
        return self.clearance.attach(GridView.of(self.slam.grid, m.free_thresh, m.occupied_thresh))

    def set_goal(self, goal: Goal | None, now: float) -> None:
        self.goal, self.dwell = goal, None
        if goal is None:
            self.nav = None
            return
        self.legs = [np.asarray(w, float) for w in goal.waypoints] + [goal.position]
        self.tight_legs = [goal.tight] * len(self.legs)
        if goal.tight and (way_out := self.way_out(self.legs[-2] if len(self.legs) > 1 else self.slam.pose[:2],
                                                   goal.position)) is not None:
            self.legs[-1:-1] = [way_out]  # beyond the tight stretch the margin holds again
            self.tight_legs[-1:] = [True, False]
        if goal.tight and (entry := self.entry(self.slam.pose, self.legs[0])) is not None:
            self.legs.insert(0, entry)  # the way to the tight stretch keeps the margin
            self.tight_legs.insert(0, False)
        self.nav = self.navigator()
        self.goal_t0, self.best = now, (np.inf, now)
        self.goal_from = self.robot.pose[:2].copy()
        self.goals.append({"time": now, "position": goal.position.tolist(), "kind": goal.kind,
                           "waypoints": len(goal.waypoints), "outcome": "active"})  # fmt: skip
        if goal.options:
            self.goals[-1]["options"] = goal.options
        if goal.tight:
            self.goals[-1]["tight"] = True

    def next_leg(self, now: float) -> None:
        self._count(self.nav)
        self.legs.pop(0)
        self.tight_legs.pop(0)
        if self.tight_legs == [True] and (ending := self.way_out(self.slam.pose[:2], self.legs[0])) is not None:
            self.legs.insert(0, ending)  # the far side seen from the gap: beyond it the margin holds again
            self.tight_legs.append(False)
        self.nav = self.navigator()
        self.goal_t0, self.best = now, (np.inf, now)

    def navigator(self) -> Navigator:
        """The navigator to the current leg: with the robot grown by the safety margin, but on the tight leg of a
        ``tight`` goal (a gap the margin does not fit through, the last resort) with its own disc, planned also where
        it touches a blocked cell's centre (the map draws a door seen from close by up to a cell narrower each side),
        and a DWA that drives the gap's middle."""
        if self.tight_legs[0]:
            return Navigator(self.legs[0], self.robot.cfg, self.tight_options)
        return Navigator(self.legs[0], self.body, self.options)

    def entry(self, pose, target) -> np.ndarray | None:
        """Where a tight goal's way to ``target`` (x, y) m leaves the room of the robot grown by the safety margin:
        of the cells that disc reaches from ``pose``, the one nearest ``target`` along the paths of the robot's own
        disc (the paths the explorer found it on); None when that is within ``ENTRY_MIN`` of the robot or
        ``target`` is out of the map."""
        view = self.view()
        goal = view.to_cell(target)
        if not view.inside(goal[None])[0]:
            return None
        return self._meeting(view, view.traversable(self.body.radius), view.to_cell(pose[:2]), goal, ENTRY_MIN)

    def way_out(self, start, target) -> np.ndarray | None:
        """Where a tight goal's way from ``start`` (x, y) m to ``target`` comes out of the gap: of the known-free
        cells the disc grown by the margin (and the leg's tolerance) fits in clear of every cell not known free, those
        it reaches from ``target``, the one nearest ``start`` along the paths of the robot's own disc; None when there
        is none or it is ``target``'s own cell."""
        view = self.view()
        cells = np.array([view.to_cell(np.asarray(start, float)[:2]), view.to_cell(target)])
        if not view.inside(cells).all():
            return None
        return self._meeting(view, view.roomy(self.body.radius + WAY_OUT_REACHED), cells[1], cells[0], 1e-9)

    def _meeting(self, view, room, inside, other, min_way: float) -> np.ndarray | None:
        """(x, y) m of the cell of ``room`` (H, W) reached from cell ``inside`` that is nearest cell ``other`` along
        the paths of the robot's own disc; None when there is none or it lies less than ``min_way`` m from
        ``inside`` within ``room``."""
        wide = geodesic(room, inside, view.resolution)
        near = np.where(np.isfinite(wide), geodesic(view.traversable(self.robot.cfg.radius), other, view.resolution),
                        np.inf)  # fmt: skip
        best = np.unravel_index(np.argmin(near), near.shape)
        if not np.isfinite(near[best]) or wide[best] < min_way:
            return None
        return view.to_world(np.array(best))

    def widen(self, pose) -> None:
        """A ``tight`` goal whose current leg the map now lets the robot reach with the safety margin (a door
        drawn wider as more of it is seen) is driven with the margin again, from here on."""
        view = self.view()
        cell = view.to_cell(self.legs[0])
        if not (view.inside(cell[None])[0] and self.body.radius > self.robot.cfg.radius):
            return
        if np.isfinite(geodesic(view.traversable(self.body.radius), view.to_cell(pose[:2]), view.resolution)[
                cell[0], cell[1]]):  # fmt: skip
            self._count(self.nav)
            self.tight_legs[0] = False
            self.nav = self.navigator()

    def close_goal(self, outcome: str) -> None:
        self._count(self.nav)
        self.goals[-1]["outcome"] = outcome
        if outcome == "inaccessible":
            self.goals[-1]["reason"] = self.nav.reason or f"no progress for {self.ecfg.goal_timeout:g} s"
            stuck = "recovery" in self.goals[-1]["reason"] or np.hypot(*(self.robot.pose[:2] - self.goal_from)) < 0.2
            if stuck:  # back out of the tight spot before the next goal
                self.escape = None, self.robot.pose[:2].copy(), None
        if outcome == "reached":
            self.explorer.reached(self.goal)
        elif outcome == "inaccessible":
            self.explorer.give_up(self.goal)
        self.goal = self.nav = None

    def _count(self, nav) -> None:
        if nav is not None:
            self.replans += nav.replans
            self.recoveries += nav.recoveries

    def no_progress(self, pose, now: float) -> bool:
        """True when the distance to the current leg has not shrunk by 0.3 m within ``goal_timeout``."""
        d = float(np.hypot(*(pose[:2] - self.legs[0])))
        if d < self.best[0] - 0.3:
            self.best = (d, now)
        return now - self.best[1] > self.ecfg.goal_timeout


def explore(cfg: ExploreConfig, progress=None, view=None) -> ExplorationRun:
    """One exploration run of ``cfg`` (no files written); ``progress(now, coverage)`` is told every second;
    ``view`` (a :class:`slam2d.viz.ExploreView`) logs every control step."""
    t_wall = time.perf_counter()
    cfg = resolved(cfg)
    loop = _Loop(cfg)
    with start_up_frozen():  # the objects of the start-up (libraries, warm-up, loop) walked by no collection
        return _drive(loop, cfg, progress, view, t_wall)


def _drive(loop: _Loop, cfg: ExploreConfig, progress, view, t_wall: float) -> ExplorationRun:
    """:func:`explore` on its ``loop``, made."""
    ecfg = cfg.exploration
    period = loop.options.period
    cover = Coverage(loop.reachable, loop.truth_frame, cfg.mapping, loop.ignored)
    step = loop.robot.step(0.0, 0.0, 0.0)
    t0 = step.scan.stamp
    loop.slam.add(step.scan)
    truth, est, stamps = [step.pose], [loop.slam.pose.copy()], [t0]
    loop.explorer.observe(est[-1], step.scan, loop.view(), force=True)
    curve, snaps = [], []
    driven, collisions, in_contact, min_clear = 0.0, 0, False, (clearance(loop.world, loop.robot), 0.0)
    next_check = next_sample = next_snap = 0.0
    idle, stop = 0, ""
    while not stop:
        now = step.scan.stamp - t0
        pose = loop.slam.pose
        if view is not None:
            view.step(now, pose, loop.slam.grid, loop.goal)
        if now >= next_sample:
            curve.append((now, driven, cover(loop.slam.grid)))
            next_sample += 1.0
            if progress:
                progress(now, curve[-1][2])
        if ecfg.animation and now >= next_snap:
            snaps.append(_snapshot(loop, len(truth)))
            next_snap += ecfg.snapshot_period
        if now > ecfg.max_time or driven > ecfg.max_distance:
            stop = "limit"
            break
        if loop.goal is not None and now >= next_check:
            next_check = now + ecfg.check_period
            checked = loop.view()
            loop.explorer.keep_up(checked)  # the decision's grids kept up with the map while the robot drives
            if loop.explorer.spent(loop.goal, checked):
                loop.close_goal("spent")
            elif loop.tight_legs[0]:
                loop.widen(pose)
        if loop.goal is None and loop.retrace is None:
            loop.set_goal(loop.explorer.decide(pose, loop.view()), now)
            if loop.goal is None and now >= WARMUP:
                way = way_out(loop, est)
                if way is None:
                    stop = "done"
                    break
                loop.retrace = way, now
        if loop.goal is None and loop.retrace is None:  # the first scans: no cell is free yet
            step = _wait(loop, step, period, truth, est, stamps)
            continue
        if loop.goal is not None:
            d_leg = float(np.hypot(*(pose[:2] - loop.legs[0])))
            view_leg = loop.goal.kind == "pocket" and len(loop.legs) == 1
            ending = len(loop.legs) > 1 and loop.tight_legs[0] and not loop.tight_legs[1]
            if d_leg < (POCKET_REACHED if view_leg else WAY_OUT_REACHED if ending else ecfg.goal_reached):
                if view_leg:  # stand still at a view long enough for the grid's cells to settle
                    loop.dwell = now + POCKET_DWELL if loop.dwell is None else loop.dwell
                    if now < loop.dwell:
                        step = _wait(loop, step, period, truth, est, stamps)
                        continue
                if len(loop.legs) > 1:
                    loop.next_leg(now)
                    continue
                loop.close_goal("reached")
                loop.explorer.observe(pose, step.scan, loop.view(), force=True)
                idle += 1
                if idle < 20:
                    continue
        cmd = retrace(loop, step, now) if loop.retrace is not None else None
        if cmd is None and loop.escape is not None:
            cmd = escape(loop, step, now)
        if cmd is None and loop.nav is not None:
            cmd = loop.nav.step(pose, step.velocity, step.scan.points_in_base(), loop.slam.grid, now - loop.goal_t0)
            if loop.nav.status == REACHED:
                loop.close_goal("reached")
            elif loop.nav.status != ACTIVE or loop.no_progress(pose, now):
                if len(loop.legs) > 1 and loop.tight_legs[1] and not loop.tight_legs[0]:
                    loop.next_leg(now)  # the way to a tight stretch failed with the margin: on with the robot's disc
                else:
                    loop.close_goal("inaccessible")
            if loop.nav is None and idle < 20:  # a new goal at once, the robot waits at most 20 decisions
                idle += 1
                continue
        idle = 0
        v, w = (cmd.v, cmd.w) if cmd is not None else (0.0, 0.0)
        before = step.pose[:2].copy()
        step = loop.robot.step(v, w, period)
        driven += float(np.hypot(*(step.pose[:2] - before)))
        collisions += int(step.collision and not in_contact)
        if step.collision and not in_contact:
            loop.contacts.append((now, *np.round(step.pose, 2), step.contact, cmd.state if cmd else ""))
        in_contact = step.collision
        gap = clearance(loop.world, loop.robot)
        if gap < min_clear[0]:
            min_clear = gap, now
        loop.slam.add(step.scan)
        truth.append(step.pose)
        est.append(loop.slam.pose.copy())
        stamps.append(step.scan.stamp)
        loop.explorer.observe(est[-1], step.scan, _Lazy(loop))
    if loop.nav is not None:
        loop.close_goal("stopped")
    loop.explorer.hybrid.finish()
    loop.slam.finish()  # the final batch optimisation, as `slam2d run` ends: the map is drawn at its poses
    grid = loop.slam.grid
    now = step.scan.stamp - t0
    curve.append((now, driven, cover(grid)))
    if view is not None:
        view.step(now, loop.slam.pose, grid, None, force=True)
    if ecfg.animation:
        snaps.append(_snapshot(loop, len(truth)))
    run = ExplorationRun(loop.world, grid, np.array(truth), np.array(est), np.array(stamps), loop.explorer,
                         np.array(curve), snaps, loop.goals)  # fmt: skip
    run.contacts = loop.contacts
    run.metrics = _metrics(run, loop, cover, stop, collisions, min_clear, time.perf_counter() - t_wall)
    return run


def _wait(loop: _Loop, step, period: float, truth, est, stamps):
    """One control period standing still (scan into SLAM, poses recorded)."""
    step = loop.robot.step(0.0, 0.0, period)
    loop.slam.add(step.scan)
    truth.append(step.pose)
    est.append(loop.slam.pose.copy())
    stamps.append(step.scan.stamp)
    return step


class _Lazy:
    """A grid view made only when a node is due (``observe`` asks for it then)."""

    def __init__(self, loop):
        self.loop, self._view = loop, None

    def __getattr__(self, name):
        if self._view is None:
            self._view = self.loop.view()
        return getattr(self._view, name)


def _metrics(run: ExplorationRun, loop: _Loop, cover: Coverage, stop: str, collisions: int, min_clear: tuple,
             wall: float) -> dict:  # fmt: skip
    curve, ex = run.curve, run.explorer
    t90, d90 = at_coverage(curve, 0.90)
    t99, d99 = at_coverage(curve, 0.99)
    dec = np.array(ex.decision_seconds) * 1000 if ex.decision_seconds else np.array([np.nan])
    cpu = np.array(ex.decision_cpu_seconds) * 1000 if ex.decision_cpu_seconds else np.array([np.nan])
    sim_time = float(curve[-1, 0])
    outcomes = [g["outcome"] for g in run.goals]
    return {
        "world": loop.world.name, "strategy": loop.ecfg.strategy, "seed": loop.cfg.seed,
        "stop_reason": stop, "coverage": float(curve[-1, 2]), "time": sim_time, "distance": float(curve[-1, 1]),
        "time_to_90": t90, "distance_to_90": d90, "time_to_99": t99, "distance_to_99": d99,
        "premature_stop": stop == "done" and curve[-1, 2] < 0.99,
        "collisions": collisions, "min_clearance": float(min_clear[0]), "min_clearance_time": float(min_clear[1]),
        "goals": len(run.goals), "goals_reached": outcomes.count("reached"), "goals_spent": outcomes.count("spent"),
        "goals_inaccessible": outcomes.count("inaccessible"), "frontier_fallbacks": ex.fallbacks,
        "pocket_goals": ex.pocket_goals, "tight_goals": ex.tight_goals,
        "replans": loop.replans, "recoveries": loop.recoveries, "escapes": loop.escapes, "retraces": loop.retraces,
        "path_repetition": path_repetition(run.truth[:, :2]),
        "coverage_disc": Coverage(loop.reachable_disc, loop.truth_frame, loop.cfg.mapping)(run.grid),
        "map_iou": cover.iou(run.grid),
        "ate_rmse": ate(run.estimate, run.truth, align=False)["rmse"],
        **_pose_error(run),
        "decisions": len(ex.decision_seconds), "decision_ms_median": float(np.median(dec)),
        "decision_ms_p95": float(np.percentile(dec, 95)), "decision_cpu_ms_median": float(np.median(cpu)),
        "decision_cpu_ms_p95": float(np.percentile(cpu, 95)),
        **ex.hybrid.counts(),
        "reachable_area_m2": float(loop.reachable.sum() * loop.truth_frame.resolution**2),
        "wall_s": wall, "real_time_factor": sim_time / wall if wall > 0 else float("nan"),
    }  # fmt: skip


def _pose_error(run: ExplorationRun) -> dict:
    """The online estimate the robot drove on against the truth, no alignment: position error p95 and max (m),
    when the max was (s from the start), and the largest heading error (deg)."""
    err = np.hypot(*(run.estimate[:, :2] - run.truth[:, :2]).T)
    turn = np.abs(geometry.wrap_angle(run.estimate[:, 2] - run.truth[:, 2]))
    worst = int(np.argmax(err))
    return {"pose_error_p95": float(np.percentile(err, 95)), "pose_error_max": float(err[worst]),
            "pose_error_max_time": float(run.stamps[worst] - run.stamps[0]),
            "heading_error_max_deg": float(np.degrees(turn.max()))}  # fmt: skip


def _snapshot(loop: _Loop, n_poses: int) -> dict:
    """The map (downsampled ×2, uint8 grey) and the counts needed to draw one animation frame."""
    grid = loop.slam.grid
    p = grid.probability()[::2, ::2]
    return {"image": (255 * (1.0 - p)).astype(np.uint8), "extent": grid.extent, "n": n_poses,
            "nodes": loop.explorer.hybrid.positions().copy(),
            "goal": None if loop.goal is None else loop.goal.position.copy()}  # fmt: skip
