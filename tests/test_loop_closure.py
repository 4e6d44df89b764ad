"""Correlative scan-to-submap matcher and loop-closure search on the simulated office."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from slam2d import geometry
from slam2d.backend.correlative import match
from slam2d.backend.probability_grid import ProbabilityGrid
from slam2d.backend.loop_closure import LoopCloser, LoopClosure
from slam2d.config import LoopClosureConfig, SimulatorConfig
from slam2d.datasets.simulator import SimulatorSource

CFG = LoopClosureConfig()
WINDOW_THETA = np.deg2rad(CFG.window_theta_deg)
KEYFRAME_STEP = 0.5  # m between keyframes on the simulated route


@pytest.fixture(scope="module")
def office():
    """Scans and ground truth of the whole default office route (two laps)."""
    src = SimulatorSource(SimulatorConfig(), seed=0)
    scans = list(src)
    return src.ground_truth_poses, [s.points_in_base() for s in scans]


@pytest.fixture(scope="module")
def keyframes(office):
    """Scan indices of keyframes every KEYFRAME_STEP m (or 30 deg) and the distance travelled at each."""
    gt, _ = office
    kf = [0]
    for i in range(1, len(gt)):
        d = geometry.between(gt[kf[-1]], gt[i])
        if np.hypot(d[0], d[1]) >= KEYFRAME_STEP or abs(d[2]) >= np.deg2rad(30):
            kf.append(i)
    kf = np.array(kf)
    travelled = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(gt[kf, :2], axis=0).T))])
    return kf, travelled


def nearest_scan(gt, xy, after: int = 0) -> int:
    """Index of the first-closest ground-truth pose to ``xy`` at or after scan ``after``."""
    return after + int(np.argmin(np.hypot(*(gt[after:, :2] - np.asarray(xy)).T)))


def submap_around(office, ref: int, half: int = 20, stride: int = 2) -> ProbabilityGrid:
    """Grid of scans ref-half..ref+half (every ``stride``) in the frame of scan ``ref``, from ground truth."""
    gt, points = office
    idx = range(max(0, ref - half), min(len(gt), ref + half + 1), stride)
    pts = [geometry.transform_points(geometry.between(gt[ref], gt[k]), points[k]) for k in idx]
    return ProbabilityGrid(np.vstack(pts), CFG.resolution)


def pose_error(a, b) -> tuple[float, float]:
    """Translation (m) and absolute rotation (deg) between two poses."""
    d = geometry.between(a, b)
    return float(np.hypot(d[0], d[1])), float(np.rad2deg(abs(d[2])))


# --------------------------------------------------------------------------- matcher


@pytest.mark.parametrize("place", [(7.5, 4.225), (17.3, 7.0), (12.5, 1.9)])
def test_match_recovers_offset_on_revisit(office, place):
    """A second-lap scan against a first-lap submap, guess off by (0.6 m, 0.5 m, 15 deg)."""
    gt, points = office
    ref = nearest_scan(gt, place)
    query = nearest_scan(gt, place, after=ref + 300)  # the same place on the second lap
    truth = geometry.between(gt[ref], gt[query])
    guess = truth + np.array([0.6, 0.5, np.deg2rad(15.0)])
    result = match(submap_around(office, ref), points[query], guess, CFG.window_xy, WINDOW_THETA)
    dxy, dth = pose_error(truth, result.pose)
    assert dxy < 0.03 and dth < 1.0, (dxy, dth)
    assert result.score > 0.8
    cov = result.covariance
    assert cov.shape == (3, 3) and np.allclose(cov, cov.T) and np.all(np.linalg.eigvalsh(cov) > 0)


def test_match_rejects_a_different_room(office):
    """A scan from meeting room T1 matched against a submap of room B4 scores below min_score.

    (Rooms B1-B4 share their shape and door position and differ only in
    furniture; between them the score reaches 0.5-0.65, so that aliasing is
    left to the robust kernel and the pose graph's residual check after the batch.)
    """
    gt, points = office
    b4 = nearest_scan(gt, (17.3, 1.9))
    t1 = nearest_scan(gt, (3.0, 9.5))
    grid = submap_around(office, b4)
    true_match = match(grid, points[b4 + 1], geometry.between(gt[b4], gt[b4 + 1]), CFG.window_xy, WINDOW_THETA)
    assert true_match.score > 0.9
    guess = np.array([0.0, 0.0, gt[t1, 2] - gt[b4, 2]])  # drift put T1 on top of B4, headings kept
    false_match = match(grid, points[t1], guess, CFG.window_xy, WINDOW_THETA)
    assert false_match.score < CFG.min_score


def test_match_covariance_is_wide_along_a_featureless_corridor():
    """Two long parallel walls constrain y and theta but not x."""
    x = np.arange(-30.0, 30.0, 0.02)
    walls = np.vstack([np.column_stack([x, np.full_like(x, 1.0)]), np.column_stack([x, np.full_like(x, -1.0)])])
    a = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    a = a[np.abs(np.sin(a)) > 1.0 / 12.0]  # beams that hit a wall within 12 m
    r = 1.0 / np.abs(np.sin(a))
    scan = np.column_stack([r * np.cos(a), r * np.sin(a)])
    result = match(ProbabilityGrid(walls, 0.05), scan, np.array([0.3, 0.2, 0.1]), 1.0, WINDOW_THETA)
    std = np.sqrt(np.diag(result.covariance))
    assert abs(result.pose[1]) < 0.01 and abs(result.pose[2]) < np.deg2rad(0.5)
    assert std[0] > 0.5 and std[1] < 0.05


def test_match_rejects_bad_input():
    grid = ProbabilityGrid(np.array([[0.0, 0.0], [1.0, 0.0]]), 0.05)
    with pytest.raises(ValueError, match="finite scan point"):
        match(grid, np.full((3, 2), np.nan), np.zeros(3), 1.0, 0.3)
    with pytest.raises(ValueError, match="at least one finite submap point"):
        ProbabilityGrid(np.zeros((0, 2)))


# --------------------------------------------------------------------------- loop closer


def drifted(gt_poses, travelled, start: float, end: float, offset) -> np.ndarray:
    """Ground truth plus a drift that ramps from 0 (before ``start`` m) to ``offset`` (3,) (after ``end`` m)."""
    ramp = np.clip((travelled - start) / (end - start), 0.0, 1.0)
    return gt_poses + ramp[:, None] * np.asarray(offset)


@pytest.fixture(scope="module")
def closer(office, keyframes):
    gt, points = office
    kf, travelled = keyframes
    lc = LoopCloser(CFG)
    for k, (i, t) in enumerate(zip(kf, travelled)):
        lc.add_keyframe(k, points[i], t)
    return lc


def test_loop_closer_accepts_true_closures_on_revisit(office, keyframes, closer, caplog):
    """Second-lap keyframes, with 0.5 m / 6 deg of drift since the first lap, close onto it."""
    gt, _ = office
    kf, travelled = keyframes
    poses = drifted(gt[kf], travelled, 40.0, 55.0, [0.4, -0.3, np.deg2rad(6.0)])
    revisits = np.flatnonzero(travelled > 56.0)[:60:6]
    accepted = []
    with caplog.at_level(logging.DEBUG, logger="slam2d.backend.loop_closure"):
        for key in revisits:
            online = poses[: key + 1]  # keyframes known when ``key`` is added
            cands = closer.candidates(key, online)
            assert cands, f"no candidate for keyframe {key}"
            assert all(travelled[key] - travelled[c] >= CFG.min_travel for c in cands)
            accepted += [lc for c in cands if (lc := closer.verify(key, c, online)) is not None]
    assert len(accepted) >= len(revisits)
    for lc in accepted:
        assert isinstance(lc, LoopClosure) and lc.score >= CFG.min_score
        guess_dxy, _ = pose_error(geometry.between(poses[lc.i], poses[lc.j]), lc.delta)
        dxy, dth = pose_error(geometry.between(gt[kf[lc.i]], gt[kf[lc.j]]), lc.delta)
        assert dxy < 0.05 and dth < 1.0, (lc.i, lc.j, dxy, dth)
        assert guess_dxy > 0.2  # the matcher did correct the drifted guess
        assert np.all(np.linalg.eigvalsh(lc.information) > 0)
    assert closer.stats["accepted"] >= len(accepted)
    assert any("accepted: score" in r.getMessage() for r in caplog.records)


def test_loop_closer_rejects_a_false_candidate(office, keyframes, closer):
    """A keyframe in meeting room T1 paired with one in room B4 that drift placed on top of it."""
    gt, _ = office
    kf, _ = keyframes
    key = int(np.argmin(np.hypot(*(gt[kf, :2] - (3.0, 9.5)).T)))
    cand = int(np.argmin(np.hypot(*(gt[kf, :2] - (17.3, 1.9)).T)))
    shift = geometry.compose(gt[kf[key]], geometry.inverse(gt[kf[cand]]))  # moves cand onto key
    poses = gt[kf].copy()
    near = np.abs(np.arange(len(kf)) - cand) <= 2 * CFG.submap_keyframes  # its whole submap
    poses[near] = geometry.compose(shift, poses[near])
    before = closer.stats["rejected_score"]
    assert closer.verify(key, cand, poses) is None
    assert closer.stats["rejected_score"] == before + 1


def test_candidates_skip_recent_keyframes():
    """On a circle of 12.6 m, neighbours closer than min_travel along the path are never candidates."""
    cfg = LoopClosureConfig(search_radius=4.0, min_travel=10.0, max_candidates=3, submap_keyframes=2)
    angle = np.arange(40) * 0.25  # keyframes 0.5 m apart on a circle of radius 2 m
    poses = np.column_stack([2 * np.cos(angle), 2 * np.sin(angle), angle + np.pi / 2])
    lc = LoopCloser(cfg)
    for k in range(len(poses)):
        lc.add_keyframe(k, np.zeros((1, 2)), 0.5 * k)
    assert lc.candidates(15, poses[:16]) == []  # 7.5 m travelled: nothing old enough
    cands = lc.candidates(39, poses)
    assert 1 <= len(cands) <= cfg.max_candidates
    assert all(0.5 * (39 - c) >= cfg.min_travel for c in cands)
    dist = np.hypot(*(poses[cands, :2] - poses[39, :2]).T)
    assert np.all(np.diff(dist) >= 0) and dist[0] < 0.3  # nearest first: 14 is the same place as 39
    assert all(abs(a - b) > cfg.submap_keyframes for i, a in enumerate(cands) for b in cands[:i])
    with pytest.raises(ValueError, match="already added"):
        lc.add_keyframe(3, np.zeros((1, 2)), 50.0)


def _box(x0: float) -> np.ndarray:
    """Outline (points every 2 cm) of a 2 m x 1.5 m box open to the left, its corner at (x0, 0)."""
    t = np.arange(0.0, 1.0, 0.01)
    return np.vstack([np.column_stack([x0 + 2.0 * t, 0 * t]), np.column_stack([x0 + 2.0 + 0 * t, 1.5 * t]),
                      np.column_stack([x0 + 2.0 * t, 1.5 + 0 * t])])


def test_match_reports_a_rival_in_a_periodic_place():
    """Two identical boxes 3 m apart: a scan of one, guessed halfway, matches both equally."""
    scan = _box(0.0) - [1.0, 0.75]  # the box seen from its centre
    guess = np.array([2.5, 0.75, 0.0])  # halfway between the boxes' centres (1, 0.75) and (4, 0.75)
    twins = ProbabilityGrid(np.vstack([_box(0.0), _box(3.0)]), 0.05)
    result = match(twins, scan, guess, 2.0, WINDOW_THETA, ambiguity_xy=0.5, ambiguity_ratio=0.9)
    assert result.score > 0.9 and result.runner_up > 0.9 * result.search_score
    single = ProbabilityGrid(_box(3.0), 0.05)
    result = match(single, scan, guess, 2.0, WINDOW_THETA, ambiguity_xy=0.5, ambiguity_ratio=0.9)
    assert result.score > 0.9 and result.runner_up == 0.0
    assert pose_error(result.pose, [4.0, 0.75, 0.0])[0] < 0.03


def test_likelihood_field_matches_the_distance_transform():
    """The splatted field equals exp(-d^2 / 2 sigma^2) from scipy's exact distance transform within the cutoff."""
    from scipy.ndimage import distance_transform_edt

    from slam2d.backend.probability_grid import FIELD_CUTOFF_SIGMAS, _likelihood_field

    rng = np.random.default_rng(3)
    cells = np.column_stack([rng.integers(0, 60, 40), rng.integers(0, 45, 40)])  # (col, row)
    sigma = 1.5
    field, _ = _likelihood_field(cells, (45, 60), sigma)
    occupied = np.zeros((45, 60), dtype=bool)
    occupied[cells[:, 1], cells[:, 0]] = True
    d = distance_transform_edt(~occupied)
    near = d <= FIELD_CUTOFF_SIGMAS * sigma
    assert np.allclose(field[near], np.exp(-0.5 * (d[near] / sigma) ** 2), atol=1e-6)
    assert np.all(field[~near] == 0) and field.max() == 1.0


def test_pyramid_levels_bound_every_cell_they_cover():
    """Level k holds, per cell, the max of the field over the 2^k x 2^k cells from it (branch and bound's bound)."""
    rng = np.random.default_rng(4)
    grid = ProbabilityGrid(rng.uniform(0, 3, (60, 2)), resolution=0.1)
    pyr = grid.pyramid(window=4, depth=3)
    ny, nx = pyr.shape
    base = pyr.levels[0].reshape(ny, nx)
    for k in range(1, 4):
        level, w = pyr.levels[k].reshape(ny, nx), 2**k
        for i, j in zip(rng.integers(0, ny, 300), rng.integers(0, nx, 300)):
            assert level[i, j] == base[i:i + w, j:j + w].max()


def test_wide_search_closes_a_revisit_far_beyond_the_local_window(office, keyframes):
    """Second-lap keyframes drifted 6.4 m / 4 deg from the first lap: no local candidate is in reach,
    the wide search over every place in reach finds the true one (the office repeats its rooms)."""
    gt, points = office
    kf, travelled = keyframes
    cfg = LoopClosureConfig(drift=0.15)  # a lap of ~56 m allows ~10 m
    lc = LoopCloser(cfg)
    for k, (i, t) in enumerate(zip(kf, travelled)):
        lc.add_keyframe(k, points[i], t)
    poses = drifted(gt[kf], travelled, 40.0, 55.0, [5.0, -4.0, np.deg2rad(4.0)])
    found = []
    for key in np.flatnonzero(travelled > 58.0)[:40:8]:
        online = poses[: key + 1]
        if not found:  # until a closure links the laps, the first lap is beyond every local window
            assert all(lc.verify(key, c, online) is None for c in lc.candidates(key, online))
        closure = lc.wide_search(key, online)
        if closure is not None:
            found.append(closure)
            dxy, dth = pose_error(geometry.between(gt[kf[closure.i]], gt[kf[closure.j]]), closure.delta)
            assert dxy < 0.05 and dth < 1.0, (closure.i, closure.j, dxy, dth)
    assert len(found) >= 3
    assert lc.stats["accepted_wide"] == len(found)


def test_a_wide_match_whose_scan_sees_no_keyframe_is_checked_on_the_nearest(office, keyframes, closer):
    """The fine check of a wide match takes the keyframes within the scan's view of the match; a scan
    whose ranges reach none of them (short returns in the open) is checked on the nearest one alone."""
    gt, points = office
    kf, _ = keyframes
    members = list(range(10, 20))
    pose = gt[kf[15]] + np.array([3.0, 0.0, 0.0])  # 3 m from every member's position but the nearest's
    short = points[kf[15]] * (0.5 / np.hypot(*points[kf[15]].T).max())  # every return within 0.5 m
    submap, anchor = closer._view_submap(members, pose, short, gt[kf])
    nearest = members[int(np.argmin(np.hypot(*(gt[kf[members], :2] - pose[:2]).T)))]
    assert anchor == nearest and submap.members == (nearest,)
    assert len(submap.grid.points) > 0


def test_a_closure_the_estimate_does_not_follow_keeps_the_window_open(office, keyframes):
    """A closure pins its pair in the path lengths (windows) only once the estimate agrees with it:
    while the estimate still holds the 6.4 m drift (a robust kernel holding back one large
    correction), the path across it costs the residual divided by ``drift``."""
    gt, points = office
    kf, travelled = keyframes
    cfg = LoopClosureConfig(drift=0.15)
    lc = LoopCloser(cfg)
    for k, (i, t) in enumerate(zip(kf, travelled)):
        lc.add_keyframe(k, points[i], t)
    poses = drifted(gt[kf], travelled, 40.0, 55.0, [5.0, -4.0, np.deg2rad(4.0)])
    closure = None
    for key in np.flatnonzero(travelled > 58.0)[:40:8]:
        closure = lc.wide_search(key, poses[: key + 1])
        if closure is not None:
            break
    assert closure is not None
    online = poses[: closure.j + 1].copy()
    residual = geometry.between(geometry.between(online[closure.i], online[closure.j]), closure.delta)
    across = lc.path_lengths(closure.j, online)[closure.i]
    assert across >= 0.99 * np.hypot(residual[0], residual[1]) / cfg.drift > 30.0
    online[closure.j] = geometry.compose(online[closure.i], closure.delta)  # the estimate follows the closure
    assert lc.path_lengths(closure.j, online)[closure.i] < 1e-3


def _scan(segments: np.ndarray, origin, beams: int = 720, max_range: float = 12.0):
    """Hit points (N, 2) of a laser at ``origin`` (x, y) on ``segments`` (K, 2, 2), in the laser's frame (heading 0)."""
    a = np.linspace(-np.pi, np.pi, beams, endpoint=False)
    d = np.column_stack([np.cos(a), np.sin(a)])
    p, e = segments[:, 0] - origin, segments[:, 1] - segments[:, 0]
    cross = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (p[None, :, 0] * e[None, :, 1] - p[None, :, 1] * e[None, :, 0]) / cross
        u = (p[None, :, 0] * d[:, None, 1] - p[None, :, 1] * d[:, None, 0]) / cross
    t = np.where((t > 0) & (u >= 0) & (u <= 1), t, np.inf).min(axis=1)
    hit = t < max_range
    return d[hit] * t[hit, None]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_sided_submap_does_not_pair_the_two_faces_of_a_thick_wall(seed):
    """A corridor along x (walls y = +-2, a niche at x -3..-2 in the north wall) and a wall block
    0.25 m thick (x 0..0.25) standing out of the south wall to y = -0.5; ranges with 1 cm noise.
    The submap is seen from the east of the block, the scan from its west: only the block's east
    face is in the submap, only its west face in the scan. Matched on points alone, the scan
    slides a wall's thickness along the corridor to put one face on the other, and the fit looks
    tight; with the side each point was seen from, the niche places it."""
    rng = np.random.default_rng(seed)

    def noisy(points):
        return points * (1 + rng.normal(0.0, 0.01, len(points)) / np.hypot(points[:, 0], points[:, 1]))[:, None]

    segs = np.array([[[-20, 2], [-3, 2]], [[-3, 2], [-3, 2.3]], [[-3, 2.3], [-2, 2.3]], [[-2, 2.3], [-2, 2]],
                     [[-2, 2], [20, 2]], [[-20, -2], [0, -2]], [[0, -2], [0, -0.5]], [[0, -0.5], [0.25, -0.5]],
                     [[0.25, -0.5], [0.25, -2]], [[0.25, -2], [20, -2]]], dtype=float)  # fmt: skip
    seen_from = [np.array([x, 0.0]) for x in (1.5, 2.0, 2.5, 3.0)]
    sub = [noisy(_scan(segs, o)) + o for o in seen_from]
    views = np.vstack([o - q for o, q in zip(seen_from, sub)])
    views /= np.hypot(views[:, 0], views[:, 1])[:, None]
    truth = np.array([-1.0, 0.5, 0.0])
    scan, guess = noisy(_scan(segs, truth[:2])), truth + [0.4, -0.1, 0.02]
    blind = match(ProbabilityGrid(np.vstack(sub), 0.05), scan, guess, 1.0, WINDOW_THETA)
    sided = match(ProbabilityGrid(np.vstack(sub), 0.05, views=views), scan, guess, 1.0, WINDOW_THETA)
    assert pose_error(blind.pose, truth)[0] > 0.2  # a wall's thickness off
    assert pose_error(sided.pose, truth)[0] < 0.03 and sided.score > CFG.min_score


def test_a_verified_loop_far_from_where_the_graph_puts_it_is_not_added():
    """Two loops verified for the same pair of a well-constrained corridor: the one agreeing with the graph is
    added; the one 4.35 m off (a look-alike office along a corridor) exceeds the innovation gate and is counted as
    gated, not added. Without the gate both go in."""
    from types import SimpleNamespace

    from slam2d.backend.slam import GraphSlamBackend
    from slam2d.config import BackendConfig

    odometry = np.diag([1 / 0.02**2, 1 / 0.02**2, 1 / 0.01**2])
    loop_info = np.diag([1 / 0.05**2, 1 / 0.05**2, 1 / 0.02**2])
    true = np.array([14.5, 0.0, 0.0])  # keyframe 29 seen from keyframe 0
    closures = [LoopClosure(0, 29, true + [0.03, -0.02, 0.005], loop_info, 0.9),
                LoopClosure(0, 29, true + [0.0, 4.35, 0.0], loop_info, 0.9)]  # fmt: skip
    added = {}
    for gate in (100.0, 0.0):
        cfg = BackendConfig(name="pose_graph")
        cfg.loop_closure.innovation_gate = gate
        backend = GraphSlamBackend(cfg)
        for k in range(30):
            backend.graph.add_keyframe([0.5 * k, 0.0, 0.0], None if k == 0 else [0.5, 0.0, 0.0],
                                       None if k == 0 else odometry)  # fmt: skip
        backend.graph.update()
        backend.loops = SimpleNamespace(candidates=lambda key, estimate: closures,
                                        verify=lambda key, cand, estimate: cand)  # fmt: skip
        added[gate] = backend._close_loops(29), backend.stats["loop closures gated"]
    assert added == {100.0: (1, 1), 0.0: (2, 0)}
