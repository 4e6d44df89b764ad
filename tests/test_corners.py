"""Corner frontend: extraction and its rejection rules, the global corner list, confidences, landmarks."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from slam2d import config, geometry
from slam2d.datasets.registry import open_dataset
from slam2d.datasets.simulator import World
from slam2d.evaluation.trajectory import ate
from slam2d.frontends.corners import (
    CornerExtractionConfig,
    CornerFrontend,
    CornerMap,
    corner_confidence,
    extract_corners,
    match_corners,
)
from slam2d.frontends.odometry import odometry_information
from slam2d.pipeline import SlamPipeline
from slam2d.types import Scan

BEAMS = np.linspace(-np.pi, np.pi, 360, endpoint=False)


def polyline(*vertices) -> World:
    v = np.array(vertices, float)
    return World(np.stack([v[:-1], v[1:]], axis=1))


def ranges_of(world, pose, beams=BEAMS, noise=0.0, seed=0):
    r = world.raycast(pose[:2], beams + pose[2], 12.0)
    r = r + noise * np.random.default_rng(seed).standard_normal(len(r))
    return np.where(r < 11.9, r, np.nan)


def corners_at(world, pose, beams=BEAMS, noise=0.0, **cfg):
    ext = extract_corners(ranges_of(world, pose, beams, noise), beams, config=CornerExtractionConfig(**cfg))
    return ext, geometry.transform_points(pose, ext.points)


@pytest.mark.parametrize("noise", [0.0, 0.01])
def test_corner_of_two_perpendicular_walls(noise):
    pose = np.array([1.5, 1.2, 0.3])
    ext, points = corners_at(polyline((0, 0), (4, 0), (4, 3)), pose, noise=noise)
    assert len(points) == 1
    assert np.linalg.norm(points[0] - [4.0, 0.0]) < 0.002 + 2 * noise
    assert abs(abs(ext.turn[0]) - np.pi / 2) < np.deg2rad(0.5 + 600 * noise)


def test_occlusion_edge_is_a_candidate_but_rejected():
    # a short wall in front of a room corner: its free end, seen against the far wall, is a range jump
    world = World(np.concatenate([polyline((0, 0), (4, 0), (4, 3)).segments, [[[0.2, 0.8], [1.0, 0.8]]]]))
    pose = np.array([1.5, 1.6, 0.0])
    ext, points = corners_at(world, pose)
    assert np.linalg.norm(points - [4.0, 0.0], axis=1).min() < 0.01  # the real corner stays
    edge = np.arctan2(0.8 - 1.6, 1.0 - 1.5)  # bearing of the short wall's free end
    beam = int(np.argmin(np.abs(geometry.wrap_angle(BEAMS - edge))))
    assert np.abs(ext.candidates - beam).min() <= 3  # the edge is a derivative extremum
    assert np.all(np.linalg.norm(points - [1.0, 0.8], axis=1) > 0.3)  # but no corner there


def test_corners_in_the_border_beams_are_rejected():
    beams = np.linspace(-np.pi / 2, np.pi / 2, 181)  # 180 degrees, 1 degree: the thesis's laser
    pose = np.array([0.0, 0.0, 0.0])
    corner = np.array([2.0 * np.cos(beams[5]), 2.0 * np.sin(beams[5])])  # exactly on beam 5
    world = polyline(corner + [-3.0, 3.0], corner, corner + [3.0, 3.0])
    loose = dict(min_arm_beams=3, arm_gap=0)
    ext, _ = corners_at(world, pose, beams, border_beams=2, **loose)
    assert ext.index.tolist() == [5]
    ext, _ = corners_at(world, pose, beams, border_beams=6, **loose)
    assert len(ext.index) == 0 and 5 in ext.candidates


def test_global_corner_list_merges_within_threshold_and_appends_otherwise():
    corners = CornerMap(merge_radius=0.2, rebuild_every=4)
    assert corners.update([[0.0, 0.0]], index=0).tolist() == [0]
    assert corners.update([[0.1, 0.0]], index=1).tolist() == [0]  # within 0.2 m: the same corner
    assert corners.count.tolist() == [2] and corners.xy[0] == pytest.approx([0.05, 0.0])
    assert corners.update([[1.0, 0.0]], index=2).tolist() == [1]  # beyond: appended once
    assert corners.update([[3.0, 0.0], [3.05, 0.0]], index=3).tolist() == [2, 2]  # two sightings, one corner
    grid = np.array([[x, y] for x in range(5, 10) for y in range(5, 10)], float)
    assert corners.update(grid, index=4).tolist() == list(range(3, 28))
    assert len(corners) == 28
    idx, dist = corners.nearest([[7.05, 7.0], [20.0, 20.0]], radius=0.2)
    assert isinstance(corners.tree, cKDTree) and corners.tree.n >= 3  # look-ups go through the tree
    assert corners.xy[idx[0]] == pytest.approx([7.0, 7.0]) and dist[0] == pytest.approx(0.05)
    assert idx[1] == -1 and np.isinf(dist[1])
    corners.prune(index=100, min_count=2, max_age=10)  # drops the single sightings, ids stay
    assert corners.ids.tolist() == [0, 2]
    assert corners.update([[3.0, 0.1]], index=101).tolist() == [1]


def test_corner_confidence_follows_the_thesis():
    assert [corner_confidence(k) for k in range(5)] == [0.0, 0.33, 0.66, 1.0, 1.0]


@pytest.mark.parametrize(
    "vertices, expected",
    [
        ([(-1, 0), (4, 0), (4, 3)], 0.33),  # one corner
        ([(0, 3), (0, 0), (4, 0), (4, 3)], 0.66),  # two
        ([(0, 3), (0, 0), (4, 0), (4, 3), (2, 3)], 1.0),  # three
    ],
)
def test_frontend_confidence_for_1_2_3_matched_corners(vertices, expected):
    world = polyline(*vertices)
    fe = CornerFrontend(CornerFrontend.Config(gate={"enabled": False}))
    poses = np.array([[2.0, 1.5, 0.0], [2.05, 1.5, 0.01], [2.1, 1.52, 0.02]])
    results = []
    for k, pose in enumerate(poses):
        scan = Scan(stamp=k, ranges=ranges_of(world, pose), angles=BEAMS, range_min=0.05, range_max=12.0, index=k)
        results.append(fe.process(scan, np.zeros(3) if k == 0 else geometry.between(poses[k - 1], pose)))
    last = results[-1]  # corners need two sightings before they are matched
    assert last.confidence == expected
    assert len(last.landmarks) == round(expected * 3)
    assert len({obs.landmark_id for obs in last.landmarks}) == len(last.landmarks)
    truth = np.array([v for v in vertices[1:-1]], float)
    for obs in last.landmarks:
        local = [[obs.range * np.cos(obs.bearing), obs.range * np.sin(obs.bearing)]]
        seen = geometry.transform_points(poses[-1], local)
        assert np.linalg.norm(truth - seen, axis=1).min() < 0.01
        assert obs.covariance.shape == (2, 2) and obs.covariance[0, 0] < obs.covariance[1, 1]  # (bearing, range)
    assert np.allclose(last.delta, geometry.between(poses[1], poses[2]), atol=2e-3)


def test_pose_from_corners_recovers_an_offset_and_one_corner_is_weak():
    truth = np.array([1.0, 2.0, 0.3])
    ref = np.array([[4.0, 0.0], [4.0, 3.0], [0.0, 5.0]])
    obs = geometry.transform_points(geometry.inverse(truth), ref)
    guess = geometry.compose(truth, [0.08, -0.05, 0.03])
    prior = odometry_information(1.0, 30.0)  # weak: the corners decide
    m = match_corners(obs, ref, guess, prior, sigma=0.03)
    assert np.allclose(m.pose, truth, atol=1e-3) and m.inliers.all()
    one = match_corners(obs[:1], ref[:1], guess, prior, sigma=0.03)
    assert np.linalg.matrix_rank(one.information, tol=1e-6 * np.abs(one.information).max()) == 2
    assert np.linalg.eigvalsh(one.information)[0] < 1e-6 * np.linalg.eigvalsh(m.information)[0]
    # a wrong pair is dropped as an outlier
    bad = ref.copy()
    bad[2] += [0.5, 0.0]
    m = match_corners(np.vstack([obs, obs[:1] + 0.01]), np.vstack([bad, ref[:1]]), guess, prior, sigma=0.03)
    assert m.inliers.tolist() == [True, True, False, True]
    assert np.allclose(m.pose, truth, atol=0.01)


def test_corners_frontend_beats_odometry_on_the_simulator():
    cfg = config.load(None, ["dataset.max_scans=200", "frontend.name=corners"])
    result = SlamPipeline(cfg).run(open_dataset(cfg.dataset))
    est = ate(result.poses, result.ground_truth)["rmse"]
    odo = ate(result.odometry, result.ground_truth)["rmse"]
    assert est < odo, (est, odo)


def test_corner_matches_calibrate_a_bending_odometry():
    # a room with four corners; the odometry bends by 3 degrees per metre of a straight run
    world = polyline((0, 0), (8, 0), (8, 4), (0, 4), (0, 0))
    bend = np.deg2rad(3.0)
    poses = np.column_stack([np.linspace(2.0, 6.0, 81), np.full(81, 2.0), np.zeros(81)])
    runs = {}
    for enabled in (True, False):
        fe = CornerFrontend(CornerFrontend.Config(calibration={"enabled": enabled, "min_updates": 10}))
        est = np.zeros(3)
        for k, pose in enumerate(poses):
            scan = Scan(stamp=0.2 * k, ranges=ranges_of(world, pose, noise=0.005, seed=k), angles=BEAMS,
                        range_min=0.05, range_max=12.0, index=k)
            odom = np.zeros(3) if k == 0 else geometry.between(poses[k - 1], pose) - [0.0, 0.0, bend * 0.05]
            est = geometry.compose(est, fe.process(scan, odom).delta)
        runs[enabled] = (fe, geometry.between(geometry.between(poses[0], poses[-1]), est))
    fe, err = runs[True]
    assert fe.calibration.updates > 20
    assert fe.calibration.params[0] == pytest.approx(bend, rel=0.3)
    assert runs[False][0].calibration.updates == 0
    assert abs(err[2]) < np.deg2rad(0.5) and np.hypot(*err[:2]) < 0.05
