"""The timed elastic band: every factor's Jacobian against a numerical derivative, a band round one
obstacle within its clearance and limits, and a closed-loop run past an obstacle the map lacks."""

from __future__ import annotations

from functools import partial

import gtsam
import numpy as np
import pytest

from slam2d.navigation import (
    NavigatorConfig,
    TimedElasticBand,
    run_navigation,
    world_grid,
)
from slam2d.navigation.config import navigator_config
from slam2d.navigation.teb_factors import (
    T,
    X,
    acceleration_residual,
    band_factor,
    kinematics_residual,
    obstacle_residual,
    segments,
    time_residual,
    velocity_residual,
    via_residual,
)
from slam2d.sim import Robot, RobotConfig, World

# a band of 5 poses, fast, turning and with one segment backwards: the limits' factors are active
BAND = np.array([[0.0, 0.0, 0.0], [0.45, 0.06, 0.3], [0.8, 0.3, 0.9], [0.7, 0.45, 1.6], [1.1, 0.9, 1.1]])
DTS = np.array([0.3, 0.25, 0.4, 0.2])
POINTS = np.array([[0.5, 0.35], [0.3, -0.2], [1.0, 0.5], [0.45, 0.8], [3.0, 3.0]])

RESIDUALS = {
    "via": (partial(via_residual, index=np.array([1, 2, 3]), vias=np.array([[0.5, 0.0], [0.9, 0.2], [0.6, 0.6]]),
                    tube=0.0), False),
    "via, tube": (partial(via_residual, index=np.array([1, 2, 3]), vias=np.array([[0.3, 0.0], [0.9, 0.2], [0.6, 0.6]]),
                          tube=0.15), False),
    "obstacle": (partial(obstacle_residual, points=POINTS, grown=np.tile([0.0, 0.0, 0.1, 0.0, 0.0], (5, 1)),
                         near=0.25, soft=0.5), False),
    "velocity": (partial(velocity_residual, v_lo=-0.2, v_hi=1.0, w_max=2.0, min_dt=0.22), True),
    "kinematics": (kinematics_residual, False),
    "time": (time_residual, True),
    "acceleration": (partial(acceleration_residual, start=np.array([0.8, -0.5]), end=np.zeros(2), a_max=1.0,
                             alpha_max=3.0), True),
    "acceleration, open end": (partial(acceleration_residual, start=np.array([0.2, 0.0]), end=np.full(2, np.nan),
                                       a_max=1.0, alpha_max=3.0), True),
}  # fmt: skip


def band_values(poses, dts) -> gtsam.Values:
    values = gtsam.Values()
    for i, p in enumerate(poses):
        values.insert(X(i), gtsam.Pose2(*p))
    for i, dt in enumerate(dts):
        values.insert(T(i), np.array([dt]))
    return values


@pytest.mark.parametrize("name", list(RESIDUALS))
def test_factor_jacobians_match_numerical_derivatives(name):
    """Each factor's analytic Jacobian (in the poses' tangent spaces, through GTSAM's linearisation) equals
    central differences of its whitened error under ``retract``; the factor is active (non-zero error)."""
    residual, timed = RESIDUALS[name]
    factor = band_factor(len(BAND), residual, np.ones(len(residual(BAND, DTS)[0])), timed)
    values = band_values(BAND, DTS)
    analytic = factor.linearize(values).jacobian()[0]  # whitened (weights 1: the error's own Jacobian)
    e0 = factor.unwhitenedError(values)
    assert np.abs(e0).sum() > 0.05
    h, columns = 1e-6, []
    for key in list(factor.keys()):
        dims = 3 if gtsam.Symbol(key).chr() == ord("x") else 1
        for k in range(dims):
            plus, minus = gtsam.Values(values), gtsam.Values(values)
            if dims == 3:
                step = np.eye(3)[k] * h
                plus.update(key, values.atPose2(key).retract(step))
                minus.update(key, values.atPose2(key).retract(-step))
            else:
                plus.update(key, values.atVector(key) + h)
                minus.update(key, values.atVector(key) - h)
            columns.append((factor.unwhitenedError(plus) - factor.unwhitenedError(minus)) / (2 * h))
    numeric = np.column_stack(columns)
    np.testing.assert_allclose(analytic, numeric, atol=1e-5, rtol=1e-4)


