"""Length scale of the ICP frontend and the scale audit's de-skewing (benchmarks/scale_audit.py): on exact
scans the frontend's lengths follow the scans, not odometry, and a range scale shows in them one to one;
a scan taken while moving is de-skewed back to the static one."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import load_benchmark
from test_icp import _box

from slam2d import geometry
from slam2d.datasets.simulator import World
from slam2d.frontends import create_frontend
from slam2d.types import Scan

BEAMS = np.deg2rad(np.arange(-90.0, 90.5, 1.0))  # 181 beams, 1 deg: the Freiburg clinic's laser
RANGE_MAX = 30.0


def _bench():
    return load_benchmark("scale_audit")


@pytest.fixture(scope="module")
def hall() -> World:
    """A 24 x 8 m hall (m) with pillars and an end wall: structure along and across."""
    pillars = [_box(x, y, x + 0.4, y + 0.4) for x in (4.0, 9.0, 14.0, 19.0) for y in (1.0, 6.6)]
    return World.from_polygons([_box(0.0, 0.0, 24.0, 8.0), *pillars])


def _scan(world: World, pose, seed: int, scale: float = 1.0, noise: float = 0.01) -> Scan:
    true = world.raycast_poses(np.asarray(pose, float), BEAMS, RANGE_MAX)[0]
    ranges = scale * true + np.random.default_rng(seed).normal(0.0, noise, true.shape)
    ranges[true >= RANGE_MAX - 1e-6] = np.nan
    return Scan(stamp=0.6 * seed, ranges=ranges, angles=BEAMS.copy(), range_min=0.1, range_max=RANGE_MAX)


def _driven_length(world: World, scale: float, odometry_scale: float, steps: int = 20) -> float:
    """Chained frontend length over ``steps`` straight steps of 0.2 m (truth 4 m), odometry ``odometry_scale``
    x the truth, ranges ``scale`` x the truth."""
    fe = create_frontend("icp", {})
    pose, step = np.array([2.0, 4.0, 0.0]), np.array([0.2, 0.0, 0.0])
    fe.process(_scan(world, pose, 0, scale), np.zeros(3))
    chained = np.zeros(3)
    for k in range(1, steps + 1):
        pose = geometry.compose(pose, step)
        chained = geometry.compose(chained, fe.process(_scan(world, pose, k, scale), odometry_scale * step).delta)
    return float(np.hypot(chained[0], chained[1]))


def test_frontend_lengths_follow_the_scans_not_odometry(hall):
    """Odometry 5 % long: the frontend's 4 m stay within 0.3 % of the truth (no scale of its own); ranges
    1.5 % long: the lengths come out 1.5 % long (as the clinic's scans against its relations)."""
    assert _driven_length(hall, 1.0, 1.05) == pytest.approx(4.0, rel=0.003)
    assert _driven_length(hall, 1.015, 1.05) == pytest.approx(4.0 * 1.015, rel=0.005)


def test_a_scan_taken_while_moving_is_deskewed_to_the_static_one(hall):
    """Beam k cast from where the robot is k/180 of a 0.1 s sweep after the stamp, driving 1 m/s and
    turning 0.5 rad/s (first order, the audit's model): placed at the stamp's pose the de-skewed points
    lie on the walls within 2 mm, the raw ones up to 40 cm off; a still scan is left as it is."""
    audit = _bench()
    start, twist, sweep = np.array([6.0, 3.0, 0.3]), np.array([1.0, 0.0, 0.5]), 0.1
    tau = sweep * np.arange(len(BEAMS)) / (len(BEAMS) - 1)
    poses = geometry.compose(start, twist[None, :] * tau[:, None])
    moving = np.array([world_ray(hall, p, a) for p, a in zip(poses, BEAMS, strict=True)])
    scan = Scan(stamp=0.0, ranges=moving, angles=BEAMS.copy(), range_min=0.1, range_max=RANGE_MAX)
    fixed = audit.deskewed(scan, twist, sweep)
    raw_gap = hall.distance(geometry.transform_points(start, scan.points_in_base()))  # to the nearest wall
    fixed_gap = hall.distance(geometry.transform_points(start, fixed.points_in_base()))
    assert np.max(raw_gap) > 0.05
    assert np.max(fixed_gap) < 0.002
    static = _scan(hall, start, 0, noise=0.0)
    unmoved = audit.deskewed(static, np.zeros(3), sweep)
    np.testing.assert_allclose(unmoved.points(), static.points(), atol=1e-12)


def world_ray(world: World, pose, angle: float) -> float:
    """Range (m) of one beam at ``angle`` from ``pose``."""
    return float(world.raycast_poses(np.asarray(pose, float), np.array([angle]), RANGE_MAX)[0, 0])


def test_deskew_keeps_beams_without_a_hit_empty(hall):
    scan = _scan(hall, [6.0, 3.0, 0.0], 0, noise=0.0)
    scan = dataclasses.replace(scan, ranges=np.where(np.arange(len(BEAMS)) % 7 == 0, np.nan, scan.ranges))
    fixed = _bench().deskewed(scan, np.array([0.5, 0.0, 0.1]), 0.05)
    assert np.array_equal(np.isnan(fixed.ranges), ~scan.hit_mask())
