"""The drivable simulation: collisions, limits, determinism, moving obstacles, odometry, scans for ICP."""

from __future__ import annotations

import numpy as np
import pytest

from slam2d import geometry
from slam2d.config import LaserModel, OdometryNoise, SimulatorConfig
from slam2d.datasets.simulator import SimulatorSource
from slam2d.errors import InputError
from slam2d.frontends import create_frontend
from slam2d.sim import LoopingDisc, Robot, RobotConfig, WanderingDisc, World, scatter_wanderers
from slam2d.sim.robot import sample_odometry

NO_ODOM_NOISE = OdometryNoise(alpha1=0, alpha2=0, alpha3=0, alpha4=0)


@pytest.fixture(scope="module")
def hall() -> World:
    """A 10 m x 4 m room split at x = 5 by a wall of zero thickness from y = 0 to y = 2.5."""
    room = World.from_polygons([[(0, 0), (10, 0), (10, 4), (0, 4)]])
    return World(np.concatenate([room.segments, [[[5.0, 0.0], [5.0, 2.5]]]]), name="hall")


def drive(robot: Robot, commands, dt: float):
    return [robot.step(v, w, dt) for v, w in commands]


# --- collisions -----------------------------------------------------------------------------------


@pytest.mark.parametrize("dt", [0.05, 1.0, 20.0])
def test_driving_at_a_thin_wall_stops_at_contact_and_reports_it(hall, dt):
    cfg = RobotConfig(max_speed=2.0, max_accel=100.0)
    robot = Robot(hall, [2.0, 1.0, 0.0], cfg)
    results = drive(robot, [(2.0, 0.0)] * int(np.ceil(20.0 / dt)), dt)
    x = np.array([r.pose[0] for r in results])
    assert x.max() <= 5.0 - cfg.radius + 1e-9  # never through, never into the wall
    hits = [r.collision for r in results]
    assert any(hits) and all(hits[hits.index(True) :])  # pressing on: still in contact, no creeping
    assert results[-1].contact == "wall" and np.allclose(results[-1].velocity, 0.0)
    assert x[-1] == pytest.approx(5.0 - cfg.radius, abs=1e-9)
    back = robot.step(-1.0, 0.0, 0.5)  # backing off is free
    assert not back.collision and back.pose[0] < x[-1]


def test_contact_with_a_wall_end_and_on_an_arc_keeps_the_radius(hall):
    cfg = RobotConfig()
    robot = Robot(hall, [3.0, 2.6, 0.0], cfg)  # passes 0.1 m above the free end of the wall at (5, 2.5)
    hit = next(r for r in drive(robot, [(1.0, 0.0)] * 60, 0.1) if r.collision)
    assert np.linalg.norm(hit.pose[:2] - [5.0, 2.5]) == pytest.approx(cfg.radius, abs=1e-9)
    robot = Robot(hall, [1.0, 2.0, 0.0], cfg)
    results = drive(robot, [(1.0, 0.8)] * 60, 0.25)  # a circle of 1.25 m radius runs into the outer walls
    assert any(r.contact == "wall" for r in results)
    assert min(hall.distance(r.pose[:2])[0] for r in results) >= cfg.radius - 1e-9


def test_robot_cannot_leave_the_world_through_its_bounds():
    world = World([[[0.0, 0.0], [4.0, 0.0]]], bounds=[[0.0, 0.0], [4.0, 3.0]], name="open")
    robot = Robot(world, [2.0, 1.5, np.pi / 2])
    result = robot.step(1.0, 0.0, 10.0)
    assert result.contact == "wall" and result.pose[1] == pytest.approx(3.0 - robot.cfg.radius, abs=1e-9)


# --- limits ---------------------------------------------------------------------------------------


