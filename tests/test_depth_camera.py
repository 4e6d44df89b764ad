"""Objects with heights, the depth camera and its obstacle layer: what the laser misses, the camera marks."""

import numpy as np
import pytest
from pydantic import ValidationError

from slam2d.config import LaserModel, ObjectSpec
from slam2d.errors import InputError
from slam2d.navigation import Navigator, NavigatorConfig, run_navigation, world_grid
from slam2d.navigation.depth_layer import ObstacleLayer, obstacle_points
from slam2d.sim import Robot, RobotConfig, World
from slam2d.sim.depth import DepthCamera, DepthCameraConfig
from slam2d.sim.objects3d import Objects3D, furnish, load_objects, scatter_objects

QUIET_LASER = LaserModel(range_noise=0.0, dropout=0.0)


def room(*specs, width=8.0):
    """An 8 m x 4 m room (walls only) with ``specs`` as objects, the laser at its default 0.25 m."""
    rings = [[[0, 0], [width, 0], [width, 4], [0, 4]]]
    return furnish(World.from_polygons(rings, name="room"), Objects3D.from_specs(specs), 0.25)


def box(x, y, h, side=0.3):
    return ObjectSpec(kind="box", at=(x, y), size=(side, side), z=(0.0, h))


def laser_range_ahead(world, pose) -> float:
    robot = Robot(world, pose, RobotConfig(laser=QUIET_LASER))
    scan = robot.step(0.0, 0.0, 0.0).scan
    return float(scan.ranges[np.argmin(np.abs(scan.angles))])


def test_the_laser_sees_table_legs_but_not_a_low_box_a_table_top_or_a_shelf_board():
    pose = [1.0, 2.0, 0.0]
    assert laser_range_ahead(room(box(3.0, 2.0, 0.04)), pose) == pytest.approx(7.0, abs=1e-6)  # the far wall
    shelf = ObjectSpec(kind="shelf", at=(3.0, 2.0), size=(1.0, 0.3))  # board at 0.30-0.34 m, panels at x 2.5, 3.5
    assert laser_range_ahead(room(shelf), [1.0, 2.1, 0.0]) == pytest.approx(1.5, abs=1e-6)  # the near end panel
    table = ObjectSpec(kind="table", at=(3.5, 2.0), size=(1.0, 0.7))  # legs 4 cm square at the corners
    assert laser_range_ahead(room(table), pose) == pytest.approx(7.0, abs=1e-6)  # between the legs, under the top
    assert laser_range_ahead(room(table), [1.0, 2.0 - 0.35 + 0.02, 0.0]) == pytest.approx(2.0, abs=1e-6)  # a leg


def test_the_robot_collides_with_what_is_at_its_body_height_only():
    shelf = ObjectSpec(kind="shelf", at=(3.0, 2.0), size=(1.0, 0.3))
    high = ObjectSpec(kind="box", at=(3.0, 2.0), size=(0.3, 0.3), z=(0.5, 0.6))  # above the 0.45 m body
    for spec, hits in ((box(3.0, 2.0, 0.04), True), (shelf, True), (high, False)):
        robot = Robot(room(spec), [2.0, 2.0, 0.0], RobotConfig(laser=QUIET_LASER))
        contacts = [robot.step(0.5, 0.0, 0.2).contact for _ in range(15)]
        assert ("object" in contacts) == hits, spec.kind
        if hits:
            assert robot.pose[0] == pytest.approx(spec.at[0] - spec.size[0] / 2 - 0.2, abs=1e-6)


def test_the_depth_camera_sees_a_4cm_box_the_laser_misses_and_the_costmap_marks_it():
    world = room(box(3.0, 2.0, 0.04))
    pose = np.array([1.5, 2.0, 0.0])
    cfg = DepthCameraConfig(enabled=True)
    layer = ObstacleLayer(cfg)
    layer.update(pose, DepthCamera(cfg, seed=1).render(world, pose), 0.0)
    on_box = np.all(np.abs(layer.points() - [3.0, 2.0]) <= 0.15 + 0.03, axis=1)
    assert on_box.sum() >= 3 and on_box.all()  # the box, nothing else
    nav = Navigator([6.0, 2.0], config=NavigatorConfig())
    nav.step(pose, [0.0, 0.0], np.zeros((0, 2)), world_grid(world), 0.0, obstacles=layer.points())
    passes = np.hypot(*(nav.path - [3.0, 2.0]).T).min()
    assert passes > 0.15 + 0.2  # the plan goes round the box (its half side + the robot's radius)
    assert nav.unmapped(pose, np.array([[1.5, 0.0]])).tolist() == [False]  # the layer's points stay
    plain = Navigator([6.0, 2.0], config=NavigatorConfig())
    plain.step(pose, [0.0, 0.0], np.zeros((0, 2)), world_grid(world), 0.0)
    assert np.hypot(*(plain.path - [3.0, 2.0]).T).min() < 0.05  # the map alone: straight over it


