"""Bounded path searches and pruned views of pockets give what the full computation gives, on random maps."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from slam2d.exploration import explorer as explorer_mod
from slam2d.exploration import pockets as pockets_mod
from slam2d.exploration.config import ExplorationConfig
from slam2d.exploration.explorer import Explorer
from slam2d.exploration.frontiers import find_frontiers
from slam2d.exploration.gridops import FREE, OCCUPIED, UNKNOWN, GridView, geodesic
from slam2d.exploration.paths import Paths, _Dense
from slam2d.exploration.pockets import LocalRefresh, pocket_state


def random_map(rng, shape=(90, 110)) -> np.ndarray:
    """Rooms of free space (some walled, some open onto the unknown) and wall segments inside them."""
    state = np.full(shape, UNKNOWN, dtype=np.int8)
    h, w = shape
    for _ in range(rng.integers(3, 7)):
        r0, c0 = rng.integers(0, h - 20), rng.integers(0, w - 20)
        r1, c1 = r0 + rng.integers(12, 40), c0 + rng.integers(12, 40)
        state[r0:r1, c0:c1] = FREE
        if rng.random() < 0.6:
            walls = np.zeros(shape, dtype=bool)
            walls[r0:r1, c0:c1] = True
            ring = walls & ~ndimage.binary_erosion(walls)
            ring[r0 + 3 : r0 + 10, c0] = False  # a door
            state[ring] = OCCUPIED
    for _ in range(rng.integers(2, 6)):
        r, c = rng.integers(0, h), rng.integers(0, w)
        if rng.random() < 0.5:
            state[r, c : c + rng.integers(5, 25)] = OCCUPIED
        else:
            state[r : r + rng.integers(5, 25), c] = OCCUPIED
    return state


def random_start(rng, view: GridView) -> np.ndarray:
    rows, cols = np.nonzero(view.traversable(0.4))
    k = rng.integers(len(rows))
    return np.array([*view.to_world(np.array([rows[k], cols[k]])), rng.uniform(-np.pi, np.pi)])


def change_a_patch(rng, state: np.ndarray) -> None:
    """Overwrite a random patch of ``state`` (possibly cut by its edges) with free, occupied and unknown cells."""
    r, c = rng.integers(-3, state.shape[0]), rng.integers(-3, state.shape[1])
    patch = state[max(r, 0) : r + rng.integers(2, 15), max(c, 0) : c + rng.integers(2, 15)]
    patch[...] = rng.choice([FREE, OCCUPIED, UNKNOWN], size=patch.shape, p=[0.6, 0.1, 0.3])


def same_decision(kept: Explorer, cfg: ExplorationConfig, pose: np.ndarray, state: np.ndarray):
    """``kept``'s goal at ``pose`` on ``state`` (None: none), asserted equal to a new explorer's (position, kind
    and score)."""
    goal = kept.decide(pose, GridView(state.copy(), 0.05, (0.0, 0.0)))
    fresh = Explorer(cfg, 0.2, 0.05, 12.0).decide(pose, GridView(state.copy(), 0.05, (0.0, 0.0)))
    assert (goal is None) == (fresh is None)
    if goal is not None:
        assert goal.kind == fresh.kind and np.array_equal(goal.position, fresh.position)
        assert goal.score == fresh.score
    return goal


@pytest.mark.parametrize("seed", range(40))
def test_paths_settled_as_far_as_asked_equal_a_full_search(seed):
    rng = np.random.default_rng(seed)
    passable = ndimage.binary_opening(rng.random((60, 80)) > 0.2) & (rng.random((60, 80)) > 0.02)
    allowed = rng.random(passable.shape) > 0.3
    rows, cols = np.nonzero(passable)
    start = np.array([rows[len(rows) // 3], cols[len(rows) // 3]]) + rng.integers(-2, 3, 2)  # may need snapping
    full = geodesic(passable, start, 0.05)
    full[~allowed] = np.inf
    cells = np.column_stack([rng.integers(-2, 62, 30), rng.integers(-2, 82, 30)])
    inside = (cells[:, 0] >= 0) & (cells[:, 0] < 60) & (cells[:, 1] >= 0) & (cells[:, 1] < 80)
    expected = np.full(len(cells), np.inf)
    expected[inside] = full[cells[inside, 0], cells[inside, 1]]

    paths = Paths(passable, start, 0.05, allowed=allowed)
    assert np.array_equal(paths.reach, np.isfinite(full))
    near = paths.lengths(cells, nearest=True)
    if np.isfinite(expected).any():
        k = int(np.argmin(expected))
        assert int(np.argmin(near)) == k and near[k] == expected[k]  # the nearest, to the last bit
        exact = near == expected
        assert np.all(exact | (near > expected.min()))  # the rest exact or a lower bound above the nearest
        assert np.all(near[np.isfinite(expected)] <= expected[np.isfinite(expected)])
    assert np.array_equal(paths.lengths(cells), expected)  # resumed to the farthest
    assert np.array_equal(paths.dense(), full)


@pytest.mark.parametrize("seed", range(25))
def test_frontiers_on_bounded_paths_equal_those_on_full_distances(seed):
    rng = np.random.default_rng(100 + seed)
    view = GridView(random_map(rng), 0.05, (0.0, 0.0))
    pose = random_start(rng, view)
    roomy = view.traversable(0.45)
    full = geodesic(view.traversable(0.4), view.to_cell(pose[:2]), 0.05)
    full[~roomy] = np.inf
    expected = find_frontiers(view, pose[:2], full, 0.4, 0.55, depth=0.4)
    for nearest in (False, True):
        paths = Paths(view.traversable(0.4), view.to_cell(pose[:2]), 0.05, allowed=roomy)
        got = find_frontiers(view, pose[:2], paths, 0.4, 0.55, depth=0.4, nearest=nearest)
        assert [tuple(f.goal) for f in got] == [tuple(f.goal) for f in expected]
        p, q = np.array([f.path for f in got]), np.array([f.path for f in expected])
        if nearest and len(q):
            assert np.argmin(p) == np.argmin(q) and p.min() == q.min()
        else:
            assert np.array_equal(p, q)


@pytest.mark.parametrize("strategy", ["nearest_frontier", "utility", "tour"])
def test_decisions_on_bounded_paths_equal_those_on_full_distances(strategy, monkeypatch):
    """Each strategy's goal, and the views of pockets once no frontier is left, are those of the full
    computation: distances over the whole grid and every place scored."""
    cfg = ExplorationConfig(strategy=strategy)
    goals = {}
    for mode in ("bounded", "full"):
        if mode == "full":
            monkeypatch.setattr(explorer_mod, "Paths", lambda *a, **k: _Dense(Paths(*a, **k).dense()))
            monkeypatch.setattr(pockets_mod, "unknown_within_reach", lambda view, xy, r, table: np.full(len(xy), np.inf))
        goals[mode] = []
        for seed in range(12):
            rng = np.random.default_rng(200 + seed)
            state = random_map(rng)
            if seed % 3 == 0:  # no frontier: only pockets (small unknown patches inside the free space) are left
                state[state == UNKNOWN] = OCCUPIED
                for _ in range(4):
                    r, c = rng.integers(5, 80), rng.integers(5, 100)
                    state[r : r + 4, c : c + 4] = UNKNOWN
            view = GridView(state, 0.05, (0.0, 0.0))
            ex = Explorer(cfg, 0.2, 0.05, 12.0)
            goal = ex.decide(random_start(rng, view), view)
            goals[mode].append(None if goal is None else (goal.kind, tuple(np.round(goal.position, 9)), goal.score))
    assert goals["bounded"] == goals["full"]
    assert sum(g is not None and g[0] == "pocket" for g in goals["full"]) >= 1
    assert sum(g is not None and g[0] != "pocket" for g in goals["full"]) >= 4


def add_pocket(state, rng) -> None:
    """A 12 × 12-cell pocket of unknown in a ring of wall with a 5-cell gap on one side (no frontier region)."""
    r, c = rng.integers(8, state.shape[0] - 22), rng.integers(8, state.shape[1] - 22)
    state[r : r + 14, c : c + 14] = OCCUPIED
    state[r + 1 : r + 13, c + 1 : c + 13] = UNKNOWN
    side = rng.integers(4)
    gap = (slice(r + 5, r + 10), c) if side == 0 else (slice(r + 5, r + 10), c + 13) if side == 1 else (
        r, slice(c + 5, c + 10)) if side == 2 else (r + 13, slice(c + 5, c + 10))  # fmt: skip
    state[gap] = UNKNOWN


def test_views_of_pockets_kept_between_decisions_equal_those_scored_anew(monkeypatch):
    """A place keeps its gain from the last decision only while nothing within its rays' reach changed: after
    local changes to the map, the goal is the one an explorer with nothing kept chooses."""
    monkeypatch.setattr(pockets_mod, "unknown_within_reach", lambda view, xy, r, table: np.full(len(xy), np.inf))
    cfg = ExplorationConfig(strategy="nearest_frontier", gain_range=2.0, pocket_gain=0.02)
    checked = 0
    for seed in range(8):
        rng = np.random.default_rng(300 + seed)
        state = np.full((130, 170), OCCUPIED, dtype=np.int8)
        state[2:-2, 2:-2] = FREE
        for _ in range(5):
            add_pocket(state, rng)
        pose = random_start(rng, GridView(state, 0.05, (0.0, 0.0)))
        kept = Explorer(cfg, 0.2, 0.05, 12.0)
        kept.decide(pose, GridView(state.copy(), 0.05, (0.0, 0.0)))
        for _ in range(4):  # the map changes in one place: a pocket seen, or a new one
            hidden = np.argwhere(state == UNKNOWN)
            if len(hidden) and rng.random() < 0.6:
                r, c = hidden[rng.integers(len(hidden))]
                state[max(r - 4, 0) : r + 4, max(c - 4, 0) : c + 4] = FREE
            else:
                add_pocket(state, rng)
            goal = same_decision(kept, cfg, pose, state)
            checked += goal is not None and goal.kind == "pocket"
    assert checked >= 10


@pytest.mark.parametrize("seed", range(6))
def test_hidden_cells_refreshed_where_the_map_changed_equal_a_full_pass(seed):
    """The utility's hidden-cell grid (``pocket_state``), kept between views and recomputed round the cells that
    changed, is the full pass's after every change, near the grid's edge too."""
    rng = np.random.default_rng(400 + seed)
    state = random_map(rng)
    outside = rng.random(state.shape) < 0.05
    kept = LocalRefresh(lambda st, out: pocket_state(st, 4, out), 2 * 4 + 4)
    for _ in range(8):
        r, c = rng.integers(-5, state.shape[0]), rng.integers(-5, state.shape[1])
        patch = state[max(r, 0) : r + rng.integers(2, 30), max(c, 0) : c + rng.integers(2, 30)]
        patch[...] = rng.choice([FREE, OCCUPIED, UNKNOWN], size=patch.shape, p=[0.5, 0.2, 0.3])
        if rng.random() < 0.3:
            outside[rng.integers(state.shape[0]), :] ^= True
        assert np.array_equal(kept(state, outside), pocket_state(state, 4, outside))


@pytest.mark.parametrize("seed", range(8))
def test_gains_aimed_at_the_entry_cells_of_unknown_space_count_what_all_rays_count(seed):
    """Rays aimed only at the unknown cells with a known 4-neighbour (a ray enters unknown space there first) count
    the same gains and shares as every ray, from points in free and unknown cells and near the grid's edge."""
    from slam2d.exploration.gridops import (
        _cast,
        information_gain,
        shared_gain,
        unknown_cells,
    )

    rng = np.random.default_rng(500 + seed)
    state = random_map(rng)
    view = GridView(state, 0.05, (0.0, 0.0))
    pts = rng.uniform([0.0, 0.0], [state.shape[1] * 0.05, state.shape[0] * 0.05], size=(60, 2))
    every = _cast(state, pts / 0.05, 120, 60.0, 2, np.zeros((0, 2), dtype=np.int64), False)
    own, shares = shared_gain(view, pts, 3.0, 120)
    assert np.array_equal(own, every[0]) and np.array_equal(shares, every[1])
    free = pts[state[(pts[:, 1] / 0.05).astype(int), (pts[:, 0] / 0.05).astype(int)] == FREE]
    alone = _cast(state, free / 0.05, 360, 60.0, 1, np.zeros((0, 2), dtype=np.int64), False)[0]
    assert np.array_equal(information_gain(view, free, 3.0, 360, unknown_cells(view)), alone)
    assert len(unknown_cells(view)) < (state == UNKNOWN).sum() and alone.max() > 0


