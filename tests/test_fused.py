"""The similarity gate and the information-weighted fusion of frontends."""

import numpy as np
import pytest

from slam2d import config, geometry
from slam2d.datasets.registry import open_dataset
from slam2d.evaluation.trajectory import ate
from slam2d.frontends.base import FrontendResult
from slam2d.frontends.common import bound_information
from slam2d.frontends.fused import FusedFrontend, fuse_deltas, se2_exp, se2_log
from slam2d.frontends.gate import SimilarityGate, nn_similarity
from slam2d.frontends.odometry import HeadingCalibration
from slam2d.pipeline import SlamPipeline
from slam2d.types import Scan


def wall_points(n=200, y=2.0):
    x = np.linspace(-4, 4, n)
    return np.column_stack([x, np.full(n, y)])


# --------------------------------------------------------------------------- gate


def test_nn_similarity_is_reflexive_symmetric_and_drops_for_other_scenes():
    a = wall_points()
    b = np.vstack([wall_points(100, 2.0), wall_points(100, -3.0)])
    assert nn_similarity(a, a) == 1.0
    assert nn_similarity(a, b) == nn_similarity(b, a)
    assert nn_similarity(a, wall_points(200, 5.0)) == 0.0
    assert 0.2 < nn_similarity(a, b) < 0.9


def test_gate_falls_back_when_similarity_drops():
    gate = SimilarityGate(SimilarityGate.Config(min_similarity=0.5, min_relative=0.7, min_confidence=0.3))
    odom = np.array([0.1, 0.0, 0.0])
    good = FrontendResult(delta=np.array([0.11, 0.01, 0.0]), information=np.eye(3) * 1e4, confidence=0.9)
    points = wall_points()
    moved = geometry.transform_points(geometry.inverse(odom), points)  # the same wall after moving by odom
    assert gate.check(None, points, good, odom) is good
    assert gate.check(points, moved, good, odom) is good
    assert gate.last_similarity == pytest.approx(1.0, abs=0.02)
    other = wall_points(200, -1.0)  # a doorway: the next scan sees something else
    out = gate.check(moved, other, good, odom)
    assert out is not good and out.confidence == 0.0
    assert np.array_equal(out.delta, odom) and np.array_equal(out.information, gate.odometry_information)
    assert gate.events == {"gate: similarity below min_similarity": 1}
    weak = FrontendResult(delta=good.delta, information=good.information, confidence=0.1)
    again = geometry.transform_points(geometry.inverse(odom), other)
    assert gate.check(other, again, weak, odom).confidence == 0.0
    assert gate.events["gate: confidence below min_confidence"] == 1


def test_gate_catches_a_dip_relative_to_the_usual_similarity():
    gate = SimilarityGate(SimilarityGate.Config(min_similarity=0.1, min_relative=0.8))
    for s in [0.95, 0.96, 0.94, 0.95]:
        assert gate.continuity(s) is None
    assert gate.continuity(0.6) == "similarity dip"  # above min_similarity but far below the usual


def calibration_run(curvature, scale, steps=400, noise_deg=0.3, seed=0, **cfg):
    """Feed a HeadingCalibration odometry deltas bent by ``curvature`` (rad/m) and ``scale``; a match
    every 3rd scan measures the heading error of the corrected prediction (with noise). Returns the
    calibration and the heading error (rad) left in the corrected deltas over the last 100 steps."""
    rng = np.random.default_rng(seed)
    cal = HeadingCalibration(HeadingCalibration.Config(**cfg))
    span, left = 0.0, []
    for k in range(steps):
        true = np.array([0.1, 0.0, np.deg2rad(5.0) * np.sin(k / 7.0)])
        odom = true.copy()
        odom[2] = true[2] - curvature * true[0] - scale * true[2]  # the odometry bends and mis-scales turns
        corrected = cal.correct(odom)
        span += corrected[2] - true[2]
        if k >= steps - 100:
            left.append(corrected[2] - true[2])
        if k % 3 == 2:
            error = -span + np.deg2rad(noise_deg) * rng.standard_normal()  # match heading - predicted
            cal.observe(np.array([0.0, 0.0, error]), np.zeros(3))
            span = 0.0
    return cal, np.sum(left)


