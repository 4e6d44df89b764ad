"""The 2016 patrol-robot thesis's obstacle-avoidance state machine (§6.3), following a path.

The latest scan is checked in four overlapping sectors centred on the heading,
each with its own distance (an obstacle within it sets the sector's bit):

====================  =======  ===============
sector                width    distance
====================  =======  ===============
straight ahead        30°      far
front                 60°      fairly far
front periphery       120°     medium
periphery             180°     near
====================  =======  ===============

State = 16·stuck + 8·ahead30 + 4·front60 + 2·periph120 + 1·periph180, and the
state picks the action (Fig. 23, with state 11 as Straight):

- Straight: forward at constant speed. The thesis's robot explores without a
  goal; here it steers towards the carrot on the path, turning on the spot
  first when the carrot is more than ``aim_angle`` off the heading.
- Find the farthest reachable direction: keep moving forward, slowly, while
  turning towards it. With ``goal_bias`` the direction is the open beam
  (free to ``far``, wide enough for the robot) nearest the carrot's bearing,
  else the beam with the longest range (the thesis).
- U-turn: turn while moving forward, towards the side with more room.
- Reverse: stop, turn 180° on the spot (latched until done), then go forward.
- Stuck alarm: less than ``stuck_distance`` of displacement for ``stuck_time``
  (outside the latched Reverse turn); reported as ``blocked`` so that the
  navigator's recovery (back off, replan, turn) tries the other actions.

Speeds are lowered to the one that stops at the goal; nothing else is added,
so this stays the paper's baseline, not a safe planner.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from slam2d import geometry
from slam2d.config import Section
from slam2d.navigation.base import register_local_planner
from slam2d.navigation.common import Command, approach_speed, in_robot_frame, path_ahead, point_along
from slam2d.sim.robot import RobotConfig

__all__ = ["FsmConfig", "AvoidanceStateMachine", "SECTOR_WIDTHS_DEG", "ACTIONS", "sector_bits", "state_code"]

SECTOR_WIDTHS_DEG = (30.0, 60.0, 120.0, 180.0)
"""Full widths of the sectors (ahead, front, front periphery, periphery), degrees."""

STRAIGHT, FARTHEST, U_TURN, REVERSE, STUCK = "straight", "farthest", "u-turn", "reverse", "stuck"
ACTIONS = (
    [STRAIGHT, STRAIGHT, FARTHEST, STRAIGHT, STRAIGHT, FARTHEST, FARTHEST, STRAIGHT]
    + [FARTHEST, FARTHEST, FARTHEST, STRAIGHT, FARTHEST, STRAIGHT, U_TURN, REVERSE]
    + [STUCK] * 16
)
"""Action of each state code 0-31 (the thesis's Fig. 23; state 11 Straight as its table says)."""


class FsmConfig(Section):
    """Sector distances (m from the laser at the robot's centre), speeds and stuck detection."""

    far: float = Field(1.2, gt=0, description="m, straight-ahead sector (30°)")
    fairly_far: float = Field(0.9, gt=0, description="m, front sector (60°)")
    medium: float = Field(0.6, gt=0, description="m, front-periphery sector (120°)")
    near: float = Field(0.4, gt=0, description="m, periphery sector (180°)")
    cruise: float = Field(0.5, gt=0, description="m/s, the constant speed of Straight")
    slow: float = Field(0.15, ge=0, description="m/s, forward speed while turning")
    turn_rate: float = Field(1.2, gt=0, description="rad/s, turning in U-turn and Reverse")
    gain: float = Field(2.0, gt=0, description="1/s, turn rate per rad of heading error")
    aim_angle: float = Field(1.0, gt=0, description="rad, carrot bearing beyond which Straight turns on the spot")
    lookahead: float = Field(0.8, gt=0, description="m along the path to the carrot")
    decel: float = Field(0.5, gt=0, le=1, description="fraction of max_accel planned for stopping at the goal")
    goal_bias: bool = Field(True, description="farthest direction: the open one nearest the carrot")
    period: float = Field(0.1, gt=0, description="s between calls (the control period)")
    stuck_time: float = Field(3.0, gt=0, description="s without stuck_distance of displacement -> stuck")
    stuck_distance: float = Field(0.05, gt=0, description="m")


def sector_bits(points, cfg: FsmConfig) -> np.ndarray:
    """Bits (4,) bool (ahead30, front60, periph120, periph180): an obstacle point (M, 2),
    robot frame, within the sector's width and distance."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    bearing = np.abs(np.arctan2(p[:, 1], p[:, 0]))
    rng = np.hypot(p[:, 0], p[:, 1])
    half = np.deg2rad(SECTOR_WIDTHS_DEG) / 2
    limits = np.array([cfg.far, cfg.fairly_far, cfg.medium, cfg.near])
    return ((bearing[None] <= half[:, None]) & (rng[None] <= limits[:, None])).any(axis=1)


def state_code(bits, stuck: bool = False) -> int:
    """State index 16·stuck + 8·ahead30 + 4·front60 + 2·periph120 + 1·periph180."""
    b = [bool(x) for x in bits]
    return 16 * bool(stuck) + 8 * b[0] + 4 * b[1] + 2 * b[2] + 1 * b[3]


@register_local_planner("fsm", config=FsmConfig)
class AvoidanceStateMachine:
    """The thesis's avoidance state machine as a local planner (see the module docstring)."""

    def __init__(self, robot: RobotConfig | None = None, config: FsmConfig | None = None):
        self.robot, self.cfg = robot or RobotConfig(), config or FsmConfig()
        self.reset()

    def reset(self) -> None:
        """Forget the latched Reverse turn and the stuck watch."""
        self._turn_left = 0.0  # rad still to turn in Reverse (signed)
        self._last_heading = None
        self._watch = None  # (time, xy) where the robot was when last seen moving
        self._clock = 0.0
        self.state = 0
        self.action = STRAIGHT

    def command(self, pose, velocity, points, path, unmapped=None) -> Command:
        """Command of the current state's action; ``blocked`` on the stuck alarm (``unmapped``
        is not used: the thesis's sectors treat every point alike)."""
        pose = np.asarray(pose, dtype=np.float64)
        points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        path = path_ahead(path, pose)
        stuck = self._stuck(pose)
        self.state = state_code(sector_bits(points, self.cfg), stuck)
        if self._turn_left and not stuck:
            return self._continue_reverse(pose)
        self.action = ACTIONS[self.state]
        carrot = in_robot_frame(pose, point_along(path, self.cfg.lookahead))
        speed = min(self.cfg.cruise, self._goal_speed(path))
        if self.action == STRAIGHT:
            return self._straight(carrot, speed)
        if self.action == FARTHEST:
            return self._farthest(points, carrot, speed)
        if self.action == U_TURN:
            return Command(min(self.cfg.slow, speed), self._freer_side(points) * self.cfg.turn_rate, False, U_TURN)
        if self.action == REVERSE:
            self._turn_left, self._last_heading = self._freer_side(points) * np.pi, pose[2]
            return self._continue_reverse(pose)
        self._watch = None
        return Command(0.0, 0.0, True, STUCK)

    def _goal_speed(self, path) -> float:
        left = float(np.linalg.norm(np.diff(np.asarray(path).reshape(-1, 2), axis=0), axis=1).sum())
        return approach_speed(left, self.cfg.decel * self.robot.max_accel)

    def _stuck(self, pose: np.ndarray) -> bool:
        """No ``stuck_distance`` of displacement within ``stuck_time`` (the clock runs a period a call)."""
        self._clock += self.cfg.period
        if self._watch is None or np.hypot(*(pose[:2] - self._watch[1])) > self.cfg.stuck_distance:
            self._watch = (self._clock, pose[:2].copy())
            return False
        return self._clock - self._watch[0] > self.cfg.stuck_time and not self._turn_left

    def _straight(self, carrot: np.ndarray, speed: float) -> Command:
        alpha = float(np.arctan2(carrot[1], carrot[0]))
        w = float(np.clip(self.cfg.gain * alpha, -self.robot.max_turn_rate, self.robot.max_turn_rate))
        if abs(alpha) > self.cfg.aim_angle:
            return Command(0.0, w, False, STRAIGHT)
        return Command(speed * float(np.cos(alpha)), w, False, STRAIGHT)

    def _farthest(self, points: np.ndarray, carrot: np.ndarray, speed: float) -> Command:
        alpha = self.farthest_direction(points, carrot)
        w = float(np.clip(self.cfg.gain * alpha, -self.robot.max_turn_rate, self.robot.max_turn_rate))
        return Command(min(self.cfg.slow, speed), w, False, FARTHEST)

    def farthest_direction(self, points: np.ndarray, carrot=None) -> float:
        """Bearing (rad, robot frame) to turn to: the open beam nearest the carrot, or the farthest point."""
        if len(points) == 0:
            return 0.0 if carrot is None else float(np.arctan2(carrot[1], carrot[0]))
        bearing = np.arctan2(points[:, 1], points[:, 0])
        rng = np.hypot(points[:, 0], points[:, 1])
        if self.cfg.goal_bias and carrot is not None:
            open_ = self._open_bearings(points)
            if len(open_):
                goal = np.arctan2(carrot[1], carrot[0])
                return float(open_[np.argmin(np.abs(geometry.wrap_angle(open_ - goal)))])
        return float(bearing[np.argmax(rng)])

    def _open_bearings(self, points: np.ndarray) -> np.ndarray:
        """Bearings (rad) of candidate headings (every 5°) along which a corridor of the robot's
        width is free of points to ``far``."""
        cand = np.deg2rad(np.arange(-180.0, 180.0, 5.0))
        d = np.stack([np.cos(cand), np.sin(cand)], axis=1)  # (C, 2)
        along = points @ d.T  # (M, C)
        across = np.abs(points @ np.stack([-d[:, 1], d[:, 0]], axis=1).T)
        blocking = (along > 0) & (along < self.cfg.far) & (across < self.robot.radius + 0.05)
        return cand[~blocking.any(axis=0)]

    def _freer_side(self, points: np.ndarray) -> float:
        """+1 (left) or -1 (right): the side whose nearest point within ``far`` is farther."""
        rng = np.hypot(points[:, 0], points[:, 1]) if len(points) else np.zeros(0)
        left = rng[(points[:, 1] > 0) & (rng < self.cfg.far)] if len(points) else rng
        right = rng[(points[:, 1] <= 0) & (rng < self.cfg.far)] if len(points) else rng
        lmin = left.min() if len(left) else np.inf
        rmin = right.min() if len(right) else np.inf
        return 1.0 if lmin >= rmin else -1.0

    def _continue_reverse(self, pose: np.ndarray) -> Command:
        """Turn on the spot until the latched half turn is done."""
        turned = float(geometry.wrap_angle(pose[2] - self._last_heading))
        self._last_heading = pose[2]
        left = self._turn_left - turned
        self._turn_left = 0.0 if left * np.sign(self._turn_left) <= 0.05 else left
        w = float(np.sign(left) * min(self.cfg.turn_rate, self.cfg.gain * abs(left)))
        return Command(0.0, w if self._turn_left else 0.0, False, REVERSE)
