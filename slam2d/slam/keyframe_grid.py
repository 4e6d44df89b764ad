"""Occupancy grid built from keyframe patches, re-placed when their keyframes move.

Each keyframe owns the beams of its scans in its own frame. Placed at a pose,
they are ray-traced (``slam2d.mapping.occupancy.trace_beams``, the beam model of
``build_grid``) into a patch: the keyframe's summed log-odds update of every
cell it touches, on the map's cell lattice, kept sparse (cell, value).

The grid applies the patches in keyframe order, clamping after each
(``clamp(l + patch, log_odds_min, log_odds_max)``), which is ``build_grid``'s
scan-by-scan clamping except inside one keyframe's few scans. A new keyframe
is applied on top. When keyframes move so that one of their beam ends could
shift by more than ``tolerance`` (m), only they are traced again; the cells
their old and new patches cover are reset and refolded from the stored
patches of every keyframe, in order, without tracing any other beam.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np
from numba import njit

from slam2d import geometry
from slam2d.config import MappingConfig
from slam2d.limits import check_memory
from slam2d.mapping.occupancy import MARGIN_M, MAX_CELLS, OccupancyGrid, beam_segments, trace_beams
from slam2d.types import Scan

GROW_M = 5.0  # room added beyond a patch when the grid grows, m
_NO_MASK = np.zeros(0, bool)


@dataclass
class _Beams:
    """A keyframe's beams in its own frame: sensors (S, 2), ends (B, 2) m, hit (B,), offsets (S+1,)."""

    sensors: np.ndarray
    ends: np.ndarray
    hit: np.ndarray
    offsets: np.ndarray
    reach: float  # farthest sensor or beam end from the keyframe, m


@dataclass
class _Patch:
    """A traced keyframe: log-odds updates ``val`` (float32) of the base grid's cells ``flat``
    (int32 flat indices); its cells lie in lattice rows and columns ``box`` (first row, first col,
    last row, last col)."""

    box: np.ndarray
    flat: np.ndarray
    val: np.ndarray


@dataclass(frozen=True)
class GridUpdate:
    """One update: keyframes traced for the first time, traced again (moved or grew), beams traced,
    and cells refolded after re-placing keyframes already in the grid."""

    placed: int = 0
    replaced: int = 0
    beams: int = 0
    refolded_cells: int = 0


