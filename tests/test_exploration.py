"""Exploration: Li et al.'s candidates on hand-made scans, frontiers, the three-ray test, the cache rules
of the hybrid map, the utility, and a whole exploration of a small two-room world with SLAM in the loop."""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest

from slam2d.errors import InputError
from slam2d.exploration import config as explore_config
from slam2d.exploration.candidates import (
    Candidate,
    CandidateParams,
    adjust,
    scan_candidates,
    stands,
)
from slam2d.exploration.coverage import path_repetition
from slam2d.exploration.explorer import Explorer
from slam2d.exploration.frontiers import find_frontiers, frontier_mask
from slam2d.exploration.gridops import (
    FREE,
    OCCUPIED,
    UNKNOWN,
    GridView,
    LiveClearance,
    geodesic,
    information_gain,
    shared_gain,
    straight_reachable,
    unknown_in_sight,
)
from slam2d.exploration.hybrid import FINAL, MARKED, HybridMap
from slam2d.exploration.regret import tour_regret
from slam2d.sim.world import World

ANGLES = np.linspace(-np.pi, np.pi, 360, endpoint=False)
R_MAX = 12.0
PARAMS = CandidateParams(width=0.4, delta=0.1, safe_d=0.25, safe_dis=0.25, d_tho=0.5)


def scan_of(segments, origin=(0.0, 0.0)):
    """Ranges (360,) from ``origin`` in a world of wall ``segments`` ((x0, y0), (x1, y1)), 12 m limit."""
    return World(np.array(segments, dtype=float)).raycast(np.array(origin, float), ANGLES, R_MAX)


# --------------------------------------------------------------------------- candidates


def test_corridor_end_at_max_range_gives_one_a_type_goal_on_the_axis():
    """A 2 m wide corridor along +x, open beyond the range limit, a wall behind the robot."""
    ranges = scan_of([((-1, -1), (40, -1)), ((-1, 1), (40, 1)), ((-1, -1), (-1, 1))])
    found = scan_candidates(ranges, ANGLES, R_MAX, np.zeros(3), PARAMS)
    assert [c.type for c in found] == ["A"]  # the corridor walls seen at a grazing angle are no occlusions
    a = found[0]
    assert a.d == pytest.approx(R_MAX - PARAMS.delta)
    np.testing.assert_allclose(a.position, [R_MAX - PARAMS.delta, 0.0], atol=0.12)
    # at the robot's pose (3, 2, 90°) the same goal is straight ahead in the map frame
    moved = scan_candidates(scan_of([((-1, -1), (40, -1)), ((-1, 1), (40, 1))]), ANGLES, R_MAX,
                            np.array([3.0, 2.0, np.pi / 2]), PARAMS)  # fmt: skip
    assert any(np.allclose(c.position, [3.0, 2.0 + R_MAX - PARAMS.delta], atol=0.15) for c in moved if c.type == "A")


def test_a_type_goal_beyond_a_slot_is_brought_back_into_free_space():
    """A 0.3 m slot in a wall 3 m ahead, open beyond the range limit: its arc at the limit is longer
    than the robot, but no goal may lie in or beyond the slot: the adjustment shortens |OP| to where
    the section leaves safe_dis on both sides."""
    walls = [((-3, -3), (3, -3)), ((-3, 3), (3, 3)), ((-3, -3), (-3, 3)), ((3, -3), (3, -0.15)), ((3, 0.15), (3, 3))]
    found = [c for c in scan_candidates(scan_of(walls), ANGLES, R_MAX, np.zeros(3), PARAMS) if c.type == "A"]
    assert len(found) == 1
    assert PARAMS.d_tho < found[0].d <= 3.0 - PARAMS.safe_dis + 1e-9
    wide = walls[:3] + [((3, -3), (3, -1.0)), ((3, 1.0), (3, 3))]  # a 2 m gap: the goal stays at the limit
    far = [c for c in scan_candidates(scan_of(wide), ANGLES, R_MAX, np.zeros(3), PARAMS) if c.type == "A"]
    assert any(c.d == pytest.approx(R_MAX - PARAMS.delta) for c in far)


def open_door_walls():
    """A 4 x 4 m room around the origin with a 1 m door in its east wall (y in [0.5, 1.5]) to a
    second room (east wall at x = 6)."""
    return [((-2, -2), (2, -2)), ((-2, 2), (2, 2)), ((-2, -2), (-2, 2)), ((2, -2), (2, 0.5)), ((2, 1.5), (2, 2)),
            ((2, -3), (6, -3)), ((2, 3), (6, 3)), ((6, -3), (6, 3)), ((2, 2), (2, 3)), ((2, -2), (2, -3))]  # fmt: skip


def test_open_door_gives_b_type_goals_inside_the_doorway_clear_of_the_jambs():
    ranges = scan_of(open_door_walls())
    found = scan_candidates(ranges, ANGLES, R_MAX, np.zeros(3), PARAMS)
    assert found and all(c.type == "B" for c in found)
    hits = ranges[:, None] * np.column_stack([np.cos(ANGLES), np.sin(ANGLES)])
    for c in found:
        x, y = c.position
        assert 1.6 < x < 2.6 and 0.5 < y < 1.5, c.position  # in the doorway, not in the room or beyond
        assert np.hypot(*(hits - c.position).T).min() > 0.2  # clear of the jambs
        assert stands(np.minimum(ranges, R_MAX), ANGLES[1] - ANGLES[0], True, c.d, c.idx, "B", PARAMS)
    # the same room with the door closed has no candidate at all
    closed = [w for w in open_door_walls() if w != ((2, 1.5), (2, 2))] + [((2, 0.5), (2, 2))]
    assert scan_candidates(scan_of(closed), ANGLES, R_MAX, np.zeros(3), PARAMS) == []


def test_adjustment_moves_a_goal_off_the_section_edge_or_discards_it():
    ranges = np.minimum(scan_of(open_door_walls()), R_MAX)
    dtheta = ANGLES[1] - ANGLES[0]
    door = np.nonzero((np.abs(ANGLES - np.arctan2(1.0, 2.0)) < 0.25) & (ranges > 2.8))[0]
    edge = int(door.max())  # the last beam through the door: too close to the jamb
    assert not stands(ranges, dtheta, True, 2.5, edge, "B", PARAMS)
    fixed = adjust(ranges, dtheta, True, 2.5, edge, "B", PARAMS)
    assert fixed is not None and fixed[1] < edge and stands(ranges, dtheta, True, 2.5, fixed[1], "B", PARAMS)
    slot = [((-3, -3), (3, -3)), ((-3, 3), (3, 3)), ((-3, -3), (-3, 3)), ((3, -3), (3, -0.1)), ((3, 0.1), (3, 3)),
            ((3, -1), (8, -1)), ((3, 1), (8, 1)), ((8, -1), (8, 1))]  # fmt: skip
    r2 = np.minimum(scan_of(slot), R_MAX)
    fixed = adjust(r2, dtheta, True, 4.0, 180, "A", PARAMS)  # a goal 4 m ahead, through a 0.2 m slot at 3 m
    assert fixed is not None and fixed[0] <= 3.0 - PARAMS.safe_dis + 1e-9  # brought back in front of the slot
    assert adjust(r2, dtheta, True, 4.0, 180, "B", PARAMS) is None  # B-type goals keep |OP|: discarded


