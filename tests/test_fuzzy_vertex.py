"""Fuzzy geometric units and vertex localisation (Chen & Zhang 2006): each formula on hand-made input."""

import numpy as np
import pytest

from slam2d import config, geometry
from slam2d.datasets.registry import open_dataset
from slam2d.evaluation.trajectory import ate
from slam2d.frontends import available_frontends
from slam2d.frontends import fuzzy_vertex as fv  # registers "fuzzy_vertex"
from slam2d.pipeline import SlamPipeline
from slam2d.types import Scan

SCALE = 1.0 / (1.0 - np.exp(-0.5))


def l_shape() -> np.ndarray:
    """Beam-ordered points: wall x = 3 (y up to 1.9 m), then wall y = 2 starting 0.1 m from the corner (3, 2)."""
    wall1 = np.column_stack([np.full(7, 3.0), [-1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 1.9]])
    wall2 = np.column_stack([[2.9, 2.5, 2.0, 1.5, 1.0, 0.5], np.full(6, 2.0)])
    return np.vstack([wall1, wall2])


def corner_points(noise: float = 0.0, seed: int = 0) -> np.ndarray:
    """Two perpendicular walls meeting at (3, 2) m, dense, in beam order."""
    rng = np.random.default_rng(seed)
    wall1 = np.column_stack([np.full(30, 3.0), np.linspace(-1.0, 1.95, 30)])
    wall2 = np.column_stack([np.linspace(2.95, 0.5, 30), np.full(30, 2.0)])
    pts = np.vstack([wall1, wall2])
    return pts + rng.normal(0.0, noise, pts.shape)


# --------------------------------------------------------------------------- twice classification


def test_coarse_pass_cuts_where_a_point_cannot_join():
    bounds, cuts = fv.coarse_classification(l_shape(), xi=0.15)
    # (2.9, 2) is within xi of the wall x = 3, so the coarse pass keeps it in Q1
    assert bounds.tolist() == [0, 8, 13]
    assert not cuts.any()


def test_fine_pass_moves_the_tail_point_to_the_next_line():
    pts = l_shape()
    coarse, cuts = fv.coarse_classification(pts, xi=0.15)
    fine = fv.fine_classification(pts, coarse, cuts)
    assert fine.tolist() == [0, 7, 13]  # (2.9, 2) moved to the wall y = 2
    bounds, _ = fv.twice_classification(pts, xi=0.15)
    assert bounds.tolist() == [0, 7, 13]


def test_gap_cut_separates_collinear_points():
    pts = np.column_stack([[0.0, 0.1, 0.2, 1.5, 1.6, 1.7], np.full(6, 2.0)])
    assert fv.coarse_classification(pts, xi=0.05)[0].tolist() == [0, 6]
    bounds, cuts = fv.coarse_classification(pts, xi=0.05, max_gap=0.5)
    assert bounds.tolist() == [0, 3, 6]
    assert cuts.tolist() == [False, True, False]


def test_collinear_set_definition_every_point_within_xi():
    # one point 0.2 m off a line: a set only while xi exceeds its leave-one-out distance
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.2], [3.0, 0.0], [4.0, 0.0]])
    assert fv.coarse_classification(pts, xi=0.4)[0].tolist() == [0, 5]
    assert len(fv.coarse_classification(pts, xi=0.1)[0]) > 2


# --------------------------------------------------------------------------- units


def test_half_width_formula():
    # eq. 3 by hand: residuals +-0.1 m, delta_a 0.1 m
    expected = SCALE * np.sqrt(0.01 + 0.01)
    assert fv.half_width([0.1, -0.1, -0.1, 0.1], 0.1) == pytest.approx(expected, rel=1e-12)
    assert fv.half_width([0.0, 0.0], 0.0) == 0.0