def test_ground_removal_keeps_the_floor_out_even_with_the_pitch_off_by_3_degrees():
    floor = World.from_polygons([[[0, 0], [10, 0], [10, 10], [0, 10]]])  # walls beyond the marking range
    seen = DepthCameraConfig(enabled=True, pitch_deg=23.0)  # the camera is mounted 3 degrees lower than assumed
    cfg = DepthCameraConfig(enabled=True)
    layer = ObstacleLayer(cfg)
    camera = DepthCamera(seen, seed=2)
    heights = []
    for k in range(20):
        pose = np.array([5.0, 5.0, 0.3 * k])
        cloud = layer.geometry.points(camera.render(floor, pose))
        heights.append(cloud[np.hypot(cloud[:, 0], cloud[:, 1]) < cfg.mark_range, 2].max())
        assert len(obstacle_points(cloud, cfg)) == 0, k
    assert max(heights) > cfg.band[0]  # the tilted floor rises into the band: only the fitted plane removes it


def test_the_smallest_box_marked_at_the_default_mount_is_2_cm():
    """The band starts 2 cm above the fitted floor: 3 and 2.1 cm boxes are marked, 1 cm ones not (1.5 cm: in
    about 1 approach of 10, benchmarks/obstacles_3d.py --experiments)."""
    cfg = DepthCameraConfig(enabled=True)

    def marked(h, seed):
        world, layer, camera = room(box(5.0, 2.0, h)), ObstacleLayer(cfg), DepthCamera(cfg, seed)
        for x in np.arange(2.0, 4.2, 0.2):
            pose = np.array([x, 2.0, 0.0])
            layer.update(pose, camera.render(world, pose), x)
        return len(layer) > 0

    assert all(marked(h, s) for h in (0.03, 0.021) for s in range(2))
    assert not any(marked(0.01, s) for s in range(2))


def test_a_stale_obstacle_is_cleared_when_seen_through_and_forgotten_out_of_view():
    cfg = DepthCameraConfig(enabled=True, persistence=5.0)
    pose = np.array([1.5, 2.0, 0.0])
    layer, camera = ObstacleLayer(cfg), DepthCamera(cfg, seed=3)
    layer.update(pose, camera.render(room(box(3.0, 2.0, 0.04)), pose), 0.0)
    assert len(layer)
    layer.update(pose, camera.render(room(), pose), 0.1)  # the box was taken away: the floor is seen behind it
    assert len(layer) == 0
    layer.update(pose, camera.render(room(box(3.0, 2.0, 0.04)), pose), 0.2)
    away = np.array([1.5, 2.0, np.pi])  # looking away: kept, then forgotten
    on_box = lambda: np.all(np.abs(layer.points() - [3.0, 2.0]) <= 0.2, axis=1).sum()
    layer.update(away, camera.render(room(), away), 1.0)
    assert on_box() > 0
    layer.update(away, camera.render(room(), away), 6.0)
    assert on_box() == 0


def test_with_the_laser_alone_the_robot_hits_a_low_box_and_with_the_depth_camera_it_drives_round():
    world = room(box(4.0, 2.0, 0.04), width=7.0)
    grid = world_grid(world)
    laser = run_navigation(world, Robot(world, [1.0, 2.0, 0.0]), grid, [6.0, 2.0], "dwa", NavigatorConfig(),
                           max_steps=60)  # fmt: skip
    assert laser.object_collisions >= 1
    cfg = NavigatorConfig.model_validate({"depth_camera": {"enabled": True}})
    camera = run_navigation(world, Robot(world, [1.0, 2.0, 0.0]), grid, [6.0, 2.0], "dwa", cfg, seed=0)
    assert camera.success and camera.collisions == 0


