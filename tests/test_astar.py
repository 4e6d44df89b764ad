"""Grid A*, planning grids and smoothing: optimality, corner rule, failures, Moving AI data."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from slam2d.errors import InputError
from slam2d.planning.astar import SQRT2, AStar, astar, check_path, path_cost, path_length
from slam2d.planning.grid import (
    PlanningGrid,
    inflate,
    load_grid,
    load_movingai_map,
    load_scenarios,
    wall_cost,
)
from slam2d.planning.smoothing import line_of_sight, shortcut, smooth_octile, supercover


def reference_lengths(free: np.ndarray, source, connectivity: int = 8, cost=None) -> np.ndarray:
    """Dijkstra (scipy) on the same grid graph: axial 1, diagonal √2 without corner cutting."""
    h, w = free.shape
    idx = np.arange(h * w).reshape(h, w)
    rows, cols, wts = [], [], []
    moves = [(0, 1), (1, 0)] + ([(1, 1), (1, -1)] if connectivity == 8 else [])
    for dr, dc in moves:
        for r in range(h - dr):
            for c in range(max(-dc, 0), w - max(dc, 0)):
                r2, c2 = r + dr, c + dc
                if not (free[r, c] and free[r2, c2]):
                    continue
                if dr and dc and not (free[r2, c] and free[r, c2]):
                    continue
                step = math.hypot(dr, dc)
                if cost is not None:
                    step *= 1 + 0.5 * (cost[r, c] + cost[r2, c2])
                rows.append(idx[r, c])
                cols.append(idx[r2, c2])
                wts.append(step)
    graph = coo_matrix((wts, (rows, cols)), shape=(h * w, h * w)).tocsr()
    return dijkstra(graph, directed=False, indices=idx[source]).reshape(h, w)


def random_free(seed: int, shape=(24, 30), density=0.3) -> np.ndarray:
    return np.random.default_rng(seed).random(shape) > density


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("connectivity", [4, 8])
def test_lengths_match_dijkstra_on_random_maps(seed, connectivity):
    free = random_free(seed)
    planner = AStar(free, connectivity)
    rng = np.random.default_rng(100 + seed)
    cells = np.argwhere(free)
    for _ in range(15):
        s, t = cells[rng.integers(len(cells), size=2)]
        ref = reference_lengths(free, tuple(s), connectivity)[tuple(t)]
        r = planner.plan(s, t)
        if np.isinf(ref):
            assert not r.found and "unreachable" in r.reason
            continue
        assert r.found and r.length == pytest.approx(ref, abs=1e-9)
        assert check_path(free, r.path, connectivity) == ""
        assert tuple(r.path[0]) == tuple(s) and tuple(r.path[-1]) == tuple(t)
        assert path_length(r.path) == pytest.approx(r.length)


def test_corner_is_not_cut():
    free = np.ones((3, 3), bool)
    free[0, 1] = False  # one side of the diagonal (0,0)->(1,1) is blocked
    r = astar(free, (0, 0), (1, 1))
    assert r.found and r.length == pytest.approx(2.0)
    assert [tuple(c) for c in r.path] == [(0, 0), (1, 0), (1, 1)]
    free[1, 0] = False  # both sides blocked: diagonal squeeze is not a passage
    r = astar(free, (0, 0), (1, 1))
    assert not r.found and "unreachable" in r.reason


def test_hand_made_wall_optimal_length():
    free = np.ones((7, 9), bool)
    free[1:7, 4] = False  # wall with a gap at row 0
    r = astar(free, (6, 0), (6, 8))
    # up the left side to the gap and down again: diagonal moves where corners allow
    assert r.found
    assert r.length == pytest.approx(reference_lengths(free, (6, 0))[6, 8])
    assert (r.path[:, 0] == 0).any()  # through the gap
    assert check_path(free, r.path) == ""


def test_unreachable_goal_is_fast_and_explained():
    free = np.ones((300, 300), bool)
    free[:, 150] = False
    planner = AStar(free)
    t0 = time.perf_counter()
    r = planner.plan((10, 10), (10, 290))
    assert time.perf_counter() - t0 < 2.0
    assert not r.found and "unreachable" in r.reason and r.path.shape == (0, 2)
    assert r.expanded == 300 * 150  # exactly the start's side was searched
    assert math.isinf(r.length)


@pytest.mark.parametrize(
    "start, goal, words",
    [((0, 0), (5, 5), "start cell (0, 0) is blocked"), ((5, 5), (9, 40), "goal cell (9, 40) is outside"),
     ((-1, 2), (5, 5), "start cell (-1, 2) is outside")],  # fmt: skip
)
def test_bad_endpoints_give_reasons(start, goal, words):
    free = np.ones((10, 10), bool)
    free[0, 0] = False
    r = AStar(free).plan(start, goal)
    assert not r.found and words in r.reason


def test_four_vs_eight_connected_lengths():
    free = np.ones((10, 10), bool)
    assert astar(free, (0, 0), (3, 5), connectivity=4).length == pytest.approx(8.0)
    assert astar(free, (0, 0), (3, 5), connectivity=8).length == pytest.approx(3 * SQRT2 + 2)
    r4 = astar(free, (0, 0), (3, 5), connectivity=4)
    assert check_path(free, r4.path, 4) == "" and (np.abs(np.diff(r4.path, axis=0)).sum(axis=1) == 1).all()


def test_ties_toward_larger_g_expand_little_on_open_grid():
    free = np.ones((100, 100), bool)
    r = astar(free, (50, 0), (50, 60))
    assert r.found and r.length == pytest.approx(60.0)
    assert r.expanded <= 61 + 5


def test_buffers_reused_across_queries():
    free = random_free(3, (40, 40))
    planner = AStar(free)
    cells = np.argwhere(free)
    pairs = [tuple(map(tuple, cells[i])) for i in np.random.default_rng(0).integers(len(cells), size=(20, 2))]
    first = [planner.plan(s, t).length for s, t in pairs]
    again = [planner.plan(s, t).length for s, t in pairs]
    fresh = [astar(free, s, t).length for s, t in pairs]
    assert first == again == fresh


def test_cost_layer_detours_and_stays_optimal():
    free = np.ones((15, 15), bool)
    free[7, 2:13] = False
    grid = PlanningGrid(free)
    cost = wall_cost(grid, distance=3.0, weight=4.0)
    assert (cost >= 0).all() and cost[3, 7] == 0.0 and cost[6, 7] > 0
    r = AStar(grid, cost=cost).plan((3, 7), (11, 7))
    ref = reference_lengths(free, (3, 7), cost=cost)[11, 7]
    assert r.found and r.cost == pytest.approx(ref) and r.cost == pytest.approx(path_cost(r.path, cost))
    assert r.cost >= r.length
    with pytest.raises(ValueError, match="cost layer"):
        AStar(grid, cost=-cost)


def test_movingai_arena_every_scenario_optimal(data_file):
    grid = load_movingai_map(data_file("movingai/arena.map"))
    scen = load_scenarios(data_file("movingai/arena.map.scen"))
    assert grid.shape == (scen.height, scen.width) == (49, 49)
    planner = AStar(grid)
    for s, t, opt in zip(scen.start_cells, scen.goal_cells, scen.optimal):
        r = planner.plan(s, t)
        assert r.found and abs(r.length - opt) <= 1e-5 * max(opt, 1.0), (s, t, r.length, opt)
        assert check_path(grid.free, r.path) == ""


# ---------------------------------------------------------------- grids


def test_movingai_errors_name_file_and_line(tmp_path):
    good = "type octile\nheight 2\nwidth 3\nmap\n.@.\nG.S\n"
    (tmp_path / "ok.map").write_text(good)
    g = load_movingai_map(tmp_path / "ok.map")
    assert g.free.tolist() == [[True, False, True], [True, True, True]]
    (tmp_path / "short.map").write_text(good.replace("G.S", "G."))
    with pytest.raises(InputError, match=r"short\.map:6: expected 3 characters"):
        load_movingai_map(tmp_path / "short.map")
    (tmp_path / "bad.map").write_text(good.replace("height 2", "height two"))
    with pytest.raises(InputError, match=r"bad\.map:2: expected 'height N'"):
        load_movingai_map(tmp_path / "bad.map")
    (tmp_path / "odd.map").write_text(good.replace(".@.", ".x."))
    with pytest.raises(InputError, match=r"odd\.map:5: unknown terrain 'x'"):
        load_movingai_map(tmp_path / "odd.map")
    scen = "version 1\n0\tm.map\t3\t2\t0\t0\t2\t1\t2.41421\n1\tm.map\t3\t2\t0\t0\t9\t1\t2\n"
    (tmp_path / "m.map.scen").write_text(scen)
    with pytest.raises(InputError, match=r"m\.map\.scen:3: start .* outside the 3x2 map"):
        load_scenarios(tmp_path / "m.map.scen")
    (tmp_path / "n.map.scen").write_text("version 1\n0\tm.map\t3\t2\t0\t0\t2\n")
    with pytest.raises(InputError, match=r"n\.map\.scen:2: expected 9 fields"):
        load_scenarios(tmp_path / "n.map.scen")


def test_scenarios_columns_are_x_then_y(tmp_path):
    (tmp_path / "m.map.scen").write_text("version 1\n4\tm.map\t3\t2\t2\t0\t0\t1\t2.41421\n")
    sc = load_scenarios(tmp_path / "m.map.scen")
    assert sc.bucket.tolist() == [4] and sc.start.tolist() == [[2, 0]] and sc.start_cells.tolist() == [[0, 2]]
    assert sc.goal_cells.tolist() == [[1, 0]] and sc.optimal[0] == pytest.approx(2.41421)


def test_floor_plan_and_map_server_loading(tmp_path):
    from PIL import Image

    from slam2d.config import MappingConfig
    from slam2d.mapping.export import save_map_server
    from slam2d.mapping.grid import OccupancyGrid

    img = np.full((4, 6), 255, np.uint8)
    img[0, :] = 0  # top row of the image is a wall
    img[3, 5] = 249  # just below the free threshold
    Image.fromarray(img).save(tmp_path / "plan.png")
    g = load_grid(tmp_path / "plan.png", resolution=0.1)
    assert g.resolution == 0.1 and not g.free[3].any()  # flipped: image row 0 is grid row 3 (top)
    assert not g.free[0, 5] and g.free[0, 0]
    assert g.world_to_cell([0.05, 0.05]).tolist() == [0, 0]
    assert np.allclose(g.cell_to_world([2, 3]), [0.35, 0.25])

    lo = np.full((5, 4), -5.0)
    lo[0, 0] = 5.0  # occupied
    lo[4, 3] = 0.0  # unknown
    save_map_server(OccupancyGrid(lo, 0.05, (1.0, 2.0)), tmp_path / "map", MappingConfig())
    m = load_grid(tmp_path / "map.yaml")
    assert m.shape == (5, 4) and m.origin == (1.0, 2.0)
    assert not m.free[0, 0] and not m.free[4, 3] and m.free.sum() == 18
    with pytest.raises(InputError, match="not found"):
        load_grid(tmp_path / "nope.yaml")


def test_inflation_by_robot_radius():
    free = np.ones((21, 21), bool)
    free[10, 10] = False
    g = PlanningGrid(free, resolution=0.05)
    inf = g.inflated(0.1)  # 2 cells
    assert not inf.free[10, 12] and not inf.free[8, 10] and inf.free[10, 13] and inf.free[8, 8]
    assert not inf.free[0, 5]  # the map border counts as an obstacle
    assert inflate(free, 0).sum() == free.sum()


# ---------------------------------------------------------------- smoothing


def test_supercover_touches_corners_and_los_matches():
    assert {tuple(c) for c in supercover((0, 0), (2, 2))} == {(0, 0), (0, 1), (1, 0), (1, 1), (1, 2), (2, 1), (2, 2)}
    free = np.ones((3, 3), bool)
    free[0, 1] = False
    assert not line_of_sight(free, (0, 0), (1, 1))  # would cut the blocked corner
    assert line_of_sight(free, (2, 0), (2, 2))
    # through the grid vertex at (0.5, 1.5): all four cells around it
    assert {tuple(c) for c in supercover((0, 0), (1, 3))} == {(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (1, 3)}
    # through the middle of the edge between (0, 1) and (1, 1): both
    assert {tuple(c) for c in supercover((0, 0), (1, 2))} == {(0, 0), (0, 1), (1, 1), (1, 2)}


@pytest.mark.parametrize("goal", [(20, 20), (10, 20), (20, 40)])
def test_shortcut_straight_corridor_gives_two_points(goal):
    """Open corridor along a diagonal / knight-move line: no zig-zag kinks survive."""
    free = np.zeros((25, 45), bool)
    for cell in supercover((0, 0), goal):
        r, c = cell
        free[max(r - 1, 0) : r + 2, max(c - 1, 0) : c + 2] = True
    r = astar(free, (0, 0), goal)
    assert r.found and len(r.path) > 2
    wp = shortcut(free, r.path)
    assert [tuple(p) for p in wp] == [(0, 0), goal]


def test_shortcut_and_octile_smoothing_stay_collision_free():
    for seed in range(4):
        free = random_free(seed, (40, 50), 0.25)
        cells = np.argwhere(free)
        rng = np.random.default_rng(seed)
        for _ in range(10):
            s, t = cells[rng.integers(len(cells), size=2)]
            r = astar(free, s, t)
            if not r.found:
                continue
            wp = shortcut(free, r.path)
            assert all(line_of_sight(free, a, b) for a, b in zip(wp[:-1], wp[1:]))
            assert path_length(wp) <= r.length + 1e-9
            sm = smooth_octile(free, r.path)
            assert check_path(free, sm) == "" and path_length(sm) <= r.length + 1e-9
            assert tuple(sm[0]) == tuple(s) and tuple(sm[-1]) == tuple(t)
