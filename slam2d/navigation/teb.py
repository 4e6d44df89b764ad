"""Timed elastic band (Rösmann et al., ROBOTIK 2012; ECMR 2013) as a GTSAM factor graph.

The band is a sequence of poses x_0 .. x_{n-1} (``gtsam.Pose2``, the robot frame of the call:
x_0 the robot, fixed) and the time intervals dt_i (s) between them. Its factors:

- start: x_0 at the robot; end: x_{n-1} at the local goal (the point ``horizon`` m along the path,
  facing along it; the final goal once within reach);
- via-points: the path every ``via_spacing`` m, each pulling the band pose nearest to it once that pose
  is more than ``via_tube`` m from it (a replanned grid path leaves the robot on a 45 degree staircase
  to the line it prefers: pulled onto each, the band wove);
- obstacles: every pose against the nearest laser point on its left and on its right (robot
  frame, found again at each evaluation): a steep cost inside radius + ``margin``, a soft
  one within ``inflation`` beyond; points the map does not explain (people) may move, so their
  margin grows by ``obstacle_speed`` per second of band time up to ``obstacle_reach`` (as in the DWA);
- velocity: |v| and |w| of every segment within the robot's limits (backwards at most
  ``max_speed_back``), dt_i above ``min_dt``;
- acceleration: of every pair of segments, from the robot's velocity at the start, to a stop at
  the final goal (a segment's speed is its mean, at its middle: each change is over the time between
  those points, from now and to the end over half an interval);
- non-holonomic kinematics: both poses of a segment make equal angles with its chord (a
  differential drive moves on arcs), and it drives forwards;
- total time: every dt_i pulled to 0, which makes the band time-optimal.

Every call re-solves the band (Levenberg-Marquardt, ``iterations``) warm-started from the last one,
moved into the new robot frame, with poses inserted or removed so that each dt stays near
``dt_ref``; the command is the band's (v, w) one period on (linear from the robot's speed now to the
first segment's at its middle), clipped to what the robot reaches in one
period and slowed on its arc until the robot, braking at full deceleration after the period,
stops short of every point (a point that may move with its margin grown, as the DWA's arcs).
A band whose first ``check_time`` s would bring the disc onto a laser point, or whose slowest
command cannot stop short, is dropped: the robot brakes and reports itself blocked. A path more than
``turn_first`` off the heading is first turned to on the spot, down to a quarter of that. With
``homotopies`` on, a band that still runs through a point (a person on the path, a box the
map lacks: pulled from both sides, it stays in the obstacle) is optimised again from two starts
moved round that point, one on each side (with half the iterations: the kept one is refined at the
following calls), and the cheapest band clear of every point is kept (teb_local_planner's
alternatives in distinct topologies, two at a time).
"""

from __future__ import annotations

import math
from functools import partial

import gtsam
import numpy as np
from pydantic import Field
from scipy.spatial import cKDTree

from slam2d import geometry
from slam2d.config import Section
from slam2d.navigation.base import register_local_planner
from slam2d.navigation.common import Command, in_robot_frame, path_ahead, point_along
from slam2d.navigation.dwa import arcs
from slam2d.navigation.teb_factors import (
    T,
    X,
    acceleration_residual,
    band_factor,
    kinematics_residual,
    obstacle_residual,
    segments,
    stacked,
    time_residual,
    velocity_residual,
    via_residual,
)
from slam2d.sim.robot import RobotConfig

__all__ = ["TebConfig", "TimedElasticBand"]