def test_speed_and_acceleration_limits_hold(hall):
    cfg = RobotConfig(max_speed=0.5, max_turn_rate=1.0, max_accel=1.0, max_turn_accel=2.0)
    robot = Robot(hall, [1.0, 1.0, 0.0], cfg)
    first = robot.step(10.0, 10.0, 0.1)  # from rest: the ramps, not the command
    np.testing.assert_allclose(first.velocity, [0.1, 0.2])
    assert np.hypot(*(first.pose[:2] - [1.0, 1.0])) == pytest.approx(0.5 * 1.0 * 0.1**2, rel=1e-3)
    assert first.pose[2] == pytest.approx(0.5 * 2.0 * 0.1**2)
    commands = [(10.0, 10.0)] * 15 + [(-10.0, -10.0)] * 15 + [(0.3, 0.0)] * 10
    prev_v, prev_pose = first.velocity, first.pose
    for r in drive(robot, commands, 0.1):
        assert np.all(np.abs(r.velocity) <= np.array([0.5, 1.0]) + 1e-12)
        assert np.all(np.abs(r.velocity - prev_v) <= np.array([1.0, 2.0]) * 0.1 + 1e-12)
        assert np.hypot(*(r.pose[:2] - prev_pose[:2])) <= 0.5 * 0.1 + 1e-12
        assert abs(geometry.wrap_angle(r.pose[2] - prev_pose[2])) <= 1.0 * 0.1 + 1e-12
        assert not r.collision
        prev_v, prev_pose = r.velocity, r.pose
    np.testing.assert_allclose(prev_v, [0.3, 0.0])


def test_bad_commands_and_start_poses_are_input_errors(hall):
    robot = Robot(hall, [1.0, 1.0, 0.0])
    for v, w, dt in [(np.nan, 0.0, 0.1), (0.0, 0.0, -0.1)]:
        with pytest.raises(InputError, match="Robot.step"):
            robot.step(v, w, dt)
    for pose in ([5.0, 1.0, 0.0], [0.1, 1.0, 0.0], [12.0, 1.0, 0.0]):  # on the wall, too close, outside
        with pytest.raises(InputError, match="robot.pose"):
            Robot(hall, pose)


# --- determinism ----------------------------------------------------------------------------------


def _run(seed: int):
    world = World.office()
    start = np.array([5.5, 4.225, 0.0])
    obstacles = scatter_wanderers(world, 3, np.random.default_rng(seed), keep_clear=(start[None, :2], [1.0]))
    robot = Robot(world, start, obstacles=obstacles, seed=seed)
    results = drive(robot, [(0.6, 0.3 * np.sin(k / 5)) for k in range(30)], 0.1)
    return (
        np.array([r.scan.ranges for r in results]),
        np.array([r.odom for r in results]),
        np.array([r.pose for r in results]),
        np.array([ob.centre for ob in obstacles]),
    )


def test_same_seed_same_run_other_seed_differs():
    a, b, c = _run(3), _run(3), _run(4)
    for x, y in zip(a, b):
        assert np.array_equal(x, y, equal_nan=True)
    ranges, odom, _, centres = c
    assert not np.array_equal(a[0], ranges, equal_nan=True)
    assert not np.array_equal(a[1], odom) and not np.array_equal(a[3], centres)


def test_robot_and_scripted_dataset_share_the_laser():
    source = SimulatorSource(SimulatorConfig(), seed=2, max_scans=1)
    robot = Robot(World.office(), source.ground_truth_poses[0], seed=2)
    first = next(iter(source))
    assert np.array_equal(robot.step(0.0, 0.0, 0.0).scan.ranges, first.ranges, equal_nan=True)


# --- moving obstacles -----------------------------------------------------------------------------


def test_laser_sees_a_moving_obstacle_the_map_does_not_hold(hall):
    laser = LaserModel(range_noise=0.0, dropout=0.0)
    disc = LoopingDisc(hall, [(7.0, 3.5), (7.0, 0.5)], radius=0.3, speed=0.5)
    robot = Robot(hall, [6.0, 2.0, 0.0], RobotConfig(laser=laser), obstacles=[disc])
    walls_before = hall.segments.copy()
    ahead = np.argmin(np.abs(robot.laser.angles))  # the beam along the heading
    seen = []
    for r in drive(robot, [(0.0, 0.0)] * 60, 0.1):  # the disc crosses the beam at y = 2
        seen.append(r.scan.ranges[ahead])
        on_beam = abs(disc.centre[1] - 2.0) < 0.01
        if on_beam:
            assert r.scan.ranges[ahead] == pytest.approx(1.0 - 0.3, abs=1e-9)
    assert min(seen) == pytest.approx(0.7, abs=0.01) and max(seen) == pytest.approx(4.0)  # the far wall
    assert hall.raycast([6.0, 2.0], [0.0], 12.0)[0] == pytest.approx(4.0)  # the map does not hold it
    assert np.array_equal(hall.segments, walls_before)