@pytest.mark.parametrize("seed", range(4))
def test_hidden_cells_within_reach_bound_every_gain(seed):
    """The count of unknown cells in the rays' square (infinite near the grid's edge) is never below the gain a
    point's rays count, and it rules out the places far from a pocket, or near one walled in, without a ray."""
    from slam2d.exploration.gridops import information_gain, unknown_within_reach

    rng = np.random.default_rng(700 + seed)
    state = random_map(rng, shape=(160, 190))
    view = GridView(state, 0.05, (0.0, 0.0))
    pts = rng.uniform([0.0, 0.0], [state.shape[1] * 0.05, state.shape[0] * 0.05], size=(3000, 2))
    pts = pts[state[(pts[:, 1] / 0.05).astype(int), (pts[:, 0] / 0.05).astype(int)] != UNKNOWN]
    for reach in (0.6, 1.5):
        bound, gain = unknown_within_reach(view, pts, reach), information_gain(view, pts, reach, 360)
        assert np.all(bound >= gain) and np.isfinite(bound).sum() > 20
    assert unknown_within_reach(view, [[0.02, 4.0]], 0.6)[0] == np.inf  # beyond the edge: unknown
    room = np.full((130, 170), OCCUPIED, dtype=np.int8)
    room[2:-2, 2:-2] = FREE
    add_pocket(room, rng)
    view = GridView(room, 0.05, (0.0, 0.0))
    free = np.argwhere(room == FREE)[:: 37][:, ::-1] * 0.05 + 0.025
    bound, gain = unknown_within_reach(view, free, 0.5), information_gain(view, free, 0.5, 360)
    assert np.all(bound >= gain) and (gain > 0).any()
    assert (bound == 0).sum() > len(free) // 2  # most places are ruled out without a ray
    hidden = np.argwhere(room == UNKNOWN)
    lo, hi = hidden.min(axis=0), hidden.max(axis=0)
    room[lo[0] - 1 : hi[0] + 2, lo[1] - 1 : hi[1] + 2] = OCCUPIED
    room[lo[0] + 1 : hi[0], lo[1] + 1 : hi[1]] = UNKNOWN  # the pocket walled in: no ray enters it
    bound = unknown_within_reach(GridView(room, 0.05, (0.0, 0.0)), free, 0.5)
    assert np.isfinite(bound).sum() > len(free) // 2 and not bound[np.isfinite(bound)].any()


