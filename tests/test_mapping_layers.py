"""Mapping layers: sparse and quadtree storage, the line map, the wall mesh."""

from __future__ import annotations

import numpy as np
import pytest

from slam2d.mapping.occupancy import OccupancyGrid


def _grid(seed: int = 0) -> OccupancyGrid:
    """A 60 x 90 grid: unknown, free and occupied cells with arbitrary float32 log-odds."""
    rng = np.random.default_rng(seed)
    lo = np.zeros((60, 90), np.float32)
    lo[5:55, 5:85] = rng.uniform(-2.0, -0.1, (50, 80))
    lo[5, 5:85] = lo[54, 5:85] = lo[5:55, 5] = rng.uniform(0.5, 3.5)
    return OccupancyGrid(lo, 0.05, (-1.25, 3.5))


# --------------------------------------------------------------------------- sparse


def test_triplets_and_hash_round_trip_bit_exact():
    from slam2d.mapping.sparse import HashedGrid, Triplets

    grid = _grid()
    for form in (Triplets.from_grid(grid), HashedGrid.from_grid(grid)):
        back = form.to_grid()
        assert back.log_odds.tobytes() == grid.log_odds.tobytes()
        assert back.resolution == grid.resolution and back.origin == grid.origin
        assert len(form) == np.count_nonzero(grid.log_odds)
    t = Triplets.from_grid(grid)
    assert np.array_equal(t.to_scipy().toarray(), grid.log_odds)
    h = HashedGrid.from_grid(grid)
    assert h[5, 5] == grid.log_odds[5, 5] and h[0, 0] == 0.0
    with pytest.raises(IndexError):
        h[60, 0]


def test_sparsity_reports_the_five_percent_rule():
    from slam2d.mapping.sparse import sparsity

    s = sparsity(_grid())
    assert s["nonzero_share"] == pytest.approx(50 * 80 / (60 * 90))
    assert not s["nonzero_sparse"]
    assert s["occupied_share"] == pytest.approx((80 + 80 + 48) / (60 * 90)) and s["occupied_sparse"]
