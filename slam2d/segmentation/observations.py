"""Observations for map segmentation: (pose, scan) pairs, real or ray-cast on a grid.

Grid convention (as :mod:`slam2d.mapping.occupancy`): ``free[row, col]`` with
row along y and col along x; cell ``[r, c]`` covers
``[ox + c*res, ox + (c+1)*res) x [oy + r*res, oy + (r+1)*res)`` where
``(ox, oy) = origin`` in metres. A PNG loaded as-is (row 0 = top) is then
mirrored in y, which changes nothing for segmentation: labels come back on the
same array.

Each observation keeps its beams (ranges and map-frame angles, ragged: flat
arrays plus offsets) and its hit points in the map frame (ragged). What an
observation *sees* is the star-shaped region its beams sweep: a point at
distance d and bearing b is visible when d is at most the range of the beam
nearest to b (:meth:`Observations.sees`); visible free cells, lattice points
and the labelling of free cells all use this one test.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy import ndimage

from slam2d import geometry
from slam2d.errors import InputError
from slam2d.types import Scan

__all__ = [
    "Observations",
    "observations_from_scans",
    "virtual_observations",
    "lattice_viewpoints",
    "raycast_grid",
    "dda_start",
    "dda_step",
    "see_through",
    "cell_centres",
]

log = logging.getLogger(__name__)

_TWO_PI = 2.0 * np.pi
_KEY_STRIDE = 8.0  # > 2*pi: observation index * stride + angle sorts beams per observation
TABLE_BINS = 720
"""Bearing bins of the range table of irregular scans (0.5 deg)."""


@njit(cache=True, nogil=True)
def _visible(table, xy, rmax, i, px, py, slack):
    dx = px - xy[i, 0]
    dy = py - xy[i, 1]
    d = np.sqrt(dx * dx + dy * dy)
    if d == 0.0:
        return True
    if d > rmax[i]:
        return False
    nb = table.shape[1]
    a = np.arctan2(dy, dx)
    j = int(np.floor(a * nb / (2.0 * np.pi) + 0.5)) % nb
    r = table[i, j]
    return r >= 0.0 and d <= r + slack


@njit(cache=True, nogil=True)
def _sees(table, xy, rmax, obs, pts, slack, out):
    for q in range(obs.shape[0]):
        out[q] = _visible(table, xy, rmax, obs[q], pts[q, 0], pts[q, 1], slack)


@njit(cache=True, nogil=True)
def _sees_all(table, xy, rmax, pts, slack, out):
    for i in range(xy.shape[0]):
        for p in range(pts.shape[0]):
            out[i, p] = _visible(table, xy, rmax, i, pts[p, 0], pts[p, 1], slack)


@dataclass(eq=False)
class Observations:
    """N observations: sensor poses and their beams and hit points in the map frame.

    poses: (N, 3) sensor poses (x, y, theta), metres / radians.
    beam_ranges: (K,) metres, no-return beams hold ``range_max``; ``beam_angles`` (K,)
        map-frame bearings in [0, 2*pi); beams of observation i are
        ``beam_offsets[i]:beam_offsets[i+1]``, in scan order.
    beam_hit: (K,) whether each beam returned a hit.
    range_max: (N,) metres, beyond which an observation sees nothing.
    points: (M,) x 2 hit points in the map frame, metres; observation i owns
        ``points[offsets[i]:offsets[i+1]]``, in scan order.
    free, resolution, origin: the grid the observations were cast on (None for real scans).
    clear: the grid the beams were cast on (``free`` plus see-through clutter), if any.
    """

    poses: np.ndarray
    beam_ranges: np.ndarray
    beam_angles: np.ndarray
    beam_hit: np.ndarray
    beam_offsets: np.ndarray
    range_max: np.ndarray
    points: np.ndarray
    offsets: np.ndarray
    free: np.ndarray | None = None
    resolution: float | None = None
    origin: tuple[float, float] = (0.0, 0.0)
    clear: np.ndarray | None = None

    def __post_init__(self):
        self._keys = None
        self._table = None

    def __len__(self) -> int:
        return len(self.poses)

    @classmethod
    def from_beams(cls, poses, ranges, angles, hit, offsets, range_max, **grid) -> Observations:
        """Build from flat beams: ranges (K,) m, map-frame angles (K,) rad, hit (K,), offsets (N+1,)."""
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        angles = np.mod(np.asarray(angles, dtype=np.float64), _TWO_PI)
        ranges = np.asarray(ranges, dtype=np.float64)
        hit = np.asarray(hit, dtype=bool)
        offsets = np.asarray(offsets, dtype=np.int64)
        owner = np.repeat(np.arange(len(poses)), np.diff(offsets))
        xy = poses[owner, :2] + ranges[:, None] * np.column_stack([np.cos(angles), np.sin(angles)])
        pts = xy[hit]
        point_offsets = np.concatenate([[0], np.cumsum(np.bincount(owner[hit], minlength=len(poses)))])
        rmax = np.broadcast_to(np.asarray(range_max, dtype=np.float64), (len(poses),)).copy()
        return cls(poses, ranges, angles, hit, offsets, rmax, pts, point_offsets, **grid)

    def scan_points(self, i: int) -> np.ndarray:
        """Hit points (m, 2) of observation ``i`` in the map frame, metres."""
        return self.points[self.offsets[i] : self.offsets[i + 1]]

    def owner(self) -> np.ndarray:
        """Observation index (M,) of every hit point."""
        return np.repeat(np.arange(len(self)), np.diff(self.offsets))

    def _beam_keys(self):
        """Beams sorted by (observation, angle): sorted keys (K,) and the beam index of each."""
        if self._keys is None:
            owner = np.repeat(np.arange(len(self)), np.diff(self.beam_offsets))
            key = owner * _KEY_STRIDE + self.beam_angles
            order = np.argsort(key, kind="stable")
            self._keys = (key[order], order)
        return self._keys

    def range_table(self) -> np.ndarray:
        """Ranges (N, B) by bearing bin: bin j is bearing ``j * 2*pi / B``, m; -1 where unseen.

        Regular 360 deg scans starting at bearing 0 (virtual observations) are
        used as they are; otherwise each of ``TABLE_BINS`` bins takes the range
        of the beam nearest in bearing, or -1 (nothing seen: see :meth:`sees`)
        when that beam is more than 1.5 beam steps away (outside the field of view).
        """
        if self._table is None:
            self._table = self._regular_table()
            if self._table is None:
                bins = TABLE_BINS
                obs = np.repeat(np.arange(len(self)), bins)
                bearing = np.tile(np.arange(bins) * (_TWO_PI / bins), len(self))
                beam, gap = self._nearest_beam(obs, bearing)
                step = self._beam_steps()
                ok = (beam >= 0) & (gap <= np.maximum(1.5 * step[obs], 0.5 * _TWO_PI / bins))
                table = np.where(ok, self.beam_ranges[np.maximum(beam, 0)], -1.0)
                self._table = table.reshape(len(self), bins)
        return self._table

    def _beam_steps(self) -> np.ndarray:
        """Mean angular step (N,) between consecutive beams of each scan, rad (2*pi if < 2 beams)."""
        owner = np.repeat(np.arange(len(self)), np.diff(self.beam_offsets))
        d = np.abs(geometry.wrap_angle(np.diff(self.beam_angles)))
        same = owner[1:] == owner[:-1]
        tot = np.bincount(owner[1:][same], weights=d[same], minlength=len(self))
        cnt = np.bincount(owner[1:][same], minlength=len(self))
        return np.where(cnt > 0, tot / np.maximum(cnt, 1), _TWO_PI)

    def _regular_table(self) -> np.ndarray | None:
        counts = np.diff(self.beam_offsets)
        if len(counts) == 0 or counts[0] == 0 or np.any(counts != counts[0]):
            return None
        b = int(counts[0])
        expected = np.tile(np.arange(b) * (_TWO_PI / b), len(self))
        if not np.allclose(self.beam_angles, expected, atol=1e-9):
            return None
        return self.beam_ranges.reshape(len(self), b)

    def sees(self, obs, points, slack: float = 0.0) -> np.ndarray:
        """Whether observation ``obs[q]`` sees point ``points[q]`` (map frame, m), for Q queries.

        True when the point lies within ``range_max`` and no farther than
        ``slack`` beyond the range of the beam nearest in bearing (see
        :meth:`range_table`). A point at the observation's own position is seen.
        """
        obs = np.ascontiguousarray(np.asarray(obs, dtype=np.int64).reshape(-1))
        pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 2))
        out = np.empty(len(obs), dtype=bool)
        _sees(self.range_table(), self.poses[:, :2].copy(), self.range_max, obs, pts, float(slack), out)
        return out

    def sees_all(self, points, slack: float = 0.0) -> np.ndarray:
        """Visibility (N, P) bool of points (P, 2) from every observation (dense, numba)."""
        pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 2))
        out = np.empty((len(self), len(pts)), dtype=bool)
        _sees_all(self.range_table(), self.poses[:, :2].copy(), self.range_max, pts, float(slack), out)
        return out

    def _nearest_beam(self, obs: np.ndarray, bearing: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Index (Q,) of the beam of ``obs`` nearest in bearing (-1 if it has none), and the
        angular distance (Q,) to it, rad."""
        keys, order = self._beam_keys()
        if len(keys) == 0:
            return np.full(len(obs), -1), np.full(len(obs), np.inf)
        start, stop = self.beam_offsets[obs], self.beam_offsets[obs + 1]
        hi = np.searchsorted(keys, obs * _KEY_STRIDE + bearing)  # keys are grouped by observation
        up = np.where(hi >= stop, start, hi)  # the next beam, wrapping to the first
        lo = np.where(hi <= start, stop - 1, hi - 1)  # the previous beam, wrapping to the last
        up, lo = np.clip(up, 0, len(keys) - 1), np.clip(lo, 0, len(keys) - 1)
        d_up = np.abs(geometry.wrap_angle(keys[up] - obs * _KEY_STRIDE - bearing))
        d_lo = np.abs(geometry.wrap_angle(keys[lo] - obs * _KEY_STRIDE - bearing))
        near_up = d_up <= d_lo
        has = stop > start
        best = np.where(has, np.where(near_up, order[up], order[lo]), -1)
        return best, np.where(has, np.where(near_up, d_up, d_lo), np.inf)