class TebConfig(Section):
    """Band resolution, horizon, clearances and the weights of the TEB's factors."""

    period: float = Field(0.1, gt=0, description="s, control period (the navigator's)")
    horizon: float = Field(2.5, gt=0, description="m along the path to the band's end (the local goal)")
    dt_ref: float = Field(0.3, gt=0, description="s, the time interval a band segment is kept near")
    dt_hysteresis: float = Field(0.1, ge=0, description="s; a segment longer than dt_ref + this is split, "
                                 "one shorter than dt_ref - this merged")  # fmt: skip
    min_dt: float = Field(0.02, gt=0, description="s, the shortest time interval")
    min_poses: int = Field(3, ge=3, le=100, description="poses in the band, at least")
    max_poses: int = Field(15, ge=3, le=200, description="poses in the band, at most (the cost grows with their square)")
    iterations: int = Field(8, ge=1, le=100, description="Levenberg-Marquardt iterations a call, at most")
    tolerance: float = Field(1e-3, gt=0, lt=1, description="relative decrease of the band's error below which "
                             "Levenberg-Marquardt stops (the band is warm-started and solved again next period)")
    margin: float = Field(0.05, ge=0, description="m kept between the robot's disc and any laser point")
    inflation: float = Field(0.25, ge=0, description="m beyond the margin over which a soft cost keeps clear")
    max_speed_back: float = Field(0.2, ge=0, description="m/s, fastest backwards")
    epsilon: float = Field(0.02, ge=0, lt=1, description="fraction of each limit kept in reserve by the band")
    via_spacing: float = Field(0.3, gt=0, description="m between via-points along the path")
    via_tube: float = Field(0.2, ge=0, description="m from a via-point within which the band is free (the "
                            "time term then straightens it); beyond, it is pulled back")
    obstacle_speed: float = Field(0.8, ge=0, description="m/s assumed for points the map does not explain")
    obstacle_reach: float = Field(0.5, ge=0, description="m, the most such a point's margin grows along the band")
    check_time: float = Field(1.0, ge=0, description="s of band checked for contact before its command goes out")
    turn_first: float = Field(1.4, gt=0, description="rad; a path this far off the heading is turned to on the "
                              "spot, until within a quarter of this")
    homotopies: bool = Field(True, description="a band through a point is optimised again round either side of it")
    obstacle_weight: float = Field(100.0, ge=0, description="inside radius + margin, per m^2")
    inflation_weight: float = Field(2.0, ge=0, description="within the inflation, per m^2")
    via_weight: float = Field(1.0, ge=0, description="per m^2 from a via-point")
    velocity_weight: float = Field(10.0, ge=0, description="per (m/s)^2 or (rad/s)^2 over a limit")
    acceleration_weight: float = Field(2.0, ge=0, description="per (m/s^2)^2 or (rad/s^2)^2 over a limit")
    kinematics_weight: float = Field(1000.0, ge=0, description="per m^2 of the non-holonomic residual")
    forward_weight: float = Field(10.0, ge=0, description="per m^2 driven backwards")
    time_weight: float = Field(1.0, ge=0, description="per s^2 of each time interval")


# --- the planner --------------------------------------------------------------------------------------------


