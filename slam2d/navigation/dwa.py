"""Dynamic window approach (Fox, Burgard & Thrun 1997) following a global path.

Every call samples (v, w) in the dynamic window (velocities reachable within
one control period under the acceleration limits), simulates each as a
constant-velocity arc over a horizon, and measures the arcs against the laser's
hit points in the robot frame, so obstacles the map lacks count as much as walls.
An arc is admissible when the robot, after one period at (v, w) and braking at
full deceleration, stops before its disc (radius + margin) would touch a point.
Admissible arcs are scored by

- heading: the heading towards the carrot (a point ``lookahead`` metres along
  the path, nearer where the robot is close to a point: see ``TIGHT``) at the arc's end, or where it comes closest to the carrot if it
  passes it,
- progress: how much closer to the carrot the arc comes,
- path: how far beyond ``path_band`` from the path that closest point lies,
- clearance: the closest approach to any point along the arc (capped),
- velocity: closeness to the target speed (full speed, lowered where the path
  ahead bends away from the heading and near the goal to the speed that stops there),

and the best is returned. Each arc sample's nearest laser point comes from a k-d tree
of the points: no Python loop over samples or beams.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field
from scipy.spatial import cKDTree

from slam2d.config import Section
from slam2d.navigation.base import register_local_planner
from slam2d.navigation.common import Command, approach_speed, in_robot_frame, path_ahead, point_along
from slam2d.sim.robot import RobotConfig

__all__ = ["DwaConfig", "DynamicWindow", "arcs"]

_SQUEEZE = 0.02  # m, closest an arc passing by may bring the robot's disc to a point within the margin
_PASSING = 0.1  # m/s; arcs along the path slower than this stay short of a passage: no reference for the margin
TIGHT = (0.2, 0.3)  # m; with less clearance than the first, the carrot comes in, down to the second at none


class DwaConfig(Section):
    """Dynamic-window sampling, horizon, safety margin and score weights."""

    period: float = Field(0.1, gt=0, description="s, control period: the window's width and the command's duration")
    horizon: float = Field(1.5, gt=0, description="s, how far ahead each arc is simulated")
    steps: int = Field(15, ge=2, le=1000, description="trajectory samples per arc")
    v_samples: int = Field(9, ge=2, le=1000)
    w_samples: int = Field(21, ge=3, le=1000)
    margin: float = Field(0.05, ge=0, description="m, kept between the robot's disc and any laser point")
    lookahead: float = Field(0.8, gt=0, description="m along the path to the carrot")
    decel: float = Field(0.5, gt=0, le=1, description="fraction of max_accel planned for stopping at the goal")
    clearance_cap: float = Field(0.6, gt=0, description="m, clearance beyond which an arc scores no better")
    heading_weight: float = Field(1.0, ge=0)
    progress_weight: float = Field(1.5, ge=0)
    path_weight: float = Field(1.0, ge=0)
    clearance_weight: float = Field(0.4, ge=0)
    margin_weight: float = Field(0.0, ge=0, description="score lost by an arc coming the margin's width farther within "
                                 "it than the arc along the path that comes least within it (a tight passage: its "
                                 "middle); exploration's tight stretches use 3")
    velocity_weight: float = Field(0.6, ge=0)
    obstacle_speed: float = Field(0.8, ge=0, description="m/s assumed for points the map does not explain")
    obstacle_reach: float = Field(0.5, ge=0, description="m, the most such a point's margin grows along an arc")
    path_band: float = Field(0.1, ge=0, description="m from the path within which straying costs nothing")


def arcs(v, w, times) -> np.ndarray:
    """Poses (S, K, 3) in the start frame after ``times`` (K,) s at constant ``v`` (S,) m/s, ``w`` (S,) rad/s."""
    v, w, t = np.asarray(v)[:, None], np.asarray(w)[:, None], np.asarray(times)[None, :]
    turn = w * t
    chord = v * t * np.sinc(turn / (2 * np.pi))  # arc length x sin(turn / 2) / (turn / 2)
    return np.stack([chord * np.cos(turn / 2), chord * np.sin(turn / 2), turn], axis=-1)


@register_local_planner("dwa", config=DwaConfig)
class DynamicWindow:
    """DWA local planner for a robot with :class:`RobotConfig` limits (see the module docstring)."""

    def __init__(self, robot: RobotConfig | None = None, config: DwaConfig | None = None):
        self.robot, self.cfg = robot or RobotConfig(), config or DwaConfig()
        self.times = np.linspace(self.cfg.horizon / self.cfg.steps, self.cfg.horizon, self.cfg.steps)
        self.lookahead = self.cfg.lookahead  # m, the carrot's distance in the last call

    def reset(self) -> None:
        """DWA keeps no manoeuvre between calls."""

    def window(self, velocity) -> tuple[np.ndarray, np.ndarray]:
        """Sampled (v, w) pairs (S,) each: the grid over the dynamic window (forward speeds only)."""
        r, dt = self.robot, self.cfg.period
        v0, w0 = float(velocity[0]), float(velocity[1])
        v_lo, v_hi = max(0.0, v0 - r.max_accel * dt), min(r.max_speed, max(0.0, v0 + r.max_accel * dt))
        w_lo, w_hi = max(-r.max_turn_rate, w0 - r.max_turn_accel * dt), min(r.max_turn_rate, w0 + r.max_turn_accel * dt)
        vs = np.unique(np.concatenate([np.linspace(v_lo, v_hi, self.cfg.v_samples), [v_lo]]))
        ws = np.unique(np.concatenate([np.linspace(w_lo, w_hi, self.cfg.w_samples), np.clip([0.0], w_lo, w_hi)]))
        vv, ww = np.meshgrid(vs, ws, indexing="ij")
        return vv.ravel(), ww.ravel()

    def command(self, pose, velocity, points, path, unmapped=None) -> Command:
        """Best admissible (v, w) towards the path; ``blocked`` when no forward arc is admissible.

        ``unmapped`` (M,) bool marks points the map does not explain (people, new furniture):
        they may be moving, so their margin grows by ``obstacle_speed`` per second along the
        arcs, up to ``obstacle_reach``.
        """
        pose = np.asarray(pose, dtype=np.float64)
        path = path_ahead(path, pose)
        points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        d2 = np.einsum("ij,ij->i", points, points)  # m^2 from the robot's centre
        self.lookahead = self._lookahead(d2)
        v, w = self.window(velocity)
        v, w = self._with_pursuit(v, w, pose, path)
        traj = arcs(v, w, self.times)
        unmapped = np.zeros(len(points), bool) if unmapped is None else np.asarray(unmapped, bool).reshape(-1)
        within = d2 < self._reach(v.max()) ** 2  # points that can matter to an arc
        dist = self._distances(traj, points[within], unmapped[within])
        # a point that may move near the arcs: no squeezing along the path
        off_path = self._off_path(traj, pose, path)
        on_path = (off_path <= self.cfg.margin) & ~(unmapped & within).any()
        ok, clearance = self._admissible(v, dist, on_path)
        score = self._scores(v, traj, clearance, pose, path)
        if self.cfg.margin_weight > 0:
            along = ok & (v > 1e-3) & (off_path <= self.cfg.path_band)  # moving arcs along the path
            score -= self.cfg.margin_weight * self._within_margin(dist, along, v)
        score[~ok] = -np.inf
        forward = ok & (v > 1e-3)
        if not ok.any():
            return self._brake(velocity)
        best = int(np.argmax(score))
        return Command(float(v[best]), float(w[best]), not forward.any(), "dwa")

    def _brake(self, velocity) -> Command:
        """No admissible arc: full braking on the arc the robot is on (its turn rate falls with its
        speed), the stop every arc was checked with; a plain stop would let the turn rate fall faster
        than the speed and run the robot straight on."""
        v0, w0 = float(velocity[0]), float(velocity[1])
        v = max(0.0, v0 - self.robot.max_accel * self.cfg.period)
        return Command(v, w0 * v / v0 if v0 > 1e-9 else 0.0, True, "no admissible arc")

    def _lookahead(self, d2: np.ndarray) -> float:
        """Carrot distance (m): ``lookahead``, or in a tight spot (clearance below ``TIGHT[0]``, from the
        points' squared distances ``d2`` (M,) m^2) nearer, linearly down to ``TIGHT[1]``, so that the arcs
        follow the path rather than cut its bends."""
        gap = float(np.sqrt(d2.min())) - self.robot.radius if len(d2) else np.inf
        near, least = TIGHT
        return float(np.clip(least + (self.cfg.lookahead - least) * gap / near, least, self.cfg.lookahead))

    def _with_pursuit(self, v, w, pose, path):
        """Adds the pure-pursuit command towards the carrot (clipped to the window) to the samples."""
        carrot = in_robot_frame(pose, point_along(path, self.lookahead))
        d = float(np.hypot(*carrot))
        alpha = float(np.arctan2(carrot[1], carrot[0]))
        vp = self._target_speed(pose, path)
        wp = 2.0 * vp * np.sin(alpha) / max(d, 1e-6) if vp > 0 else 2.0 * alpha
        vp, wp = np.clip(vp, v.min(), v.max()), np.clip(wp, w.min(), w.max())
        return np.append(v, vp), np.append(w, wp)

    def _target_speed(self, pose, path) -> float:
        """Speed (m/s) to aim for: full speed, lowered where the path ahead bends away from the
        heading (cosine of the larger bearing to the carrot and to a point twice as far), and
        the speed that stops at the goal (the path's end)."""
        left = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
        marks = [point_along(path, self.lookahead), point_along(path, 2 * self.lookahead)]
        ahead = in_robot_frame(pose, np.stack(marks))
        bend = np.abs(np.arctan2(ahead[:, 1], ahead[:, 0]))
        bend = bend[np.hypot(*ahead.T) > 0.05].max(initial=0.0)
        turn = self.robot.max_speed * max(float(np.cos(bend)), 0.0)
        return min(turn, approach_speed(left, self.cfg.decel * self.robot.max_accel))

    def _distances(self, traj: np.ndarray, near: np.ndarray, moving: np.ndarray) -> np.ndarray:
        """Distance (S, K + 1) m from the robot's centre on each arc sample (now first) to the nearest
        of the points ``near`` (M, 2), every one of them (thinning them let an arc through a corner
        pass), less the grown margin of ``moving`` (unmapped) ones."""
        s, k = traj.shape[:2]
        if len(near) == 0:
            return np.full((s, k + 1), np.inf)
        flat = traj[:, :, :2].reshape(-1, 2)
        along = np.full((s, k), np.inf)
        for group, grow in ((near[~moving], 0.0), (near[moving], self._growth())):
            if len(group):
                along = np.minimum(along, cKDTree(group).query(flat)[0].reshape(s, k) - grow)
        now = np.full(s, np.sqrt(np.einsum("ij,ij->i", near, near).min()))
        return np.column_stack([now, along])

    def _growth(self) -> np.ndarray:
        """Margin (K,) m an unmapped point has grown by at each trajectory sample time."""
        return np.minimum(self.cfg.obstacle_speed * self.times, self.cfg.obstacle_reach)

    def _admissible(self, v: np.ndarray, dist: np.ndarray, on_path: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Whether each arc stops before its disc touches a point, and its clearance (S,) m.

        Where the robot is already within the margin, an arc is safe while it gets no closer,
        or, if it ends farther away than it starts (passing by) or keeps to the global path
        within the margin (``on_path`` (S,): planned where the disc fits, through a passage narrower
        than the margin if need be; not with a point that may move nearby), while it keeps ``_SQUEEZE``.
        """
        r, now = self.robot.radius, dist[:, 0]
        passing = (dist[:, -1] >= now) | on_path
        closer = np.where(passing, np.minimum(r + _SQUEEZE, now - 1e-4), now - 1e-4)
        limit = np.minimum(r + self.cfg.margin, closer)
        hit = dist[:, 1:] < limit[:, None]
        first = np.where(hit.any(axis=1), hit.argmax(axis=1), len(self.times))
        free_time = np.concatenate([[0.0], self.times])[first]  # last sample before the hit
        stop = v * self.cfg.period + v**2 / (2 * self.robot.max_accel)
        ok = (stop <= v * free_time) | (v <= 1e-9)
        return ok, dist.min(axis=1) - r

    def _within_margin(self, dist: np.ndarray, along: np.ndarray, v: np.ndarray) -> np.ndarray:
        """How much farther (S,) each arc's disc comes within the margin of a point ahead than the arc ``along``
        (S,) the path (moving, within ``path_band`` of it) that comes least within it, as a fraction of the margin;
        of the arcs along the path only those at ``_PASSING`` m/s or more (``v`` (S,) m/s; or the fastest there
        are): in a passage narrower than the disc + twice the margin the arcs along its middle lose nothing, and
        neither a stop, turning away nor a crawl that stays short of the passage within the horizon gains anything
        over driving through it slowly."""
        if self.cfg.margin <= 0 or not along.any():
            return np.zeros(len(dist))
        within = np.clip(1.0 - (dist[:, 1:].min(axis=1) - self.robot.radius) / self.cfg.margin, 0.0, 1.0)
        passing = along & (v >= min(_PASSING, v[along].max()) - 1e-9)
        return np.maximum(within - within[passing].min(), 0.0)

    def _reach(self, v_max: float) -> float:
        """Distance (m) within which points can matter to an arc."""
        c = self.cfg
        return v_max * c.horizon + self.robot.radius + c.margin + c.obstacle_reach + 0.1

    def _off_path(self, traj, pose, path) -> np.ndarray:
        """How far (S,) m the farthest sample of each arc lies from the path ahead (inf: no path within reach)."""
        local = in_robot_frame(pose, path)
        reach = self.robot.max_speed * self.cfg.horizon + self.cfg.margin
        local = local[np.einsum("ij,ij->i", local, local) < reach**2]
        if len(local) == 0:
            return np.full(len(traj), np.inf)
        gap = cKDTree(local).query(traj[:, :, :2].reshape(-1, 2))[0].reshape(traj.shape[:2])  # (S, K) m
        return gap.max(axis=1)

    def _scores(self, v, traj, clearance, pose, path) -> np.ndarray:
        """Weighted score (S,) of every arc (higher is better)."""
        c, vmax = self.cfg, self.robot.max_speed
        local = in_robot_frame(pose, path)
        carrot = in_robot_frame(pose, point_along(path, self.lookahead))
        gap = np.hypot(traj[..., 0] - carrot[0], traj[..., 1] - carrot[1])  # (S, K)
        closest = np.where(gap[:, -1] <= gap.min(axis=1) + 1e-3, gap.shape[1] - 1, gap.argmin(axis=1))
        near = traj[np.arange(len(traj)), closest]  # where each arc comes closest to the carrot (or its end)
        window = local[np.einsum("ij,ij->i", local, local) < (self.lookahead + vmax * c.horizon) ** 2]
        window = window if len(window) else local[-1:]
        off = np.sqrt(((near[:, None, :2] - window[None]) ** 2).sum(-1).min(axis=1))
        to_carrot = carrot - near[:, :2]
        bearing = np.arctan2(to_carrot[:, 1], to_carrot[:, 0]) - near[:, 2]
        heading = 1.0 - np.abs(np.angle(np.exp(1j * bearing))) / np.pi
        heading = np.where(gap.min(axis=1) < 0.05, 1.0, heading)  # at the carrot, any heading
        progress = (np.hypot(*carrot) - gap.min(axis=1)) / (vmax * c.horizon)
        velocity = 1.0 - np.abs(v - self._target_speed(pose, path)) / vmax
        stray = np.maximum(off - c.path_band, 0.0) / 0.5
        return (c.heading_weight * heading + c.progress_weight * progress - c.path_weight * stray
                + c.clearance_weight * np.clip(clearance, 0, c.clearance_cap) / c.clearance_cap
                + c.velocity_weight * velocity)  # fmt: skip