def test_heading_calibration_learns_curvature_and_turn_scale():
    curvature, scale = np.deg2rad(2.0), 0.04
    cal, left = calibration_run(curvature, scale)
    assert cal.params[0] == pytest.approx(curvature, rel=0.15)
    assert cal.params[1] == pytest.approx(scale, abs=0.01)
    assert np.all(cal.applied != 0)
    _, raw = calibration_run(curvature, scale, enabled=False)
    assert abs(left) < 0.2 * abs(raw)  # the corrected odometry drifts far less


def test_heading_calibration_leaves_unbiased_odometry_alone():
    cal, left = calibration_run(0.0, 0.0)
    assert np.all(cal.applied == 0)  # nothing significant: odometry is used as it is
    delta = np.array([0.1, 0.02, 0.03])
    np.testing.assert_array_equal(cal.correct(delta), delta)
    off, _ = calibration_run(np.deg2rad(2.0), 0.0, enabled=False)
    assert np.all(off.params == 0) and off.updates == 0


def test_bounded_information_keeps_the_std_within_limits():
    info = np.diag([1e12, 1e-6, 1.0])
    out = bound_information(info, np.array([0.01, 0.01, 0.01]), np.array([1.0, 1.0, 1.0]))
    assert np.allclose(np.diag(out), [1e4, 1.0, 1.0])


# --------------------------------------------------------------------------- fusion


def test_se2_log_inverts_exp():
    for xi in ([0.3, -0.2, 0.0], [0.3, -0.2, 1.2], [-1.0, 0.5, -2.5]):
        assert np.allclose(se2_log(se2_exp(xi)), xi)
    assert np.allclose(se2_exp([1.0, 0.0, np.pi / 2]), [2 / np.pi, 2 / np.pi, np.pi / 2])


def test_fusion_is_the_information_weighted_mean():
    odom = np.array([1.0, 0.0, 0.0])
    a, wa = np.array([1.1, 0.0, 0.0]), np.diag([100.0, 100.0, 100.0])
    b, wb = np.array([1.0, 0.2, 0.0]), np.diag([300.0, 100.0, 100.0])
    delta, info = fuse_deltas(odom, [a, b], [wa, wb])
    # by hand: x = (100 * 0.1 + 300 * 0) / 400, y = (100 * 0 + 100 * 0.2) / 200, theta = 0
    assert np.allclose(delta, [1.025, 0.1, 0.0])
    assert np.allclose(info, np.diag([200.0, 100.0, 100.0]))  # sum / 2 sources
    _, unscaled = fuse_deltas(odom, [a, b], [wa, wb], scale=False)
    assert np.allclose(unscaled, np.diag([400.0, 200.0, 200.0]))
    # correlated information: the weighted mean uses the full matrices
    wc = np.array([[100.0, 50.0, 0.0], [50.0, 100.0, 0.0], [0.0, 0.0, 100.0]])
    delta, _ = fuse_deltas(np.zeros(3), [[0.1, 0.0, 0.0], [0.0, 0.0, 0.0]], [wc, np.eye(3) * 100.0])
    expected = np.linalg.solve(wc + 100 * np.eye(3), wc @ [0.1, 0.0, 0.0])
    assert np.allclose(delta, expected)


class Fixed:
    """A stand-in source returning a fixed result."""

    def __init__(self, result):
        self.result, self.events = result, {"stub reason": 2}

    def process(self, scan, odom_delta):
        return self.result


