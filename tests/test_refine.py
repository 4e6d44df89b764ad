"""Dense refinement: keyframes aligned point-to-line to each other's scans after the final batch."""

import numpy as np
import pytest

from slam2d import config, geometry
from slam2d.backend import dense
from slam2d.backend.pose_graph import PoseGraph
from slam2d.backend.refine import pairs_within, refine
from slam2d.config import RefineConfig
from slam2d.datasets.registry import open_dataset
from slam2d.evaluation.trajectory import ate


def _keyframes(n_scans=400, every=2):
    """Every ``every``-th scan of the simulator's office route: points (base frame) and true poses."""
    cfg = config.load(None, [f"dataset.max_scans={n_scans}"])
    scans = list(open_dataset(cfg.dataset, seed=0))[::every]
    return [s.points_in_base() for s in scans], np.array([s.ground_truth for s in scans])


def _perturbed_graph(truth, sigma_xy=0.03, sigma_theta_deg=1.0, seed=3):
    """A graph whose odometry chain puts the keyframes at the truth plus known noise."""
    rng = np.random.default_rng(seed)
    noisy = truth + rng.normal(0, [sigma_xy, sigma_xy, np.deg2rad(sigma_theta_deg)], truth.shape)
    noisy[0] = truth[0]
    graph = PoseGraph()
    info = np.diag([1 / 0.05**2, 1 / 0.05**2, 1 / np.deg2rad(2.0) ** 2])
    graph.add_keyframe(noisy[0])
    for k in range(1, len(noisy)):
        graph.add_keyframe(noisy[k], geometry.between(noisy[k - 1], noisy[k]), info)
    graph.optimize_batch()
    return graph


def test_refinement_lowers_the_error_of_a_known_perturbation():
    points, truth = _keyframes()
    graph = _perturbed_graph(truth)
    before = ate(graph.estimate(), truth)["rmse"]
    assert before > 0.02  # the perturbation is there
    poses, stats = refine(graph, points, RefineConfig(rounds=2))
    after = ate(poses, truth)["rmse"]
    assert after < 0.3 * before, (before, after)
    assert stats["dense pairs kept"] > len(truth)
    assert np.allclose(graph.estimate(), poses)  # the graph holds the refined poses


def test_pairs_face_the_same_way_and_lie_within_the_radius():
    poses = np.array([[0, 0, 0], [0.5, 0, 0.1], [0.5, 0.1, np.pi], [3, 0, 0]])
    assert pairs_within(poses, 1.0).tolist() == [[0, 1]]


def test_alignment_finds_a_shift_along_the_lines_it_sees():
    """An L-shaped corner: the source, moved 5 cm and 1 degree, is put back; the information is
    large along both walls' normals."""
    wall = np.linspace(0, 3, 120)
    corner = np.vstack([np.column_stack([wall, np.full_like(wall, 2.0)]), np.column_stack([np.full_like(wall, 3.0), wall - 1])])
    truth = np.array([0.05, -0.03, np.deg2rad(1.0)])
    source = geometry.transform_points(geometry.inverse(truth), corner)
    pose, info, share = dense.align_pairs([dense.surface(corner)], [source], [[0, 0]], np.zeros((1, 3)))
    assert np.allclose(pose[0], truth, atol=2e-3), pose
    assert share[0] > 0.9
    assert np.linalg.eigvalsh(info[0]).min() > 1e4


def test_a_corridor_leaves_the_direction_along_it_unconstrained():
    wall = np.linspace(0, 6, 200)
    corridor = np.vstack([np.column_stack([wall, np.full_like(wall, 1.0)]), np.column_stack([wall, np.full_like(wall, -1.0)])])
    _, info, _ = dense.align_pairs([dense.surface(corridor)], [corridor], [[0, 0]], np.zeros((1, 3)))
    assert info[0][0, 0] < 1e-6 * info[0][1, 1]


@pytest.mark.parametrize("rounds", [0, 1])
def test_the_back_end_refines_only_when_asked(rounds):
    from slam2d.pipeline import SlamPipeline

    cfg = config.load(None, ["dataset.max_scans=200", f"backend.refine.rounds={rounds}"])
    result = SlamPipeline(cfg).run(open_dataset(cfg.dataset, seed=cfg.seed))
    assert ("dense pairs kept" in result.stats) == bool(rounds)
