"""The ICP frontend leaves out points an earlier scan saw through (people walking past)."""

from __future__ import annotations

import numpy as np
import pytest

from slam2d import geometry
from slam2d.datasets.simulator import World
from slam2d.frontends import create_frontend
from slam2d.frontends.icp import MOVING_EVENT
from slam2d.frontends.icp.moving import Views
from slam2d.types import Scan

BEAMS = np.linspace(-np.pi, np.pi, 360, endpoint=False)
RANGE_MAX = 10.0


def scan_at(world: World, pose, stamp: float, person=None) -> Scan:
    """A 360-beam scan from ``pose`` (odometry exact), seeing the disc ``person`` (centre, radius) too."""
    circles = None if person is None else (np.array([person[0]]), np.array([person[1]]))
    true = world.raycast_poses(pose, BEAMS, RANGE_MAX, circles)[0]
    ranges = true + np.random.default_rng(int(stamp * 10)).normal(0.0, 0.005, true.shape)
    ranges[true >= RANGE_MAX - 1e-6] = RANGE_MAX  # no return
    return Scan(stamp=stamp, ranges=ranges, angles=BEAMS.copy(), range_min=0.05, range_max=RANGE_MAX,
                odom=np.asarray(pose, float), ground_truth=np.asarray(pose, float))


ON = {"moving_margin": 0.1}


def drive(world, poses, people, options=ON):
    """The frontend over scans at ``poses`` (N, 3) with a person at ``people[i]`` (or None); its last pose."""
    fe = create_frontend("icp", options)
    for i, (pose, person) in enumerate(zip(poses, people)):
        delta = np.zeros(3) if i == 0 else geometry.between(poses[i - 1], pose)
        fe.process(scan_at(world, pose, 0.1 * i, person), delta)
    return fe


@pytest.fixture(scope="module")
def corridor() -> World:
    """A corridor 2 m wide and 60 m long, closed 9 m ahead of the start: the end wall fixes x."""
    return World(np.array([[[-30, 0], [30, 0]], [[-30, 2], [30, 2]], [[9, 0], [9, 2]]], dtype=float))


def test_a_person_walking_past_in_a_corridor_does_not_drag_the_pose(corridor):
    """The robot creeps 1 cm a scan along a corridor whose end wall, 9 m ahead, is all that fixes the
    position along it; after 10 scans a person steps out 1.5 m ahead, 0.7 m beside it, and walks past at
    0.5 m/s; odometry is exact. The earlier scans saw the corridor free where the person walks, so the
    person's points are left out and the pose stays on the wall's; matched with them (the code before)
    the pose went along with the person."""
    n = 50
    poses = np.column_stack([0.01 * np.arange(n), np.full(n, 0.6), np.zeros(n)])
    people = [None] * 10 + [(np.array([1.5 - 0.05 * i, 1.3]), 0.25) for i in range(n - 10)]
    travelled = geometry.between(poses[0], poses[-1])  # the frontend's frame starts at the first scan
    fe = drive(corridor, poses, people)
    assert fe.events[MOVING_EVENT] > (n - 10) // 2
    assert np.hypot(*(fe.pose[:2] - travelled[:2])) < 0.01, fe.pose
    dragged = drive(corridor, poses, people, {"moving_margin": 0.0})
    assert np.hypot(*(dragged.pose[:2] - travelled[:2])) > 0.2, dragged.pose


def test_a_static_room_has_no_moving_points():
    """Driving through an L-shaped room with a pillar (corners, edges, walls at grazing angles) nothing is
    seen through: no scan is matched again."""
    outer = np.array([[0, 0], [8, 0], [8, 3], [5, 3], [5, 6], [0, 6]], dtype=float)
    pillar = np.array([[2.0, 2.0], [2.4, 2.0], [2.4, 2.4], [2.0, 2.4]])
    room = World.from_polygons([outer, pillar])
    t = np.linspace(0, 1, 60)
    poses = np.column_stack([1.0 + 5.5 * t, 1.0 + 0.8 * np.sin(3 * t), 0.5 * np.sin(4 * t)])
    fe = drive(room, poses, [None] * len(poses))
    assert fe.events[MOVING_EVENT] == 0


def test_seen_through_needs_every_nearby_beam_past_the_point():
    """A point is seen through only where the beams either side of its bearing all reach beyond it by the
    margin (an edge seen past by one beam is not), and by two earlier scans."""
    angles = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    reach = np.full(360, 5.0)
    reach[170:175] = 1.0  # something 1 m off at bearings -10 .. -6 deg
    views = Views(5)
    scan = Scan(stamp=0.0, ranges=reach, angles=angles, range_min=0.05, range_max=10.0)
    views.add(np.zeros(3), scan)
    bearings = np.radians([0.0, -8.0, -4.5, 0.0])
    points = np.array([2.0, 2.0, 2.0, 4.95])[:, None] * np.column_stack([np.cos(bearings), np.sin(bearings)])
    assert not views.moving(points, 0.1).any()  # one scan is not enough
    views.add(np.zeros(3), scan)
    # seen through; behind the thing; beside its edge; within the margin
    assert views.moving(points, 0.1).tolist() == [True, False, False, False]