class KeyframeGrid:
    """Log-odds grid of keyframe patches; ``update(poses, closed)`` places new keyframes and
    re-places those that moved.

    ``tolerance`` (m, default a quarter cell): largest shift of any beam end a keyframe
    may have before it is traced again.
    """

    def __init__(self, cfg: MappingConfig, tolerance: float | None = None):
        self.cfg = cfg
        self.tolerance = cfg.resolution / 4 if tolerance is None else float(tolerance)
        self._beams: list[_Beams | None] = []
        self._patches: list[_Patch | None] = []
        self._placed = np.zeros((0, 3))  # pose each keyframe was traced at (NaN: never)
        self._reach = np.zeros(0)  # farthest beam end of each keyframe, m
        self._scans = np.zeros(0, np.int64)  # scans each keyframe has
        self._traced = np.zeros(0, np.int64)  # scans each keyframe was traced with (-1: never)
        self._box = np.zeros((0, 4), np.int64)  # lattice (row, col) of each patch's first and last cell
        self._base = np.zeros((0, 0), np.float32)  # keyframes 0 .. _folded-1 applied in order
        self._corner = np.zeros(2, np.int64)  # lattice (row, col) of the base's cell [0, 0]
        self._folded = 0
        self._retired: list[_Patch] = []  # patches being replaced during an update
        self._limits = np.float32(cfg.log_odds_min), np.float32(cfg.log_odds_max)
        self.last = GridUpdate()
        self.stats: Counter[str] = Counter()

    @property
    def num_keyframes(self) -> int:
        return len(self._beams)

    @property
    def nbytes(self) -> int:
        """Memory held by the patches, the keyframes' beams and the grid, bytes."""
        patches = sum(p.flat.nbytes + p.val.nbytes for p in self._patches if p is not None)
        beams = sum(b.sensors.nbytes + b.ends.nbytes + b.hit.nbytes for b in self._beams if b is not None)
        return patches + beams + self._base.nbytes

    def add_scan(self, key: int, offset, scan: Scan) -> None:
        """Scan ``scan`` taken at ``offset`` (3,) in keyframe ``key``'s frame joins that keyframe."""
        self.reserve(key + 1)
        sensors, ends, hit, offsets = beam_segments(np.asarray(offset, float).reshape(1, 3), [scan], self.cfg)
        self._beams[key] = _join(self._beams[key], sensors, ends, hit, offsets)
        self._reach[key] = self._beams[key].reach
        self._scans[key] += 1

    def placed_poses(self) -> np.ndarray:
        """Pose (K, 3) each keyframe was last traced at (NaN where never)."""
        return self._placed.copy()

    def stale(self, poses) -> np.ndarray:
        """Keys among the first ``len(poses)`` that have scans and were never traced, gained scans
        since, or were traced where a beam end lies more than ``tolerance`` from its place at ``poses``."""
        poses = np.asarray(poses, float).reshape(-1, 3)
        k = len(poses)
        self.reserve(k)
        placed, reach, scans, traced = self._placed[:k], self._reach[:k], self._scans[:k], self._traced[:k]
        turn = np.abs(geometry.wrap_angle(poses[:, 2] - placed[:, 2]))
        shift = np.hypot(poses[:, 0] - placed[:, 0], poses[:, 1] - placed[:, 1]) + reach * turn
        moved = ~(shift <= self.tolerance)  # NaN (never traced) counts as moved
        return np.flatnonzero((moved | (scans != traced)) & (scans > 0))

    def update(self, poses, closed: int | None = None) -> GridUpdate:
        """Bring keyframe ``k`` to ``poses[k]`` (K, 3). Keyframes below ``closed`` (default all) are
        final in scans and join the grid; later ones are drawn on top of it by :meth:`grid` only."""
        poses = np.asarray(poses, float).reshape(-1, 3)
        closed = len(poses) if closed is None else min(int(closed), len(poses))
        keys = self.stale(poses)
        placed = sum(self._patches[k] is None for k in keys)
        moved = [k for k in keys if k < self._folded]
        self._retired = [self._patches[k] for k in moved]  # their cells are refolded (flats kept up to date)
        for k in keys:
            self._patches[k] = self._trace(self._beams[k], poses[k])
            self._placed[k], self._traced[k], self._box[k] = poses[k], self._scans[k], self._patches[k].box
        refolded = self._refold(self._retired + [self._patches[k] for k in moved]) if moved else 0
        self._retired = []
        for k in range(self._folded, max(closed, self._folded)):  # new keyframes go on top, in order
            if self._patches[k] is not None:
                self._apply(self._base, self._patches[k], None)
        self._folded = max(closed, self._folded)
        beams = int(sum(len(self._beams[k].ends) for k in keys))
        self.last = GridUpdate(placed, len(keys) - placed, beams, refolded)
        self.stats.update({"keyframes placed": placed, "keyframes re-placed": len(keys) - placed,
                           "beams traced": beams, "cells refolded": refolded})  # fmt: skip
        return self.last

    def grid(self) -> OccupancyGrid:
        """The current grid (a copy): the folded keyframes, then the open ones on top."""
        log_odds = self._base.copy() if self._base.size else np.zeros((1, 1), np.float32)
        for p in self._patches[self._folded :]:
            if p is not None:
                self._apply(log_odds, p, None)
        res = self.cfg.resolution
        return OccupancyGrid(log_odds, res, (self._corner[1] * res, self._corner[0] * res))

    def _refold(self, patches: list[_Patch]) -> int:
        """Reset the cells of ``patches`` and fold every folded keyframe into them again, in order;
        how many cells."""
        mask = np.zeros(self._base.shape, bool)
        for p in patches:
            mask.ravel()[p.flat] = True
        if not mask.any():
            return 0
        self._base[mask] = 0.0
        r, c = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
        lo, hi = np.array([r[0], c[0]]) + self._corner, np.array([r[-1], c[-1]]) + self._corner
        box = self._box[: self._folded]
        for k in np.flatnonzero(np.all(box[:, :2] <= hi, axis=1) & np.all(box[:, 2:] >= lo, axis=1)):
            self._apply(self._base, self._patches[k], mask)
        return int(mask.sum())

    def _apply(self, log_odds: np.ndarray, patch: _Patch, mask: np.ndarray | None) -> None:
        """Add ``patch`` to ``log_odds`` (laid out as the base) and clamp, where ``mask`` (or everywhere)."""
        _fold(log_odds.ravel(), _NO_MASK if mask is None else mask.ravel(), mask is not None,
              patch.flat, patch.val, *self._limits)

    def reserve(self, k: int) -> None:
        """Room for keyframes 0..k-1 (with no scans yet)."""
        extra = max(0, k - len(self._beams))
        if extra:
            self._beams += [None] * extra
            self._patches += [None] * extra
            self._placed = np.vstack([self._placed, np.full((extra, 3), np.nan)])
            self._reach = np.concatenate([self._reach, np.zeros(extra)])
            self._scans = np.concatenate([self._scans, np.zeros(extra, np.int64)])
            self._traced = np.concatenate([self._traced, np.full(extra, -1, np.int64)])
            self._box = np.vstack([self._box, np.tile([1, 1, 0, 0], (extra, 1))])  # empty: first > last

    def _trace(self, beams: _Beams, pose: np.ndarray) -> _Patch:
        """Trace ``beams`` at ``pose`` into a fresh patch: per cell the sum of its scans' updates."""
        res = self.cfg.resolution
        sensors = geometry.transform_points(pose, beams.sensors)
        ends = geometry.transform_points(pose, beams.ends)
        pts = np.vstack([sensors, ends])
        lo = np.floor(pts.min(axis=0) / res).astype(np.int64)[::-1] - 1  # (row, col), one cell of slack
        hi = np.floor(pts.max(axis=0) / res).astype(np.int64)[::-1] + 1
        block = OccupancyGrid(np.zeros(hi - lo + 1, np.float32), res, (lo[1] * res, lo[0] * res))
        trace_beams(block, sensors, ends, beams.hit, beams.offsets, self.cfg, clamp=False)
        self._cover(lo, hi)
        width = self._base.shape[1]
        flat, val = _nonzero(block.log_odds, width, (lo[0] - self._corner[0]) * width + lo[1] - self._corner[1])
        return _Patch(np.concatenate([lo, hi]), flat, val)

    def _cover(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Grow the base, with room to spare, so that lattice cells ``lo``..``hi`` (row, col) lie inside it;
        the patches' flat indices follow."""
        h, w = self._base.shape
        top = self._corner + (h - 1, w - 1)
        if self._base.size and np.all(lo >= self._corner) and np.all(hi <= top):
            return
        pad = int(np.ceil((MARGIN_M + GROW_M) / self.cfg.resolution))
        new_lo, new_hi = (np.minimum(lo - pad, self._corner), np.maximum(hi + pad, top)) if self._base.size \
            else (lo - pad, hi + pad)
        shape = new_hi - new_lo + 1
        if shape[0] * shape[1] > MAX_CELLS:
            raise ValueError(f"the map would need {shape[0]} x {shape[1]} cells, more than {MAX_CELLS:.0e} "
                             "(diverged poses, or set mapping.max_range)")
        check_memory(4.0 * (shape[0] * shape[1] + h * w), "mapping.resolution",
                     f"a {shape[0]} x {shape[1]} map grid at {self.cfg.resolution} m")
        grown = np.zeros(tuple(shape), np.float32)
        r, c = self._corner - new_lo
        grown[r : r + h, c : c + w] = self._base
        for p in {id(p): p for p in self._patches + self._retired if p is not None}.values():  # each once
            p.flat = ((p.flat // w + r) * shape[1] + p.flat % w + c).astype(np.int32)
        self._base, self._corner = grown, new_lo


@njit(cache=True, nogil=True)
def _fold(log_odds, mask, masked, flat, val, l_min, l_max):
    """``log_odds[f] = clamp(log_odds[f] + val)`` at each flat cell ``f`` of a patch (where ``mask``, if ``masked``)."""
    for e in range(len(flat)):
        f = flat[e]
        if not masked or mask[f]:
            log_odds[f] = min(max(log_odds[f] + val[e], l_min), l_max)


@njit(cache=True, nogil=True)
def _nonzero(block, width, first):
    """Flat indices (int32) in a grid ``width`` cells wide, where ``block``'s cell [0, 0] has index
    ``first``, and values of ``block``'s non-zero cells (row-major)."""
    h, w = block.shape
    n = 0
    for r in range(h):
        for c in range(w):
            n += block[r, c] != 0
    flat, val = np.empty(n, np.int32), np.empty(n, np.float32)
    n = 0
    for r in range(h):
        for c in range(w):
            if block[r, c] != 0:
                flat[n], val[n] = first + r * width + c, block[r, c]
                n += 1
    return flat, val


def _join(beams: _Beams | None, sensors, ends, hit, offsets) -> _Beams:
    """``beams`` with one more scan's beams appended."""
    reach = float(np.sqrt(np.max(np.sum(np.vstack([sensors, ends]) ** 2, axis=1))))
    if beams is None:
        return _Beams(sensors, ends, hit, offsets, reach)
    return _Beams(
        np.vstack([beams.sensors, sensors]), np.vstack([beams.ends, ends]), np.concatenate([beams.hit, hit]),
        np.concatenate([beams.offsets, beams.offsets[-1] + offsets[1:]]), max(beams.reach, reach),
    )  # fmt: skip