# --------------------------------------------------------------------------- grids


def view_of(state, res=0.05):
    return GridView(np.asarray(state, dtype=np.int8), res, (0.0, 0.0))


def test_three_rays_with_and_without_an_obstacle():
    blocked = np.zeros((60, 100), dtype=bool)  # 5 m x 3 m at 5 cm
    a, b = (0.5, 1.5), (4.5, 1.5)
    assert straight_reachable(blocked, 0.05, (0, 0), a, b, 0.6)
    mid = blocked.copy()
    mid[30, 50] = True  # on the midline
    assert not straight_reachable(mid, 0.05, (0, 0), a, b, 0.6)
    side = blocked.copy()
    side[36, 50] = True  # 0.3 m off the midline: on a long side of the 0.6 m box
    assert not straight_reachable(side, 0.05, (0, 0), a, b, 0.6)
    assert straight_reachable(side, 0.05, (0, 0), a, b, 0.3)  # a narrower box passes it
    outside = blocked.copy()
    outside[45, 50] = True  # 0.75 m off: outside the box
    assert straight_reachable(outside, 0.05, (0, 0), a, b, 0.6)


def corridor_state(w=200, h=60, width_cells=30):
    """A straight corridor along x (free rows in the middle, walls above and below)."""
    state = np.full((h, w), OCCUPIED, dtype=np.int8)
    lo = (h - width_cells) // 2
    state[lo : lo + width_cells, :] = FREE
    return state


def test_straight_corridor_keeps_no_intermediate_node():
    view = view_of(corridor_state())
    blocked = view.state == OCCUPIED
    hybrid = HybridMap(step=0.9, box_width=0.6)
    for x in np.arange(0.5, 9.5, 0.9):
        hybrid.add([x, 1.5, 0.0], [], blocked, view.resolution, view.origin)
    hybrid.finish()
    roles = [n.role for n in hybrid.nodes.values()]
    assert roles[0] == FINAL and roles[-1] == FINAL  # the first node and the last cache
    assert all(r == MARKED for r in roles[1:-1]) and len(roles) == 10


def test_a_corner_keeps_one_node_and_an_open_candidate_keeps_its_node():
    """An L: a corridor along x to a corner at (5, 1.5), then along y."""
    state = np.full((200, 200), OCCUPIED, dtype=np.int8)
    state[15:45, 0:115] = FREE  # y 0.75-2.25, x 0-5.75
    state[15:200, 85:115] = FREE  # x 4.25-5.75 up
    view = view_of(state)
    blocked = view.state == OCCUPIED
    hybrid = HybridMap(step=0.9, box_width=0.6)
    path = [[x, 1.5] for x in np.arange(0.5, 5.01, 0.9)] + [[5.0, y] for y in np.arange(2.4, 9.0, 0.9)]
    for xy in path:
        hybrid.add([*xy, 0.0], [], blocked, view.resolution, view.origin)
    finals = [hybrid.nodes[i].pose[:2] for i in hybrid.final_ids]
    assert len(finals) == 2  # the start and one node at the corner
    np.testing.assert_allclose(finals[1], [5.0, 1.5])  # the node at the corner
    assert len(hybrid.marked_ids) == len(path) - 3  # the start, the corner and the cache are not marked
    # rule (2): in the straight corridor a node holding an open candidate joins the graph
    from slam2d.exploration.candidates import Candidate

    hybrid = HybridMap(step=0.9, box_width=0.6)
    straight = view_of(corridor_state())
    for k, x in enumerate(np.arange(0.5, 6.0, 0.9)):
        cands = [Candidate(np.array([x, 2.0]), 1.0, 0, "B")] if k == 3 else []
        hybrid.add([x, 1.5, 0.0], cands, straight.state == OCCUPIED, 0.05, (0, 0))
    assert hybrid.nodes[3].role == FINAL and hybrid.nodes[2].role == MARKED


@pytest.mark.parametrize("seed", range(4))
def test_frontier_cells_and_regions_match_the_definition_and_scipy_labels(seed):
    """Frontier cells: free, an unknown 4-neighbour (the edge counts), no occupied cell within the wall gap;
    regions: scipy's 8-connected labels, each region's cells in raster order, regions by first cell."""
    from scipy import ndimage

    from slam2d.exploration.frontiers import frontier_regions

    rng = np.random.default_rng(seed)
    state = rng.choice(3, size=(37 + seed, 53), p=[0.55, 0.1, 0.35]).astype(np.int8)
    for gap in (0, 2):
        unknown = np.pad(state == UNKNOWN, 1, constant_values=True)
        near = unknown[:-2, 1:-1] | unknown[2:, 1:-1] | unknown[1:-1, :-2] | unknown[1:-1, 2:]
        walled = ndimage.maximum_filter(state == OCCUPIED, size=2 * gap + 1, mode="constant")
        expected = (state == FREE) & near & ~walled
        mask = frontier_mask(state, gap)
        assert np.array_equal(mask, expected) and mask.sum() > 20
    labels, n = ndimage.label(mask, structure=np.ones((3, 3)))
    regions = frontier_regions(mask, 3)
    expected = [np.argwhere(labels == k) for k in range(1, n + 1) if (labels == k).sum() >= 3]
    assert len(regions) == len(expected) >= 3
    assert all(np.array_equal(a, b) for a, b in zip(regions, expected))


def test_frontiers_regions_goal_size_visited_and_bounds():
    state = np.full((80, 120), UNKNOWN, dtype=np.int8)
    state[10:70, 10:60] = FREE  # a known room, open to the unknown on its east side (x = 3 m)
    state[9, 9:61] = state[70, 9:61] = OCCUPIED
    state[9:71, 9] = OCCUPIED
    view = view_of(state)
    mask = frontier_mask(view.state)
    assert mask[:, 59].sum() >= 50 and mask[:, :59].sum() == 0  # the open side only
    dist = geodesic(view.traversable(0.25), view.to_cell([1.5, 2.0]), 0.05)
    found = find_frontiers(view, [1.5, 2.0], dist, 0.4, 0.55)
    assert len(found) == 1
    f = found[0]
    assert f.goal[1] == pytest.approx(2.0, abs=0.15) and 2.6 < f.goal[0] < 3.0  # the region's centre, reachable
    assert f.path == pytest.approx(np.hypot(*(f.goal - [1.5, 2.0])), rel=0.1)
    assert find_frontiers(view, [1.5, 2.0], dist, 3.5, 0.55) == []  # regions shorter than min_size dropped
    assert find_frontiers(view, [1.5, 2.0], dist, 0.4, 0.55, avoid=[f.goal]) == []  # visited
    box = [(0, 0), (2.5, 0), (2.5, 4), (0, 4)]
    assert find_frontiers(view, [1.5, 2.0], dist, 0.4, 0.55, polygon=box) == []  # outside the bounds


