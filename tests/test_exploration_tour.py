"""The tour strategy's parts: the open tour by OR-tools against nearest-first, the greedy set cover of frontier
cells by line of sight."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from slam2d.exploration.frontiers import frontier_mask
from slam2d.exploration.gridops import FREE, OCCUPIED, UNKNOWN, GridView, geodesic
from slam2d.exploration.tour import (
    cheapest_insertion,
    coverage_matrix,
    greedy_cover,
    greedy_order,
    path_length,
    solve_open_tour,
)


def best_length(cost, end=None) -> float:
    nodes = [k for k in range(1, len(cost)) if k != end]
    return min(path_length(cost, list(p), end) for p in itertools.permutations(nodes))


def line_costs(xs) -> np.ndarray:
    pts = np.concatenate([[0.0], xs])
    return np.abs(pts[:, None] - pts[None])


def test_the_open_tour_visits_every_node_once_and_beats_nearest_first_on_a_line():
    """Nodes left and right of the robot along a corridor: nearest-first zigzags (1 m right, 2.8 m left, 5.8 m
    right, 2 m on: 11.6 m), the tour clears the near left side first (9.6 m, the optimum)."""
    cost = line_costs([1.0, -1.8, 4.0, 6.0])
    order = solve_open_tour(cost)
    assert sorted(order) == [1, 2, 3, 4]
    greedy = path_length(cost, greedy_order(cost, [1, 2, 3, 4]))
    assert greedy == pytest.approx(11.6)
    assert path_length(cost, order) == pytest.approx(best_length(cost)) == pytest.approx(9.6)
    # warm-started from the nearest-first order, with a fixed end: still every node once, the optimum
    order = solve_open_tour(cost, end=4, initial=greedy_order(cost, [1, 2, 3]))
    assert sorted(order) == [1, 2, 3]
    assert path_length(cost, order, 4) == pytest.approx(best_length(cost, 4))


def test_the_tour_over_rooms_on_a_hand_made_map_is_shorter_than_nearest_first():
    """Geodesic costs on a U-shaped corridor: rooms at both ends of each arm; the robot near the bottom of the
    left arm. Nearest-first goes back and forth; the tour is no longer, and as short as the best order."""
    free = np.zeros((60, 60), dtype=bool)
    free[5:55, 5:10] = True  # left arm
    free[5:55, 50:55] = True  # right arm
    free[50:55, 5:55] = True  # the bottom joining them
    rooms = np.array([[40, 7], [6, 7], [6, 52], [30, 52], [52, 30]])
    robot = np.array([45, 7])
    pts = np.vstack([robot, rooms])
    cost = np.array([geodesic(free, p, 0.1)[pts[:, 0], pts[:, 1]] for p in pts])
    assert np.isfinite(cost).all()
    order = solve_open_tour(cost)
    assert sorted(order) == [1, 2, 3, 4, 5]
    tour, greedy = path_length(cost, order), path_length(cost, greedy_order(cost, [1, 2, 3, 4, 5]))
    assert tour <= greedy + 1e-9
    assert tour == pytest.approx(best_length(cost), abs=0.02)


def test_cheapest_insertion_keeps_the_old_order_and_adds_the_new_nodes():
    cost = line_costs([1.0, 2.0, 3.0, 4.0])
    assert cheapest_insertion(cost, [1, 2, 4], [1, 2, 3, 4]) == [1, 2, 3, 4]


def room_with_an_opening():
    """A 4 x 3 m room (0.05 m cells) known-free, its top wall open between x 1.5 and 2.5 m onto unknown, a pillar
    in the middle; the frontier cells and every reachable cell every 0.3 m as viewpoints."""
    state = np.full((80, 100), UNKNOWN, dtype=np.int8)
    state[5:65, 5:85] = FREE
    state[4, 4:86] = state[65, 4:86] = OCCUPIED
    state[4:66, 4] = state[4:66, 85] = OCCUPIED
    state[65, 35:55] = FREE  # the opening in the top wall (row 65)
    state[30:38, 40:48] = OCCUPIED  # the pillar
    view = GridView(state, 0.05, (0.0, 0.0))
    mask = frontier_mask(state)
    cells = np.argwhere(mask)
    vp = np.argwhere(state == FREE)
    vp = vp[(vp[:, 0] % 6 == 0) & (vp[:, 1] % 6 == 0)]
    return view, cells, vp


def test_greedy_set_cover_covers_every_coverable_frontier_cell():
    view, cells, vp = room_with_an_opening()
    assert len(cells) > 5
    sees = coverage_matrix(view.state, vp, cells, 3.0 / view.resolution)
    coverable = sees.any(axis=0)
    assert coverable.any()
    chosen = greedy_cover(sees)
    assert sees[chosen].any(axis=0).tolist() == coverable.tolist()
    assert len(chosen) <= len(cells)
    # each chosen viewpoint adds cells the ones before it did not cover
    covered = np.zeros(len(cells), dtype=bool)
    for k in chosen:
        assert (sees[k] & ~covered).any()
        covered |= sees[k]


def test_a_viewpoint_sees_no_frontier_cell_behind_a_wall_or_out_of_range():
    view, cells, _ = room_with_an_opening()
    behind = np.array([[20, 44]])  # below the pillar, the opening above it
    near = np.array([[60, 44]])  # just under the opening
    assert not coverage_matrix(view.state, behind, cells, 100.0).any()
    assert coverage_matrix(view.state, near, cells, 100.0).all()
    assert not coverage_matrix(view.state, near, cells, 2.0).any()  # 0.1 m of range: the cells are farther


def test_the_tour_drives_to_a_viewpoint_of_the_opening_and_spends_it_once_its_cells_are_seen():
    from slam2d.exploration import config as explore_config
    from slam2d.exploration.explorer import Explorer

    view, _, _ = room_with_an_opening()
    ex = Explorer(explore_config.load(None, {"exploration.strategy": "tour"}).exploration, 0.2, 0.05, 12.0)
    goal = ex.decide(np.array([1.0, 1.0, 0.0]), view)
    assert goal is not None and goal.kind == "viewpoint"
    seen = view.to_cell(goal.targets)
    assert len(seen) and frontier_mask(view.state, depth=8)[seen[:, 0], seen[:, 1]].all()
    assert np.hypot(*(goal.position - view.to_world(seen).mean(axis=0))) <= 3.0  # within the view range
    assert not ex.spent(goal, view)
    state = view.state.copy()
    state[66:80, 30:60] = FREE  # the unknown beyond the opening seen: its cells are no frontier any more
    assert ex.spent(goal, GridView(state, view.resolution, view.origin))


def test_the_subspaces_within_the_horizon_are_toured_before_the_others():
    """A corridor east of the robot returns west below it and ends 4 m from a small leftover N 5 m west of the
    robot: the shortest open tour leaves N to the end (a trip back once the east grows further); with a 6 m
    horizon the three subspaces within it (N, M 3 m east, F 5 m south-west) come first, each subspace once, and
    stay first once the robot has moved away."""
    from slam2d.exploration.tour import TourPlanner

    pts = np.array([[0, 0], [-5, 1], [3, 0], [10, 0], [17, 0], [17, -6], [10, -6], [3, -6], [-4, -3]], dtype=float)
    cost = np.hypot(*(pts[:, None] - pts[None]).transpose(2, 0, 1))
    keys = [(k, 0) for k in range(1, len(pts))]  # N is subspace 0, M 1, F 7
    plain = TourPlanner()._global_order(keys, cost, 50.0, 0.0)
    assert plain[-1] == 0 and sorted(plain) == list(range(8))
    planner = TourPlanner()
    local = planner._global_order(keys, cost, 50.0, 6.0)
    assert sorted(local[:3]) == [0, 1, 7] and sorted(local) == list(range(8))
    # the robot drives east to (14, -1): N, M and F stay begun and come before D and E, never within 6 m
    pts[0] = [14.0, -1.0]
    cost = np.hypot(*(pts[:, None] - pts[None]).transpose(2, 0, 1))
    later = planner._global_order(keys, cost, 50.0, 6.0)
    assert max(later.index(k) for k in (0, 1, 7)) < min(later.index(k) for k in (5, 6))
    assert TourPlanner()._global_order(keys, cost, 50.0, 6.0)[-1] == 0  # without memory N is last again


def test_frontier_cells_a_reached_viewpoint_did_not_clear_are_no_target_any_more():
    """The robot reaches the viewpoint of the opening and the map does not change (the cells stay frontier, as
    a grazing view leaves them): the next decision does not send it to look at the same cells again."""
    from slam2d.exploration import config as explore_config
    from slam2d.exploration.explorer import Explorer

    view, _, _ = room_with_an_opening()
    ex = Explorer(explore_config.load(None, {"exploration.strategy": "tour"}).exploration, 0.2, 0.05, 12.0)
    first = ex.decide(np.array([1.0, 1.0, 0.0]), view)
    assert first is not None and first.kind == "viewpoint"
    ex.reached(first)
    again = ex.decide(np.array([*first.position, 0.0]), view)
    old = {tuple(c) for c in np.round(first.targets, 3)}
    assert again is None or again.targets is None or not old & {tuple(c) for c in np.round(again.targets, 3)}
