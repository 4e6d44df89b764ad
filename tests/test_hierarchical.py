"""HPA* and the room-graph planner: valid paths, completeness, bounded suboptimality."""

from __future__ import annotations

import numpy as np
import pytest

from slam2d.planning.astar import AStar, check_path
from slam2d.planning.grid import PlanningGrid, load_movingai_map, load_scenarios
from slam2d.planning.hierarchical import HPAStar, entrances
from slam2d.planning.room_graph import RoomGraphPlanner


def assert_valid(free, result, start, goal):
    assert result.found, result.reason
    assert check_path(free, result.path) == ""
    assert tuple(result.path[0]) == tuple(start) and tuple(result.path[-1]) == tuple(goal)


def maze(seed: int, shape=(60, 70)) -> np.ndarray:
    """Random obstacles plus a few long walls with gaps (so detours matter)."""
    rng = np.random.default_rng(seed)
    free = rng.random(shape) > 0.2
    for c in (15, 35, 52):
        free[:, c] = False
        free[rng.integers(0, shape[0], 3), c] = True
    return free


def test_entrances_one_or_two_transitions():
    free = np.zeros((10, 20), bool)
    free[:, :] = True
    free[:, 9] = False  # border between clusters 0 and 1 (cluster size 10) is cols 9 | 10
    free[2:5, 9] = True  # width-3 entrance: one transition, in the middle
    a, b = entrances(free, 10)
    assert a.tolist() == [[3, 9]] and b.tolist() == [[3, 10]]
    free[:, 9] = True  # width 10: two transitions, at the ends
    a, b = entrances(free, 10)
    assert sorted(map(tuple, a.tolist())) == [(0, 9), (9, 9)]


@pytest.mark.parametrize("cluster", [5, 8, 13])
@pytest.mark.parametrize("seed", range(3))
def test_hpa_paths_valid_complete_and_near_optimal(seed, cluster):
    free = maze(seed)
    exact = AStar(free)
    raw, smooth = HPAStar(free, cluster, smooth=False), HPAStar(free, cluster)
    assert raw.build_seconds > 0 and raw.n_nodes > 0
    cells = np.argwhere(free)
    rng = np.random.default_rng(seed)
    ratios = []
    for _ in range(40):
        s, t = cells[rng.integers(len(cells), size=2)]
        ref = exact.plan(s, t)
        for planner in (raw, smooth):
            r = planner.plan(s, t)
            if not ref.found:
                assert not r.found and "unreachable" in r.reason
                continue
            assert_valid(free, r, s, t)
            assert r.length >= ref.length - 1e-9
            ratios.append((planner is smooth, r.length / max(ref.length, 1e-9)))
    raw_r = np.array([q for sm, q in ratios if not sm])
    sm_r = np.array([q for sm, q in ratios if sm])
    assert raw_r.max() < 1.5 and raw_r.mean() < 1.10
    assert sm_r.max() < 1.25 and sm_r.mean() < 1.03
    assert (sm_r <= raw_r + 1e-9).all()


def test_hpa_unreachable_and_blocked_endpoints():
    free = np.ones((40, 40), bool)
    free[:, 20] = False
    hpa = HPAStar(free, 10)
    r = hpa.plan((5, 5), (5, 35))
    assert not r.found and "unreachable" in r.reason
    r = hpa.plan((5, 20), (5, 35))
    assert not r.found and "blocked" in r.reason
    assert hpa.plan((5, 5), (5, 5)).path.tolist() == [[5, 5]]


def test_hpa_on_arena_within_bounds(data_file):
    grid = load_movingai_map(data_file("movingai/arena.map"))
    sc = load_scenarios(data_file("movingai/arena.map.scen"))
    hpa = HPAStar(grid, 10)
    sub = []
    for s, t, opt in zip(sc.start_cells, sc.goal_cells, sc.optimal):
        r = hpa.plan(s, t)
        assert_valid(grid.free, r, s, t)
        sub.append(r.length / opt - 1.0)
    assert np.mean(sub) < 0.02 and np.max(sub) < 0.2 and np.min(sub) > -1e-5


def test_hpa_16room_long_queries_optimal(data_file):
    """16-cell clusters align with the rooms of 16room_000: transitions sit in the doors."""
    grid = load_movingai_map(data_file("movingai/16room_000.map"))
    sc = load_scenarios(data_file("movingai/16room_000.map.scen"))
    hpa = HPAStar(grid, 16)
    for i in np.flatnonzero(sc.bucket >= 150)[::10]:
        r = hpa.plan(sc.start_cells[i], sc.goal_cells[i])
        assert_valid(grid.free, r, sc.start_cells[i], sc.goal_cells[i])
        assert abs(r.length - sc.optimal[i]) <= 1e-5 * sc.optimal[i]
        assert r.expanded < 20_000


# ---------------------------------------------------------------- room graph