def test_segment_speeds_are_signed_by_the_heading():
    v, w, _, _ = segments(np.array([[0.0, 0.0, 0.0], [-0.3, 0.0, 0.6]]), np.array([0.5]))
    assert v[0] == pytest.approx(-0.6) and w[0] == pytest.approx(1.2)


def band_limits(poses, dts):
    """(Speeds (n - 1,), turn rates, accelerations, angular accelerations) of a band."""
    v, w, _, _ = segments(poses, dts)
    mid = (dts[1:] + dts[:-1]) / 2
    return v, w, np.diff(v) / mid, np.diff(w) / mid


def test_band_round_one_obstacle_keeps_its_clearance_and_the_limits():
    """A box 1.5 m ahead on the straight path: the optimised band goes round it, keeping the disc + margin
    off every point of it (within 1 cm), and every segment within the speed and acceleration limits (+ 5 %)."""
    teb, robot = TimedElasticBand(), RobotConfig()
    edge = np.linspace(-0.15, 0.15, 13)
    box = np.vstack([np.column_stack([np.full(13, 1.35), edge]), np.column_stack([np.full(13, 1.65), edge]),
                     np.column_stack([1.5 + edge, np.full(13, -0.15)]), np.column_stack([1.5 + edge, np.full(13, 0.15)])])
    path = np.column_stack([np.linspace(0.0, 4.0, 81), np.zeros(81)])
    velocity = np.array([0.5, 0.0])
    teb.command(np.zeros(3), velocity, box, path)
    for _ in range(5):  # the warm-started band settles
        cmd = teb.command(np.zeros(3), velocity, box, path)
    assert not cmd.blocked and cmd.state == "teb"
    poses, dts = teb.band
    gap = np.hypot(*(poses[:, None, :2] - box[None]).transpose(2, 0, 1)).min(axis=1) - robot.radius
    assert gap.min() >= teb.cfg.margin - 0.01
    beside = np.abs(poses[:, 0] - 1.5) < 0.3
    assert beside.any() and (np.abs(poses[beside, 1]) > 0.15 + robot.radius).all()  # it goes round
    v, w, acc, alpha = band_limits(poses, dts)
    assert (v <= robot.max_speed * 1.05).all() and (v >= -teb.cfg.max_speed_back * 1.05).all()
    assert (np.abs(w) <= robot.max_turn_rate * 1.05).all()
    assert np.abs(acc).max() <= robot.max_accel * 1.05 and np.abs(alpha).max() <= robot.max_turn_accel * 1.05
    assert abs(cmd.v - velocity[0]) <= robot.max_accel * teb.cfg.period + 1e-9  # one period's reach


def test_band_reaches_full_speed_on_a_clear_path_and_stops_at_the_goal():
    """Time-optimal: on a clear straight 2 m to the goal the band speeds up at the acceleration limit
    (the first command) and ends at rest."""
    teb = TimedElasticBand()
    path = np.column_stack([np.linspace(0.0, 2.0, 41), np.zeros(41)])
    cmd = teb.command(np.zeros(3), np.zeros(2), np.empty((0, 2)), path)
    assert cmd.v == pytest.approx(teb.robot.max_accel * teb.cfg.period, rel=0.05)
    poses, dts = teb.band
    v, _, _, _ = segments(poses, dts)
    assert v.max() > 0.9 and poses[-1, :2] == pytest.approx([2.0, 0.0], abs=0.02)
    assert v[-1] <= teb.robot.max_accel * dts[-1] * 1.06  # it can stop within the last interval (a soft limit)


def test_the_first_segment_is_reachable_ramping_from_the_robots_velocity():
    """A segment's speed is its mean over the interval, reached ramping from the robot's speed now: the change
    from now to the first segment's middle is within the limits (as between two segments' middles). Turning
    right at 1 rad/s with the path turning left, the band used to ask twice the turn acceleration (measured
    over the whole first interval), which the command could not follow: it lagged the band and wove."""
    teb = TimedElasticBand()
    path = np.vstack([np.column_stack([np.arange(0.0, 0.8, 0.05), np.zeros(16)]),
                      np.column_stack([np.full(40, 0.8), np.arange(0.05, 2.05, 0.05)])])  # fmt: skip
    start = np.array([1.0, -1.0])
    teb.command(np.zeros(3), start, np.empty((0, 2)), path)
    poses, dts = teb.band
    v, w, _, _ = segments(poses, dts)
    half = dts[0] / 2
    assert abs(w[0] - start[1]) <= 1.05 * teb.robot.max_turn_accel * half
    assert abs(v[0] - start[0]) <= 1.05 * teb.robot.max_accel * half


