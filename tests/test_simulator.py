"""The embedded simulator: worlds, ray casting, laser and odometry models, the route."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from slam2d import geometry
from slam2d.config import LaserModel, OdometryNoise, SimulatorConfig
from slam2d.datasets.simulator import (
    SimulatorSource,
    World,
    measure_ranges,
    office_route,
    route_poses,
    sample_odometry,
)
from slam2d.errors import InputError


@pytest.fixture(scope="module")
def office_truth():
    """Stamps and ground-truth poses of the default route."""
    cfg = SimulatorConfig()
    return route_poses(office_route(), cfg.speed, cfg.turn_rate, cfg.scan_rate)


def _arrays(source):
    scans = list(source)
    return np.array([s.ranges for s in scans]), np.array([s.odom for s in scans])


def test_same_seed_same_scans_other_seed_differs():
    r0, o0 = _arrays(SimulatorSource(SimulatorConfig(), seed=3, max_scans=40))
    r1, o1 = _arrays(SimulatorSource(SimulatorConfig(), seed=3, max_scans=40))
    r2, o2 = _arrays(SimulatorSource(SimulatorConfig(), seed=4, max_scans=40))
    assert np.array_equal(r0, r1, equal_nan=True) and np.array_equal(o0, o1)
    assert not np.array_equal(r0, r2, equal_nan=True) and not np.array_equal(o0, o2)


def test_iterating_twice_gives_the_same_scans():
    source = SimulatorSource(SimulatorConfig(), seed=1, max_scans=20)
    (r0, _), (r1, _) = _arrays(source), _arrays(source)
    assert np.array_equal(r0, r1, equal_nan=True)


def test_raycast_square_room_exact():
    world = World.from_polygons([[(0, 0), (4, 0), (4, 4), (0, 4)]])
    angles = np.array([0.0, np.pi / 2, np.pi, -np.pi / 2, np.pi / 4, np.arctan2(2, -1)])
    expected = [3.0, 2.0, 1.0, 2.0, 2.0 * np.sqrt(2.0), np.sqrt(5.0)]
    np.testing.assert_allclose(world.raycast([1.0, 2.0], angles, 10.0), expected, atol=1e-12)
    assert world.raycast([1.0, 2.0], [0.0], 2.5)[0] == 2.5  # nothing within range
    poses = np.array([[1.0, 2.0, np.pi / 2], [3.0, 3.0, 0.0]])
    np.testing.assert_allclose(world.raycast_poses(poses, [0.0, np.pi], 10.0), [[2.0, 2.0], [1.0, 3.0]])


def test_raycast_hits_the_nearest_wall_and_the_box_from_outside():
    world = World.from_polygons([[(0, 0), (10, 0), (10, 10), (0, 10)], [(4, 4), (6, 4), (6, 6), (4, 6)]])
    np.testing.assert_allclose(world.raycast([1.0, 5.0], [0.0, np.pi], 20.0), [3.0, 1.0])


def test_measure_ranges_conventions():
    laser = LaserModel(range_min=0.1, range_max=5.0)
    true = np.array([0.05, 1.0, 4.99, 5.0, 7.0])
    out = measure_ranges(true, laser, np.full(5, 0.02), np.array([False, False, False, False, False]))
    np.testing.assert_allclose(out, [np.nan, 1.02, 5.0, 5.0, 5.0])
    out = measure_ranges(true, laser, np.zeros(5), np.array([False, True, False, False, False]))
    assert np.isnan(out[1])


def test_dropout_rate_and_range_noise_as_configured():
    laser = LaserModel(range_noise=0.05, dropout=0.1)
    source = SimulatorSource(SimulatorConfig(laser=laser), seed=7, max_scans=200)
    ranges, _ = _arrays(source)
    true = source.world.raycast_poses(source.ground_truth_poses, source.beam_angles, laser.range_max)
    dropped = np.isnan(ranges)
    assert ranges.size == 200 * laser.beams
    assert abs(dropped.mean() - 0.1) < 0.006  # about 5 standard errors
    hits = ~dropped & (true < laser.range_max - 0.5)
    residual = ranges[hits] - true[hits]
    assert abs(residual.mean()) < 0.002
    assert abs(residual.std() - 0.05) < 0.002


def test_zero_odometry_noise_gives_ground_truth():
    cfg = SimulatorConfig(odometry=OdometryNoise(alpha1=0, alpha2=0, alpha3=0, alpha4=0))
    source = SimulatorSource(cfg, max_scans=300)
    gt = source.ground_truth_poses
    np.testing.assert_allclose(source.odometry_poses[:, :2], gt[:, :2], atol=1e-9)
    np.testing.assert_allclose(geometry.wrap_angle(source.odometry_poses[:, 2] - gt[:, 2]), 0, atol=1e-9)
    scan = next(iter(source))
    np.testing.assert_allclose(scan.odom, gt[0])


def test_default_odometry_drifts_plausibly(office_truth):
    _, gt = office_truth
    final = []
    for seed in range(20):
        odom = sample_odometry(gt, OdometryNoise(), np.random.default_rng(seed))
        final.append(np.linalg.norm(odom[-1, :2] - gt[-1, :2]))
    assert min(final) > 0.05
    assert 0.5 < np.median(final) < 3.0


def test_route_is_long_and_closes_loops(office_truth):
    _, gt = office_truth
    xy = gt[:, :2]
    travelled = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    assert 100.0 < travelled[-1] < 150.0
    assert np.linalg.norm(xy[-1] - xy[0]) < 0.2  # back at the start
    # revisits: within 1 m of a pose passed more than 30 m of travel earlier
    q = np.searchsorted(travelled, np.arange(0.0, travelled[-1], 1.0))
    close = np.linalg.norm(xy[q][:, None] - xy[None], axis=-1) < 1.0
    earlier = travelled[q][:, None] - travelled[None] > 30.0
    revisit = (close & earlier).any(axis=1)
    runs = np.count_nonzero(np.diff(revisit.astype(int)) == 1) + int(revisit[0])
    assert runs >= 2
    # two laps round the corridor ring: the robot winds twice round the core's centre
    winding = np.sum(geometry.wrap_angle(np.diff(np.arctan2(xy[:, 1] - 6.0, xy[:, 0] - 10.0)))) / (2 * np.pi)
    assert winding >= 1.99


def test_ground_truth_keeps_clear_of_walls(office_truth):
    _, gt = office_truth
    world = World.office()
    assert world.distance(gt[:, :2]).min() >= 0.25
    assert not world.occupied(gt[:, :2]).any()


def test_office_has_rooms_and_doorways():
    world = World.office()
    (x0, y0), (x1, y1) = world.bounds
    assert 19.0 < x1 - x0 < 22.0 and 11.0 < y1 - y0 < 13.0
    # doorways: a beam from the corridor through each door reaches the room beyond
    for x in (3.0, 7.5, 12.5, 17.3):
        assert world.raycast([x, 4.225], [-np.pi / 2], 12.0)[0] > 2.0
    assert world.raycast([6.0, 4.225], [-np.pi / 2], 12.0)[0] < 1.0  # wall beside a door


def test_scans_follow_the_laser_model_and_timing():
    cfg = SimulatorConfig(laser=LaserModel(beams=181, fov_deg=180.0, range_max=8.0), scan_rate=10.0)
    source = SimulatorSource(cfg, max_scans=30)
    scans = list(source)
    assert len(scans) == len(source) == 30
    s = scans[5]
    assert s.ranges.shape == s.angles.shape == (181,)
    np.testing.assert_allclose(s.angles[[0, 90, 180]], [-np.pi / 2, 0.0, np.pi / 2])
    assert s.stamp == pytest.approx(0.5) and s.range_max == 8.0
    np.testing.assert_allclose(s.sensor_pose, 0.0)
    np.testing.assert_allclose(s.ground_truth, source.ground_truth_poses[5])
    assert np.nanmax(s.ranges) <= 8.0


def _png_world(path, h=60, w=100):
    """5 m x 3 m at 0.05 m/px: 2-pixel border walls and a 0.5 m block at x 3.0-3.5, y 0.5-1.0."""
    img = np.full((h, w), 255, dtype=np.uint8)
    img[:2], img[-2:], img[:, :2], img[:, -2:] = 0, 0, 0, 0
    img[40:50, 60:70] = 30  # rows from the top: y = (60 - 50) * 0.05 .. (60 - 40) * 0.05
    Image.fromarray(img).save(path)
    return path


def test_png_world_raycast(tmp_path):
    world = World.from_png(_png_world(tmp_path / "room.png"), resolution=0.05)
    np.testing.assert_allclose(world.bounds, [[0, 0], [5, 3]])
    r = world.raycast([1.0, 1.5], [0.0, np.pi / 2, np.pi, -np.pi / 2], 10.0)
    np.testing.assert_allclose(r, [3.9, 1.4, 0.9, 1.4], atol=1e-9)
    assert world.raycast([1.0, 0.75], [0.0], 10.0)[0] == pytest.approx(2.0)
    assert world.occupied([[3.2, 0.7], [1.0, 1.0]]).tolist() == [True, False]


def test_png_world_as_a_dataset(tmp_path):
    path = _png_world(tmp_path / "room.png")
    cfg = SimulatorConfig(world=str(path), route=[(1.0, 1.5), (4.0, 2.0), (4.0, 0.5)])
    scans = list(SimulatorSource(cfg))
    assert len(scans) > 10 and all(np.nanmax(s.ranges) < 6.0 for s in scans)


@pytest.mark.parametrize(
    "route",
    [
        [(5.5, 4.225), (10.0, 6.0)],  # inside the service core
        [(6.0, 4.225), (6.0, 1.9)],  # through a wall beside a doorway
        [(5.5, 4.225), (25.0, 4.225)],  # outside the world
        [(5.5, 4.225)],  # one waypoint
    ],
)
def test_bad_route_is_an_input_error(route):
    with pytest.raises(InputError, match="route"):
        SimulatorSource(SimulatorConfig(route=route))


def test_missing_png_is_an_input_error(tmp_path):
    missing = tmp_path / "nope.png"
    with pytest.raises(InputError, match="nope.png"):
        SimulatorSource(SimulatorConfig(world=str(missing), route=[(1, 1), (2, 1)]))


def test_png_world_without_route_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="route"):
        SimulatorSource(SimulatorConfig(world=str(_png_world(tmp_path / "room.png"))))
