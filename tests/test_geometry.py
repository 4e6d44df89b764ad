"""SE(2) maths against gtsam.Pose2 (property tests)."""

import gtsam
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slam2d import geometry

coord = st.floats(-50, 50, allow_nan=False)
angle = st.floats(-10, 10, allow_nan=False)
pose = st.tuples(coord, coord, angle).map(np.array)


def P(p):
    return gtsam.Pose2(*p)


def arr(g):
    return np.array([g.x(), g.y(), g.theta()])


def close_pose(a, b, tol=1e-9):
    assert np.allclose(a[..., :2], b[..., :2], atol=tol)
    assert np.allclose(geometry.wrap_angle(a[..., 2] - b[..., 2]), 0, atol=tol)


@settings(max_examples=200, deadline=None)
@given(pose, pose)
def test_compose_between_inverse_match_gtsam(a, b):
    close_pose(geometry.compose(a, b), arr(P(a).compose(P(b))))
    close_pose(geometry.between(a, b), arr(P(a).between(P(b))))
    close_pose(geometry.inverse(a), arr(P(a).inverse()))


@settings(max_examples=100, deadline=None)
@given(pose, st.lists(st.tuples(coord, coord), min_size=1, max_size=5))
def test_transform_points_matches_gtsam(a, pts):
    pts = np.array(pts, float)
    expected = np.array([P(a).transformFrom(gtsam.Point2(*p)) for p in pts])
    assert np.allclose(geometry.transform_points(a, pts), expected, atol=1e-9)


def test_vectorised_equals_loop():
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(50, 3)) * 5, rng.normal(size=(50, 3)) * 5
    for f in (geometry.compose, geometry.between):  # one pose takes a scalar path
        batch = f(a, b)
        for i in range(50):
            close_pose(batch[i], f(a[i], b[i]))
    batch = geometry.inverse(a)
    for i in range(50):
        close_pose(batch[i], geometry.inverse(a[i]))
    close_pose(geometry.compose(a[0], b), np.array([geometry.compose(a[0], bi) for bi in b]))


def test_wrap_angle_range():
    a = geometry.wrap_angle(np.linspace(-20, 20, 1001))
    assert a.min() >= -np.pi and a.max() < np.pi
    assert np.allclose(np.sin(a), np.sin(np.linspace(-20, 20, 1001)))


def test_interpolate_midpoint_and_shortest_arc():
    stamps = np.array([0.0, 1.0])
    poses = np.array([[0, 0, np.pi - 0.1], [2, 4, -np.pi + 0.1]])
    mid = geometry.interpolate(stamps, poses, 0.5)
    assert np.allclose(mid[:2], [1, 2])
    assert abs(abs(mid[2]) - np.pi) < 1e-9  # through pi, not through 0
    clamped = geometry.interpolate(stamps, poses, [-1.0, 5.0])
    assert np.allclose(clamped, poses)


def test_interpolate_one_stamp_equals_many():
    rng = np.random.default_rng(2)
    stamps = np.sort(rng.uniform(0, 10, 30))
    stamps[5] = stamps[4]  # a repeated stamp
    poses = rng.normal(size=(30, 3)) * 3
    query = np.concatenate([rng.uniform(-1, 11, 200), stamps[3:7]])
    batch = geometry.interpolate(stamps, poses, query)
    for q, expected in zip(query, batch):
        close_pose(geometry.interpolate(stamps, poses, q), expected)


def test_bad_pose_shape():
    with pytest.raises(ValueError, match="3 values"):
        geometry.compose([1, 2], [0, 0, 0])


@settings(max_examples=50, deadline=None)
@given(pose)
def test_adjoint_matches_gtsam(a):
    assert np.allclose(geometry.adjoint(a), P(a).AdjointMap(), atol=1e-9)


@settings(max_examples=50, deadline=None)
@given(pose, pose)
def test_adjoint_and_logmap_of_many_poses_match_gtsam(a, b):
    import gtsam

    both = np.array([a, b])
    assert np.allclose(geometry.adjoint(both), [P(a).AdjointMap(), P(b).AdjointMap()], atol=1e-9)
    assert np.allclose(geometry.logmap(both), [gtsam.Pose2.Logmap(P(a)), gtsam.Pose2.Logmap(P(b))], atol=1e-7)


def test_compose_covariance_matches_sampling():
    rng = np.random.default_rng(0)
    a, b = np.array([1.0, 0.5, 0.3]), np.array([0.8, -0.2, -0.5])
    cov_a, cov_b = np.diag([0.01, 0.02, 0.03]) ** 2 * 10, np.diag([0.02, 0.01, 0.02]) ** 2 * 10
    n = 40000
    ea = rng.multivariate_normal(np.zeros(3), cov_a, n)
    eb = rng.multivariate_normal(np.zeros(3), cov_b, n)
    # perturb in the local tangent space (retract ~ compose with the small pose)
    pa = np.array([P(a).compose(gtsam.Pose2.Expmap(e)) for e in ea[:4000]])
    pb = np.array([P(b).compose(gtsam.Pose2.Expmap(e)) for e in eb[:4000]])
    c = P(a).compose(P(b))
    errs = np.array([gtsam.Pose2.Logmap(c.between(x.compose(y))) for x, y in zip(pa, pb)])
    assert np.allclose(np.cov(errs.T), geometry.compose_covariance(cov_a, b, cov_b), atol=2e-4)