@pytest.mark.parametrize("seed", range(4))
def test_first_place_seeing_enough_counted_one_at_a_time_is_the_first_of_all_gains(seed):
    """The search for the nearest place that sees at least the floor stops at the first place in order whose
    gain reaches it, with the gains of the places counted up to it (and those known before kept) equal to
    ``information_gain``; -1 when none does."""
    from slam2d.exploration.gridops import first_seeing, information_gain, unknown_cells

    rng = np.random.default_rng(800 + seed)
    view = GridView(random_map(rng, shape=(120, 150)), 0.05, (0.0, 0.0))
    rows, cols = np.nonzero(view.state != UNKNOWN)
    pick = rng.choice(len(rows), 300, replace=False)
    xy = view.to_world(np.column_stack([rows[pick], cols[pick]]))
    every = information_gain(view, xy, 1.5, 360)
    for floor in (np.median(every), every.max(), every.max() + 1):
        gains = np.full(len(xy), np.nan)
        gains[::7] = every[::7]  # known from an earlier level
        k = first_seeing(view, xy, 1.5, 360, floor, gains, unknown_cells(view))
        first = np.nonzero(every >= floor)[0]
        assert k == (first[0] if len(first) else -1)
        counted = ~np.isnan(gains)
        assert np.array_equal(gains[counted], every[counted])
        last = k if k >= 0 else len(xy) - 1
        assert counted[: last + 1].all()  # every place up to the first that sees enough
        beyond = np.arange(last + 1, len(xy))
        assert np.array_equal(counted[beyond], beyond % 7 == 0)  # no place beyond it counted anew