def three_rooms():
    """30 x 60: rooms 1 | 2 | 3 split by walls at cols 20 and 40 with doors; room 4 sealed off."""
    free = np.ones((30, 60), bool)
    free[:, 20] = False
    free[:, 40] = False
    free[24, 41:] = False
    free[5:8, 20] = True  # door 1-2
    free[20:23, 40] = True  # door 2-3
    labels = np.zeros(free.shape, np.int32)
    labels[:, :21] = 1  # the door cells belong to the room on their left
    labels[:, 21:41] = 2
    labels[:24, 41:] = 3
    labels[25:, 41:] = 4
    labels[~free] = 0
    return free, labels


def region_graph_of(labels):
    from slam2d.mapping.topological import region_graph

    return region_graph(labels, 0.05, row0_top=False)


def test_room_graph_planner_three_rooms():
    free, labels = three_rooms()
    grid = PlanningGrid(free, 0.05)
    graph = region_graph_of(labels)
    assert set(graph.edges) == {(1, 2), (2, 3)}
    exact = AStar(grid)
    for smooth in (False, True):
        planner = RoomGraphPlanner(grid, labels, graph, smooth=smooth)
        s, t = (28, 2), (2, 57)
        r = planner.plan(s, t)
        assert_valid(free, r, s, t)
        assert r.info["mode"] == "regions" and r.info["regions"] == 3
        cells = {tuple(c) for c in r.path}
        assert cells & {(5, 20), (6, 20), (7, 20)} and cells & {(20, 40), (21, 40), (22, 40)}
        ref = exact.plan(s, t).length
        assert ref - 1e-9 <= r.length <= 1.05 * ref
        assert r.length_m == pytest.approx(0.05 * r.length)
    same = planner.plan((2, 2), (28, 18))
    assert_valid(free, same, (2, 2), (28, 18)) and same.info["regions"] == 1
    sealed = planner.plan((2, 2), (27, 50))
    assert not sealed.found and "unreachable" in sealed.reason
    assert not planner.plan((2, 20), (2, 2)).found  # start in a wall


def test_room_graph_unlabelled_cells_and_fallback():
    free, labels = three_rooms()
    labels[10:14, 25:30] = 0  # free cells without a region join the nearest one
    grid = PlanningGrid(free)
    planner = RoomGraphPlanner(grid, labels, region_graph_of(labels))
    r = planner.plan((12, 27), (2, 2))
    assert_valid(free, r, (12, 27), (2, 2)) and r.info["mode"] == "regions"
    # A bad segmentation: region 2 is two pieces split by a wall at col 30 whose only gap lies in
    # region 5 (a strip along the bottom). The route 1 -> 2 -> 3 cannot be stitched inside region 2
    # (nor inside the corridor 1 + 2 + 3), so the planner falls back to the whole grid.
    free2 = free.copy()
    free2[:, 30] = False
    free2[27:, 30] = True
    labels2 = labels.copy()
    labels2[25:, 21:40] = 5
    labels2[~free2] = 0
    graph = region_graph_of(labels2)
    assert graph.has_edge(2, 5) and graph.has_edge(1, 2) and graph.has_edge(2, 3)
    r = RoomGraphPlanner(PlanningGrid(free2), labels2, graph).plan((2, 2), (2, 57))
    assert_valid(free2, r, (2, 2), (2, 57))
    assert r.info["mode"] in ("corridor", "grid")
    assert r.length == pytest.approx(AStar(free2).plan((2, 2), (2, 57)).length, rel=0.05)


def test_room_graph_corridor_is_shortest_inside_the_route_rooms():
    from slam2d.planning.query import make_planner

    free, labels = three_rooms()
    grid = PlanningGrid(free, 0.05)
    planner = make_planner(grid, "rooms", labels=labels, corridor=True)
    assert planner.corridor and not make_planner(grid, "rooms", labels=labels).corridor
    planner.smooth = False
    stitched = RoomGraphPlanner(grid, labels, region_graph_of(labels), smooth=False)
    for s, t in (((28, 2), (2, 57)), ((2, 2), (22, 58)), ((15, 10), (10, 45))):
        r = planner.plan(s, t)
        assert_valid(free, r, s, t) and r.info["mode"] == "corridor"
        ref = AStar(grid).plan(s, t).length  # rooms 1-3 hold every path: the corridor is exact
        assert r.length == pytest.approx(ref) and r.length <= stitched.plan(s, t).length + 1e-9


@pytest.mark.parametrize("corridor", [False, True])
def test_room_graph_corridor_bounds_the_detour_where_portal_routing_detours(data_file, corridor):
    """office_b's morphological rooms: routing portal to portal detours by over 50 % on some queries; the
    corridor search over the route's rooms and those near them is exact on all of them."""
    from slam2d.planning.config import PlanConfig
    from slam2d.planning.query import plan_queries

    cfg = PlanConfig.model_validate({"map": str(data_file("rooms/office_b.png")), "planning": {
        "hierarchy": "rooms", "queries": 40, "min_distance": 10.0, "corridor": corridor},
        "segmentation": {"method": "morphological"}})  # fmt: skip
    m = plan_queries(cfg.map, cfg)
    assert m["failures"] == 0
    if corridor:
        assert m["max_subopt_pct"] <= 5.0 and m["mean_subopt_pct"] <= 1.0
    else:
        assert m["max_subopt_pct"] > 50.0