# --------------------------------------------------------------------------- grid ray casting


def cell_centres(cells, resolution: float, origin=(0.0, 0.0)) -> np.ndarray:
    """Map-frame centres (P, 2) in metres of cells (P, 2) given as (row, col)."""
    cells = np.asarray(cells, dtype=np.float64).reshape(-1, 2)
    return np.column_stack([cells[:, 1] + 0.5, cells[:, 0] + 0.5]) * resolution + np.asarray(origin)


@njit(cache=True, nogil=True)
def dda_start(gx, gy, dx, dy):
    """Amanatides & Woo set-up from grid coordinates (gx, gy) (cells) along (dx, dy): the cell
    steps, the distance (cells) between column and row crossings, and to the first of each
    (inf along an axis the ray does not move on, also from a cell edge)."""
    c, r = np.floor(gx), np.floor(gy)
    step_c = 1 if dx > 0 else -1
    step_r = 1 if dy > 0 else -1
    inv_x = 1.0 / abs(dx) if dx != 0 else np.inf
    inv_y = 1.0 / abs(dy) if dy != 0 else np.inf
    tmx = ((c + 1 - gx) if dx > 0 else (gx - c)) * inv_x if dx != 0 else np.inf
    tmy = ((r + 1 - gy) if dy > 0 else (gy - r)) * inv_y if dy != 0 else np.inf
    return step_c, step_r, inv_x, inv_y, tmx, tmy