def test_unit_of_hand_made_points():
    pts = np.array([[0.0, 2.1], [1.0, 1.9], [2.0, 1.9], [3.0, 2.1]])  # least-squares line y = 2
    units = fv.fit_units(pts, [0, 4], delta_a=0.1)
    assert len(units) == 1
    assert units.l[0] == pytest.approx(SCALE * np.sqrt(0.01 + 0.01), rel=1e-9)
    assert units.n[0] == 4
    np.testing.assert_allclose(units.begin[0], [0.0, 2.0], atol=1e-12)  # end points projected on the line
    np.testing.assert_allclose(units.end[0], [3.0, 2.0], atol=1e-12)
    assert units.phi[0] == pytest.approx(np.pi / 2) and units.rho[0] == pytest.approx(2.0)
    a, b = units.slope_intercept()
    assert a[0] == pytest.approx(0.0, abs=1e-12) and b[0] == pytest.approx(2.0)


# --------------------------------------------------------------------------- vertices


def test_perpendicular_walls_give_one_vertex_at_the_corner():
    pts = corner_points(noise=0.005)
    bounds, _ = fv.twice_classification(pts, xi=0.03)
    units = fv.fit_units(pts, bounds, delta_a=0.02)
    assert len(units) == 2
    v = fv.extract_vertices(units, sigma=0.3)
    assert len(v) == 1
    np.testing.assert_allclose(v.o[0], [3.0, 2.0], atol=0.01)
    assert v.R[0] == min(units.l)  # eq. 5
    assert v.m[0] == 1
    assert sorted(np.rad2deg(v.arms[0]).round()) == [-90.0, 180.0]  # walls leave the corner down and left


def test_vertex_needs_joined_units():
    pts = corner_points()
    bounds, _ = fv.twice_classification(pts, xi=0.03)
    units = fv.fit_units(pts, bounds)
    gap = float(np.linalg.norm(units.end[0] - units.begin[1]))
    assert len(fv.extract_vertices(units, sigma=gap * 0.9)) == 0
    assert len(fv.extract_vertices(units, sigma=gap * 1.1)) == 1


def test_eq4_slopes_match_the_normal_form():
    a1, b1, a2, b2 = 0.5, 1.0, -2.0, 4.0
    o = fv.vertex_from_slopes(a1, b1, a2, b2)
    np.testing.assert_allclose(o, [1.2, 1.6])
    # the same lines in normal form: cos(phi) x + sin(phi) y = rho
    phi1, phi2 = np.arctan2(1.0, -a1), np.arctan2(1.0, -a2)
    rho1, rho2 = b1 * np.sin(phi1), b2 * np.sin(phi2)
    np.testing.assert_allclose(fv.line_intersection(phi1, rho1, phi2, rho2), o, atol=1e-12)


# --------------------------------------------------------------------------- matching, offset, update


def vertices(o, R, m=None, arms=None):
    o = np.asarray(o, float).reshape(-1, 2)
    m = np.ones(len(o)) if m is None else np.asarray(m, float)
    arms = np.zeros((len(o), 2)) if arms is None else np.asarray(arms, float)
    return fv.Vertices(o, np.asarray(R, float), m, arms, np.full(len(o), 0.01))


def test_matching_rule_distance_within_min_radius():
    local = vertices([[0.0, 0.0]], [0.5])
    assert fv.match_vertices(local, vertices([[0.3, 0.0]], [0.2]))[0].size == 0  # 0.3 > min(0.5, 0.2)
    li, gj = fv.match_vertices(local, vertices([[0.3, 0.0], [0.15, 0.0]], [0.2, 0.2]))
    assert li.tolist() == [0] and gj.tolist() == [1]
    li, _ = fv.match_vertices(local, vertices([[0.0, 0.2]], [0.2]))  # d == min(R, R') matches
    assert li.tolist() == [0]
    far = vertices([[0.0, 0.45]], [2.0])  # within R' but not within R
    assert fv.match_vertices(local, far)[0].tolist() == [0]
    assert fv.match_vertices(vertices([[0.0, 0.0]], [0.4]), far)[0].size == 0


