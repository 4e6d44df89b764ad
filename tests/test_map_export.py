"""Map export of large grids: bounded memory, streamed PGM, downsampled figure."""

from __future__ import annotations

import tracemalloc

import numpy as np
from matplotlib.axes import Axes
from PIL import Image

from slam2d.config import MappingConfig
from slam2d.mapping import export
from slam2d.mapping.export import FREE, OCCUPIED, UNKNOWN, load_map_server, save_map_png, save_map_server
from slam2d.mapping.grid import OccupancyGrid


def walled_grid(rows: int, cols: int, room: int = 250) -> OccupancyGrid:
    """Free rooms behind one-cell walls, an unknown border; log-odds float32."""
    lo = np.zeros((rows, cols), np.float32)
    b = rows // 20
    lo[b:-b, b:-b] = -2.0
    lo[b:-b:room, b:-b] = 3.0
    lo[b:-b, b:-b:room] = 3.0
    return OccupancyGrid(lo, 0.05, (-3.0, 7.0))


def test_large_map_written_in_bounded_memory(tmp_path, monkeypatch):
    grid = walled_grid(8000, 8000)  # 64 M cells, 256 MB of log-odds
    save_map_png(walled_grid(40, 40), tmp_path / "warm.png", {"estimate": np.zeros((2, 3))})  # imports, fonts
    shown = []
    imshow = Axes.imshow
    monkeypatch.setattr(Axes, "imshow", lambda ax, img, **kw: shown.append(np.shape(img)[:2]) or imshow(ax, img, **kw))
    tracemalloc.start()
    try:
        save_map_server(grid, tmp_path / "map", MappingConfig())
        png = save_map_png(grid, tmp_path / "map.png", {"estimate": np.zeros((2, 3))}, title="large")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 100e6  # 60 MB; the old export peaked at 4.6 GB (float64 copies, a full-size image)
    assert len(shown) == 1 and max(shown[0]) <= 8 * 150  # drawn downsampled: no more pixels than the figure
    with Image.open(png) as im:
        assert im.width <= 8 * 150 and im.height <= 16 * 150
    assert (tmp_path / "map.pgm").stat().st_size > 8000 * 8000


def test_streamed_pgm_matches_whole_grid_and_round_trips(tmp_path, monkeypatch):
    rng = np.random.default_rng(3)
    lo = rng.uniform(-3.0, 3.0, (37, 23)).astype(np.float32)
    cfg = MappingConfig()
    for row, t in enumerate((cfg.occupied_thresh, cfg.free_thresh)):  # cells either side of each threshold
        edge = np.float32(np.log(t / (1 - t)))
        lo[row, :3] = [np.nextafter(edge, np.float32(-9)), edge, np.nextafter(edge, np.float32(9))]
    grid = OccupancyGrid(lo, 0.1, (0.5, -2.0))
    monkeypatch.setattr(export, "CHUNK_CELLS", 5 * 23)  # 5-row chunks, a ragged last one
    pgm, yml = save_map_server(grid, tmp_path / "map", cfg)

    p = 1.0 / (1.0 + np.exp(-lo.astype(np.float64)))  # the map_server definition, whole grid at once
    expected = np.full(lo.shape, UNKNOWN, np.uint8)
    expected[p < cfg.free_thresh] = FREE
    expected[p > cfg.occupied_thresh] = OCCUPIED
    assert pgm.read_bytes().split(b"\n", 4)[4] == np.flipud(expected).tobytes()

    back = load_map_server(yml)
    assert back.shape == grid.shape and back.origin == grid.origin and back.log_odds.flags.c_contiguous
    np.testing.assert_array_equal(back.occupied_mask(cfg.occupied_thresh), p > cfg.occupied_thresh)
    np.testing.assert_array_equal(back.free_mask(cfg.free_thresh), p < cfg.free_thresh)
    np.testing.assert_array_equal(grid.occupied_mask(cfg.occupied_thresh), p > cfg.occupied_thresh)
    np.testing.assert_array_equal(grid.free_mask(cfg.free_thresh), p < cfg.free_thresh)


def test_downsample_keeps_thin_walls_and_free_space():
    lo = np.zeros((12, 11), np.float32)  # unknown
    lo[:, :5] = -2.0  # free on the left
    lo[7, :] = 3.0  # a one-cell wall across
    lo[0, 10] = -1.0  # one free cell in an unknown block
    small = export.downsample(lo, 5)
    assert small.shape == (3, 3)
    assert np.all(small[1] == 3.0)  # the wall's blocks (rows 5-9)
    assert small[0, 0] == -2.0 and small[2, 0] == -2.0  # free; a ragged block of free cells
    assert small[0, 2] == -1.0 and small[0, 1] == 0.0  # free wins over unknown; an unknown block
    np.testing.assert_array_equal(export.downsample(lo, 1), lo)