def test_a_band_that_would_touch_a_point_brakes_and_reports_blocked():
    """A wall across a corridor 0.6 m ahead at full speed: no band gets through; braking, blocked."""
    teb = TimedElasticBand()
    wall = np.column_stack([np.full(41, 0.6), np.linspace(-1.0, 1.0, 41)])
    path = np.column_stack([np.linspace(0.0, 3.0, 61), np.zeros(61)])
    cmd = teb.command(np.zeros(3), np.array([1.0, 0.0]), wall, path)
    assert cmd.blocked and cmd.v == pytest.approx(1.0 - teb.robot.max_accel * teb.cfg.period)


def test_teb_section_is_validated_with_the_navigation_options():
    cfg = navigator_config({"planner": "teb", "teb": {"horizon": 2.0}}, slam=False)
    assert cfg.planner == "teb" and cfg.teb.horizon == 2.0
    with pytest.raises(Exception, match="navigation.options"):
        navigator_config({"teb": {"horizon": -1.0}}, slam=False)


def test_teb_drives_round_a_box_the_map_lacks_to_its_goal():
    """A 10 m x 4 m hall with a box on the straight line the map does not hold: the TEB reaches the goal
    without contact, goes round the box, within 3 cm of the goal (the rate, wall-clock on a shared machine,
    is measured by the benchmark; here only a floor far below it)."""
    world = World.from_polygons([[(0, 0), (10, 0), (10, 4), (0, 4)]], name="hall")
    grid = world_grid(world)
    boxed = World.from_polygons([[(0, 0), (10, 0), (10, 4), (0, 4)], [(4.7, 1.7), (5.3, 1.7), (5.3, 2.3), (4.7, 2.3)]],
                                name="hall with a box")  # fmt: skip
    robot = Robot(boxed, [1.0, 2.0, 0.0], seed=2)
    result = run_navigation(boxed, robot, grid, [9.0, 2.0], "teb", NavigatorConfig(max_time=40.0))
    assert result.success and result.collisions == 0 and result.min_clearance > 0.0
    passing = result.trajectory[np.abs(result.trajectory[:, 0] - 5.0) < 0.05]
    assert np.abs(passing[:, 1] - 2.0).min() > 0.3 + robot.cfg.radius  # it went round
    assert result.goal_error <= 0.03
    assert result.planner_hz >= 5.0


def test_a_path_far_off_the_heading_is_turned_to_on_the_spot_then_driven_straight():
    """Starting 1.5 rad off a straight path, the TEB turns on the spot (past turn_first, down to a quarter of
    it) and then drives: the way is within 1 % of the straight line (an arc from where turning stopped at
    turn_first was longer by up to 5 %)."""
    path = np.column_stack([np.linspace(0.0, 4.0, 81), np.zeros(81)])
    teb, pose, velocity, trajectory, index = TimedElasticBand(), np.array([0.0, 0.0, 1.5]), np.zeros(2), [], 0
    for _ in range(120):
        index += int(np.argmin(np.hypot(*(path[index : index + 40] - pose[:2]).T)))
        cmd = teb.command(pose, velocity, np.zeros((0, 2)), path[index:])
        velocity = np.array([cmd.v, cmd.w])
        for _ in range(10):  # a unicycle, 10 ms steps
            pose = pose + 0.01 * np.array([cmd.v * np.cos(pose[2]), cmd.v * np.sin(pose[2]), cmd.w])
        trajectory.append(pose[:2].copy())
        if np.hypot(*(pose[:2] - path[-1])) < 0.2:
            break
    trajectory = np.array(trajectory)
    assert np.hypot(*(trajectory[-1] - path[-1])) < 0.2
    length = np.hypot(*trajectory[0]) + np.linalg.norm(np.diff(trajectory, axis=0), axis=1).sum()
    assert length < 1.01 * np.hypot(*trajectory[-1])
    assert np.abs(trajectory[:, 1]).max() < 0.05