def test_matching_checks_wall_directions_when_asked():
    local = vertices([[0.0, 0.0]], [0.5], arms=[[0.0, np.pi / 2]])
    turned = vertices([[0.1, 0.0]], [0.5], arms=[[np.pi / 2 + 0.1, 0.1]])  # same walls, other order
    assert fv.match_vertices(local, turned, max_arm_error=0.2)[0].tolist() == [0]
    assert fv.match_vertices(local, turned, max_arm_error=0.05)[0].size == 0


def test_offset_is_the_m_weighted_mean():
    glob = [[1.0, 1.0], [2.0, 2.0]]
    loc = [[0.9, 1.1], [2.2, 1.8]]
    v = fv.translation_offset(glob, loc, [3, 1])  # eq. 9
    np.testing.assert_allclose(v, [(3 * 0.1 - 0.2) / 4, (-3 * 0.1 + 0.2) / 4], atol=1e-15)


def test_update_rules_on_hand_computed_numbers():
    o, r, m = fv.update_vertices([[0.0, 0.0]], [0.4], [3], [[0.4, 0.0]], [0.3])
    np.testing.assert_allclose(o, [[0.1, 0.0]])  # (3 * 0 + 0.4) / 4
    np.testing.assert_allclose(r, [0.15])  # (0.4 + 0.3 - 0.4) / 2
    np.testing.assert_allclose(m, [4])
    _, r, _ = fv.update_vertices([[0.0, 0.0]], [0.1], [1], [[0.3, 0.0]], [0.1], min_radius=0.05)
    np.testing.assert_allclose(r, [0.05])  # (0.1 + 0.1 - 0.3) / 2 < 0: floored


@pytest.mark.parametrize("n", [2, 3, 6])
def test_se2_fit_recovers_a_known_pose(n):
    rng = np.random.default_rng(n)
    pose = np.array([1.5, -0.7, 0.4])
    local = rng.uniform(-5, 5, (n, 2))
    target = geometry.transform_points(pose, local)
    np.testing.assert_allclose(fv.fit_se2(local, target, rng.uniform(1, 5, n)), pose, atol=1e-12)


def test_se2_fit_weights_follow_m():
    local = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    target = local.copy()
    target[2] += [0.3, 0.0]  # one vertex disagrees
    light = fv.fit_se2(local, target, [100.0, 100.0, 1.0])
    heavy = fv.fit_se2(local, target, [1.0, 1.0, 100.0])
    assert np.abs(light).max() < np.abs(heavy).max()


def test_rigid_check_drops_the_inconsistent_match():
    local = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 2.0]])
    mapped = local + [5.0, 1.0]
    mapped[2] += [0.0, 1.0]
    assert fv.rigid_matches(local, mapped, np.full(3, 0.1)).tolist() == [True, True, False]


# --------------------------------------------------------------------------- unit fusion


def test_unit_fusion_weights_by_points():
    pts1 = np.column_stack([np.linspace(0, 2, 20), np.full(20, 2.0)])
    pts2 = np.column_stack([np.linspace(1, 3, 10), np.full(10, 2.1)])
    u1, u2 = fv.fit_units(pts1, [0, 20], 0.05), fv.fit_units(pts2, [0, 10], 0.05)
    li, gj = fv.match_units(u1, u2, np.zeros(2))
    assert li.tolist() == [0] and gj.tolist() == [0]
    fused = fv.fuse_units(u1, u2, np.zeros(2))
    assert fused.n[0] == 30  # eq. 17
    d12 = (20 * u2.l[0] * 2.0 + 10 * u1.l[0] * 2.1) / (20 * u2.l[0] + 10 * u1.l[0])  # eq. 21
    assert fused.rho[0] == pytest.approx(d12)
    np.testing.assert_allclose(fused.begin[0], [0.0, d12], atol=1e-9)  # outermost projections
    np.testing.assert_allclose(fused.end[0], [3.0, d12], atol=1e-9)
    assert fused.l[0] == pytest.approx((20 * u1.l[0] + 10 * u2.l[0]) / 30 - 0.05)  # eq. 20 as read
    far = fv.fit_units(pts2 + [0.0, 1.0], [0, 10], 0.05)  # a parallel wall 1 m away
    assert fv.match_units(u1, far, np.zeros(2))[0].size == 0