def scan_of(points, k):
    r, a = np.hypot(points[:, 0], points[:, 1]), np.arctan2(points[:, 1], points[:, 0])
    order = np.argsort(a)
    return Scan(stamp=float(k), ranges=r[order], angles=a[order], range_min=0.01, range_max=30.0, index=k)


ODOM = np.array([0.1, 0.0, 0.0])  # odometry delta between the two wall scans of fuse_two_scans


def fuse_two_scans(cfg, lines_result, corners_result):
    """A FusedFrontend whose lines and corners sources answer with fixed results, run on a wall
    scan and the same wall after moving ODOM; the frontend and its result for the second scan."""
    fe = FusedFrontend(cfg)
    fe.sources = {"lines": Fixed(lines_result), "corners": Fixed(corners_result)}
    points = wall_points()
    fe.process(scan_of(points, 0), np.zeros(3))
    return fe, fe.process(scan_of(geometry.transform_points(geometry.inverse(ODOM), points), 1), ODOM)


def test_fused_frontend_gates_each_source_and_combines_the_rest():
    cfg = FusedFrontend.Config(sources=["lines", "corners"], min_confidence={"lines": 0.3, "corners": 0.66})
    a = FrontendResult(delta=np.array([0.12, 0.0, 0.0]), information=np.diag([100.0, 100.0, 100.0]), confidence=0.9)
    b = FrontendResult(delta=np.array([0.10, 0.02, 0.0]), information=np.diag([300.0, 100.0, 100.0]), confidence=0.66)
    fe, out = fuse_two_scans(cfg, a, b)
    odom, points = ODOM, wall_points()
    assert np.allclose(out.delta, [0.105, 0.01, 0.0])
    assert np.allclose(out.information, np.diag([200.0, 100.0, 100.0]))
    # corners at 0.33 (one corner) is below its threshold: lines alone
    fe.sources["corners"] = Fixed(FrontendResult(delta=b.delta, information=b.information, confidence=0.33))
    out = fe.process(scan_of(geometry.transform_points(geometry.inverse(odom), points), 2), odom)
    assert np.allclose(out.delta, a.delta) and np.allclose(out.information, a.information)
    assert fe.events["gate corners: confidence below min_confidence"] == 1
    assert fe.events["lines: stub reason"] == 2
    # a scan unlike the previous one: odometry
    out = fe.process(scan_of(wall_points(200, -6.0), 3), odom)
    assert np.array_equal(out.delta, odom) and out.confidence == 0.0
    assert fe.events["no source accepted"] == 1


def test_fused_frontend_beats_odometry_on_the_simulator():
    cfg = config.load(None, ["dataset.max_scans=200", "frontend.name=fused"])
    pipeline = SlamPipeline(cfg)
    result = pipeline.run(open_dataset(cfg.dataset))
    est = ate(result.poses, result.ground_truth)["rmse"]
    odo = ate(result.odometry, result.ground_truth)["rmse"]
    assert est < 0.5 * odo, (est, odo)
    assert set(pipeline.frontend.sources) == {"lines", "corners", "icp"}
    assert result.stats["frontend fused lines"] > 150


def test_fused_weights_scale_each_source_information():
    cfg = FusedFrontend.Config(sources=["lines", "corners"], weights={"lines": 3.0, "corners": 1.0})
    a = FrontendResult(delta=np.array([0.12, 0.0, 0.0]), information=np.diag([100.0, 100.0, 100.0]), confidence=0.9)
    b = FrontendResult(delta=np.array([0.10, 0.02, 0.0]), information=np.diag([300.0, 100.0, 100.0]), confidence=1.0)
    _, out = fuse_two_scans(cfg, a, b)
    # by hand: x = 0.1 + (300 * 0.02 + 300 * 0) / 600, y = (300 * 0 + 100 * 0.02) / 400
    assert np.allclose(out.delta, [0.11, 0.005, 0.0])
    assert np.allclose(out.information, np.diag([300.0, 200.0, 200.0]))