def test_a_path_replanned_in_grid_steps_from_the_robot_is_driven_straight():
    """With SLAM in the loop the path is replanned several times a second, each time from the robot's cell
    on an 8-connected grid: a 45 degree staircase of 5 cm cells to the line it prefers, here 0.15 m to
    one side and then the other. The band is free within ``via_tube`` of the path, so the robot drives on
    nearly straight (pulled onto each staircase it wove: 1 % longer, heading 0.15 rad rms)."""
    teb, pose, velocity, trajectory = TimedElasticBand(), np.zeros(3), np.zeros(2), []
    xs = np.arange(-2.0, 16.0, 0.05)
    walls = np.vstack([np.column_stack([xs, np.full_like(xs, 1.1)]), np.column_stack([xs, np.full_like(xs, -1.1)])])
    for k in range(200):
        if k % 3 == 0:
            line = 0.15 if (k // 3) % 2 else -0.15
            x0, y0 = np.round(pose[:2] / 0.05) * 0.05
            steps = np.arange(1, int((12.0 - x0) / 0.05))
            ys = np.where(steps <= round(abs(line - y0) / 0.05), y0 + np.sign(line - y0) * 0.05 * steps, line)
            path = np.vstack([pose[:2], np.column_stack([x0 + 0.05 * steps, ys])])
            teb.reset()
        c, s = np.cos(pose[2]), np.sin(pose[2])
        rel = walls - pose[:2]
        points = np.column_stack([rel @ [c, s], rel @ [-s, c]])
        nearest = int(np.argmin(np.hypot(*(path - pose[:2]).T)))
        cmd = teb.command(pose, velocity, points[np.hypot(*points.T) < 4.0], path[nearest:])
        velocity = np.array([cmd.v, cmd.w])
        for _ in range(10):  # a unicycle, 10 ms steps
            pose = pose + 0.01 * np.array([cmd.v * np.cos(pose[2]), cmd.v * np.sin(pose[2]), cmd.w])
        trajectory.append(pose.copy())
        if pose[0] > 11.0:
            break
    trajectory = np.array(trajectory)
    assert trajectory[-1, 0] > 11.0
    length = np.linalg.norm(np.diff(trajectory[:, :2], axis=0), axis=1).sum()
    assert length < 1.003 * np.hypot(*(trajectory[-1, :2] - trajectory[0, :2]))
    assert np.sqrt(np.mean(trajectory[:, 2] ** 2)) < 0.06


def test_a_path_joined_at_an_angle_is_driven_onto_without_weaving():
    """Joining a straight path 0.5-1.2 rad off it at full speed (as after a door or a replan), the command
    follows the band's own speed profile (linear from the robot's speed now to each segment's middle): the
    turn rate changes direction 12 times over the three joins. Commanding the first segment's mean speed at
    once ran ahead of the band, the robot overshot its turns and corrected back: 33 changes."""
    path = np.column_stack([np.arange(0.0, 12.0, 0.05), np.zeros(240)])
    changes = 0
    for heading in (0.5, 0.85, 1.2):
        teb, pose, velocity, turns = TimedElasticBand(), np.array([0.0, 0.0, heading]), np.array([1.0, 0.0]), []
        for _ in range(80):
            near = int(np.argmin(np.hypot(*(path - pose[:2]).T)))
            cmd = teb.command(pose, velocity, np.empty((0, 2)), np.vstack([pose[:2], path[near + 1 :]]))
            velocity = np.array([cmd.v, cmd.w])
            turns.append(cmd.w)
            for _ in range(10):  # a unicycle, 10 ms steps
                pose = pose + 0.01 * np.array([cmd.v * np.cos(pose[2]), cmd.v * np.sin(pose[2]), cmd.w])
        assert abs(pose[1]) < 0.05 and abs(pose[2]) < 0.05  # on the path, along it
        turns = np.array(turns)
        changes += int((np.diff(np.sign(turns[np.abs(turns) > 0.05])) != 0).sum())
    assert changes <= 15
