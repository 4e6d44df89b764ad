"""Simple Subgoal Graphs: A*'s optimal lengths on random maps and queries, valid paths, A*'s failures,
the published Moving AI optima, the registry."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_planning_jps import assert_same_as_astar, random_map

from slam2d.planning.astar import AStar, check_path
from slam2d.planning.base import GLOBAL_PLANNERS
from slam2d.planning.grid import PlanningGrid, load_movingai_map, load_scenarios
from slam2d.planning.query import make_planner
from slam2d.planning.subgoal import SubgoalGraph, subgoal_mask


def test_equal_lengths_to_astar_on_random_maps_and_queries():
    """4000 random maps x 4 queries (16 000 cases), and their unreachable pairs."""
    rng = np.random.default_rng(2013)
    for _ in range(4000):
        free = random_map(rng)
        if free.sum() < 1:
            continue
        assert_same_as_astar(free, [SubgoalGraph(free)], 4, rng)


@pytest.mark.parametrize("seed", range(3))
def test_equal_lengths_on_open_and_large_maps(seed):
    """Long edges: big rooms with doors and sparse pillars (200 x 260)."""
    rng = np.random.default_rng(seed)
    free = rng.random((200, 260)) > 0.02
    free[::40, :] = False
    free[:, ::50] = False
    for r in range(20, 200, 40):
        free[r - 20 : r - 17, ::50] = True
    free[::40, 25:28] = True
    assert_same_as_astar(free, [SubgoalGraph(free)], 60, rng)


def test_subgoals_are_convex_corners_without_corner_cutting():
    free = np.ones((5, 5), bool)
    free[2, 2] = False
    assert sorted(map(tuple, np.argwhere(subgoal_mask(free)))) == [(1, 1), (1, 3), (3, 1), (3, 3)]
    free[1, 2] = False  # (1, 1)'s sides toward (2, 2): (1, 2) now blocked
    assert sorted(map(tuple, np.argwhere(subgoal_mask(free)))) == [(0, 1), (0, 3), (3, 1), (3, 3)]
    assert not subgoal_mask(np.ones((4, 4), bool)).any()  # the border makes none


def test_corner_is_not_cut_and_squeeze_is_no_passage():
    free = np.ones((3, 3), bool)
    free[0, 1] = False
    r = SubgoalGraph(free).plan((0, 0), (1, 1))
    assert r.found and r.length == pytest.approx(2.0) and check_path(free, r.path) == ""
    free[1, 0] = False
    r = SubgoalGraph(free).plan((0, 0), (1, 1))
    assert not r.found and "unreachable" in r.reason


def test_unreachable_goal_like_astar():
    free = np.ones((300, 300), bool)
    free[:, 150] = False
    free[100:110, 60:70] = False
    r = SubgoalGraph(free).plan((10, 10), (10, 290))
    ref = AStar(free).plan((10, 10), (10, 290))
    assert not r.found and not ref.found and "is unreachable from start (10, 10)" in r.reason
    assert r.path.shape == (0, 2) and math.isinf(r.length) and math.isinf(r.cost)
    assert 0 < r.expanded < ref.expanded  # graph nodes, not cells


@pytest.mark.parametrize(
    "start, goal",
    [((0, 0), (5, 5)), ((5, 5), (0, 0)), ((5, 5), (9, 40)), ((-1, 2), (5, 5)), ((5, 5), (10, 3))],
)
def test_bad_endpoints_give_astar_reasons(start, goal):
    free = np.ones((10, 10), bool)
    free[0, 0] = False
    r = SubgoalGraph(free).plan(start, goal)
    ref = AStar(free).plan(start, goal)
    assert not r.found and r.reason == ref.reason and r.path.shape == (0, 2)


def test_start_is_goal_and_world_points():
    grid = PlanningGrid(np.ones((8, 8), bool), resolution=0.5, origin=(1.0, 2.0))
    p = SubgoalGraph(grid)
    r = p.plan((3, 4), (3, 4))
    assert r.found and r.length == 0.0 and [tuple(c) for c in r.path] == [(3, 4)]
    r = p.plan_world((1.2, 2.2), (4.9, 5.9))
    assert r.found and r.length_m == pytest.approx(7 * math.sqrt(2) * 0.5)


def test_endpoints_on_subgoals():
    free = np.ones((12, 12), bool)
    free[4:8, 4:8] = False
    p = SubgoalGraph(free)
    corners = [tuple(c) for c in np.argwhere(subgoal_mask(free))]
    assert set(corners) == {(3, 3), (3, 8), (8, 3), (8, 8)}
    for s in corners + [(0, 0), (11, 11), (5, 10)]:
        for t in corners + [(0, 11), (6, 1)]:
            r, ref = p.plan(s, t), AStar(free).plan(s, t)
            assert r.length == pytest.approx(ref.length, rel=1e-9) and check_path(free, r.path) == ""


def test_cost_layer_is_refused_zero_layer_accepted():
    free = np.ones((6, 6), bool)
    with pytest.raises(ValueError, match="uniform step costs.*astar"):
        SubgoalGraph(free, cost=np.full((6, 6), 0.5))
    assert SubgoalGraph(free, cost=np.zeros((6, 6))).plan((0, 0), (5, 5)).found


def test_build_is_timed_and_counted():
    free = np.ones((40, 50), bool)
    free[10:20, 10:20] = False
    p = SubgoalGraph(free)
    assert p.build_seconds >= 0 and p.subgoals == 4 and p.edges >= 4
    assert p.arcs == 2 * p.edges == len(p.wgt)  # stored both ways


def test_registered_name_resolves():
    free = PlanningGrid(np.ones((5, 5), bool))
    assert "subgoal" in set(GLOBAL_PLANNERS.names())
    assert isinstance(GLOBAL_PLANNERS.create("subgoal", None, free), SubgoalGraph)
    p = make_planner(free, "subgoal", cluster_size=16)
    assert isinstance(p, SubgoalGraph) and p.plan((0, 0), (4, 4)).length == pytest.approx(4 * math.sqrt(2))


@pytest.mark.parametrize("name", ["arena", "den312d"])
def test_movingai_scenarios_optimal(data_file, name):
    grid = load_movingai_map(data_file(f"movingai/{name}.map"))
    sc = load_scenarios(data_file(f"movingai/{name}.map.scen"))
    planner = SubgoalGraph(grid)
    for s, t, opt in zip(sc.start_cells, sc.goal_cells, sc.optimal):
        r = planner.plan(s, t)
        assert r.found and abs(r.length - opt) <= 1e-5 * max(opt, 1.0), (s, t)
        assert check_path(grid.free, r.path) == ""


def test_plan_queries_on_a_floor_plan_match_astar(data_file):
    from slam2d.planning.config import PlanConfig
    from slam2d.planning.query import plan_queries

    plan = data_file("rooms/Freiburg52_scan.png")
    cfg = PlanConfig.model_validate({"planning": {"hierarchy": "subgoal", "queries": 8, "min_distance": 5.0}})
    m = plan_queries(plan, cfg)
    assert m["planner"] == "subgoal" and m["queries"] == 8 and m["failures"] == 0
    assert abs(m["mean_subopt_pct"]) < 1e-9 and abs(m["max_subopt_pct"]) < 1e-9 and m["min_query_m"] >= 5.0