@register_local_planner("teb", config=TebConfig)
class TimedElasticBand:
    """TEB local planner for a robot with :class:`RobotConfig` limits (see the module docstring)."""

    def __init__(self, robot: RobotConfig | None = None, config: TebConfig | None = None):
        self.robot, self.cfg = robot or RobotConfig(), config or TebConfig()
        self.band: tuple[np.ndarray, np.ndarray] | None = None  # world poses (n, 3), dts (n - 1,) s
        self.cost = np.nan  # the kept band's graph error
        self.turning = False  # turning on the spot to the path

    def reset(self) -> None:
        """Forget the band: the next call starts a new one along the path."""
        self.band, self.turning = None, False

    def command(self, pose, velocity, points, path, unmapped=None) -> Command:
        """(v, w) of the optimised band's first segment; ``blocked`` when the band would touch a point."""
        pose = np.asarray(pose, dtype=np.float64)
        velocity = np.asarray(velocity, dtype=np.float64)
        points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        moving = np.zeros(len(points), bool) if unmapped is None else np.asarray(unmapped, bool).reshape(-1)
        local = in_robot_frame(pose, path_ahead(path, pose))
        goal, final = self._local_goal(local)
        ahead = point_along(local, min(0.5, _length(local)))
        bearing = math.atan2(ahead[1], ahead[0])
        self.turning = abs(bearing) > self.cfg.turn_first / (4 if self.turning else 1) and np.hypot(*ahead) > 0.05
        if self.turning:  # an arc to a path far off the heading would lengthen the way
            self.band = None
            return self._turn(velocity, bearing)
        start = self._warm(pose, goal, local) if self.band is not None else self._along(goal, local)
        best = self._best([start], velocity, points, moving, local, final)
        if best is None and self.band is not None:  # the warm band is stuck: one along the path (no detours)
            best = self._best([self._along(goal, local)], velocity, points, moving, local, final, detours=False)
        if best is None:
            self.band = None
            return self._brake(velocity, "band touches a point")
        poses, dts, self.cost = best
        self.band = (geometry.compose(pose, poses), dts)
        return self._first_command(poses, dts, velocity, points, moving)

    def _best(self, starts, velocity, points, moving, local, final, detours: bool = True):
        """The cheapest clear band (poses, dts, cost) optimised from ``starts``; with ``homotopies``, when the
        cheapest runs through a point, also from it moved round that point on either side (another homotopy
        class); None if no band is clear."""
        found = [self.optimise(poses, dts, velocity, points, moving, local, final) for poses, dts in starts]
        if detours and self.cfg.homotopies and (hit := self._first_contact(min(found, key=lambda b: b[2]), points)) is not None:
            found += [self.optimise(*detour, velocity, points, moving, local, final, max(2, self.cfg.iterations // 2))
                      for detour in self._detours(min(found, key=lambda b: b[2]), *hit)]  # fmt: skip
        clear = [b for b in found if self._clear(b[0], b[1], points)]
        through = [self._first_contact(b, points) is not None for b in clear]
        return min(zip(clear, through), key=lambda c: (c[1], c[0][2]))[0] if clear else None

    # the band's start ---------------------------------------------------------------------------------

    def _local_goal(self, local: np.ndarray) -> tuple[np.ndarray, bool]:
        """The band's end (3,) in the robot frame: ``horizon`` m along the ``local`` path facing along it,
        or the path's end; and whether it is the path's end."""
        length = _length(local)
        s = min(self.cfg.horizon, length)
        end = point_along(local, s)
        before, after = point_along(local, max(s - 0.3, 0.0)), point_along(local, s + 0.3)
        d = after - before if np.hypot(*(after - before)) > 1e-6 else end
        return np.array([*end, math.atan2(d[1], d[0])]), s >= length - 1e-9

    def _along(self, goal: np.ndarray, local: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A new band along the path from the robot to ``goal``: one pose per ``dt_ref`` s at full speed."""
        c, r = self.cfg, self.robot
        s_goal = _arc_length_at(local, goal[:2])
        n = int(np.clip(math.ceil(s_goal / (r.max_speed * c.dt_ref)) + 1, c.min_poses, c.max_poses))
        xy = np.array([point_along(local, s) for s in np.linspace(0.0, s_goal, n)])
        xy[0], xy[-1] = 0.0, goal[:2]
        step = np.diff(xy, axis=0)
        heading = np.arctan2(step[:, 1], step[:, 0])
        poses = np.column_stack([xy, np.concatenate([[0.0], heading[1:], [goal[2]]])])
        return poses, self._times(poses)

    def _times(self, poses: np.ndarray) -> np.ndarray:
        """Time intervals (n - 1,) s to move between ``poses`` at the robot's top speeds."""
        step = np.diff(poses, axis=0)
        turn = np.abs(geometry.wrap_angle(step[:, 2]))
        return np.maximum(np.maximum(np.hypot(step[:, 0], step[:, 1]) / self.robot.max_speed,
                                     turn / self.robot.max_turn_rate), self.cfg.min_dt)  # fmt: skip

    def _warm(self, pose, goal, local) -> tuple[np.ndarray, np.ndarray]:
        """The last band in the robot's frame, the poses already passed dropped, starting at the robot and
        ending at ``goal``, then resized so that every dt stays near ``dt_ref``."""
        poses, dts = geometry.compose(geometry.inverse(pose), self.band[0]), self.band[1].copy()
        passed = int(np.argmax(poses[:, 0] > 0.05)) if (poses[:, 0] > 0.05).any() else len(poses) - 1
        passed = max(passed, 1)
        keep, dts = poses[passed:], dts[passed - 1 :]
        full = np.hypot(*(poses[passed, :2] - poses[passed - 1, :2]))
        dts[0] *= min(1.0, np.hypot(*keep[0, :2]) / full) if full > 1e-9 else 1.0
        poses = np.vstack([np.zeros(3), keep])
        if np.hypot(*(poses[-1, :2] - goal[:2])) > 0.5 or len(poses) < 2:
            return self._along(goal, local)
        poses[-1] = goal
        dts[-1] = max(dts[-1], self._times(poses[-2:])[0])
        return self._resize(poses, np.maximum(dts, self.cfg.min_dt))

    def _resize(self, poses, dts) -> tuple[np.ndarray, np.ndarray]:
        """Splits segments longer than dt_ref + hysteresis and merges shorter than dt_ref - hysteresis."""
        c = self.cfg
        poses, dts = list(poses), list(dts)
        i = 0
        while i < len(dts):
            if dts[i] > c.dt_ref + c.dt_hysteresis and len(poses) < c.max_poses:
                a, b = poses[i], poses[i + 1]
                mid = np.array([(a[0] + b[0]) / 2, (a[1] + b[1]) / 2, a[2] + geometry.wrap_angle(b[2] - a[2]) / 2])
                poses.insert(i + 1, mid)
                dts[i : i + 1] = [dts[i] / 2, dts[i] / 2]
                continue
            if dts[i] < c.dt_ref - c.dt_hysteresis and len(poses) > c.min_poses and i < len(dts) - 1:
                del poses[i + 1]
                dts[i : i + 2] = [dts[i] + dts[i + 1]]
                continue
            i += 1
        return np.array(poses), np.array(dts)

    def _first_contact(self, band, points):
        """(Band pose index, laser point (2,)) where the disc first comes within radius + half the margin of a
        point along the band (every 2 cm), or None."""
        poses = band[0]
        if len(points) == 0 or len(poses) < 3:
            return None
        xy, owner = _densify(poses[:, :2], 0.02, with_index=True)
        dist, idx = cKDTree(points).query(xy)
        inside = np.flatnonzero(dist < self.robot.radius + self.cfg.margin / 2)
        inside = inside[owner[inside] > 0]  # not where the robot is already
        return None if len(inside) == 0 else (int(owner[inside[0]]), points[idx[inside[0]]])

    def _detours(self, band, k: int, point) -> list[tuple[np.ndarray, np.ndarray]]:
        """``band`` with its poses around pose ``k`` moved sideways so that it passes ``point`` (2,) at radius +
        margin + inflation on its left, and on its right: starts in the two homotopy classes round it."""
        poses, dts = band[0], band[1]
        k = int(np.clip(k, 1, len(poses) - 2))
        ahead = poses[k + 1, :2] - poses[k - 1, :2]
        normal = np.array([-ahead[1], ahead[0]]) / max(np.hypot(*ahead), 1e-9)  # the band's left at pose k
        across = float((point - poses[k, :2]) @ normal)  # the point's offset to the left of pose k
        reach = self.robot.radius + self.cfg.margin + self.cfg.inflation
        weights = np.exp(-0.5 * ((np.arange(len(poses)) - k) / max(1.0, len(poses) / 5)) ** 2)
        weights[0] = weights[-1] = 0.0
        out = []
        for side in (1.0, -1.0):
            moved = poses.copy()
            moved[:, :2] += weights[:, None] * ((across + side * reach) * normal)[None]
            step = np.diff(moved[:, :2], axis=0)
            moved[1:-1, 2] = np.arctan2(step[1:, 1], step[1:, 0])
            out.append((moved, np.maximum(dts, self._times(moved))))
        return out

    # the graph ----------------------------------------------------------------------------------------

    def optimise(self, poses, dts, velocity, points, moving, local, final: bool, iterations: int | None = None):
        """The band (poses (n, 3) robot frame, dts (n - 1,) s) optimised from the given one (``iterations``, default
        the config's), and its cost."""
        graph, values = self.graph(poses, dts, velocity, points, moving, local, final)
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(iterations or self.cfg.iterations)
        params.setRelativeErrorTol(self.cfg.tolerance)
        result = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
        n = len(poses)
        out = np.array([[p.x(), p.y(), p.theta()] for p in (result.atPose2(X(i)) for i in range(n))])
        times = np.maximum(gtsam.utilities.extractVectors(result, "t")[:, 0], self.cfg.min_dt)
        return out, times, graph.error(result)

    def graph(self, poses, dts, speed, points, moving, local, final: bool):
        """The factor graph and initial values of the band (see the module docstring)."""
        c, r = self.cfg, self.robot
        n = len(poses)
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        for i, p in enumerate(poses):
            values.insert(X(i), gtsam.Pose2(*p))
        for i, dt in enumerate(dts):
            values.insert(T(i), np.array([dt]))  # a 1-vector: inserted and read far faster than a double
        graph.add(gtsam.PriorFactorPose2(X(0), gtsam.Pose2(*poses[0]), gtsam.noiseModel.Isotropic.Sigma(3, 1e-4)))
        end_sigmas = np.array([0.01, 0.01, 1.0 if final else 0.2])
        graph.add(gtsam.PriorFactorPose2(X(n - 1), gtsam.Pose2(*poses[-1]), gtsam.noiseModel.Diagonal.Sigmas(end_sigmas)))
        kinds = [(time_residual, np.full(n - 1, c.time_weight))]  # (residual, weights (E,)): stacked into one
        # factor, so that an evaluation of the graph is one Python callback
        if (vias := self._vias(poses, local)) is not None:
            kinds.append((partial(via_residual, index=vias[0], vias=vias[1], tube=c.via_tube), np.full(2 * len(vias[0]), c.via_weight)))
        if len(points):
            at = np.concatenate([[0.0], np.cumsum(dts)])  # s, when the band reaches each pose
            grown = np.minimum(c.obstacle_speed * at, c.obstacle_reach)[:, None] * moving[None, :]
            near = r.radius + c.margin
            kinds.append((partial(obstacle_residual, points=points, grown=grown, near=near, soft=near + c.inflation),
                          np.repeat([c.obstacle_weight, c.inflation_weight], 2 * (n - 1))))  # fmt: skip
        limits = (-c.max_speed_back * (1 - c.epsilon), r.max_speed * (1 - c.epsilon))
        kinds.append((partial(velocity_residual, v_lo=limits[0], v_hi=limits[1], w_max=r.max_turn_rate * (1 - c.epsilon),
                              min_dt=c.min_dt),
                      np.repeat([c.velocity_weight, c.velocity_weight, 100 * c.velocity_weight], n - 1)))  # fmt: skip
        kinds.append((kinematics_residual, np.repeat([c.kinematics_weight, c.forward_weight], n - 1)))
        a_max, alpha_max = r.max_accel * (1 - c.epsilon), r.max_turn_accel * (1 - c.epsilon)
        end = np.zeros(2) if final else np.full(2, np.nan)
        kinds.append((partial(acceleration_residual, start=np.asarray(speed[:2], float), end=end, a_max=a_max,
                              alpha_max=alpha_max), np.full(2 * (n - 1 + final), c.acceleration_weight)))  # fmt: skip
        graph.add(band_factor(n, stacked([k[0] for k in kinds]), np.concatenate([k[1] for k in kinds]), True))
        return graph, values

    def _vias(self, poses, local):
        """(Band pose index (V,), via-point (V, 2) m): the path every ``via_spacing`` m up to the band's end, each
        on its nearest inner band pose; None for none."""
        s_end = _arc_length_at(local, poses[-1, :2])
        along = np.arange(self.cfg.via_spacing, s_end - 0.5 * self.cfg.via_spacing, self.cfg.via_spacing)
        if len(poses) < 3 or len(along) == 0:
            return None
        vias = np.array([point_along(local, s) for s in along])
        index = 1 + np.argmin(np.hypot(*(poses[None, 1:-1, :2] - vias[:, None]).transpose(2, 0, 1)), axis=1)
        return index, vias

    # the command --------------------------------------------------------------------------------------

    def _clear(self, poses, dts, points) -> bool:
        """Whether the disc, along the band's first ``check_time`` s (every 2 cm), keeps off every point
        (or, already closer, gets no closer)."""
        if len(points) == 0:
            return True
        at = np.concatenate([[0.0], np.cumsum(dts)])
        last = max(1, int(np.searchsorted(at, self.cfg.check_time, side="right")))
        xy = _densify(poses[: last + 1, :2], 0.02)
        tree = cKDTree(points)
        now = float(tree.query([0.0, 0.0])[0])
        return bool((tree.query(xy[1:])[0] >= min(self.robot.radius + 0.005, now - 1e-4)).all())

    def _first_command(self, poses, dts, velocity, points, moving) -> Command:
        """The band's (v, w) one period on, within what the robot reaches in one period, slowed (on the same arc)
        until it can still stop short of every point, a ``moving`` one's margin grown as in the band; braking
        and blocked when even the slowest reachable speed cannot."""
        r, period = self.robot, self.cfg.period
        v0, w0 = float(velocity[0]), float(velocity[1])
        v, w = _speeds_at(period, poses, dts, velocity)
        v = float(np.clip(v, v0 - r.max_accel * period, v0 + r.max_accel * period))
        v = float(np.clip(v, -self.cfg.max_speed_back, r.max_speed))
        w = float(np.clip(w, w0 - r.max_turn_accel * period, w0 + r.max_turn_accel * period))
        w = float(np.clip(w, -r.max_turn_rate, r.max_turn_rate))
        if len(points) == 0 or abs(v) <= 1e-3:
            return Command(v, w, False, "teb")
        slowest = max(abs(v0) - r.max_accel * period, 0.0)
        for speed in np.linspace(abs(v), slowest, 6) if abs(v) > slowest else [abs(v)]:
            if speed <= 1e-3 or self._stops_short(float(speed) * np.sign(v), w * speed / abs(v), points, moving):
                return Command(float(speed * np.sign(v)), w * speed / abs(v), False, "teb" if speed == abs(v) else "teb, slowed")
        self.band = None
        return self._brake(velocity, "stopping arc touches a point")

    def _stops_short(self, v: float, w: float, points, moving) -> bool:
        """Whether the disc, driving (v, w) for a period and then braking at full deceleration on the same arc,
        keeps off every point (a ``moving`` one's margin grown by ``obstacle_speed`` per second, up to
        ``obstacle_reach``); already closer than the radius + 5 mm to one, whether it gets no closer."""
        r, c = self.robot, self.cfg
        stop = c.period + abs(v) / r.max_accel
        times = np.linspace(0.02, stop, max(2, math.ceil(stop / 0.02)))
        braking = np.maximum(times - c.period, 0.0)
        travelled = abs(v) * times - 0.5 * r.max_accel * braking**2
        on = arcs(np.array([np.sign(v)]), np.array([w / abs(v)]), travelled)[0, :, :2]
        grow = np.minimum(c.obstacle_speed * times, c.obstacle_reach)
        for group, extra in ((points[~moving], 0.0), (points[moving], grow)):
            if len(group):
                tree = cKDTree(group)
                now = float(tree.query([0.0, 0.0])[0])
                if (tree.query(on)[0] - extra < min(r.radius + 0.005, now - 1e-4)).any():
                    return False
        return True

    def _brake(self, velocity, why: str) -> Command:
        """Full braking on the arc the robot is on, reported as blocked."""
        v0, w0 = float(velocity[0]), float(velocity[1])
        v = max(0.0, abs(v0) - self.robot.max_accel * self.cfg.period) * np.sign(v0)
        return Command(float(v), w0 * v / v0 if abs(v0) > 1e-9 else 0.0, True, why)

    def _turn(self, velocity, bearing: float) -> Command:
        """Braking while turning on the spot towards ``bearing`` (rad), within the turn acceleration."""
        r, period = self.robot, self.cfg.period
        v0, w0 = float(velocity[0]), float(velocity[1])
        v = max(0.0, abs(v0) - r.max_accel * period) * np.sign(v0)
        brake = math.sqrt(r.max_turn_accel * abs(bearing))  # stops within the bearing at half the accel
        w = math.copysign(min(r.max_turn_rate, brake), bearing)
        w = float(np.clip(w, w0 - r.max_turn_accel * period, w0 + r.max_turn_accel * period))
        return Command(float(v), w, False, "turn to path")


def _speeds_at(t: float, poses, dts, velocity) -> tuple[float, float]:
    """The band's (v m/s, w rad/s) at ``t`` s: linear between the robot's ``velocity`` now and each segment's
    speed at its middle (a segment's speed is its mean: the acceleration factors measure between these points).
    The first segment's speed itself, commanded at once, ran ahead of the band: the robot turned late, then
    too far, and wove."""
    v, w = segments(poses, dts)[:2]
    at = np.concatenate([[0.0], np.cumsum(dts) - 0.5 * dts])
    return tuple(float(np.interp(t, at, np.concatenate([[x0], x]))) for x0, x in zip(velocity[:2], (v, w)))


def _length(path: np.ndarray) -> float:
    """Length (m) of a polyline (L, 2)."""
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()) if len(path) > 1 else 0.0


def _arc_length_at(path: np.ndarray, xy) -> float:
    """Arc length (m) along ``path`` (L, 2) of its point nearest ``xy``."""
    if len(path) < 2:
        return 0.0
    a, b = path[:-1], path[1:]
    d = b - a
    seg = np.einsum("ij,ij->i", d, d)
    u = np.clip(np.einsum("ij,ij->i", np.asarray(xy) - a, d) / np.where(seg > 0, seg, 1.0), 0.0, 1.0)
    gap = np.hypot(*(a + u[:, None] * d - xy).T)
    k = int(np.argmin(gap))
    cum = np.concatenate([[0.0], np.cumsum(np.sqrt(seg))])
    return float(cum[k] + u[k] * math.sqrt(seg[k]))


def _densify(xy: np.ndarray, step: float, with_index: bool = False):
    """The polyline ``xy`` (K, 2) with points inserted so that none are more than ``step`` m apart; with
    ``with_index`` also the index (P,) of the vertex each point follows (the segment it lies on)."""
    seg = np.diff(xy, axis=0)
    counts = np.maximum(1, np.ceil(np.hypot(seg[:, 0], seg[:, 1]) / step)).astype(np.int64)
    owner = np.repeat(np.arange(len(seg)), counts)
    frac = (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts) + 1) / counts[owner]
    out = np.vstack([xy[:1], xy[owner] + frac[:, None] * seg[owner]])
    return (out, np.concatenate([[0], owner])) if with_index else out