def test_no_pocket_search_when_the_robot_reaches_no_cell(monkeypatch):
    """With no cell the robot can reach there is no place to try: the decision is None, and the pocket grid is
    not made."""
    state = np.full((80, 80), UNKNOWN, dtype=np.int8)
    state[30:50, 30:50] = OCCUPIED
    state[38:42, 38:42] = FREE  # the robot's own cells, too narrow for its disc
    state[60:70, 60:70] = FREE
    state[64:66, 64:66] = UNKNOWN  # a pocket it could not reach
    ex = Explorer(ExplorationConfig(strategy="utility"), 0.2, 0.05, 12.0)
    made = []
    monkeypatch.setattr(explorer_mod.Explorer, "_pocket_grid", lambda self, view: made.append(1))
    assert ex.decide(np.array([2.0, 2.0, 0.0]), GridView(state, 0.05, (0.0, 0.0))) is None
    assert not made


def test_a_frontier_goal_off_the_region_is_the_reachable_cell_within_reach_nearest_its_centre():
    """A region with no reachable cell of its own: its goal is, among the reachable cells within the reach
    (Euclidean, between cell centres) of one of its cells, the one nearest its centre (the first in raster order
    of equals); none when no reachable cell is that near."""
    from slam2d.exploration.frontiers import _goal_cell

    rng = np.random.default_rng(900)
    checked = 0
    for _ in range(300):
        h, w = rng.integers(20, 80, 2)
        reachable = rng.random((h, w)) < rng.uniform(0.01, 0.4)
        start = rng.integers(0, [h, w])
        steps = np.cumsum(rng.integers(-1, 2, (rng.integers(1, 25), 2)), axis=0)
        cells = np.unique(np.clip(start + steps, 0, [h - 1, w - 1]), axis=0)
        reachable[cells[:, 0], cells[:, 1]] = False
        reach = float(rng.choice([10.000000000000002, 4.0, rng.uniform(1.0, 9.0)]))
        every = np.argwhere(reachable)  # raster order
        gap = np.sqrt(((every[:, None, :] - cells[None]) ** 2).sum(axis=2)).min(axis=1)
        near = every[gap <= reach]
        got = _goal_cell(cells, reachable, reach)
        if len(near) == 0:
            assert got is None
            continue
        assert np.array_equal(got, near[np.argmin(np.hypot(*(near - cells.mean(axis=0)).T))])
        checked += 1
    assert checked > 100