def test_a_thick_walls_unseen_face_is_no_frontier_but_a_door_into_the_unknown_is():
    """A room whose west wall (7 cells thick) was seen from the far side only: its interior, between
    the occupied far face and the room, is unknown; the east wall has a 1 m door into an unknown room."""
    state = np.full((60, 100), FREE, dtype=np.int8)
    state[:, 0:10] = FREE  # the far side of the west wall, seen
    state[:, 10] = OCCUPIED  # the west wall's far face
    state[:, 11:18] = UNKNOWN  # its interior and the unseen near face (7 cells, 0.35 m)
    state[:, 70] = OCCUPIED  # the east wall, with a door
    state[25:45, 70] = FREE
    state[:, 71:] = UNKNOWN  # the room behind the door, never seen
    state[0, :] = state[-1, :] = state[:, 0] = OCCUPIED
    view = view_of(state)
    plain, deep = frontier_mask(state), frontier_mask(state, depth=8)  # 8 cells: the robot's 0.4 m
    assert plain[1:-1, 18].sum() >= 50  # Yamauchi's definition: the whole unseen face
    assert not deep[:, :70].any()  # the strip no deeper than the robot is no opening
    assert deep[27:43, 70].all() and np.array_equal(deep[:, 70:], plain[:, 70:])  # the door stays
    dist = geodesic(view.traversable(0.25), view.to_cell([2.2, 1.5]), 0.05)
    found = find_frontiers(view, [2.2, 1.5], dist, 0.4, 0.55, depth=0.4)
    assert len(found) == 1 and found[0].goal[0] == pytest.approx(3.5, abs=0.1)  # the door
    assert len(find_frontiers(view, [2.2, 1.5], dist, 0.4, 0.55)) == 2
    assert np.array_equal(frontier_mask(state, depth=6)[:, 18], plain[:, 18])  # 7 cells deep: open to 6
    assert not frontier_mask(state, depth=7)[:, 18].any()
    thin = state.copy()
    thin[1:-1, 11:18] = FREE
    thin[1:-1, 14:16] = UNKNOWN  # a strip of unknown between free cells, two cells wide
    assert frontier_mask(thin)[1:-1, [13, 16]].sum() >= 100 and not frontier_mask(thin, depth=8)[:, :70].any()


def test_information_gain_counts_unknown_cells_in_sight():
    state = np.full((100, 100), UNKNOWN, dtype=np.int8)
    state[:, :50] = FREE
    state[[0, -1], :] = state[:, [0, -1]] = OCCUPIED  # a closed box (beyond a grid is unknown too)
    view = view_of(state)
    near, far = information_gain(view, [[2.4, 2.5], [0.3, 2.5]], 3.0)
    assert near > 2 * far > 0
    walled = state.copy()
    walled[:, 50] = OCCUPIED
    assert information_gain(view_of(walled), [[2.4, 2.5]], 3.0)[0] == 0  # a wall hides the unknown


def test_utility_trades_gain_against_distance_and_turning():
    cfg = explore_config.ExplorationConfig(k1=0.5, k2=1.0, distance="path")
    ex = Explorer(cfg, 0.2, 0.05, R_MAX)
    pose = np.array([0.0, 0.0, 0.0])
    pts = np.array([[2.0, 0.0], [4.0, 0.0], [-2.0, 0.0]])
    f = ex.utility(pose, pts, np.array([100.0, 100.0, 100.0]), np.array([2.0, 4.0, 2.0]))
    assert f[0] > f[1] and f[0] > f[2]  # nearer beats farther, ahead beats behind
    assert f[1] / f[0] == pytest.approx(np.exp(-0.5 * 2.0))
    assert f[2] / f[0] == pytest.approx(np.exp(-1.0 * np.pi))
    more = ex.utility(pose, pts[1:2], np.array([1000.0]), np.array([4.0]))
    assert more[0] > f[0]  # ten times the gain is worth 2 m more
    euclid = Explorer(explore_config.ExplorationConfig(distance="euclidean"), 0.2, 0.05, R_MAX)
    assert euclid.utility(pose, pts[:1], np.array([1.0]), np.array([50.0]))[0] == pytest.approx(np.exp(-1.0 * 2.0))


def test_tour_regret_weighs_each_goal_by_its_gain():
    """Goals 1 m behind and 3 m / 4 m ahead (path = straight line): with equal gains the goal behind
    first reaches the cells at 1, 5, 6 m (mean 4), the one 3 m ahead first at 3, 4, 9 m (mean 5.33);
    with a tenth of the gain behind, going ahead first is best: the small goal waits for the way back.
    Behind a wall (9 m of path) the difference of path lengths bounds the way between goals."""
    goals = np.array([[-1.0, 0.0], [3.0, 0.0], [4.0, 0.0]])
    path = np.array([1.0, 3.0, 4.0])
    assert tour_regret(goals, path, np.ones(3)) == pytest.approx([0.0, 4 / 3, 2.0])
    assert tour_regret(goals, path, np.array([0.1, 1.0, 1.0])) == pytest.approx([3.2 / 2.1, 0.0, 2.0 / 2.1])
    assert tour_regret(goals, np.array([9.0, 3.0, 4.0]), np.ones(3)) == pytest.approx([22 / 3, 0.0, 4 / 3])
    cfg = explore_config.ExplorationConfig(distance="tour", k1=1.0, k2=0.0)
    ex = Explorer(cfg, 0.2, 0.05, R_MAX)
    f = ex.utility(np.zeros(3), goals, np.array([10.0, 100.0, 100.0]), path)
    g = ex.utility(np.zeros(3), goals, np.array([100.0, 100.0, 100.0]), path)
    assert np.argmax(f) == 1 and np.argmax(g) == 0


def test_hidden_cells_seen_from_several_goals_are_shared_among_them():
    """Two goals at one place and a third seeing part of the same hidden block: the shares add up to the block's
    cells in sight of any of them, a cell seen from k goals counting 1/k; the twin goals split theirs."""
    state = np.full((100, 100), FREE, dtype=np.int8)
    state[[0, -1], :] = state[:, [0, -1]] = OCCUPIED
    state[40:60, 70:90] = UNKNOWN
    view = view_of(state)
    pts = np.array([[1.0, 2.5], [1.0, 2.5], [4.0, 0.5]])
    own, shares = shared_gain(view, pts, 6.0, 120)
    assert np.array_equal(own, information_gain(view, pts, 6.0, 120))
    union = unknown_in_sight(view, pts[0], 6.0, 120) | unknown_in_sight(view, pts[2], 6.0, 120)
    assert shares.sum() == pytest.approx(union.sum())
    assert shares[0] == shares[1] < own[0] / 2 and own[2] / 3 < shares[2] < own[2]
    alone = unknown_in_sight(view, pts[2], 6.0, 120) & ~unknown_in_sight(view, pts[0], 6.0, 120)
    both = unknown_in_sight(view, pts[2], 6.0, 120) & unknown_in_sight(view, pts[0], 6.0, 120)
    assert shares[2] == pytest.approx(alone.sum() + both.sum() / 3)


