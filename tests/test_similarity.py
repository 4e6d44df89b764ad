"""Observations (grid ray casting, visibility) and the four similarity measures."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse
from scipy.spatial.distance import cdist

from slam2d.segmentation.observations import (
    Observations,
    lattice_viewpoints,
    observations_from_scans,
    raycast_grid,
    see_through,
    virtual_observations,
)
from slam2d.segmentation.similarity import (
    SIMILARITIES,
    associate_corners,
    directed_distances,
    extract_corners,
    hausdorff_similarity,
    nearest_neighbour_similarity,
    similarity_matrix,
    visibility_similarity,
)
from slam2d.errors import InputError
from slam2d.types import Scan

RES = 0.05


def box_room(h_m=4.0, w_m=6.0, wall=4) -> np.ndarray:
    """Free mask of one rectangular room with walls ``wall`` cells thick."""
    free = np.zeros((int(h_m / RES) + 2 * wall, int(w_m / RES) + 2 * wall), dtype=bool)
    free[wall:-wall, wall:-wall] = True
    return free


def two_rooms(door_m: float | None = 0.9) -> np.ndarray:
    """Two 4 m x 4 m rooms side by side, a 0.2 m wall between them with a door (or none)."""
    free = np.zeros((int(4 / RES) + 8, int(8.2 / RES) + 8), dtype=bool)
    free[4:-4, 4:-4] = True
    wall = slice(4 + 80, 4 + 84)
    free[:, wall] = False
    if door_m:
        mid, half = free.shape[0] // 2, int(door_m / RES / 2)
        free[mid - half : mid + half, wall] = True
    return free


def obs_from_points(point_sets, poses=None) -> Observations:
    """Observations holding just the given hit point sets (no beams)."""
    n = len(point_sets)
    poses = np.zeros((n, 3)) if poses is None else np.asarray(poses, float)
    pts = np.concatenate([np.asarray(p, float).reshape(-1, 2) for p in point_sets])
    off = np.concatenate([[0], np.cumsum([len(p) for p in point_sets])])
    empty = np.zeros(0)
    return Observations(poses, empty, empty, empty.astype(bool), np.zeros(n + 1, np.int64), np.full(n, 10.0),
                        pts, off)


# --------------------------------------------------------------------------- observations


def test_raycast_grid_exact_distances_in_a_box():
    free = box_room(4.0, 6.0, wall=4)
    origin = np.array([[2.0, 1.0]]) + 4 * RES  # 2 m from the left wall, 1 m from the bottom one
    ranges, hit = raycast_grid(free, RES, origin, np.array([0.0, np.pi / 2, np.pi, 3 * np.pi / 2]), 20.0)
    assert hit.all()
    np.testing.assert_allclose(ranges[0], [4.0, 3.0, 2.0, 1.0], atol=1e-9)
    far, hit_far = raycast_grid(free, RES, origin, np.array([0.0]), 1.5)
    assert far[0, 0] == 1.5 and not hit_far[0, 0]


def test_virtual_observations_ragged_points_lie_on_walls():
    free = box_room()
    obs = virtual_observations(free, RES, spacing_m=1.0, beams=90, max_range=20.0)
    assert len(obs) > 10 and obs.poses.shape == (len(obs), 3)
    assert obs.offsets[-1] == len(obs.points) == len(obs) * 90  # a closed room: every beam hits
    cells = np.floor(obs.points / RES + 1e-6 * np.sign(obs.points - obs.poses[obs.owner(), :2])).astype(int)
    inside = (cells[:, 1] >= 0) & (cells[:, 1] < free.shape[0]) & (cells[:, 0] >= 0) & (cells[:, 0] < free.shape[1])
    assert not free[cells[inside, 1], cells[inside, 0]].any()  # hits are in wall cells


def test_lattice_viewpoints_cover_small_isolated_rooms():
    free = box_room(6.0, 6.0)
    free[10:20, 10:20] = False
    free[12:18, 12:18] = True  # a 0.3 m x 0.3 m closet, closed off, missed by a 1 m lattice
    cells = lattice_viewpoints(free, RES, 1.0, clearance_m=0.05, min_area_m2=0.05)
    assert any((12 <= r < 18) and (12 <= c < 18) for r, c in cells)
    assert free[cells[:, 0], cells[:, 1]].all()


def test_see_through_removes_only_small_obstacles():
    free = box_room(4.0, 4.0)
    free[40:42, 40:42] = False  # a 0.1 m chair leg
    free[20:25, 20:60] = False  # a 2 m table
    clear = see_through(free, RES, clutter_m=1.0)
    assert clear[40:42, 40:42].all() and not clear[20:25, 20:60].any()
    assert not clear[0].any()  # the walls stay


def test_sees_uses_the_nearest_beam():
    free = two_rooms(door_m=None)
    obs = virtual_observations(free, RES, spacing_m=1.0, beams=360)
    i = 0
    x, y = obs.poses[i, :2]
    same_room = [x + 0.5, y + 0.5]
    other_room = [x + 5.0, y]
    assert obs.sees([i, i], [same_room, other_room]).tolist() == [True, False]
    vis = obs.sees_all(np.array([same_room, other_room]))
    assert vis.shape == (len(obs), 2) and vis[i].tolist() == [True, False]


def test_observations_from_scans_handles_mounting_and_no_returns():
    angles = np.array([-np.pi / 2, 0.0, np.pi / 2])
    scan = Scan(stamp=0.0, ranges=np.array([1.0, 30.0, np.nan]), angles=angles, range_min=0.1, range_max=30.0,
                sensor_pose=np.array([0.5, 0.0, 0.0]))
    obs = observations_from_scans(np.array([[1.0, 2.0, np.pi / 2]]), [scan])
    np.testing.assert_allclose(obs.poses[0], [1.0, 2.5, np.pi / 2], atol=1e-12)
    assert len(obs.beam_ranges) == 2 and obs.beam_hit.tolist() == [True, False]  # NaN dropped
    np.testing.assert_allclose(obs.points, [[2.0, 2.5]], atol=1e-12)  # beam -90 deg of a robot facing +y
    assert obs.sees([0], [[1.0, 10.0]])[0]  # straight ahead, within the no-return beam's 30 m
    half = Scan(stamp=0.0, ranges=np.full(181, 2.0), angles=np.linspace(-np.pi / 2, np.pi / 2, 181),
                range_min=0.1, range_max=30.0)
    obs = observations_from_scans(np.array([[0.0, 0.0, 0.0]]), [half])
    table = obs.range_table()
    assert table.shape == (1, 720) and (table[0] == -1.0).sum() == pytest.approx(360, abs=8)  # 180 deg unseen
    assert obs.sees([0, 0, 0], [[1.5, 0.0], [2.5, 0.0], [-1.0, 0.0]]).tolist() == [True, False, False]


def test_observations_from_scans_rejects_mismatch():
    with pytest.raises(InputError, match="2 poses but 0 scans"):
        observations_from_scans(np.zeros((2, 3)), [])


# --------------------------------------------------------------------------- point-set measures


def test_directed_distances_match_brute_force():
    rng = np.random.default_rng(1)
    sets = [rng.normal(size=(n, 2)) for n in (5, 9, 1, 7)]
    obs = obs_from_points(sets)
    pairs = np.array([[0, 1], [1, 2], [0, 3], [2, 3]])
    st = directed_distances(obs.points, obs.offsets, pairs, threshold=0.5)
    for p, (i, j) in enumerate(pairs):
        d = cdist(sets[i], sets[j])
        ab, ba = d.min(axis=1), d.min(axis=0)
        np.testing.assert_allclose(st[p, :2], [ab.max(), ba.max()])
        np.testing.assert_allclose(st[p, 2:4], [ab[ab >= 0.5].sum(), ba[ba >= 0.5].sum()])
        np.testing.assert_array_equal(st[p, 4:], [len(sets[i]), len(sets[j])])


def test_hausdorff_hand_computed():
    a = [[0.0, 0.0], [1.0, 0.0]]
    b = [[0.0, 0.0], [3.0, 0.0]]
    # h(A, B) = 1 (from (1, 0)), h(B, A) = 2 (from (3, 0)): H = 2
    s = hausdorff_similarity(obs_from_points([a, b]), sigma=1.0, radius=1.0, max_points=None).toarray()
    np.testing.assert_allclose(s, [[1.0, np.exp(-2.0)], [np.exp(-2.0), 1.0]])


def test_nearest_neighbour_hand_computed():
    a = [[0.0, 0.0], [1.0, 0.0]]
    b = [[0.05, 0.0], [3.0, 0.0]]
    # A->B: (0,0) shared, (1,0) adds 0.95; B->A: (0.05,0) shared, (3,0) adds 2: R = 2.95 / 4 per point
    s = nearest_neighbour_similarity(obs_from_points([a, b]), threshold=0.1, sigma=0.5, radius=1.0,
                                     max_points=None).toarray()
    assert s[0, 1] == pytest.approx(1.0 / (1.0 + (2.95 / 4) / 0.5))
    same = nearest_neighbour_similarity(obs_from_points([a, a]), sigma=0.5, radius=1.0).toarray()
    assert same[0, 1] == pytest.approx(1.0)


def test_point_measures_far_apart_are_zero_and_identical_are_one():
    a = np.array([[0.0, 0.0], [1.0, 0.5], [2.0, 0.0]])
    poses = [[0, 0, 0], [0, 0, 0], [50, 0, 0]]
    obs = obs_from_points([a, a, a + [50.0, 0.0]], poses)
    for fn in (hausdorff_similarity, nearest_neighbour_similarity):
        s = fn(obs, radius=4.0).toarray()
        assert s[0, 1] == pytest.approx(1.0) and s[0, 2] == 0.0 and s[1, 2] == 0.0
    far = hausdorff_similarity(obs_from_points([a, a + [30.0, 0.0]]), sigma=0.5, radius=100.0).toarray()
    assert far[0, 1] < 1e-20


# --------------------------------------------------------------------------- corners


def test_extract_corners_of_a_box_from_its_centre():
    free = box_room(4.0, 6.0, wall=4)
    obs = virtual_observations(free, RES, spacing_m=4.0, beams=360, clearance_m=0.5)
    pts, owner = extract_corners(obs)
    lo, hi = 4 * RES, np.array([6.0, 4.0]) + 4 * RES
    corners = np.array([[lo, lo], [hi[0], lo], [lo, hi[1]], [hi[0], hi[1]]])
    for i in range(len(obs)):
        mine = pts[owner == i]
        assert len(mine) == 4, mine
        assert cdist(mine, corners).min(axis=1).max() < 0.15


def test_associate_corners_chains_within_threshold():
    pts = np.array([[0.0, 0.0], [0.2, 0.0], [0.4, 0.0], [5.0, 5.0]])
    ids = associate_corners(pts, threshold=0.3)
    assert ids[0] == ids[1] == ids[2] != ids[3]


# --------------------------------------------------------------------------- properties of all four


@pytest.fixture(scope="module")
def door_obs():
    return virtual_observations(two_rooms(0.9), RES, spacing_m=1.0, beams=360)


@pytest.mark.parametrize("name", sorted(SIMILARITIES))
def test_measure_properties(door_obs, name):
    s = similarity_matrix(door_obs, name)
    d = s.toarray() if sparse.issparse(s) else np.asarray(s)
    assert d.shape == (len(door_obs), len(door_obs))
    np.testing.assert_allclose(d, d.T, atol=1e-12)
    np.testing.assert_allclose(np.diag(d), 1.0)
    assert d.min() >= 0.0 and d.max() <= 1.0 + 1e-12


@pytest.mark.parametrize("name", sorted(SIMILARITIES))
def test_identical_observations_are_fully_similar(door_obs, name):
    twin = virtual_observations(two_rooms(0.9), RES, spacing_m=1.0, beams=360)
    idx = np.array([0, 0, len(twin) - 1])
    dup = Observations.from_beams(
        twin.poses[idx],
        np.concatenate([twin.beam_ranges[twin.beam_offsets[i] : twin.beam_offsets[i + 1]] for i in idx]),
        np.concatenate([twin.beam_angles[twin.beam_offsets[i] : twin.beam_offsets[i + 1]] for i in idx]),
        np.concatenate([twin.beam_hit[twin.beam_offsets[i] : twin.beam_offsets[i + 1]] for i in idx]),
        np.arange(4) * 360, 20.0, free=twin.free, resolution=RES,
    )
    s = similarity_matrix(dup, name)
    d = s.toarray() if sparse.issparse(s) else np.asarray(s)
    assert d[0, 1] == pytest.approx(1.0)


@pytest.mark.parametrize("name", sorted(SIMILARITIES))
def test_far_apart_observations_are_dissimilar(name):
    free = np.zeros((100, 300), dtype=bool)
    free[10:90, 10:90] = True  # two closed 4 m rooms, 6 m apart
    free[10:90, 210:290] = True
    obs = virtual_observations(free, RES, spacing_m=1.0)
    s = similarity_matrix(obs, name)
    d = s.toarray() if sparse.issparse(s) else np.asarray(s)
    left = obs.poses[:, 0] < 7.5
    assert d[np.ix_(left, ~left)].max() < 0.01
    assert d[np.ix_(left, left)].mean() > 0.1


def test_visibility_counts_match_sets():
    free = two_rooms(0.9)
    obs = virtual_observations(free, RES, spacing_m=1.5, beams=360)
    s = visibility_similarity(obs, spacing_m=1.0, norm="jaccard")
    from slam2d.segmentation.similarity import virtual_points

    vp = virtual_points(obs, 1.0)
    sets = [set(np.nonzero(row)[0]) for row in obs.sees_all(vp, 0.05)]
    for i, j in [(0, 1), (0, len(obs) - 1), (2, 5)]:
        union = len(sets[i] | sets[j])
        assert s[i, j] == pytest.approx(len(sets[i] & sets[j]) / union if union else 0.0)
    cos = visibility_similarity(obs, spacing_m=1.0, norm="cosine")
    assert cos[0, 1] == pytest.approx(len(sets[0] & sets[1]) / np.sqrt(len(sets[0]) * len(sets[1])))


def test_visibility_is_zero_between_closed_rooms():
    obs = virtual_observations(two_rooms(door_m=None), RES, spacing_m=1.0)
    s = visibility_similarity(obs)
    left = obs.poses[:, 0] < 4.2 + 4 * RES
    assert s[np.ix_(left, ~left)].max() == 0.0
    assert s[np.ix_(left, left)].min() > 0.5  # one convex room: everyone sees nearly everything


def test_unknown_measure_is_an_input_error(door_obs):
    with pytest.raises(InputError, match="unknown measure"):
        similarity_matrix(door_obs, "cosmic")


def test_grid_ray_from_a_cell_edge_along_an_axis_is_finite():
    """A ray starting exactly on a cell edge and moving along the other axis (0 x inf in the
    traversal's set-up) returned NaN; it stops at the wall like any other."""
    from slam2d.segmentation.observations import raycast_grid

    free = np.ones((10, 10), dtype=bool)
    free[:, 8] = False  # a wall at x = 0.8 m (cells 0.1 m)
    origins = np.array([[0.3, 0.5], [0.35, 0.5]])  # the first on a cell edge
    ranges, hit = raycast_grid(free, 0.1, origins, np.array([0.0, np.pi / 2]), 5.0)
    assert np.all(np.isfinite(ranges)) and hit.all()
    assert np.allclose(ranges[:, 0], [0.5, 0.45])  # east to the wall
    assert np.allclose(ranges[:, 1], [0.5, 0.5])  # north to the grid's edge
