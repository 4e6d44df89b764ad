"""Degeneracy-aware fusion in the ICP frontend: the scan where it constrains, odometry where it does not."""

from __future__ import annotations

import numpy as np
import pytest
from test_icp import _box, assert_close_pose, scan_at

from slam2d import geometry
from slam2d.datasets.simulator import World
from slam2d.frontends import create_frontend
from slam2d.frontends.icp import DEGENERATE_EVENT, STILL_EVENT
from slam2d.frontends.icp.degeneracy import constrained_projector, remap
from slam2d.frontends.odometry import odometry_information

ODOM = odometry_information(0.05, 2.0)
FUSED = {"degeneracy_ratio": 10.0}  # off by default: see docs/benchmarks.md (degeneracy-aware fusion)


@pytest.fixture(scope="module")
def corridor() -> World:
    """Two parallel walls 2 m apart and 60 m long, with a 2 cm ledge on one wall 4 m ahead:
    a sliver of structure along x, weaker than odometry, and strong across (y) and in heading."""
    walls = np.array([[[-30, 0], [4, 0]], [[4, 0.02], [30, 0.02]], [[4, 0], [4, 0.02]], [[-30, 2], [30, 2]]],
                     dtype=float)
    return World(walls)


@pytest.fixture(scope="module")
def room() -> World:
    """An L-shaped room with a pillar and a cabinet: every direction constrained."""
    outer = np.array([[0, 0], [8, 0], [8, 3], [5, 3], [5, 6], [0, 6]], dtype=float)
    return World.from_polygons([outer, _box(2.0, 2.0, 2.4, 2.4), _box(6.5, 0.0, 7.2, 0.8)])


def test_projector_keeps_only_the_constrained_directions():
    scan = np.diag([1e-3, 1e6, 1e7])  # nothing along x, strong in y and theta
    projector, free = constrained_projector(scan, ODOM, 1.0)
    assert free == 1
    np.testing.assert_allclose(projector @ [0.1, 0.02, 0.01], [0.0, 0.02, 0.01], atol=1e-12)
    full, none = constrained_projector(np.diag([1e6, 1e6, 1e7]), ODOM, 1.0)
    assert none == 0 and np.array_equal(full, np.eye(3))


def test_remap_of_a_rotated_base_keeps_the_prediction_along_the_free_direction():
    """Base turned 90 deg: the delta frame's x is the map's y. The free delta-x part of the match
    goes back to the prediction, the constrained delta-y part stays."""
    base = np.array([1.0, 2.0, np.pi / 2])
    predicted = geometry.compose(base, [0.3, 0.0, 0.0])
    matched = geometry.compose(base, [0.2, 0.05, 0.01])
    pose, free = remap(base, predicted, matched, np.diag([0.0, 1e6, 1e7]), ODOM, 1.0)
    assert free == 1
    np.testing.assert_allclose(geometry.between(base, pose), [0.3, 0.05, 0.01], atol=1e-9)
    same, _ = remap(base, predicted, matched, np.diag([0.0, 1e6, 1e7]), ODOM, 0.0)
    np.testing.assert_array_equal(same, matched)


def _drive(world, start, step, odometry, n, options):
    """Chained frontend poses (in the start's frame) over ``n`` steps of ``step`` with odometry deltas
    ``odometry``; the frontend too."""
    fe = create_frontend("icp", options or {})
    true = [np.asarray(start, float)]
    for _ in range(n):
        true.append(geometry.compose(true[-1], step))
    fe.process(scan_at(world, true[0], seed=0), np.zeros(3))
    pose = true[0]
    for k, p in enumerate(true[1:], start=1):
        pose = geometry.compose(pose, fe.process(scan_at(world, p, seed=k), odometry).delta)
    return fe, pose, true[-1]


def test_corridor_follows_odometry_along_and_the_scans_across(corridor):
    """Odometry says 0.25 m per scan (truth 0.20), drifting 2 cm sideways and 1 deg a scan: the fused
    poses take the distance travelled from odometry to the millimetre, position across the corridor
    and heading from the walls. Without the fusion the ledge drags the match along x."""
    start, step = np.array([0.0, 1.0, 0.0]), np.array([0.2, 0.0, 0.0])
    odometry = np.array([0.25, 0.02, np.deg2rad(1.0)])
    fe, pose, end = _drive(corridor, start, step, odometry, 6, FUSED)
    assert fe.events[DEGENERATE_EVENT] == 6
    assert abs(pose[0] - (start[0] + 6 * 0.25)) < 0.003  # along: odometry
    assert abs(pose[1] - end[1]) < 0.01 and abs(np.rad2deg(pose[2] - end[2])) < 0.3  # across: the walls
    plain, unfused, _ = _drive(corridor, start, step, odometry, 6, {"degeneracy_ratio": 0.0})
    assert not plain.events[DEGENERATE_EVENT]
    assert abs(unfused[0] - (start[0] + 6 * 0.25)) > 3 * abs(pose[0] - (start[0] + 6 * 0.25))


def test_frozen_odometry_in_a_constrained_room_is_overruled(room):
    """Odometry frozen (zero deltas) while the robot drives 5 cm and turns 2 deg a scan through a room
    whose scans constrain every direction: no direction is left to odometry, the poses follow the truth."""
    fe, pose, end = _drive(room, [1.5, 1.2, 0.0], np.array([0.05, 0.0, np.deg2rad(2.0)]), np.zeros(3), 8, FUSED)
    assert not fe.events[DEGENERATE_EVENT] and not fe.events[STILL_EVENT]
    assert_close_pose(pose, end, xy=0.02, theta_deg=0.5)
