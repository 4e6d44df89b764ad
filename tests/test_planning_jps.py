"""JPS and JPS+: A*'s optimal lengths on random maps and queries, A*'s failures, the registry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slam2d.planning.astar import AStar, check_path, path_length
from slam2d.planning.base import GLOBAL_PLANNERS
from slam2d.planning.grid import PlanningGrid, load_movingai_map, load_scenarios
from slam2d.planning.jps import JPS, jps
from slam2d.planning.jps_plus import JPSPlus, jump_distances
from slam2d.planning.query import make_planner

PLANNERS = [JPS, JPSPlus]


def random_map(rng: np.random.Generator) -> np.ndarray:
    """Noise, rectangles (rooms and pillars) or a mix, 2 to 48 cells a side."""
    h, w = (int(v) for v in rng.integers(2, 48, size=2))
    kind = rng.integers(3)
    free = rng.random((h, w)) > (rng.uniform(0.0, 0.45) if kind != 1 else 1.0)
    if kind >= 1:
        for _ in range(rng.integers(1, 12)):
            r, c = rng.integers(0, h), rng.integers(0, w)
            free[r : r + rng.integers(1, 10), c : c + rng.integers(1, 10)] = False
    return free


def assert_same_as_astar(free, planners, queries, rng):
    """``queries`` random start-goal pairs: each planner finds what A* finds, as long, a valid path."""
    astar = AStar(free)
    cells = np.argwhere(free)
    for _ in range(queries):
        s, t = cells[rng.integers(len(cells), size=2)]
        ref = astar.plan(s, t)
        for p in planners:
            r = p.plan(s, t)
            assert r.found == ref.found, (p.name, s, t, r.reason)
            if not ref.found:
                assert "unreachable" in r.reason and r.path.shape == (0, 2) and math.isinf(r.length)
                continue
            assert r.length == pytest.approx(ref.length, rel=1e-9, abs=1e-9), (p.name, s, t)
            assert check_path(free, r.path) == ""  # no blocked cell, no gap, no cut corner
            assert tuple(r.path[0]) == tuple(s) and tuple(r.path[-1]) == tuple(t)
            assert path_length(r.path) == pytest.approx(r.length)
            nodes = r.info.get("jump_points", r.info.get("subgoals"))  # the corners the path was built from
            assert r.cost == r.length and nodes <= len(r.path)


def test_equal_lengths_to_astar_on_random_maps_and_queries():
    """2000 random maps x 4 queries (8000 cases per planner), and their unreachable pairs."""
    rng = np.random.default_rng(53)
    for _ in range(2000):
        free = random_map(rng)
        if free.sum() < 1:
            continue
        assert_same_as_astar(free, [JPS(free), JPSPlus(free)], 4, rng)


@pytest.mark.parametrize("seed", range(3))
def test_equal_lengths_on_open_and_large_maps(seed):
    """Long jumps: big rooms with doors and sparse pillars (200 x 260)."""
    rng = np.random.default_rng(seed)
    free = rng.random((200, 260)) > 0.02
    free[::40, :] = False
    free[:, ::50] = False
    for r in range(20, 200, 40):
        free[r - 20 : r - 17, ::50] = True  # doors through the vertical walls
    free[::40, 25:28] = True  # and through the horizontal ones
    assert_same_as_astar(free, [JPS(free), JPSPlus(free)], 60, rng)


@pytest.mark.parametrize("planner", PLANNERS)
def test_corner_is_not_cut_and_squeeze_is_no_passage(planner):
    free = np.ones((3, 3), bool)
    free[0, 1] = False
    r = planner(free).plan((0, 0), (1, 1))
    assert r.found and r.length == pytest.approx(2.0) and check_path(free, r.path) == ""
    free[1, 0] = False
    r = planner(free).plan((0, 0), (1, 1))
    assert not r.found and "unreachable" in r.reason


@pytest.mark.parametrize("planner", PLANNERS)
def test_unreachable_goal_like_astar(planner):
    free = np.ones((300, 300), bool)
    free[:, 150] = False
    r = planner(free).plan((10, 10), (10, 290))
    ref = AStar(free).plan((10, 10), (10, 290))
    assert not r.found and not ref.found and "is unreachable from start (10, 10)" in r.reason
    assert r.path.shape == (0, 2) and math.isinf(r.length) and math.isinf(r.cost)
    assert 0 < r.expanded < ref.expanded  # jump points, not cells


@pytest.mark.parametrize("planner", PLANNERS)
@pytest.mark.parametrize(
    "start, goal",
    [((0, 0), (5, 5)), ((5, 5), (0, 0)), ((5, 5), (9, 40)), ((-1, 2), (5, 5)), ((5, 5), (10, 3))],
)
def test_bad_endpoints_give_astar_reasons(planner, start, goal):
    free = np.ones((10, 10), bool)
    free[0, 0] = False
    r = planner(free).plan(start, goal)
    ref = AStar(free).plan(start, goal)
    assert not r.found and r.reason == ref.reason and r.path.shape == (0, 2)


@pytest.mark.parametrize("planner", PLANNERS)
def test_start_is_goal_and_world_points(planner):
    grid = PlanningGrid(np.ones((8, 8), bool), resolution=0.5, origin=(1.0, 2.0))
    p = planner(grid)
    r = p.plan((3, 4), (3, 4))
    assert r.found and r.length == 0.0 and [tuple(c) for c in r.path] == [(3, 4)]
    r = p.plan_world((1.2, 2.2), (4.9, 5.9))
    assert r.found and r.length_m == pytest.approx(7 * math.sqrt(2) * 0.5)


@pytest.mark.parametrize("planner", PLANNERS)
def test_cost_layer_is_refused_zero_layer_accepted(planner):
    free = np.ones((6, 6), bool)
    with pytest.raises(ValueError, match="uniform step costs.*astar"):
        planner(free, cost=np.full((6, 6), 0.5))
    assert planner(free, cost=np.zeros((6, 6))).plan((0, 0), (5, 5)).found


def test_jump_distances_on_a_corridor_and_a_corner():
    free = np.ones((1, 6), bool)
    d = jump_distances(free)
    assert d[3, 0].tolist() == [-5, -4, -3, -2, -1, 0]  # right: steps to the wall
    assert d[2, 0].tolist() == [0, -1, -2, -3, -4, -5]  # left
    assert (d[[0, 1, 4, 5, 6, 7]] == 0).all()  # no vertical or diagonal move in one row
    free = np.ones((3, 6), bool)
    free[0, :3] = False  # moving right along row 1: cell (1, 3) has a forced side (0, 3)
    d = jump_distances(free)
    assert d[3, 1, 0] == 3 and d[3, 1, 2] == 1 and d[3, 1, 3] == -2
    assert (d[:, ~free] == 0).all()


def test_jps_plus_build_is_timed_and_small():
    free = np.ones((100, 120), bool)
    p = JPSPlus(free)
    assert p.build_seconds >= 0 and p.table_bytes == 102 * 122 * 8 * 2  # int16


def test_registered_names_resolve():
    free = PlanningGrid(np.ones((5, 5), bool))
    assert {"jps", "jps_plus"} <= set(GLOBAL_PLANNERS.names())
    assert isinstance(GLOBAL_PLANNERS.create("jps", None, free), JPS)
    assert isinstance(GLOBAL_PLANNERS.create("jps_plus", None, free), JPSPlus)
    p = make_planner(free, "jps_plus", cluster_size=16)
    assert isinstance(p, JPSPlus) and p.plan((0, 0), (4, 4)).length == pytest.approx(4 * math.sqrt(2))
    assert jps(free.free, (0, 0), (4, 2)).length == pytest.approx(2 + 2 * math.sqrt(2))


@pytest.mark.parametrize("name", ["arena", "den312d"])
def test_movingai_scenarios_optimal(data_file, name):
    grid = load_movingai_map(data_file(f"movingai/{name}.map"))
    sc = load_scenarios(data_file(f"movingai/{name}.map.scen"))
    for planner in (JPS(grid), JPSPlus(grid)):
        for s, t, opt in zip(sc.start_cells, sc.goal_cells, sc.optimal):
            r = planner.plan(s, t)
            assert r.found and abs(r.length - opt) <= 1e-5 * max(opt, 1.0), (planner.name, s, t)


@pytest.mark.parametrize("name", ["jps", "jps_plus"])
def test_plan_queries_on_a_floor_plan_match_astar(data_file, name):
    from slam2d.planning.config import PlanConfig
    from slam2d.planning.query import plan_queries

    plan = data_file("rooms/Freiburg52_scan.png")
    cfg = PlanConfig.model_validate({"planning": {"hierarchy": name, "queries": 8, "min_distance": 5.0}})
    m = plan_queries(plan, cfg)
    assert m["planner"] == name and m["queries"] == 8 and m["failures"] == 0
    assert abs(m["mean_subopt_pct"]) < 1e-9 and abs(m["max_subopt_pct"]) < 1e-9 and m["min_query_m"] >= 5.0