@njit(cache=True, nogil=True)
def dda_step(tmx, tmy, inv_x, inv_y, c, r, step_c, step_r):
    """One Amanatides & Woo step to the next cell: (distance reached in cells, tmx, tmy, c, r)."""
    if tmx < tmy:
        return tmx, tmx + inv_x, tmy, c + step_c, r
    return tmy, tmx, tmy + inv_y, c, r + step_r


@njit(cache=True, nogil=True)
def _dda(blocked, gx, gy, angles, max_t, out_t, out_hit):
    """Amanatides & Woo traversal from grid coordinates (gx, gy) (cells) along angles (B,).

    Writes the distance in cells to the first blocked cell (or the grid edge,
    counted as blocked) into out_t, or max_t with out_hit False when none.
    """
    h, w = blocked.shape
    c0 = int(np.floor(gx))
    r0 = int(np.floor(gy))
    for b in range(angles.shape[0]):
        dx = np.cos(angles[b])
        dy = np.sin(angles[b])
        c, r = c0, r0
        if c < 0 or r < 0 or c >= w or r >= h or blocked[r, c]:
            out_t[b] = 0.0
            out_hit[b] = True
            continue
        step_c, step_r, inv_x, inv_y, tmx, tmy = dda_start(gx, gy, dx, dy)
        t = 0.0
        hit = False
        while True:
            t, tmx, tmy, c, r = dda_step(tmx, tmy, inv_x, inv_y, c, r, step_c, step_r)
            if t >= max_t:
                break
            if c < 0 or r < 0 or c >= w or r >= h or blocked[r, c]:
                hit = True
                break
        out_t[b] = t if hit else max_t
        out_hit[b] = hit


@njit(cache=True, nogil=True)
def _dda_many(blocked, gxy, angles, max_t, out_t, out_hit):
    for p in range(gxy.shape[0]):
        _dda(blocked, gxy[p, 0], gxy[p, 1], angles[p], max_t, out_t[p], out_hit[p])