# --------------------------------------------------------------------------- the frontend


def scan_of(points: np.ndarray, index: int = 0) -> Scan:
    angles = np.arctan2(points[:, 1], points[:, 0])
    order = np.argsort(angles)
    return Scan(0.1 * index, np.linalg.norm(points, axis=1)[order], angles[order], 0.05, 20.0, index=index)


def room_scan(pose, index: int) -> Scan:
    """A 360-beam scan of a 6 m x 4 m room with an inner box, from ``pose``."""
    from slam2d.datasets.simulator import World

    room = [[0, 0], [6, 0], [6, 4], [0, 4]]
    box = [[4, 1], [5, 1], [5, 2], [4, 2]]
    world = World.from_polygons([room, box])
    angles = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    ranges = world.raycast_poses(np.asarray(pose)[None], angles, 20.0)[0]
    return Scan(0.1 * index, ranges, angles, 0.05, 20.0, index=index)


def test_registered_by_name():
    assert "fuzzy_vertex" in available_frontends()


def test_frontend_corrects_odometry_and_emits_stable_landmarks():
    truth = np.array([[1.0, 1.0, 0.0], [1.2, 1.05, 0.05], [1.4, 1.1, 0.1]])
    front = fv.FuzzyVertexFrontend(fv.FuzzyVertexFrontend.Config(max_mahalanobis=None))
    front.process(room_scan(truth[0], 0), np.zeros(3))
    ids = None
    for k in (1, 2):
        true_delta = geometry.between(truth[k - 1], truth[k])
        odom = true_delta + [0.03, -0.02, 0.01]  # biased odometry
        result = front.process(room_scan(truth[k], k), odom)
        assert np.abs(result.delta - true_delta).max() < np.abs(odom - true_delta).max()
        assert len(result.landmarks) >= 2 and 0 < result.confidence < 1
        seen = {obs.landmark_id for obs in result.landmarks}
        ids = seen if ids is None else ids
        assert seen & ids  # the same corners keep their ids
        for obs in result.landmarks:  # (bearing, range) order, as gtsam's BearingRange; isotropic in the plane
            bearing_var, range_var = np.diag(obs.covariance)
            assert bearing_var * obs.range**2 == pytest.approx(range_var, rel=1e-9)
        assert np.linalg.eigvalsh(result.information).min() > 0
    assert not front.events


def test_translation_mode_keeps_the_odometry_heading():
    truth = np.array([[1.0, 1.0, 0.0], [1.2, 1.0, 0.0]])
    paper = dict(heading="translation", arm_heading=False, wall_heading=False, odometry_prior=False)
    front = fv.FuzzyVertexFrontend(fv.FuzzyVertexFrontend.Config(**paper))
    front.process(room_scan(truth[0], 0), np.zeros(3))
    result = front.process(room_scan(truth[1], 1), np.array([0.25, 0.04, 0.0]))
    assert result.delta[2] == 0.0
    np.testing.assert_allclose(result.delta[:2], [0.2, 0.0], atol=0.01)


def test_fallback_to_odometry_is_counted():
    front = fv.FuzzyVertexFrontend()
    empty = Scan(0.0, np.full(10, np.nan), np.linspace(-1, 1, 10), 0.05, 20.0)
    front.process(empty, np.zeros(3))
    odom = np.array([0.1, 0.0, 0.02])
    result = front.process(empty, odom)
    np.testing.assert_allclose(result.delta, odom)
    assert result.confidence == 0.0 and result.landmarks == ()
    assert front.events["too few vertices matched"] == 1


def test_pipeline_by_name_beats_odometry_on_the_simulator():
    cfg = config.load(None, ["dataset.max_scans=200", "frontend.name=fuzzy_vertex"])
    result = SlamPipeline(cfg).run(open_dataset(cfg.dataset))
    est = ate(result.poses, result.ground_truth)["rmse"]
    odo = ate(result.odometry, result.ground_truth)["rmse"]
    assert est < odo