def test_objects_are_scattered_clear_of_walls_each_other_and_the_start():
    world = World.from_polygons([[[0, 0], [10, 0], [10, 8], [0, 8]]])
    specs = scatter_objects(world, {"box": 5, "table": 2, "chair": 2, "shelf": 1}, np.random.default_rng(4),
                            keep_clear=([[1.0, 1.0]], [1.0]))  # fmt: skip
    assert [s.kind for s in specs].count("box") == 5 and len(specs) == 10
    again = scatter_objects(world, {"box": 5, "table": 2, "chair": 2, "shelf": 1}, np.random.default_rng(4),
                            keep_clear=([[1.0, 1.0]], [1.0]))  # fmt: skip
    assert specs == again
    parts = Objects3D.from_specs(specs).parts
    assert parts[:, :2].min() >= 0.7 and parts[:, 3:5].max(axis=0).tolist() <= [9.3, 7.3]
    low = [s for s in specs if s.kind == "box"]
    assert all(0.03 <= s.z[1] <= 0.05 for s in low)


def test_object_files_and_config_are_checked(tmp_path):
    path = tmp_path / "objects.yaml"
    path.write_text("- {kind: box, at: [1, 2], size: [0.3, 0.2], z: [0, 0.04]}\n- {kind: table, at: [3, 2], size: [1, 0.7]}\n")
    assert [s.kind for s in load_objects(path)] == ["box", "table"]
    path.write_text("- {kind: box, at: [1, 2], size: [0.3, -0.2]}\n")
    with pytest.raises(InputError, match="object 0: size"):
        load_objects(path)
    with pytest.raises(ValidationError, match="bottom < top"):
        ObjectSpec(kind="box", at=(0, 0), size=(1, 1), z=(0.1, 0.05))
    with pytest.raises(ValidationError, match="band must be"):
        NavigatorConfig.model_validate({"depth_camera": {"band": [0.3, 0.1]}})
    with pytest.raises(ValidationError, match="extra"):
        NavigatorConfig.model_validate({"depth_camera": {"pitch": 10}})


def test_the_look_around_marks_a_box_beside_the_start_before_the_robot_drives_and_it_is_not_hit():
    """A 3.5 cm box beside the start, the goal past it: the camera, looking ahead, never sees it; the start-up
    sweep marks it before the robot moves, and the robot then drives round it (without the sweep it turns
    into it)."""
    world = room(box(2.0, 1.7, 0.035), width=6.0)
    start, goal = [2.0, 1.0, 0.0], [2.0, 3.4]
    cfg = DepthCameraConfig(enabled=True)
    robot, nav = Robot(world, start), Navigator(goal, config=NavigatorConfig(depth_camera=cfg))
    camera, layer, grid = DepthCamera(cfg, seed=0), ObstacleLayer(cfg), world_grid(world)
    step, states = robot.step(0.0, 0.0, 0.0), []
    for _ in range(100):
        layer.update(step.pose, camera.render(world, step.pose), step.scan.stamp, step.scan.points_in_base())
        cmd = nav.step(step.pose, step.velocity, step.scan.points_in_base(), grid, step.scan.stamp, layer.points())
        states.append(cmd.state)
        if cmd.state != "look around":
            break
        assert cmd.v == 0.0
        step = robot.step(cmd.v, cmd.w, 0.1)
    assert states[0] == "look around" and states[-1] != "look around"
    assert np.hypot(*(robot.pose[:2] - start[:2])) < 1e-6  # turned on the spot
    assert abs(nav._look.left) < 0.05 and nav._look.sweep > 5.0  # the whole sweep, ending facing the path
    on_box = np.all(np.abs(layer.points() - [2.0, 1.7]) <= 0.15 + 0.03, axis=1)
    assert on_box.sum() >= 3
    runs = {}
    for look in (False, True):
        options = NavigatorConfig.model_validate({"depth_camera": {"enabled": True, "look_around": look}})
        runs[look] = run_navigation(world, Robot(world, start), grid, goal, "dwa", options, seed=0)
    assert runs[False].object_collisions >= 1
    assert runs[True].success and runs[True].collisions == 0