def raycast_grid(free, resolution: float, origins, angles, max_range: float, origin=(0.0, 0.0)):
    """Ray-cast on a grid: ranges (P, B) m and hit flags (P, B) from origins (P, 2) m.

    ``angles`` are map-frame bearings, (B,) shared or (P, B). Non-free cells and
    the outside of the grid stop a beam; a beam that stops nowhere within
    ``max_range`` returns ``max_range`` with hit False. Exact grid traversal
    (Amanatides & Woo 1987) in numba.
    """
    blocked = ~np.asarray(free, dtype=bool)
    origins = np.asarray(origins, dtype=np.float64).reshape(-1, 2)
    angles = np.asarray(angles, dtype=np.float64)
    angles = np.ascontiguousarray(np.broadcast_to(angles, (len(origins), angles.shape[-1])))
    gxy = np.ascontiguousarray((origins - np.asarray(origin, dtype=np.float64)) / resolution)
    t = np.empty(angles.shape)
    hit = np.empty(angles.shape, dtype=bool)
    _dda_many(blocked, gxy, angles, float(max_range) / resolution, t, hit)
    return t * resolution, hit


# --------------------------------------------------------------------------- viewpoints


def lattice_viewpoints(free, resolution: float, spacing_m: float, clearance_m: float = 0.2,
                       min_area_m2: float = 0.25) -> np.ndarray:
    """Viewpoint cells (P, 2) as (row, col): a square lattice over the free space.

    Lattice nodes every ``spacing_m`` whose cell is free with no non-free cell
    (or grid edge) closer than ``clearance_m``. Every 8-connected free
    component of at least ``min_area_m2`` that the lattice misses gets one
    viewpoint at its most open cell (largest distance to an obstacle), so no
    room of that size goes unobserved.
    """
    free = np.asarray(free, dtype=bool)
    step = max(1, int(round(spacing_m / resolution)))
    off = step // 2
    rows, cols = np.nonzero(free[off::step, off::step])
    rows, cols = rows * step + off, cols * step + off
    keep = _clear_around(free, rows, cols, max(clearance_m, resolution) / resolution)
    cells = np.column_stack([rows[keep], cols[keep]]).astype(np.int64)
    if not np.isfinite(min_area_m2):
        return cells
    lab, n = ndimage.label(free, structure=np.ones((3, 3), dtype=int))
    if n == 0:
        return cells
    size = np.bincount(lab.ravel(), minlength=n + 1)
    seen = np.zeros(n + 1, dtype=bool)
    seen[lab[cells[:, 0], cells[:, 1]]] = True
    want = np.nonzero(~seen & (size * resolution**2 >= min_area_m2))[0]
    want = want[want > 0]
    if len(want):
        boxes = ndimage.find_objects(lab)
        extra = [_most_open(lab, w, boxes[w - 1]) for w in want]  # only rooms the lattice missed
        cells = np.concatenate([cells, np.asarray(extra, dtype=np.int64).reshape(-1, 2)])
    return cells


def _clear_around(free: np.ndarray, rows: np.ndarray, cols: np.ndarray, radius: float) -> np.ndarray:
    """Whether every cell closer than ``radius`` cells to (rows, cols) is free (outside counts as blocked)."""
    r = int(np.ceil(radius))
    dy, dx = np.mgrid[-r : r + 1, -r : r + 1]
    disk = dy**2 + dx**2 < radius**2
    dy, dx = dy[disk], dx[disk]
    pad = np.pad(free, r, constant_values=False)
    return pad[rows[:, None] + r + dy, cols[:, None] + r + dx].all(axis=1)


def _most_open(lab: np.ndarray, which: int, box) -> tuple[int, int]:
    """Cell (row, col) of component ``which`` farthest from anything else (EDT on its box)."""
    sub = np.pad(lab[box] == which, 1)
    d = ndimage.distance_transform_edt(sub)
    r, c = np.unravel_index(np.argmax(d), d.shape)
    return r - 1 + box[0].start, c - 1 + box[1].start


def see_through(free, resolution: float, clutter_m: float) -> np.ndarray:
    """``free`` plus clutter: 8-connected obstacle components whose bounding box
    is shorter than ``clutter_m`` m on both sides (chair legs, bins, small tables)."""
    free = np.asarray(free, dtype=bool)
    if not clutter_m > 0:
        return free
    lab, n = ndimage.label(~free, structure=np.ones((3, 3), dtype=int))
    if n == 0:
        return free
    boxes = ndimage.find_objects(lab)
    ext = np.array([max(b[0].stop - b[0].start, b[1].stop - b[1].start) for b in boxes]) * resolution
    small = np.concatenate([[False], ext < clutter_m])
    return free | small[lab]