@pytest.mark.parametrize("seed", range(3))
def test_shares_split_each_cell_a_point_sees_among_the_points_seeing_it(seed):
    """``shared_gain``: each point's gain is the unknown cells in its sight, its share the sum over them of one over
    the number of points that see each (the shares add up to the cells the points see together)."""
    from slam2d.exploration.gridops import shared_gain, unknown_in_sight

    rng = np.random.default_rng(1000 + seed)
    view = GridView(random_map(rng), 0.05, (0.0, 0.0))
    rows, cols = np.nonzero(view.state[25:-25, 25:-25] == FREE)  # rays of 1 m stay inside the grid
    pick = rng.choice(len(rows), 30, replace=False)
    pts = view.to_world(np.column_stack([rows[pick] + 25, cols[pick] + 25]))
    seen = [unknown_in_sight(view, p, 1.0, 120) for p in pts]
    seers = np.sum(seen, axis=0)
    own, shares = shared_gain(view, pts, 1.0, 120)
    assert np.array_equal(own, [s.sum() for s in seen]) and own.max() > 0
    assert np.allclose(shares, [(1.0 / seers[s]).sum() for s in seen])
    assert np.isclose(shares.sum(), np.count_nonzero(seers))


@pytest.mark.parametrize("seed", range(6))
def test_ray_records_kept_between_grids_give_the_gains_and_shares_cast_anew(seed):
    """``RayRecords``: after random local changes of the hidden grid (near the edge too) and points that come and go,
    the kept records give bit for bit the gains and shares of every point's rays cast anew, and points far from the
    changes are not cast again."""
    from slam2d.exploration.gains import RayRecords
    from slam2d.exploration.gridops import shared_gain, unknown_cells

    rng = np.random.default_rng(1100 + seed)
    state = random_map(rng, (120, 150))
    records, recast = RayRecords(), 0
    pool = rng.uniform([0.0, 0.0], [150 * 0.05, 120 * 0.05], size=(40, 2))
    for step in range(10):
        if step:
            r, c = rng.integers(-5, state.shape[0]), rng.integers(-5, state.shape[1])
            patch = state[max(r, 0) : r + rng.integers(2, 12), max(c, 0) : c + rng.integers(2, 12)]
            patch[...] = rng.choice([FREE, OCCUPIED, UNKNOWN], size=patch.shape, p=[0.5, 0.2, 0.3])
        view = GridView(state.copy(), 0.05, (0.0, 0.0))
        records.update(view)
        pts = pool[rng.random(len(pool)) < 0.7]
        before = len(records._kept)
        own, shares = records.shared(view, pts, 1.5, 120, unknown_cells(view))
        recast += len(records._kept) - before
        fresh_own, fresh_shares = shared_gain(view, pts, 1.5, 120)
        assert np.array_equal(own, fresh_own) and np.array_equal(shares, fresh_shares)
        assert np.array_equal(records.gains(view, pts[::2], 1.5, 120, unknown_cells(view)), fresh_own[::2])
    assert 0 < recast < 0.8 * 10 * len(pool)