def test_the_tour_weighs_twin_goals_by_their_shares_of_the_cells():
    """A goal 1 m behind (10 cells) and three twins 3 m ahead seeing the same 12 cells: weighed by each goal's
    own gain the twins count their cells three times and the tour goes ahead first; by their shares (4 each),
    the goal behind is first."""
    ex = Explorer(explore_config.ExplorationConfig(distance="tour", k1=1.0, k2=0.0), 0.2, 0.05, R_MAX)
    pts = np.array([[-1.0, 0.0], [3.0, 0.0], [3.0, 0.0], [3.0, 0.0]])
    gain, path = np.array([10.0, 12.0, 12.0, 12.0]), np.array([1.0, 3.0, 3.0, 3.0])
    assert np.argmax(ex.utility(np.zeros(3), pts, gain, path)) == 1
    assert np.argmax(ex.utility(np.zeros(3), pts, gain, path, shares=np.array([10.0, 4.0, 4.0, 4.0]))) == 0


def test_utility_takes_a_side_opening_nearby_before_a_far_candidate():
    """A corridor with a side opening 2 m from the robot and a candidate at its far end (9 m): the
    opening has no candidate, and the utility scores its frontier beside the candidates."""
    state = np.full((100, 200), UNKNOWN, dtype=np.int8)
    state[20:80, 10:190] = FREE  # 9 m x 3 m, closed at x = 0.5 m, open at x = 9.5 m
    state[19, 10:190] = state[80, 10:190] = OCCUPIED
    state[19:81, 9] = OCCUPIED
    state[80, 25:40] = FREE  # a 0.75 m side opening at x = 1.25-2 m
    view = view_of(state)
    ex = Explorer(explore_config.ExplorationConfig(strategy="utility"), 0.2, 0.05, R_MAX)
    far = Candidate(np.array([9.2, 2.5]), 7.7, 0, "A")
    ex.hybrid.add([1.5, 2.5, 0.0], [far], state == OCCUPIED, view.resolution, view.origin)
    goal = ex.decide([1.5, 2.5, 0.0], view)
    assert goal.kind == "frontier" and goal.position[1] > 3.8 and 1.2 < goal.position[0] < 2.1
    # the decision's options, best first, say why: the opening, then the far candidate
    first, *rest = goal.options
    assert first["kind"] == "frontier" and np.allclose(first["position"], goal.position, atol=1e-3)
    assert [o["F"] for o in goal.options] == sorted((o["F"] for o in goal.options), reverse=True)
    assert any(o["kind"] == "candidate" and o["position"][0] > 8.5 for o in rest)
    for o in goal.options:
        cost = ex.cfg.k1 * o["L_m"] + ex.cfg.k2 * o["gamma_rad"]
        assert o["F"] == pytest.approx(o["gain_m2"] / 0.05**2 * np.exp(-cost), rel=2e-3)
    state[80, 25:40] = OCCUPIED  # no opening: the far end is the best goal
    assert ex.decide([1.5, 2.5, 0.0], view_of(state)).position[0] > 8.5


def test_backtracking_takes_the_graph_unless_the_grid_knows_a_shortcut():
    """The robot went up the west side of a wall, across its north end and down the east side; a candidate
    of the first node is left at the west. With the wall closed the graph's way round is the way; once a
    door through the wall is mapped, the graph's way round is a detour and the grid path is taken."""
    def u_world(door):
        s = np.full((200, 200), FREE, dtype=np.int8)
        s[[0, -1], :] = s[:, [0, -1]] = OCCUPIED
        s[0:160, 89:92] = OCCUPIED  # a wall at x = 4.5 m from y = 0 to 8 m
        if door:
            s[10:30, 89:92] = FREE  # a 1 m door at y = 0.5-1.5 m
        s[40:80, 2:20] = UNKNOWN  # a hidden block west, x 0.1-1 m, y 2-4 m
        return view_of(s)

    cfg = explore_config.load(None, {"exploration.strategy": "nearest_candidate"}).exploration
    ex = Explorer(cfg, 0.2, 0.05, R_MAX)
    blocked = u_world(False).state == OCCUPIED
    way = [(2, 1), (2, 3), (2, 5), (2, 7), (2, 8.8), (4, 8.8), (5.5, 8.8), (7, 8.8), (7, 7), (7, 5), (7, 3), (7, 1)]
    for i, (x, y) in enumerate(way):
        found = [Candidate(np.array([1.4, 3.0]), 1.0, 0, "A")] if i == 0 else []
        ex.hybrid.add(np.array([x, y, 0.0]), found, blocked, 0.05, (0.0, 0.0))
    round_the_wall = ex.decide(np.array([7.0, 1.0, 0.0]), u_world(door=False))
    assert round_the_wall.kind == "candidate" and [tuple(w) for w in round_the_wall.waypoints] == [(7, 7), (4, 8.8)]
    through_the_door = ex.decide(np.array([7.0, 1.0, 0.0]), u_world(door=True))
    assert through_the_door.candidate is round_the_wall.candidate and through_the_door.waypoints == []


def test_path_repetition():
    line = np.column_stack([np.linspace(0, 10, 201), np.zeros(201)])
    assert path_repetition(line) == 0.0
    back = np.vstack([line, line[::-1][1:]])
    assert 0.4 < path_repetition(back) < 0.5  # the way back, less the turn
    with pytest.raises(InputError, match="exploration.strategy"):
        explore_config.load(None, {"exploration.strategy": "greedy"})


# --------------------------------------------------------------------------- a whole run


def two_rooms_png(tmp_path):
    """Two 4 x 3 m rooms side by side joined by a 1 m door, 5 cm pixels, walls 2 px."""
    from PIL import Image

    img = np.full((80, 180), 255, dtype=np.uint8)  # 4 m x 9 m canvas
    img[:, :] = 0
    img[10:70, 10:90] = 255  # room A: x 0.5-4.5, y 0.5-3.5
    img[10:70, 92:170] = 255  # room B: x 4.6-8.5
    img[30:50, 88:94] = 255  # the door: y 1.5-2.5
    path = tmp_path / "two_rooms.png"
    Image.fromarray(img).save(path)
    return path