def virtual_observations(free, resolution: float, spacing_m: float = 1.2, beams: int = 360,
                         max_range: float = 20.0, *, clearance_m: float = 0.2, clutter_m: float = 0.0,
                         origin=(0.0, 0.0)) -> Observations:
    """Observations ray-cast over 360 deg from a lattice of viewpoints on the free space.

    free: (H, W) bool; resolution: m per cell; spacing_m: lattice step, m;
    beams: beams per scan spread evenly over 2*pi; max_range: m. Viewpoints come
    from :func:`lattice_viewpoints` (uniform in area, so the graph weights area
    evenly); headings are 0. Obstacles smaller than ``clutter_m`` m
    (:func:`see_through`) do not stop the virtual beams: furniture should not
    cut a room into pieces. The observations keep ``free`` itself as their grid.
    """
    free = np.asarray(free, dtype=bool)
    if free.ndim != 2:
        raise InputError("virtual_observations", f"free must be a 2-D mask, got shape {free.shape}")
    if not (resolution > 0 and spacing_m > 0 and max_range > 0 and beams > 0):
        raise InputError("virtual_observations", "resolution, spacing_m, max_range and beams must be > 0")
    clear = see_through(free, resolution, clutter_m)
    cells = lattice_viewpoints(clear, resolution, spacing_m, clearance_m)
    cells = cells[free[cells[:, 0], cells[:, 1]]]
    xy = cell_centres(cells, resolution, origin)
    angles = np.arange(beams) * (_TWO_PI / beams)
    ranges, hit = raycast_grid(clear, resolution, xy, angles, max_range, origin)
    n = len(xy)
    log.debug("%d virtual observations, %d beams each", n, beams)
    pts = xy[:, None, :] + ranges[..., None] * np.stack([np.cos(angles), np.sin(angles)], axis=-1)
    obs = Observations(
        poses=np.column_stack([xy, np.zeros(n)]),
        beam_ranges=ranges.ravel(),
        beam_angles=np.tile(angles, n),
        beam_hit=hit.ravel(),
        beam_offsets=np.arange(n + 1, dtype=np.int64) * beams,
        range_max=np.full(n, float(max_range)),
        points=pts[hit],
        offsets=np.concatenate([[0], np.cumsum(hit.sum(axis=1))]).astype(np.int64),
        free=free, resolution=float(resolution), origin=tuple(map(float, origin)), clear=clear,
    )
    obs._table = ranges  # regular beams from bearing 0: the range table itself
    return obs


def observations_from_scans(poses, scans: Sequence[Scan], *, free=None, resolution: float | None = None,
                            origin=(0.0, 0.0)) -> Observations:
    """Observations from a SLAM run: base poses (N, 3) in the map frame and their scans.

    Each scan's sensor mounting pose is applied. NaN beams and beams below
    ``range_min`` are dropped; no-return beams (``>= range_max``) are kept as
    free space up to ``range_max`` without a hit. An optional grid (free,
    resolution, origin) is kept for labelling free cells.
    """
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 2 or poses.shape[1] != 3:
        raise InputError("observations_from_scans", f"poses must be (N, 3), got {poses.shape}")
    if len(poses) != len(scans):
        raise InputError("observations_from_scans", f"{len(poses)} poses but {len(scans)} scans")
    mounts = np.array([s.sensor_pose for s in scans], dtype=np.float64).reshape(-1, 3)
    sensor = geometry.compose(poses, mounts).reshape(-1, 3)
    ranges, angles, hits, counts = [], [], [], []
    for s, sp in zip(scans, sensor):
        r = np.asarray(s.ranges, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            keep = np.isfinite(r) & (r >= s.range_min) | (np.isinf(r) & (r > 0))
            hit = np.isfinite(r) & (r < s.range_max)
        keep &= ~np.isnan(r)
        r = np.where(hit, r, s.range_max)[keep]
        ranges.append(r)
        angles.append(sp[2] + np.asarray(s.angles, dtype=np.float64)[keep])
        hits.append(hit[keep])
        counts.append(len(r))
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    cat = (lambda xs, dt: np.concatenate(xs).astype(dt) if xs else np.zeros(0, dt))
    rmax = np.array([s.range_max for s in scans], dtype=np.float64)
    return Observations.from_beams(
        sensor, cat(ranges, np.float64), cat(angles, np.float64), cat(hits, bool), offsets, rmax,
        free=None if free is None else np.asarray(free, dtype=bool),
        resolution=resolution, origin=tuple(map(float, origin)),
    )