@pytest.mark.parametrize("seed", range(4))
def test_frontier_cells_refreshed_where_the_map_changed_equal_a_full_pass(seed):
    """The frontier cells (``frontier_mask`` with the depth the explorer uses), kept between views and recomputed round
    the cells that changed, are the full pass's after every change, near the grid's edge too."""
    from slam2d.exploration.frontiers import WALL_GAP, frontier_mask

    rng = np.random.default_rng(1300 + seed)
    state = random_map(rng)
    kept = LocalRefresh(lambda st: frontier_mask(st, depth=8), max(8 + 1, WALL_GAP))
    for _ in range(8):
        r, c = rng.integers(-5, state.shape[0]), rng.integers(-5, state.shape[1])
        patch = state[max(r, 0) : r + rng.integers(2, 30), max(c, 0) : c + rng.integers(2, 30)]
        patch[...] = rng.choice([FREE, OCCUPIED, UNKNOWN], size=patch.shape, p=[0.6, 0.1, 0.3])
        assert np.array_equal(kept(state), frontier_mask(state, depth=8))


@pytest.mark.parametrize("strategy", ["nearest_frontier", "utility"])
def test_decisions_of_an_explorer_kept_over_changing_maps_equal_those_made_from_nothing(strategy):
    """One explorer deciding on a map that changes here and there between decisions (its frontier cells, hidden
    cells and gains' rays kept where nothing changed) chooses the goals, with the scores, of a new explorer each time."""
    cfg = ExplorationConfig(strategy=strategy)
    rng = np.random.default_rng(1400)
    state = random_map(rng, (120, 150))
    kept = Explorer(cfg, 0.2, 0.05, 12.0)
    chosen = 0
    for _ in range(12):
        for _ in range(rng.integers(1, 4)):
            change_a_patch(rng, state)
        pose = random_start(rng, GridView(state.copy(), 0.05, (0.0, 0.0)))
        chosen += same_decision(kept, cfg, pose, state) is not None
    assert chosen >= 8


def test_searches_reusing_one_scratch_equal_searches_on_fresh_arrays():
    """Paths made one after another with the same ``Scratch`` (grids of two shapes, starts anywhere) give the lengths
    and reach of searches on fresh arrays."""
    from slam2d.exploration.paths import Scratch

    rng = np.random.default_rng(1500)
    scratch = Scratch()
    for k in range(12):
        view = GridView(random_map(rng, (90, 110) if k % 3 else (100, 80)), 0.05, (0.0, 0.0))
        passable = view.traversable(0.2)
        start = np.argwhere(passable)[rng.integers(np.count_nonzero(passable))]
        kept = Paths(passable, start, 0.05, scratch=scratch)
        fresh = Paths(passable, start, 0.05)
        cells = np.argwhere(fresh.reach)[:: 7]
        assert np.array_equal(kept.reach, fresh.reach)
        assert np.array_equal(kept.lengths(cells), fresh.lengths(cells)) and np.array_equal(kept.dense(), fresh.dense())


@pytest.mark.parametrize("seed", range(4))
def test_entry_cells_refreshed_where_the_grid_changed_equal_a_full_pass(seed):
    """The cells rays enter the hidden cells by (``entry_mask``), kept between grids and recomputed round the cells
    that changed, list the full pass's ``unknown_cells`` after every change, near the grid's edge too."""
    from slam2d.exploration.gridops import entry_mask, unknown_cells

    rng = np.random.default_rng(1600 + seed)
    state = random_map(rng)
    kept = LocalRefresh(entry_mask, 1)
    for _ in range(8):
        r, c = rng.integers(-5, state.shape[0]), rng.integers(-5, state.shape[1])
        patch = state[max(r, 0) : r + rng.integers(2, 30), max(c, 0) : c + rng.integers(2, 30)]
        patch[...] = rng.choice([FREE, OCCUPIED, UNKNOWN], size=patch.shape, p=[0.5, 0.2, 0.3])
        assert np.array_equal(np.argwhere(kept(state)), unknown_cells(GridView(state, 0.05, (0.0, 0.0))))
