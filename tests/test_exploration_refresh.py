"""The grids kept between decisions (``LocalRefresh``'s inputs and output, the rays' changed tiles) equal what is
computed from nothing after random sequences of local changes."""

from __future__ import annotations

import numpy as np
import pytest

from slam2d.exploration.gains import TILE, _changed_tiles
from slam2d.exploration.gridops import FREE, OCCUPIED, UNKNOWN, cells_of
from slam2d.exploration.pockets import LocalRefresh, _changed_box, pocket_state


def changed_here_and_there(rng, state, outside):
    """Random patches of ``state`` redrawn (near the edges too), now and then a row of ``outside`` flipped only."""
    for _ in range(rng.integers(0, 3)):
        r, c = rng.integers(-5, state.shape[0]), rng.integers(-5, state.shape[1])
        patch = state[max(r, 0) : r + rng.integers(1, 20), max(c, 0) : c + rng.integers(1, 20)]
        patch[...] = rng.choice([FREE, OCCUPIED, UNKNOWN], size=patch.shape, p=[0.5, 0.2, 0.3])
    if rng.random() < 0.3:
        outside[rng.integers(state.shape[0]), : rng.integers(1, state.shape[1])] ^= True


@pytest.mark.parametrize("seed", range(6))
def test_refreshed_grid_over_two_inputs_equals_the_full_pass_after_every_change(seed):
    """A LocalRefresh of two grids (int8 and bool) keeps only the changed box of its inputs: after a sequence of
    changes (in one input, the other, both or none) its output is the function's on the whole grid every time, and
    it recomputes only round the changes since the last call (none, none)."""
    rng = np.random.default_rng(2000 + seed)
    state = rng.choice([FREE, OCCUPIED, UNKNOWN], size=(70, 90), p=[0.6, 0.15, 0.25]).astype(np.int8)
    outside = rng.random(state.shape) < 0.05
    windows = []

    def fn(st, out):
        windows.append(st.size)
        return pocket_state(st, 3, out)

    kept = LocalRefresh(fn, 2 * 3 + 4)
    for _ in range(25):
        last = state.copy(), outside.copy()
        changed_here_and_there(rng, state, outside)
        out = kept(state, outside)
        assert np.array_equal(out, pocket_state(state, 3, outside))
        out[...] = OCCUPIED  # the caller's copy: changing it changes nothing kept
        rows, cols = np.nonzero((last[0] != state) | (last[1] != outside))
        if len(windows) > 1 and len(rows):  # the window: the changes since the last call, 2 radii round
            span = (np.ptp(rows) + 1 + 4 * kept.radius) * (np.ptp(cols) + 1 + 4 * kept.radius)
            assert windows.pop() <= span
        elif len(windows) > 1:
            assert False, "recomputed with nothing changed"
    assert np.array_equal(kept(state, outside), pocket_state(state, 3, outside))


@pytest.mark.parametrize("seed", range(20))
def test_changed_box_and_tiles_hold_exactly_the_changed_cells(seed):
    """The box round the changed cells and the changed tiles equal those found from the list of changed cells."""
    rng = np.random.default_rng(2100 + seed)
    a = rng.integers(0, 3, size=(rng.integers(1, 60), rng.integers(1, 60))).astype(np.int8)
    b = a.copy()
    flip = rng.random(a.shape) < rng.choice([0.0, 0.002, 0.05])
    b[flip] = (b[flip] + 1) % 3
    cells = np.argwhere(a != b)
    assert np.array_equal(cells_of(a != b), cells)
    box = np.array([a.shape[0], 0, a.shape[1], 0])
    _changed_box(a, b, box)
    if len(cells):
        assert box.tolist() == [cells[:, 0].min(), cells[:, 0].max() + 1, cells[:, 1].min(), cells[:, 1].max() + 1]
    else:
        assert box[0] >= box[1] and box[2] >= box[3]
    tiles, any_changed = _changed_tiles(a, b, TILE)
    expected = np.zeros_like(tiles)
    expected[cells[:, 0] // TILE, cells[:, 1] // TILE] = True
    assert any_changed == bool(len(cells)) and np.array_equal(tiles, expected)


@pytest.mark.parametrize("seed", range(6))
def test_ray_records_outlive_grids_nothing_was_asked_on(seed):
    """The rays' records of a decision's points outlive the grids of the checks before the next decision (nothing
    asked on them): only the points with a changed cell within reach on one of those grids are cast again, and the
    gains and shares equal those cast anew."""
    from slam2d.exploration.gains import RayRecords
    from slam2d.exploration.gridops import GridView, shared_gain, unknown_cells

    rng = np.random.default_rng(2200 + seed)
    state = rng.choice([FREE, OCCUPIED, UNKNOWN], size=(200, 260), p=[0.7, 0.05, 0.25]).astype(np.int8)
    records = RayRecords()
    pts = rng.uniform([0.0, 0.0], [260 * 0.05, 200 * 0.05], size=(30, 2))
    for decision in range(4):
        touched = np.zeros(len(pts), dtype=bool)
        for _ in range(2 if decision else 0):  # the checks between two decisions: a changed patch each
            r, c = rng.integers(0, 194), rng.integers(0, 254)
            state[r : r + 6, c : c + 6] = rng.choice([FREE, OCCUPIED, UNKNOWN], size=(6, 6))
            cx, cy = (c + 3) * 0.05, (r + 3) * 0.05
            near = 1.5 + 0.1 + 2 * 0.4 + 0.15  # reach + 2 cells, a tile each side, half the patch (m)
            touched |= np.maximum(np.abs(pts[:, 0] - cx), np.abs(pts[:, 1] - cy)) <= near
            records.update(GridView(state.copy(), 0.05, (0.0, 0.0)))
        view = GridView(state.copy(), 0.05, (0.0, 0.0))
        records.update(view)
        before = len(records._kept)
        own, shares = records.shared(view, pts, 1.5, 120, unknown_cells(view))
        fresh_own, fresh_shares = shared_gain(view, pts, 1.5, 120)
        assert np.array_equal(own, fresh_own) and np.array_equal(shares, fresh_shares)
        if decision:
            assert len(records._kept) - before <= np.count_nonzero(touched) < len(pts)


@pytest.mark.parametrize("strategy", ["utility", "tour"])
def test_decisions_after_keeping_up_with_the_map_equal_those_made_from_nothing(strategy):
    """An explorer kept up with the map at every check between decisions (``keep_up``: frontier cells, hidden cells,
    entry cells, rays' records refreshed where the map changed) chooses the goals, with the scores, of a new explorer."""
    from test_exploration_paths import (
        change_a_patch,
        random_map,
        random_start,
        same_decision,
    )

    from slam2d.exploration.config import ExplorationConfig
    from slam2d.exploration.explorer import Explorer
    from slam2d.exploration.gridops import GridView

    cfg = ExplorationConfig(strategy=strategy)
    rng = np.random.default_rng(2300)
    state = random_map(rng, (120, 150))
    kept, chosen = Explorer(cfg, 0.2, 0.05, 12.0), 0
    for _ in range(10):
        for _ in range(rng.integers(1, 4)):  # the checks while the robot drives: the map changes, the grids kept up
            change_a_patch(rng, state)
            kept.keep_up(GridView(state.copy(), 0.05, (0.0, 0.0)))
        state[rng.integers(state.shape[0]), rng.integers(state.shape[1])] = UNKNOWN  # and once more before deciding
        pose = random_start(rng, GridView(state.copy(), 0.05, (0.0, 0.0)))
        chosen += same_decision(kept, cfg, pose, state) is not None
    assert chosen >= 6
