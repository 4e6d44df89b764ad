"""Log-odds occupancy grid from poses and scans (vectorised ray casting).

Conventions: ``log_odds[row, col]`` with row = y and col = x; cell ``[0, 0]``
has its lower-left corner at ``origin`` (metres). A log-odds of 0 is unknown
(p = 0.5).

Beam model of :func:`build_grid`:

- a hit (finite range in ``[range_min, range_max)``, and ``<= cfg.max_range``
  when set) marks its end cell occupied and every other cell the beam crosses
  free (exact grid traversal, Amanatides & Woo 1987);
- a no-return beam (range ``>= range_max``) marks cells free up to
  ``min(range_max, cfg.max_range or NO_RETURN_CLEAR_M)`` and no hit; a hit
  farther than ``cfg.max_range`` is treated the same way (free up to
  ``cfg.max_range``);
- NaN beams and ranges below ``range_min`` are ignored.

Within one scan each cell is updated at most once; a cell both hit and passed
through counts as hit. Log-odds are clamped to
``[cfg.log_odds_min, cfg.log_odds_max]`` after every update.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit

from slam2d import geometry
from slam2d.config import MappingConfig
from slam2d.errors import InputError
from slam2d.limits import check_memory
from slam2d.mapping.grid import OccupancyGrid, logit
from slam2d.types import Scan

__all__ = [
    "OccupancyGrid", "build_grid", "beam_segments", "trace_beams", "check_resolution", "logit",
    "NO_RETURN_CLEAR_M", "MARGIN_M", "MAX_CELLS",
]

NO_RETURN_CLEAR_M = 5.0
"""Farthest a no-return beam clears free space when ``cfg.max_range`` is unset, m.