@pytest.mark.parametrize("strategy", ["nearest_frontier", "utility", "tour"])
def test_exploring_two_rooms_terminates_with_full_coverage(tmp_path, strategy, caplog):
    from slam2d.runs.explore import run_explore

    world = two_rooms_png(tmp_path)
    cfg = explore_config.load(None, {
        "output.root": str(tmp_path / "out"), "dataset.simulator.world": str(world), "seed": 1,
        "exploration.strategy": strategy, "exploration.start": [1.5, 2.0, 0.0], "exploration.max_time": 150,
        "exploration.animation": strategy == "utility",
    })  # fmt: skip
    with caplog.at_level(logging.INFO, logger="slam2d.backend.pose_graph"):
        folder = run_explore(cfg)
    assert any(r.message.startswith("batch LM") for r in caplog.records)  # the final map at batch poses
    m = json.loads((folder / "metrics.json").read_text())
    assert m["stop_reason"] == "done" and not m["premature_stop"]
    assert m["coverage"] >= 0.99 and m["collisions"] == 0
    assert m["map_iou"] > 0.85 and m["ate_rmse"] < 0.1
    assert m["nodes_final"] <= m["nodes_all"]
    hybrid = json.loads((folder / "hybrid.json").read_text())
    assert len(hybrid["nodes"]) == m["nodes_all"]
    goals = json.loads((folder / "goals.json").read_text())
    chosen = [g for g in goals if "options" in g]
    assert len(chosen) == (sum(g["kind"] != "pocket" for g in goals) if strategy == "utility" else 0)
    assert all(np.allclose(g["options"][0]["position"], g["position"], atol=1e-3) for g in chosen)
    names = ["config.yaml", "map.pgm", "map.yaml", "map.png", "coverage.png", "coverage.csv", "trajectory.tum"]
    names += ["explore.gif"] if strategy == "utility" else []
    for name in names:
        assert (folder / name).stat().st_size > 0, name
    page = (folder / "report.html").read_text()
    assert 'alt="coverage.png"' in page and "over distance driven" in page and "<th>coverage</th>" in page
    spans = m["map_accuracy"]  # seeded spans across the two rooms, in the final grid
    assert spans["seen"] >= 0.75 * spans["spans"] and spans["max_abs_error_m"] < 0.1
    # room B was mapped: SLAM's grid is free at its centre
    from slam2d.mapping.export import load_map_server

    grid = load_map_server(folder / "map.yaml")
    cell = grid.world_to_cell(np.array([6.5, 2.0]))
    assert grid.free_mask()[cell[0], cell[1]]


def test_a_bounded_exploration_stays_in_its_polygon_and_counts_coverage_inside_it(tmp_path):
    """Bounds around room A of the two rooms: the laser sees into room B through the door, but no goal
    (frontier, candidate or view of a pocket) lies outside the polygon, the robot stays in room A, and
    the coverage and the map's IoU are counted inside the polygon."""
    from slam2d.runs.explore import run_explore

    world = two_rooms_png(tmp_path)
    box = [[0.3, 0.3], [4.3, 0.3], [4.3, 3.7], [0.3, 3.7]]
    cfg = explore_config.load(None, {
        "output.root": str(tmp_path / "out"), "dataset.simulator.world": str(world), "seed": 1,
        "exploration.start": [1.5, 2.0, 0.0], "exploration.max_time": 150, "exploration.animation": False,
        "exploration.bounds": box,
    })  # fmt: skip
    folder = run_explore(cfg)
    m = json.loads((folder / "metrics.json").read_text())
    assert m["stop_reason"] == "done" and not m["premature_stop"] and m["coverage"] >= 0.99
    assert m["reachable_area_m2"] < 4.0 * 3.0 and m["map_iou"] > 0.85  # room A alone
    goals = np.array([g["position"] for g in json.loads((folder / "goals.json").read_text())]).reshape(-1, 2)
    assert (goals[:, 0] < 4.3).all()  # room A is seen from the start: often no goal at all
    path = np.loadtxt(folder / "ground_truth.tum")
    assert path[:, 1].max() < 4.3


def test_bounds_must_be_a_polygon_around_the_start(tmp_path):
    from slam2d.runs.explore import run_explore

    for bad, what in (([[0, 0], [1, 0]], "at least 3"), ([[0, 0], [1, 0], [2, 0]], "no area")):
        with pytest.raises(InputError, match=what):
            explore_config.load(None, {"exploration.bounds": bad})
    cfg = explore_config.load(None, {"output.root": str(tmp_path), "exploration.bounds": [[20, 20], [21, 20], [21, 21]]})
    with pytest.raises(InputError, match="outside the polygon"):
        run_explore(cfg)
    assert not list(tmp_path.iterdir())


def test_the_area_to_explore_leaves_out_what_a_plan_leaves_unknown(tmp_path):
    """A room whose wall has a one-pixel hole onto a band of the plan's unknown grey (205, a wall's
    interior in a scanned plan): the laser sees into the band through the hole, but the band is no
    area the explorer must map."""
    from PIL import Image

    from slam2d.exploration.coverage import reachable_free, truth_map
    from slam2d.sim.world import load_world

    img = np.zeros((80, 120), dtype=np.uint8)
    img[10:70, 10:80] = 254  # the room, 3.5 m x 3 m
    img[10:70, 82:100] = 205  # the unknown band beyond its 2 px east wall
    img[40, 80:82] = 254  # a pinhole in the wall
    path = tmp_path / "pinhole.png"
    Image.fromarray(img).save(path)
    world = load_world(str(path), 0.05)
    free, frame = truth_map(world)
    band = np.zeros_like(free)
    band[10:70, 82:100] = True
    band = band[::-1]  # row 0 of the grid is the bottom of the image
    assert world.unmapped is not None and (world.unmapped == band).all()
    seen = reachable_free(free, frame, (2.0, 2.0), 0.25, 10.0)
    asked = reachable_free(free, frame, (2.0, 2.0), 0.25, 10.0, world.unmapped)
    assert (seen & band).sum() > 10  # the laser sees through the hole
    assert not (asked & band).any() and (asked == (seen & ~band)).all()

    from slam2d.config import MappingConfig
    from slam2d.exploration.coverage import Coverage
    from slam2d.mapping.grid import OccupancyGrid

    mapped = OccupancyGrid(np.where(seen, -3.0, 0.0), frame.resolution, frame.origin)  # free where the laser saw
    assert Coverage(asked, frame, MappingConfig(), world.unmapped).iou(mapped) == 1.0  # the band says nothing
    assert Coverage(asked, frame, MappingConfig()).iou(mapped) < 1.0


def test_bad_explore_input_leaves_no_folder(tmp_path):
    from slam2d.runs.explore import run_explore

    with pytest.raises(InputError, match="world PNG not found"):
        run_explore(explore_config.load(None, {"output.root": str(tmp_path), "dataset.simulator.world": "nope.png"}))
    with pytest.raises(InputError, match="exploration.start"):
        run_explore(explore_config.load(None, {"output.root": str(tmp_path), "exploration.start": [-50, -50, 0]}))
    assert not list(tmp_path.iterdir())


def test_explore_command_reports_bad_input_in_one_line(tmp_path):
    from typer.testing import CliRunner

    from slam2d.cli import app

    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["explore", "-q", "--strategy", "greedy", "--set", f"output.root={out}"])
    assert res.exit_code == 2 and "exploration.strategy" in res.output
    res = CliRunner().invoke(app, ["explore", "-q", "--set", "exploration.bogus=1", "--set", f"output.root={out}"])
    assert res.exit_code == 2 and "unknown key 'exploration.bogus'" in res.output
    res = CliRunner().invoke(app, ["explore", "-q", "--set", "exploration.options.bogus=1", "--set", f"output.root={out}"])
    assert res.exit_code == 2 and "exploration.options.bogus: unknown key (valid: " in res.output
    assert not out.exists() or not list(out.iterdir())


