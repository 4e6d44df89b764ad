"""Occupancy grid building and map export."""

from __future__ import annotations

import numpy as np
import pytest

from slam2d import geometry
from slam2d.config import MappingConfig
from slam2d.mapping.export import load_map_server, save_map_png, save_map_server
from slam2d.mapping.occupancy import OccupancyGrid, build_grid
from slam2d.types import Scan

HALF = 2.0  # the room spans [-2, 2] x [-2, 2] m
ANGLES = np.deg2rad(np.arange(360.0))


def room_ranges(sensor, half=HALF):
    """Exact ranges (360 beams) from a sensor pose (3,) to the walls of the square room."""
    a = sensor[2] + ANGLES
    c, s = np.cos(a), np.sin(a)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (half - sensor[0]) / c, np.where(c < 0, (-half - sensor[0]) / c, np.inf))
        ty = np.where(s > 0, (half - sensor[1]) / s, np.where(s < 0, (-half - sensor[1]) / s, np.inf))
    return np.minimum(tx, ty)


def room_scan(base=(0.3, -0.2, 0.4), mount=(0.1, 0.05, 0.2), range_max=12.0, ranges=None):
    """(pose, scan) in the room, with a mounted sensor so that compose(pose, mount) matters."""
    base, mount = np.asarray(base, float), np.asarray(mount, float)
    if ranges is None:
        ranges = room_ranges(geometry.compose(base, mount))
    return base, Scan(0.0, np.asarray(ranges, float), ANGLES, 0.05, range_max, sensor_pose=mount)


def cells_centres(grid):
    h, w = grid.shape
    rc = np.stack(np.meshgrid(np.arange(h), np.arange(w), indexing="ij"), -1)
    return grid.cell_to_world(rc)


def test_world_cell_round_trip():
    grid = OccupancyGrid(np.zeros((4, 6)), 0.5, (-1.0, 2.0))
    assert tuple(grid.world_to_cell([-0.99, 2.01])) == (0, 0)
    assert tuple(grid.world_to_cell([1.9, 3.9])) == (3, 5)  # row = y, col = x
    rc = np.array([[0, 0], [3, 5], [2, 1]])
    np.testing.assert_array_equal(grid.world_to_cell(grid.cell_to_world(rc)), rc)
    np.testing.assert_allclose(grid.cell_to_world([0, 0]), [-0.75, 2.25])
    assert grid.in_bounds(np.array([[3, 5], [4, 0], [0, -1]])).tolist() == [True, False, False]


def test_single_scan_room_walls_free_unknown():
    pose, scan = room_scan()
    cfg = MappingConfig(resolution=0.05, log_odds_miss=-1.5)
    grid = build_grid(pose[None], [scan], cfg)
    xy = cells_centres(grid)
    wall_dist = np.abs(HALF - np.max(np.abs(xy), axis=-1))

    occ = grid.occupied_mask(cfg.occupied_thresh)
    assert occ.sum() > 4 * (2 * HALF / cfg.resolution) * 0.9  # walls densely hit
    assert np.all(wall_dist[occ] <= 1.5 * cfg.resolution)  # and nothing else
    inside = np.max(np.abs(xy), axis=-1) < HALF - 2 * cfg.resolution
    assert np.all(grid.free_mask(cfg.free_thresh)[inside])
    outside = np.max(np.abs(xy), axis=-1) > HALF + 2 * cfg.resolution
    assert outside.any() and np.all(grid.log_odds[outside] == 0.0)
    # one update per cell per scan, whatever the number of beams through it
    assert set(np.unique(grid.log_odds)) == {np.float32(-1.5), np.float32(0.0), np.float32(cfg.log_odds_hit)}


def test_grid_extent_covers_scan_with_margin():
    pose, scan = room_scan()
    grid = build_grid(pose[None], [scan], MappingConfig(resolution=0.1))
    x0, x1, y0, y1 = grid.extent
    assert x0 < -HALF and y0 < -HALF and x1 > HALF and y1 > HALF
    assert x1 - x0 < 2 * HALF + 2.0 and y1 - y0 < 2 * HALF + 2.0
    assert np.isclose(x0 / 0.1, round(x0 / 0.1))  # origin on the cell lattice


def test_cell_hit_and_traversed_in_one_scan_counts_as_hit():
    # two beams along +x: one ends at 1.02 m, the other passes that cell to end at 2.02 m
    scan = Scan(0.0, np.array([1.02, 2.02]), np.zeros(2), 0.05, 12.0)
    cfg = MappingConfig(resolution=0.1)
    grid = build_grid(np.zeros((1, 3)), [scan], cfg)
    (r, c1), (_, c2), (_, c0) = grid.world_to_cell([[1.02, 0.0], [2.02, 0.0], [0.5, 0.0]])
    assert grid.log_odds[r, c1] == grid.log_odds[r, c2] == np.float32(cfg.log_odds_hit)
    assert grid.log_odds[r, c0] == np.float32(cfg.log_odds_miss)
    assert (grid.log_odds != 0).sum() == 21  # cells 0..20 along the beam, no others