As Cartographer's ``missing_data_ray_length``: indoors a no-return often means
glass or a dark surface, not open space (Intel has 68k beams at its 80 m limit),
so clearing far would cut through walls and inflate the grid.
"""

MARGIN_M = 0.5
"""Unknown border added around the mapped extent, m."""

MAX_CELLS = 100_000_000
GRID_BYTES_PER_CELL = 12  # the log-odds (float32) and the two marks of the ray casting (int32)
"""Largest grid build_grid will allocate (12 bytes a cell while building)."""


def build_grid(poses, scans: Sequence[Scan], cfg: MappingConfig) -> OccupancyGrid:
    """Integrate ``scans`` taken at base ``poses`` (N, 3) (map frame) into a new grid.

    Uses every ``cfg.every_nth_scan``-th scan; the grid covers every sensor
    position and beam end point plus :data:`MARGIN_M`. See the module docstring
    for the beam model.
    """
    poses = geometry.as_pose(poses).reshape(-1, 3)
    if len(poses) != len(scans):
        raise ValueError(f"{len(poses)} poses but {len(scans)} scans")
    if len(scans) == 0:
        raise ValueError("cannot build a grid without scans")
    if not np.all(np.isfinite(poses)):
        raise ValueError("poses contain NaN or inf")
    step = cfg.every_nth_scan
    poses, scans = poses[::step], list(scans)[::step]
    origins, ends, is_hit, offsets = beam_segments(poses, scans, cfg)
    grid = _empty_grid(np.vstack([origins, ends]), cfg.resolution)
    trace_beams(grid, origins, ends, is_hit, offsets, cfg)
    return grid


def trace_beams(grid: OccupancyGrid, sensors, ends, is_hit, offsets, cfg: MappingConfig, clamp: bool = True) -> None:
    """Ray-cast beams (as :func:`beam_segments` returns them, in the grid's frame, m) into
    ``grid.log_odds`` in place, scan by scan, with the beam model of :func:`build_grid`.
    ``clamp=False`` sums the updates without clamping to ``[cfg.log_odds_min, cfg.log_odds_max]``."""
    low, high = (cfg.log_odds_min, cfg.log_odds_max) if clamp else (-np.inf, np.inf)
    _integrate(
        grid.log_odds, _cell_coords(grid, sensors), _cell_coords(grid, ends), is_hit, offsets,
        np.float32(cfg.log_odds_hit), np.float32(cfg.log_odds_miss), np.float32(low), np.float32(high),
    )  # fmt: skip


def beam_segments(poses: np.ndarray, scans: list[Scan], cfg: MappingConfig):
    """The beams :func:`build_grid` traces for ``scans`` at base ``poses`` (S, 3): sensor positions
    (S, 2) m, beam ends (B, 2) m, hit flags (B,), scan offsets (S+1,) (beams of scan s are
    ``offsets[s]:offsets[s+1]``).

    Only usable beams are returned: hits end at the hit, no-return beams at
    their clearing range.
    """
    counts = np.array([len(s.ranges) for s in scans])
    ranges = np.concatenate([np.asarray(s.ranges, dtype=np.float64) for s in scans])
    angles = np.concatenate([np.asarray(s.angles, dtype=np.float64) for s in scans])
    r_min = np.repeat([s.range_min for s in scans], counts)
    r_max = np.repeat([s.range_max for s in scans], counts)
    usable, hit, length = _classify_beams(ranges, r_min, r_max, cfg.max_range)

    mounts = np.array([s.sensor_pose for s in scans], dtype=np.float64).reshape(-1, 3)
    sensors = geometry.compose(poses, mounts)
    scan_of_beam = np.repeat(np.arange(len(scans)), counts)[usable]
    s = sensors[scan_of_beam]
    a, d = s[:, 2] + angles[usable], length[usable]
    ends = np.column_stack([s[:, 0] + d * np.cos(a), s[:, 1] + d * np.sin(a)])
    offsets = np.concatenate([[0], np.cumsum(np.bincount(scan_of_beam, minlength=len(scans)))])
    return sensors[:, :2], ends, hit[usable], offsets.astype(np.int64)


def _classify_beams(ranges, r_min, r_max, max_range):
    """Per beam: usable (not NaN, >= range_min), hit, and the length to trace (m)."""
    cap = max_range if max_range is not None else NO_RETURN_CLEAR_M
    with np.errstate(invalid="ignore"):
        usable = np.isfinite(ranges) & (ranges >= r_min)
        hit = usable & (ranges < r_max) & (ranges <= (max_range or np.inf))
        length = np.where(hit, ranges, np.minimum(np.minimum(ranges, r_max), cap))
    return usable, hit, length


def _cell_coords(grid: OccupancyGrid, xy: np.ndarray) -> np.ndarray:
    """Continuous (row, col) coordinates (M, 2) of points ``xy`` (M, 2) m; floor gives the cell."""
    return np.column_stack([xy[:, 1] - grid.origin[1], xy[:, 0] - grid.origin[0]]) / grid.resolution


def check_resolution(resolution: float) -> None:
    """InputError (mapping.resolution) if even the smallest grid, the margin alone, would exceed MAX_CELLS."""
    side = 2 * MARGIN_M / resolution + 1
    if side * side > MAX_CELLS:
        raise InputError("mapping.resolution", f"{resolution} m per cell: even the {2 * MARGIN_M:g} m margin "
                         f"alone would exceed {MAX_CELLS:.0e} cells")


def _empty_grid(points: np.ndarray, resolution: float) -> OccupancyGrid:
    """An all-unknown grid covering ``points`` (M, 2) plus the margin, origin on the cell lattice."""
    lo = np.floor((points.min(axis=0) - MARGIN_M) / resolution) * resolution
    hi = points.max(axis=0) + MARGIN_M
    w, h = np.ceil((hi - lo) / resolution).astype(int) + 1
    if w * h > MAX_CELLS:
        raise ValueError(
            f"the scans span {hi[0] - lo[0]:.0f} m x {hi[1] - lo[1]:.0f} m: {h} x {w} cells at "
            f"{resolution} m exceed {MAX_CELLS:.0e} (diverged poses, or set mapping.max_range)"
        )
    check_memory(w * h * GRID_BYTES_PER_CELL, "mapping.resolution", f"a {h} x {w} map grid at {resolution} m")
    return OccupancyGrid(np.zeros((h, w), np.float32), resolution, (lo[0], lo[1]))


@njit(cache=True, nogil=True)
def _integrate(log_odds, starts, ends, is_hit, offsets, l_hit, l_miss, l_min, l_max):
    """Ray-cast every scan into ``log_odds`` in place, scan by scan.

    starts (S, 2) and ends (B, 2) are continuous (row, col) cell coordinates
    (cell (r, c) spans [r, r+1) x [c, c+1)); beams of scan s are
    ``offsets[s]:offsets[s+1]``. Hits are applied first so that a cell both hit
    and traversed in one scan counts as hit; each cell changes once per scan.
    """
    h, w = log_odds.shape
    hit_mark = np.full((h, w), -1, np.int32)
    miss_mark = np.full((h, w), -1, np.int32)
    for s in range(len(offsets) - 1):
        for b in range(offsets[s], offsets[s + 1]):
            r, c = int(np.floor(ends[b, 0])), int(np.floor(ends[b, 1]))
            if is_hit[b] and 0 <= r < h and 0 <= c < w and hit_mark[r, c] != s:
                hit_mark[r, c] = s
                log_odds[r, c] = min(max(log_odds[r, c] + l_hit, l_min), l_max)
        for b in range(offsets[s], offsets[s + 1]):
            _trace_free(log_odds, hit_mark, miss_mark, s, starts[s, 0], starts[s, 1],
                        ends[b, 0], ends[b, 1], not is_hit[b], l_miss, l_min, l_max)  # fmt: skip


@njit(cache=True, nogil=True)
def _trace_free(log_odds, hit_mark, miss_mark, s, y0, x0, y1, x1, include_end, l_miss, l_min, l_max):
    """Mark free every cell the segment (y0, x0) -> (y1, x1) crosses (Amanatides & Woo).

    Coordinates are continuous (row, col); the end cell only if ``include_end``.
    Cells already hit or marked free in scan ``s`` are left alone.
    """
    h, w = log_odds.shape
    r, c = int(np.floor(y0)), int(np.floor(x0))
    r1, c1 = int(np.floor(y1)), int(np.floor(x1))
    dx, dy = x1 - x0, y1 - y0
    sc = 1 if dx > 0 else -1
    sr = 1 if dy > 0 else -1
    t_dx = abs(1.0 / dx) if dx != 0 else np.inf
    t_dy = abs(1.0 / dy) if dy != 0 else np.inf
    t_x = ((c + 1 - x0) if dx > 0 else (x0 - c)) * t_dx if dx != 0 else np.inf
    t_y = ((r + 1 - y0) if dy > 0 else (y0 - r)) * t_dy if dy != 0 else np.inf
    n = abs(r1 - r) + abs(c1 - c) + (1 if include_end else 0)
    for _ in range(n):  # one row or column step each, ending at (r1, c1)
        if 0 <= r < h and 0 <= c < w and hit_mark[r, c] != s and miss_mark[r, c] != s:
            miss_mark[r, c] = s
            log_odds[r, c] = min(max(log_odds[r, c] + l_miss, l_min), l_max)
        if c != c1 and (t_x < t_y or r == r1):
            t_x += t_dx
            c += sc
        elif r != r1:
            t_y += t_dy
            r += sr