def test_rays_aimed_at_the_few_unknown_cells_count_what_all_rays_count():
    """With few unknown cells a point casts only the rays aimed at one within reach: the same gains, shares and
    cells in sight as with every ray, from random points (inside unknown cells and near the grid's edge too)."""
    from slam2d.exploration.gridops import _cast

    rng = np.random.default_rng(5)
    for trial in range(6):
        state = rng.choice([FREE, OCCUPIED], size=(60, 80), p=[0.93, 0.07]).astype(np.int8)
        state[rng.random(state.shape) < 0.01 * (trial + 1)] = UNKNOWN
        state[30:33, 40:44] = UNKNOWN
        points = rng.uniform([0, 0], [80, 60], size=(150, 2))  # (x, y) grid units
        unknown = np.ascontiguousarray(np.argwhere(state == UNKNOWN))
        for rays, reach in ((90, 8.0), (360, 20.0)):
            every = _cast(state, points, rays, reach, 2, unknown, False)
            aimed = _cast(state, points, rays, reach, 2, unknown, True)
            for a, b in zip(every, aimed):
                assert np.array_equal(a, b)
    assert every[0].max() > 0 and (every[0] == 0).any()  # some points see unknown cells, some none


def test_a_robot_its_map_has_cut_off_drives_back_the_way_it_came_loops_skipped():
    """A gap the robot drove through, drawn narrower than the robot on its map (0.3 m, the robot 0.4 m wide),
    closes a small room: from inside, the way out is its own path back past the gap, without the loop it drove
    inside; from the large room, or once the ways out are used up, there is none."""
    from types import SimpleNamespace

    from slam2d.exploration.recovery import MAX_RETRACES, way_out

    state = np.full((60, 100), FREE, dtype=np.int8)  # 5 m x 3 m at 5 cm
    state[[0, -1], :] = state[:, [0, -1]] = OCCUPIED
    state[:, 70] = OCCUPIED  # the wall at x = 3.5 m
    state[27:33, 70] = FREE  # the gap, y 1.35-1.65 m
    state[:20, 71:] = state[41:, 71:] = OCCUPIED  # the small room: x 3.55-4.95 m, y 1.0-2.05 m
    view = view_of(state)
    straight = np.column_stack([np.linspace(1.0, 4.2, 65), np.full(65, 1.5)])
    t = np.linspace(0, 2 * np.pi, 60)
    circle = np.column_stack([4.2 + 0.3 * np.sin(t), 1.5 + 0.2 * (1 - np.cos(t))])  # a loop of 1.6 m
    est = [np.array([x, y, 0.0]) for x, y in np.vstack([straight, circle])]
    loop = SimpleNamespace(view=lambda: view, body=SimpleNamespace(radius=0.2),
                           slam=SimpleNamespace(pose=est[-1]), retraces=0)  # fmt: skip
    way = way_out(loop, est)
    assert way is not None and loop.retraces == 1
    large = np.isfinite(geodesic(view.traversable(0.2), view.to_cell([2.0, 1.5]), view.resolution))
    end = view.to_cell(way[-1])
    assert large[end[0], end[1]] and abs(way[-1][1] - 1.5) < 0.05  # in the large room, on the path it came by
    assert np.hypot(*(way[0] - est[-1][:2])) < 0.15  # from where the robot stands
    length = np.hypot(*np.diff(way, axis=0).T).sum()
    assert length < 1.2 * (est[-1][0] - way[-1][0])  # straight back: the loop in the small room is not retraced
    outside = SimpleNamespace(view=lambda: view, body=loop.body, slam=SimpleNamespace(pose=np.array([2.0, 1.5, 0.0])),
                              retraces=0)  # fmt: skip
    assert way_out(outside, [np.array([x, y, 0.0]) for x, y in straight[:30]]) is None  # not cut off
    loop.retraces = MAX_RETRACES
    assert way_out(loop, est) is None


def test_pocket_cells_are_hidden_unknown_cells_walls_close_small_gaps_and_escape_turns_to_open_space():
    from slam2d.exploration.pockets import pocket_state
    from slam2d.exploration.recovery import open_heading

    state = np.full((40, 40), UNKNOWN, dtype=np.int8)
    state[5:35, 5:35] = FREE
    state[4, 4:36] = state[35, 4:36] = OCCUPIED  # the room's walls ...
    state[4:36, 4] = state[4:36, 35] = OCCUPIED
    state[35, 20:22] = UNKNOWN  # ... one missed for two cells, another seen free for one
    state[4, 10] = FREE
    state[10:20, 10:30] = UNKNOWN  # a pocket: cells with no known cell within one cell are hidden
    scored = pocket_state(state, 4)
    assert (scored[11:19, 11:29] == UNKNOWN).all() and (scored[10, 10:30] == FREE).all()
    assert (scored[35, 20:22] == OCCUPIED).all() and scored[4, 10] == OCCUPIED  # no ray leaks out
    assert (scored[:3] == UNKNOWN).all()  # the outside stays hidden, behind the closed walls
    view = GridView(scored, 0.05, (0.0, 0.0))
    inside, outside = (0.5 * 0.05 * 30, 0.5 * 0.05 * 30), (0.5 * 0.05 * 30, 0.05 * 38)
    assert information_gain(view, [inside], 6.0, 360)[0] >= 8 * 18 and information_gain(view, [outside], 6.0, 360)[0] > 0
    gained = information_gain(view, [(0.05 * 20, 0.05 * 25)], 6.0, 360)[0]  # in the room, above the pocket
    assert gained >= 18  # sees its upper rows
    wall = np.column_stack([np.full(50, 0.25), np.linspace(-1, 1, 50)])  # a wall 5 cm in front of the disc
    heading = open_heading(wall, 0.2)
    assert abs(abs(heading) - np.pi) < 0.5  # away from it


@pytest.mark.parametrize("wall_cells, shape", [(1, (50, 70)), (2, (50, 70)), (4, (50, 70)), (5, (50, 70)),
                                               (0, (1, 30)), (7, (30, 1)), (3, (4, 9))])  # fmt: skip
def test_pocket_state_is_a_closing_of_the_walls_by_a_square_and_hidden_cells_have_no_known_neighbour(
    wall_cells, shape
):
    from scipy import ndimage

    from slam2d.exploration.pockets import pocket_state

    rng = np.random.default_rng(wall_cells)
    state = rng.choice(np.array([FREE, OCCUPIED, UNKNOWN], dtype=np.int8), size=shape, p=[0.5, 0.1, 0.4])
    size = wall_cells + 1
    closed = ndimage.binary_closing(np.pad(state == OCCUPIED, size), np.ones((size, size), bool))[size:-size, size:-size]
    unknown = state == UNKNOWN
    hidden = unknown & ~ndimage.binary_dilation(~unknown, np.ones((3, 3), bool))
    scored = pocket_state(state, wall_cells)
    assert np.array_equal(scored == OCCUPIED, closed)
    assert np.array_equal(scored == UNKNOWN, hidden & ~closed)