def test_clamping_after_many_scans():
    pose, scan = room_scan()
    cfg = MappingConfig(resolution=0.1)
    grid = build_grid(np.repeat(pose[None], 60, axis=0), [scan] * 60, cfg)
    assert grid.log_odds.max() == np.float32(cfg.log_odds_max)
    assert grid.log_odds.min() == np.float32(cfg.log_odds_min)


def test_every_nth_scan():
    pose, scan = room_scan()
    cfg = MappingConfig(resolution=0.1, every_nth_scan=3)
    grid = build_grid(np.repeat(pose[None], 4, axis=0), [scan] * 4, cfg)  # scans 0 and 3
    assert grid.log_odds.max() == np.float32(2 * cfg.log_odds_hit)


def test_no_return_beams_clear_but_do_not_hit():
    range_max = 1.5  # every wall is farther than this from the sensor at the centre
    pose, scan = room_scan(base=(0, 0, 0), mount=(0, 0, 0), range_max=range_max)
    scan_nan = Scan(0.0, np.where(np.arange(360) % 2 == 0, scan.ranges, np.nan), ANGLES, 0.05, range_max)
    cfg = MappingConfig(resolution=0.05)
    for s in (scan, scan_nan):
        grid = build_grid(pose[None], [s], cfg)
        assert grid.log_odds.max() == 0.0  # no hits
        r = np.hypot(*np.moveaxis(cells_centres(grid), -1, 0))
        assert np.all(grid.log_odds[r < range_max - 0.3] < 0)
        assert np.all(grid.log_odds[r > range_max + 0.1] == 0)


def test_hits_beyond_max_range_only_clear():
    pose, scan = room_scan(base=(0, 0, 0), mount=(0, 0, 0))
    grid = build_grid(pose[None], [scan], MappingConfig(resolution=0.05, max_range=1.0))
    assert grid.log_odds.max() == 0.0
    assert grid.log_odds.min() < 0


def test_all_nan_scan_leaves_grid_unknown():
    pose, scan = room_scan(ranges=np.full(360, np.nan))
    grid = build_grid(pose[None], [scan], MappingConfig())
    assert np.all(grid.log_odds == 0)


def test_build_grid_rejects_mismatched_input():
    pose, scan = room_scan()
    with pytest.raises(ValueError):
        build_grid(np.zeros((2, 3)), [scan], MappingConfig())


def _wall_grid():
    """8 x 10 grid: top row (max y) occupied, bottom row free, the rest unknown."""
    lo = np.zeros((8, 10), np.float32)
    lo[-1, :] = 3.0
    lo[0, :] = -2.0
    lo[3, 4] = 0.3  # p = 0.57: unknown under the default thresholds
    return OccupancyGrid(lo, 0.05, (-1.25, 3.5))


def test_map_server_pgm_header_and_orientation(tmp_path):
    cfg = MappingConfig()
    pgm, yml = save_map_server(_wall_grid(), tmp_path / "map", cfg)
    assert (pgm.name, yml.name) == ("map.pgm", "map.yaml")
    data = pgm.read_bytes()
    assert data.startswith(b"P5\n")
    lines = data.split(b"\n", 4)
    assert lines[2] == b"10 8" and lines[3] == b"255"
    img = np.frombuffer(lines[4], np.uint8).reshape(8, 10)
    assert np.all(img[0] == 0)  # wall at high y -> top rows of the image
    assert np.all(img[-1] == 254)
    assert np.all(img[1:-1] == 205)
    text = yml.read_text()
    for line in ("image: map.pgm", "resolution: 0.05", "origin: [-1.25, 3.5, 0.0]", "negate: 0",
                 "occupied_thresh: 0.65", "free_thresh: 0.196", "mode: trinary"):  # fmt: skip
        assert line in text.splitlines()


def test_map_server_round_trip(tmp_path):
    pose, scan = room_scan()
    cfg = MappingConfig(log_odds_miss=-1.5)
    grid = build_grid(pose[None], [scan], cfg)
    _, yml = save_map_server(grid, tmp_path / "sub" / "room", cfg)
    back = load_map_server(yml)
    assert back.shape == grid.shape and back.resolution == grid.resolution and back.origin == grid.origin
    np.testing.assert_array_equal(back.occupied_mask(cfg.occupied_thresh), grid.occupied_mask(cfg.occupied_thresh))
    np.testing.assert_array_equal(back.free_mask(cfg.free_thresh), grid.free_mask(cfg.free_thresh))


def test_save_map_png(tmp_path):
    pose, scan = room_scan()
    grid = build_grid(pose[None], [scan], MappingConfig())
    traj = np.array([[0.0, 0.0, 0.0], [0.5, 0.2, 0.1], [1.0, 0.5, 0.2]])
    out = save_map_png(grid, tmp_path / "map.png", {"estimate": traj, "odometry": traj + 0.1}, title="room")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