def test_driving_into_an_obstacle_is_a_collision(hall):
    disc = LoopingDisc(hall, [(8.0, 1.5), (8.0, 1.0)], radius=0.3, speed=0.0)  # parked
    robot = Robot(hall, [6.0, 1.2, 0.0], obstacles=[disc])
    hit = next(r for r in drive(robot, [(1.0, 0.0)] * 40, 0.2) if r.collision)
    assert hit.contact == "obstacle"
    assert np.linalg.norm(hit.pose[:2] - disc.centre) == pytest.approx(0.3 + robot.cfg.radius, abs=1e-9)


def test_obstacles_never_walk_into_the_robot_or_the_walls(hall):
    loop = LoopingDisc(hall, [(3.0, 3.5), (3.0, 0.5)], radius=0.3, speed=0.8)  # its loop runs through the robot
    rng = np.random.default_rng(0)
    walkers = scatter_wanderers(hall, 4, rng, radius=0.25, speed=1.0, keep_clear=([[3.0, 2.0], [3.0, 3.5]], [1.0, 1.0]))
    robot = Robot(hall, [3.0, 2.0, 0.0], obstacles=[loop, *walkers])
    for _ in range(200):
        robot.step(0.0, 0.0, 0.25)
        for ob in robot.obstacles:
            assert np.linalg.norm(ob.centre - robot.pose[:2]) >= ob.radius + robot.cfg.radius - 1e-9
            assert hall.free(ob.centre, ob.radius - 1e-9)[0]
    assert abs(loop.centre[1] - 2.0) == pytest.approx(0.5, abs=1e-9)  # waiting at the robot
    assert all(isinstance(w, WanderingDisc) and w.heading is not None for w in walkers)


def test_a_loop_through_a_wall_is_an_input_error(hall):
    with pytest.raises(InputError, match="waypoints"):
        LoopingDisc(hall, [(4.0, 1.0), (6.0, 1.0)])


# --- odometry and the frontend --------------------------------------------------------------------


def test_zero_odometry_noise_gives_the_true_pose(hall):
    robot = Robot(hall, [1.5, 2.0, 0.0], RobotConfig(odometry=NO_ODOM_NOISE), seed=9)
    commands = [(0.8, 0.5)] * 20 + [(-0.5, -1.0)] * 20 + [(0.0, 2.0)] * 10
    for r in drive(robot, commands, 0.1):
        np.testing.assert_allclose(r.odom[:2], r.pose[:2], atol=1e-9)
        assert abs(geometry.wrap_angle(r.odom[2] - r.pose[2])) < 1e-9
        np.testing.assert_array_equal(r.scan.odom, r.odom)
        np.testing.assert_array_equal(r.scan.ground_truth, r.pose)


def test_backward_steps_are_as_noisy_as_forward_ones():
    forward = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.05]])
    backward = np.array([[0.0, 0.0, 0.0], [-0.1, 0.0, 0.05]])
    err_f = np.array([sample_odometry(forward, OdometryNoise(), np.random.default_rng(s))[1] for s in range(50)])
    err_b = np.array([sample_odometry(backward, OdometryNoise(), np.random.default_rng(s))[1] for s in range(50)])
    np.testing.assert_allclose(np.abs(err_b[:, 2] - 0.05), np.abs(err_f[:, 2] - 0.05), atol=1e-12)
    assert np.abs(err_b[:, 2] - 0.05).max() < 0.05


def test_icp_tracks_a_driven_robot():
    robot = Robot(World.office(), [5.5, 4.225, 0.0], seed=1)
    frontend = create_frontend("icp")
    first = robot.step(0.0, 0.0, 0.0)
    frontend.process(first.scan, np.zeros(3))
    estimate, prev = first.odom.copy(), first
    commands = [(0.8, 0.0)] * 20 + [(0.5, 0.6)] * 10 + [(0.8, -0.3)] * 10
    for r in drive(robot, commands, 0.1):
        result = frontend.process(r.scan, geometry.between(prev.odom, r.odom))
        estimate, prev = geometry.compose(estimate, result.delta), r
        assert not r.collision
    err = geometry.between(prev.pose, estimate)
    assert np.hypot(err[0], err[1]) < 0.05 and abs(np.rad2deg(err[2])) < 1.0
    assert np.linalg.norm(prev.pose[:2] - first.pose[:2]) > 2.0