def desk_room_png(tmp_path):
    """A 4 x 3 m room (x 0.5-4.5, y 0.5-3.5, 5 cm pixels) with a 2 x 0.55 m desk 0.55 m from its south
    wall: the space behind the desk is seen only along the gap, whose mouths are narrower than a
    frontier region once the cells near the desk and the wall are left out."""
    from PIL import Image

    img = np.zeros((80, 100), dtype=np.uint8)
    img[10:70, 10:90] = 255
    img[48:59, 30:70] = 0  # the desk: x 1.5-3.5, y 1.05-1.6
    path = tmp_path / "desk_room.png"
    Image.fromarray(img).save(path)
    return path


def test_exploring_a_room_with_a_desk_near_a_wall_sees_behind_the_desk(tmp_path):
    from slam2d.exploration.loop import explore

    cfg = explore_config.load(None, {
        "dataset.simulator.world": str(desk_room_png(tmp_path)), "seed": 1, "exploration.strategy": "nearest_frontier",
        "exploration.start": [2.5, 2.5, 0.0], "exploration.max_time": 150, "exploration.animation": False,
    })  # fmt: skip
    m = explore(cfg).metrics
    assert m["stop_reason"] == "done" and not m["premature_stop"] and m["collisions"] == 0
    assert m["coverage"] >= 0.99 and m["pocket_goals"] > 0
    off = explore(cfg.model_copy(update={"exploration": cfg.exploration.model_copy(update={"pockets": False})}))
    assert off.metrics["premature_stop"] and off.metrics["coverage"] < 0.97  # frontiers alone stop early


