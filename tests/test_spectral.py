"""Spectral clustering: Laplacian, eigenvectors, silhouette, k choice, labelling, end to end."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError
from scipy import sparse
from sklearn.metrics import silhouette_samples as sk_samples
from sklearn.metrics import silhouette_score

import slam2d.segmentation.spectral as spectral
from slam2d.errors import InputError
from slam2d.segmentation.evaluate import score
from slam2d.segmentation.labelling import label_free_cells, merge_open_boundaries
from slam2d.segmentation.observations import virtual_observations
from slam2d.segmentation.spectral import (
    SpectralConfig,
    binarise,
    choose_k,
    random_walk_laplacian,
    row_normalise,
    second_order,
    segment_spectral,
    silhouette,
    silhouette_samples,
    spectral_clusters,
    spectral_embedding,
)

RES = 0.05


def blocks(sizes, inside=0.8, outside=0.02, seed=0) -> np.ndarray:
    """Symmetric similarity with dense blocks of the given sizes plus noise."""
    rng = np.random.default_rng(seed)
    n = sum(sizes)
    lab = np.repeat(np.arange(len(sizes)), sizes)
    s = np.where(lab[:, None] == lab[None, :], inside, outside) + rng.uniform(0, 0.05, (n, n))
    s = np.minimum((s + s.T) / 2, 1.0)
    np.fill_diagonal(s, 1.0)
    return s


# --------------------------------------------------------------------------- Laplacian and eigenvectors


def test_random_walk_laplacian_against_numpy():
    s = blocks([3, 4])
    s[0, 0] = 0.3  # the diagonal is set to 1 first
    expected = np.eye(7) - np.linalg.inv(np.diag(np.where(np.eye(7, dtype=bool), 1.0, s).sum(1))) @ np.where(
        np.eye(7, dtype=bool), 1.0, s
    )
    np.testing.assert_allclose(random_walk_laplacian(s), expected, atol=1e-12)


@pytest.mark.parametrize("dense_max", [10_000, 5])
def test_embedding_is_the_smallest_eigenpairs_of_l_rw(monkeypatch, dense_max):
    monkeypatch.setattr(spectral, "DENSE_EIGEN_MAX", dense_max)  # LAPACK and ARPACK paths
    s = blocks([6, 8, 10])
    lam, u = spectral_embedding(s, 4)
    l_rw = random_walk_laplacian(s)
    ref = np.sort(np.linalg.eigvals(l_rw).real)[:4]
    np.testing.assert_allclose(lam, ref, atol=1e-6)
    np.testing.assert_allclose(l_rw @ u, u * lam, atol=1e-6)  # right eigenvectors of L_rw
    assert lam[0] == pytest.approx(0.0, abs=1e-9)


def test_sparse_and_dense_inputs_agree():
    s = blocks([5, 7])
    lam_d, _ = spectral_embedding(s, 3)
    lam_s, _ = spectral_embedding(sparse.csr_array(s), 3)
    np.testing.assert_allclose(lam_d, lam_s, atol=1e-9)


def test_zero_degree_gets_the_thesis_shift():
    d = spectral._degrees(np.array([[0.0, 0.0], [0.0, 1.0]]))
    np.testing.assert_allclose(d, [0.01, 1.01])


def test_binarise_by_acceptance_ratio():
    s = np.array([[1.0, 0.1, 0.9], [0.1, 1.0, 0.5], [0.9, 0.5, 1.0]])
    # switch = 0.1 + 0.95 * (0.9 - 0.1) = 0.86: only the 0.9 edge survives
    np.testing.assert_array_equal(binarise(s, 0.95), [[1, 0, 1], [0, 1, 0], [1, 0, 1]])
    sp = binarise(sparse.csr_array(s), 0.5).toarray()  # switch 0.5: 0.9 only (strictly greater)
    np.testing.assert_array_equal(sp, [[1, 0, 1], [0, 1, 0], [1, 0, 1]])


def test_second_order_is_a_cosine():
    s = blocks([3, 3])
    c = second_order(s)
    n = np.linalg.norm(s, axis=1)
    np.testing.assert_allclose(c, (s @ s.T) / np.outer(n, n), atol=1e-12)
    np.testing.assert_allclose(np.diag(c), 1.0)


# --------------------------------------------------------------------------- silhouette and k


def test_silhouette_hand_computed():
    x = np.array([[0.0], [1.0], [10.0], [11.0]])
    # a = 1 everywhere; b = 10.5, 9.5, 9.5, 10.5
    expected = np.mean([(10.5 - 1) / 10.5, (9.5 - 1) / 9.5, (9.5 - 1) / 9.5, (10.5 - 1) / 10.5])
    assert silhouette(x, [0, 0, 1, 1]) == pytest.approx(expected)


def test_silhouette_matches_scikit_learn():
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.normal(c, 0.5, (15, 3)) for c in (0, 3, 6)])
    lab = np.repeat([0, 1, 2], 15)
    lab[[0, 20]] = [2, 0]  # a few bad assignments
    lab[44] = 3  # and a singleton cluster (s = 0 by definition)
    assert silhouette(x, lab) == pytest.approx(silhouette_score(x, lab), abs=1e-12)
    d = np.sqrt(((x[:, None] - x[None]) ** 2).sum(-1))
    np.testing.assert_allclose(silhouette_samples(d, lab), sk_samples(d, lab, metric="precomputed"), atol=1e-12)


def test_silhouette_needs_two_clusters():
    with pytest.raises(InputError):
        silhouette(np.zeros((3, 2)), [1, 1, 1])


def test_choose_k_finds_the_block_count():
    s = blocks([10, 12, 8, 9])
    _, u = spectral_embedding(s, 8)
    k, lab, sc, scores = choose_k(u, range(2, 9), 1.0 - s)
    assert k == 4 and set(scores) == set(range(2, 9)) and sc == max(scores.values())
    assert len(set(zip(np.repeat(range(4), [10, 12, 8, 9]), lab))) == 4  # blocks are the clusters
    k_emb, _, _, _ = choose_k(u, range(2, 9))  # silhouette on the embedding (thesis reading)
    assert k_emb == 4


def test_spectral_clusters_recovers_blocks_and_is_seeded():
    s = blocks([15, 20, 10])
    lab, k, sc = spectral_clusters(s)
    assert k == 3 and sc > 0.5
    truth = np.repeat([0, 1, 2], [15, 20, 10])
    assert len(set(zip(truth, lab))) == 3
    lab2, _, _ = spectral_clusters(s)
    np.testing.assert_array_equal(lab, lab2)
    fixed, k2, _ = spectral_clusters(s, k=2)
    assert k2 == 2 and len(np.unique(fixed)) == 2
    binary, kb, _ = spectral_clusters(s, accept_ratio=0.5)
    assert kb == 3


def test_row_normalise_keeps_zero_rows():
    f = row_normalise(np.array([[3.0, 4.0], [0.0, 0.0]]))
    np.testing.assert_allclose(f, [[0.6, 0.8], [0.0, 0.0]])


# --------------------------------------------------------------------------- labelling the grid


def two_rooms(door_m=0.9) -> np.ndarray:
    """Two 4 m x 4 m rooms side by side joined by a door in a 0.2 m wall (free mask)."""
    free = np.zeros((88, 172), dtype=bool)
    free[4:-4, 4:-4] = True
    free[:, 84:88] = False
    if door_m:
        half = int(door_m / RES / 2)
        free[44 - half : 44 + half, 84:88] = True
    return free


def two_rooms_gt(free) -> np.ndarray:
    gt = np.zeros(free.shape, dtype=np.int32)
    gt[4:-4, 4:84] = 1
    gt[4:-4, 88:-4] = 2
    return gt


def test_two_rooms_joined_by_a_door_come_out_as_two_regions():
    free = two_rooms()
    res = segment_spectral(free, RES)
    assert res.labels.shape == free.shape and res.labels.dtype == np.int32
    assert res.k == 2
    assert set(np.unique(res.labels[free])) == {1, 2} and not res.labels[~free].any()
    s = score(res.labels, two_rooms_gt(free))
    assert s["recall"] > 97 and s["precision"] > 97
    assert res.seconds > 0 and set(res.timings["cpu"]) >= {"observations", "similarity", "clustering"}


@pytest.mark.parametrize("rule", ["fraction", "vote", "nearest"])
def test_label_free_cells_follows_observation_labels(rule):
    free = two_rooms(door_m=None)
    obs = virtual_observations(free, RES, spacing_m=1.0)
    obs_labels = (obs.poses[:, 0] > 4.3).astype(int)
    labels = label_free_cells(obs, obs_labels, rule=rule)
    gt = two_rooms_gt(free)
    assert score(labels, gt)["recall"] == 100.0
    assert set(np.unique(labels[gt == 1])) == {1} and set(np.unique(labels[gt == 2])) == {2}


def test_unobserved_free_components_get_labels_of_their_own():
    free = two_rooms()
    free[30:45, 30:45] = False
    free[36:39, 36:39] = True  # a 0.15 m pocket behind 0.3 m of wall: no viewpoint sees it
    obs = virtual_observations(free, RES, spacing_m=1.0)
    labels = label_free_cells(obs, np.zeros(len(obs), dtype=int))
    pocket = labels[36:39, 36:39]
    assert (pocket > 0).all() and len(np.unique(pocket)) == 1
    rest = free.copy()
    rest[36:39, 36:39] = False
    assert np.unique(labels[rest]).tolist() == [1]  # one connected label for the rest


def test_merge_open_boundaries_joins_a_cut_corridor_but_not_a_door():
    free = np.zeros((60, 300), dtype=bool)
    free[10:50, 10:290] = True  # a 2 m x 14 m corridor
    labels = np.where(free, 1, 0)
    labels[:, 150:] *= 2  # cut across into two labels
    merged = merge_open_boundaries(labels, free, RES, ratio=0.7, elongation=3.0)
    assert len(np.unique(merged[free])) == 1
    rooms = two_rooms()
    lab = np.where(rooms, np.where(np.arange(rooms.shape[1])[None, :] < 86, 1, 2), 0)
    kept = merge_open_boundaries(lab, rooms, RES, ratio=0.7, elongation=0.0)
    assert len(np.unique(kept[rooms])) == 2


# --------------------------------------------------------------------------- configuration


def test_config_rejects_unknown_keys():
    with pytest.raises(ValidationError, match="spacing"):
        SpectralConfig(spacing=1.0)
    cfg = SpectralConfig(k=3, seed=7)
    assert cfg.similarity == "visibility" and cfg.k == 3


def test_segment_spectral_reports_bad_parameters():
    with pytest.raises(InputError, match="nonsense"):
        segment_spectral(two_rooms(), RES, nonsense=1)
    with pytest.raises(InputError, match="spacing_m"):
        segment_spectral(two_rooms(), RES, spacing_m=-1.0)


def test_segment_spectral_with_a_fixed_k_and_config():
    cfg = SpectralConfig(k=2, merge_ratio=None)
    res = segment_spectral(two_rooms(), RES, config=cfg)
    assert res.k == 2 and len(np.unique(res.labels[two_rooms()])) == 2


def test_observations_from_a_slam_run_segment_the_rooms():
    from slam2d.segmentation.observations import observations_from_scans, raycast_grid
    from slam2d.segmentation.similarity import visibility_similarity
    from slam2d.types import Scan

    free = two_rooms()
    rng = np.random.default_rng(0)
    xs = np.concatenate([np.linspace(0.7, 3.7, 12), np.linspace(4.7, 7.7, 12)]) + 4 * RES
    poses = np.column_stack([xs, rng.uniform(0.8, 3.2, 24) + 4 * RES, rng.uniform(-np.pi, np.pi, 24)])
    beam = np.linspace(-np.pi, np.pi, 360, endpoint=False)  # 360 deg (a 180 deg laser over-segments: thesis 7.3)
    ranges, _ = raycast_grid(free, RES, poses[:, :2], poses[:, 2:3] + beam[None], 10.0)
    scans = [Scan(stamp=float(i), ranges=r, angles=beam, range_min=0.05, range_max=10.0) for i, r in enumerate(ranges)]
    obs = observations_from_scans(poses, scans, free=free, resolution=RES)
    lab, k, _ = spectral_clusters(visibility_similarity(obs, spacing_m=0.5))
    assert k == 2
    labels = label_free_cells(obs, lab)
    s = score(labels, two_rooms_gt(free))
    assert s["recall"] > 90 and s["precision"] > 90


def test_unknown_similarity_parameters_are_named():
    with pytest.raises(InputError, match="sigmaa"):
        segment_spectral(two_rooms(), RES, "hausdorff", similarity_params={"sigmaa": 1.0})
    with pytest.raises(InputError, match="similarity: unknown measure .cosmic."):
        segment_spectral(two_rooms(), RES, "cosmic")