def test_geodesic_distances_are_dijkstras_on_the_8_connected_grid():
    """Against scipy's Dijkstra on the same graph: 8 neighbours, diagonals √2 and never across a corner."""
    from scipy import ndimage
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    rng = np.random.default_rng(3)
    for _ in range(20):
        passable = ndimage.binary_opening(rng.random((40, 50)) > 0.15)
        rows, cols = np.nonzero(passable)
        start = rows[len(rows) // 2], cols[len(rows) // 2]
        h, w = passable.shape
        edges = []
        for dr, dc in [(0, 1), (1, 0), (1, 1), (1, -1)]:
            r, c = rows + dr, cols + dc
            ok = (r < h) & (c >= 0) & (c < w)
            ok[ok] &= passable[r[ok], c[ok]]
            if dr and dc:  # no corner cutting
                ok[ok] &= passable[rows[ok] + dr, cols[ok]] & passable[rows[ok], cols[ok] + dc]
            edges.append((rows[ok] * w + cols[ok], r[ok] * w + c[ok], np.full(ok.sum(), np.hypot(dr, dc))))
        a, b, cost = (np.concatenate(x) for x in zip(*edges))
        graph = coo_matrix((cost, (a, b)), shape=(h * w, h * w))
        expected = dijkstra(graph, directed=False, indices=start[0] * w + start[1]).reshape(h, w)
        got = geodesic(passable, start, 0.05) / 0.05
        assert np.array_equal(np.isfinite(got), np.isfinite(expected)) and np.isfinite(got).sum() > 100
        assert np.allclose(got[np.isfinite(got)], expected[np.isfinite(expected)])


def test_the_live_clearance_of_a_growing_map_is_the_clearance_of_each_view():
    rng = np.random.default_rng(4)
    live = LiveClearance(0.5)
    state = np.full((60, 80), UNKNOWN, dtype=np.int8)
    for k in range(8):
        r, c = rng.integers(0, 50), rng.integers(0, 70)
        state[r : r + 10, c : c + 10] = FREE  # more of the map seen
        state[rng.integers(0, 60, 5), rng.integers(0, 80, 5)] = OCCUPIED  # and walls
        state[rng.integers(0, 60, 2), rng.integers(0, 80, 2)] = FREE  # a cell taken for a wall, now free
        origin = (0.0, 0.0) if k < 5 else (-1.0, 0.0)  # the frame moves once
        view = live.attach(GridView(state.copy(), 0.05, origin))
        fresh = GridView(state.copy(), 0.05, origin)
        for radius in (0.1, 0.25, 0.45):
            assert np.array_equal(view.traversable(radius), fresh.traversable(radius))
        assert view.clearance_cap == 10.0 and view.clearance.max() <= 10.0
    assert view.traversable(0.45).any() and not view.traversable(0.1).all()


def test_a_robot_boxed_in_by_the_margin_leaves_through_the_gap_it_came_in_by():
    """A room whose only door is 0.45 m wide: the robot's disc (0.4 m) fits, its disc + margins (0.5 m, 0.6 m)
    do not. Beyond the door, unknown space: the explorer must not call the exploration done from inside."""
    state = np.full((80, 240), UNKNOWN, dtype=np.int8)
    state[10:70, 10:50] = FREE  # the room, 2 x 3 m
    state[10:70, 50:52] = OCCUPIED  # its east wall
    state[36:45, 50:52] = FREE  # the door: 9 cells
    state[10:70, 52:210] = FREE  # the hall beyond, open to the unknown at its east end, out of the room's sight
    state[8:10, 8:212] = OCCUPIED
    state[70:72, 8:212] = OCCUPIED
    state[10:70, 8:10] = OCCUPIED
    view = GridView(state, 0.05, (0.0, 0.0))
    cfg = explore_config.load(None, {"exploration.strategy": "nearest_frontier"}).exploration
    explorer = Explorer(cfg, 0.2, 0.05, 12.0)
    goal = explorer.decide(np.array([1.5, 2.0, 0.0]), view)
    assert goal is not None and goal.kind == "frontier" and goal.position[0] > 10 and explorer.tight_goals == 1
    assert goal.tight  # driven with the robot's own disc: the safety margin does not fit through the door
    wide = state.copy()
    wide[30:50, 50:52] = FREE  # a 1 m door: the margin is kept, no tight goal
    explorer = Explorer(cfg, 0.2, 0.05, 12.0)
    assert explorer.decide(np.array([1.5, 2.0, 0.0]), GridView(wide, 0.05, (0.0, 0.0))) is not None
    assert explorer.tight_goals == 0


def test_unknown_inside_furniture_keeps_no_candidate_open():
    """A desk whose outline has a gap narrower than the robot's radius: the unknown inside is no gain (it is
    not what the coverage counts), so a candidate seeing only it is closed; a wide opening keeps it."""
    state = np.full((80, 80), FREE, dtype=np.int8)
    state[[0, -1], :] = state[:, [0, -1]] = OCCUPIED
    state[30:50, 30:50] = UNKNOWN
    state[30:50, [30, 49]] = state[[30, 49], 30:50] = OCCUPIED  # the desk's outline
    state[38:42, 30] = FREE  # a gap of 4 cells (0.2 m, the robot's radius) facing the candidate
    cfg = explore_config.load(None, {"exploration.min_gain": 0.2}).exploration
    explorer = Explorer(cfg, 0.2, 0.05, 12.0)
    spot = np.array([1.2, 2.0])
    explorer.hybrid.add(np.array([0.5, 0.5, 0.0]), [Candidate(spot.copy(), 1.0, 0, "A")],
                        state == OCCUPIED, 0.05, (0.0, 0.0))  # fmt: skip
    view = GridView(state, 0.05, (0.0, 0.0))
    seen = information_gain(view, spot[None], cfg.gain_range, cfg.gain_rays)[0] * 0.05**2
    assert seen > cfg.min_gain  # the unknown seen through the gap
    assert explorer.maintain(view) == []
    opened = state.copy()
    opened[34:46, 30] = FREE  # 0.6 m open
    explorer.hybrid.nodes[0].candidates[0].alive = True
    assert len(explorer.maintain(GridView(opened, 0.05, (0.0, 0.0)))) == 1


def test_views_of_pockets_do_not_see_into_a_wall_block_through_a_gap_but_still_behind_a_desk():
    """Rays that entered a block of walls through a gap and ran along its unseen inner face kept robots
    looking after 99 %, a column of hidden cells at a time; the pocket behind a desk must stay."""
    from slam2d.exploration.gridops import unknown_in_sight
    from slam2d.exploration.pockets import opaque_faces, pocket_state

    state = np.full((60, 60), UNKNOWN, dtype=np.int8)
    state[10:50, 10:50] = FREE  # a room
    state[9, 9:51] = state[50, 9:51] = OCCUPIED
    state[9:51, 9] = state[9:51, 50] = OCCUPIED
    state[15:22, 15:23] = OCCUPIED  # a block of walls, its inside unknown, seen into through a 2-cell gap
    state[16:21, 16:22] = UNKNOWN
    state[21, 18:20] = FREE
    state[44:50, 30:45] = UNKNOWN  # behind a desk at the north wall, seen through its open east end
    state[43, 29:45] = state[43:50, 29] = OCCUPIED
    scored = pocket_state(state, 1)
    faces = opaque_faces(scored, state, 8)
    res = 0.05
    before, after = GridView(scored, res, (0.0, 0.0)), GridView(faces, res, (0.0, 0.0))
    gap, desk = (18.5 * res, 23 * res), (47.5 * res, 46.5 * res)  # (x, y) m
    seen = lambda view, xy: unknown_in_sight(view, xy, 6.0, 360)
    block, pocket = np.s_[15:22, 15:23], np.s_[44:50, 30:45]
    assert seen(before, gap)[block].any() and not seen(after, gap)[block].any()  # its inner face stops rays
    kept = seen(after, desk)[pocket]
    assert np.array_equal(kept, seen(before, desk)[pocket]) and kept.sum() >= 4 * 12  # behind the desk: kept
    assert (faces[16, 16:22] == OCCUPIED).all() and (faces[44, 30:45] == OCCUPIED).all()  # the faces
    assert (faces[17:20, 17:21] == UNKNOWN).all() and (faces[46, 44] == FREE).all()  # not the rest (its mouth)
    assert np.array_equal(faces == UNKNOWN, scored == UNKNOWN)  # the hidden cells stay as they were


def test_views_of_pockets_do_not_see_into_a_thick_wall_through_its_unseen_face():
    """A wall 7 cells thick seen as occupied from the far room only: from the near room, its inside is
    hidden behind free cells. Rays must not enter such a strip, no deeper than the robot's width (8 cells);
    a strip deeper than that still lets them in."""
    from slam2d.exploration.frontiers import shallow_entries
    from slam2d.exploration.gridops import unknown_in_sight
    from slam2d.exploration.pockets import opaque_faces, pocket_state

    state = np.full((40, 60), FREE, dtype=np.int8)
    state[[0, -1], :] = state[:, [0, -1]] = OCCUPIED
    state[1:-1, 12] = OCCUPIED  # the far face
    state[1:-1, 13:20] = UNKNOWN  # the inside and the near face the laser never marked
    scored = pocket_state(state, 1)
    view = lambda grid: GridView(grid, 0.05, (0.0, 0.0))
    room = (30 * 0.05, 20 * 0.05)  # (x, y) m, in the near room
    inside = unknown_in_sight(view(opaque_faces(scored, state)), room, 6.0, 360)
    assert inside[:, 14:19].sum() >= 5 * 25  # without the depth, the inside is a target
    assert not unknown_in_sight(view(opaque_faces(scored, state, 8)), room, 6.0, 360).any()
    assert unknown_in_sight(view(opaque_faces(scored, state, 6)), room, 6.0, 360).any()  # 7 cells: deeper than 6
    for i in range(16):  # a wedge of unknown floor beside the east wall, behind a door jamb: a staircase edge
        state[1 + i, 43 + i : 59] = UNKNOWN
    scored = pocket_state(state, 1)
    wedge = unknown_in_sight(view(opaque_faces(scored, state, 8)), room, 6.0, 360)[:, 40:]
    assert wedge.sum() >= 30  # entered where it is deep (from the west at the top, from below at the wall)
    assert not shallow_entries(state, 8)[1 + 12, 43 + 12]  # shallow from the west (3 cells), deep from below


def test_views_of_pockets_leave_the_outside_to_the_frontiers_but_keep_a_pocket_at_the_outer_wall():
    """Slivers of the outside between beams through a room's open end kept robots looking after 99 %;
    the space behind a desk at the outer wall, whose wall stretch is unseen, joins the outside unless the
    wall is bridged."""
    from slam2d.exploration.gridops import unknown_in_sight
    from slam2d.exploration.pockets import pocket_state, without_outside

    state = np.full((70, 90), UNKNOWN, dtype=np.int8)
    state[10:50, 10:60] = FREE  # a room ...
    state[9, 9:61] = state[50, 9:61] = OCCUPIED
    state[9:51, 9] = state[9:51, 60] = OCCUPIED
    state[26:34, 60] = FREE  # ... open to the east, where beams fan out into the outside
    for row in (22, 26, 30, 33, 37):
        cols = np.arange(61, 90)
        state[np.round(30 + (row - 30) * (cols - 60) / 30).astype(int), cols] = FREE
    state[44, 25:41] = OCCUPIED  # a desk at the north wall, the wall behind it never seen
    state[45:51, 24:42] = UNKNOWN
    scored = pocket_state(state, 1)
    res = 0.05
    view = lambda grid: GridView(grid, res, (0.0, 0.0))
    seen = lambda grid, xy: unknown_in_sight(view(grid), xy, 6.0, 360)
    opening, beside = (56 * res, 30 * res), (21 * res, 47.5 * res)  # (x, y) m: at the open end, beside the desk
    kept = without_outside(scored, 40)
    assert seen(scored, opening)[:, 61:].any() and not seen(kept, opening)[:, 61:].any()  # no sliver is a target
    pocket = np.s_[45:50, 25:41]
    behind = seen(scored, beside)[pocket]
    assert behind.sum() >= 20 and np.array_equal(seen(kept, beside)[pocket], behind)  # kept
    assert not seen(without_outside(scored, 0), beside)[pocket].any()  # unbridged, it is the outside's
