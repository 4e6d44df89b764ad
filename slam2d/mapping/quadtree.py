"""Point-region quadtree of occupied cells (Tian 2016, sections 3.1.2, 6.6.1, 7.1.1).

The root is a square of side ``cell * 2**depth`` m with its lower-left corner at
``corner``; a node at level l covers ``2**(depth - l)`` cells a side and has at
most four children, numbered as the thesis does: 1 upper right, 2 upper left,
3 lower left, 4 lower right (stored 0..3). Only regions holding occupied points
get children; the leaves at level ``depth`` are the occupied cells.

Quadrants are half-open, ``[lo, mid)`` and ``[mid, hi)`` in x and in y, so a
point on a quadrant boundary goes where the child regions say it lies (the
thesis sends x == xMid, y > yMid to the lower right child: fixed).

:meth:`QuadTree.find` has the thesis's three outcomes (:class:`Outcome`):
FREE (the descent stops above the last level: no obstacle near), NEAR (it stops
at the last level: an obstacle within the 2 x 2 cells of the parent), OCCUPIED;
OUTSIDE for points beyond the root. Inserting outside the root rebuilds the tree
on the new extent + 200 % (the thesis's root region); the cell size is kept, so
the depth grows and no stored cell is coarsened.

:meth:`QuadTree.to_bytes` writes the tree breadth first, one 4-bit child mask
per internal node (about half a byte a node), or, when that is smaller, 2-bit
child codes with blocks that are all occupied left unexpanded.
"""

from __future__ import annotations

import math
import struct
from enum import IntEnum
from pathlib import Path

import numpy as np
from numba import njit

__all__ = ["Outcome", "QuadTree", "draw_tree", "GROWTH", "encode_trinary", "decode_trinary", "trinary_values"]

GROWTH = 3.0
"""Root side / side of the points' extent: the thesis's extent + 200 %."""

_MAGIC = b"QT01"  # 4-bit child masks
_MAGIC_FULL = b"QT02"  # 2-bit child codes, all-occupied blocks pruned
_HEADER = struct.Struct("<4sB3d2i2i")  # magic, depth, corner x, y, cell, grid offset (row, col), grid shape (H, W)
_BX = np.array([1, 0, 0, 1], np.int64)  # x bit of quadrant 0..3 (UR, UL, LL, LR)
_BY = np.array([1, 1, 0, 0], np.int64)  # y bit


class Outcome(IntEnum):
    """Result of :meth:`QuadTree.find`."""

    OUTSIDE = -1
    FREE = 0
    NEAR = 1
    OCCUPIED = 2


def _digit(bx, by):
    """Quadrant 0..3 (UR, UL, LL, LR) of x bit ``bx`` and y bit ``by`` (ints or arrays)."""
    return np.where(by == 1, 1 - bx, 2 + bx)


class QuadTree:
    """Quadtree of occupied cells; ``children`` (N, 4) int32 node ids (-1 none), node 0 the root.

    ``offset`` (row, col) is the lattice cell of grid cell [0, 0] and ``shape``
    (H, W) the grid's size, so that ``tree[row, col]`` reads like the grid.
    """

    def __init__(self, corner, cell: float, depth: int, ix=(), iy=(), offset=(0, 0), shape=(0, 0)):
        self.corner = (float(corner[0]), float(corner[1]))
        self.cell, self.depth = float(cell), int(depth)
        self.offset, self.shape = (int(offset[0]), int(offset[1])), (int(shape[0]), int(shape[1]))
        self.children, self._free = _build(np.asarray(ix, np.int64), np.asarray(iy, np.int64), self.depth), []

    # construction ---------------------------------------------------------

    @classmethod
    def from_points(cls, xy, max_depth: int = 10) -> QuadTree:
        """The thesis's tree of points (M, 2) m: root = their extent + 200 % (centred), ``2**max_depth``
        cells a side (1 m extent when the points coincide)."""
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        lo, hi = (xy.min(0), xy.max(0)) if len(xy) else (np.zeros(2), np.zeros(2))
        side = GROWTH * (float((hi - lo).max()) or 1.0)
        corner = (lo + hi) / 2 - side / 2
        tree = cls(corner, side / 2**max_depth, max_depth)
        ix, iy = tree._lattice(xy)
        return cls(corner, tree.cell, max_depth, ix, iy, shape=(2**max_depth, 2**max_depth))

    @classmethod
    def from_mask(cls, mask, resolution: float, origin=(0.0, 0.0)) -> QuadTree:
        """Tree of a grid's occupied cells (``mask`` (H, W) bool, row = y), its cells the grid's
        (lossless); root = the grid + 200 %, centred, on the grid's lattice."""
        mask = np.asarray(mask, bool)
        h, w = mask.shape
        depth = max(1, math.ceil(math.log2(GROWTH * max(h, w, 1))))
        oy, ox = (2**depth - h) // 2, (2**depth - w) // 2
        rows, cols = np.nonzero(mask)
        corner = (origin[0] - ox * resolution, origin[1] - oy * resolution)
        return cls(corner, resolution, depth, cols + ox, rows + oy, offset=(oy, ox), shape=(h, w))

    @classmethod
    def from_grid(cls, grid, occupied_thresh: float = 0.65) -> QuadTree:
        """Tree of an :class:`~slam2d.mapping.occupancy.OccupancyGrid`'s occupied cells."""
        return cls.from_mask(grid.occupied_mask(occupied_thresh), grid.resolution, grid.origin)

    # queries ----------------------------------------------------------------

    @property
    def side(self) -> float:
        """Root side, m."""
        return self.cell * 2**self.depth

    @property
    def node_count(self) -> int:
        return len(self.children) - len(self._free)

    def find(self, x: float, y: float) -> Outcome:
        """The thesis's query at one point (m)."""
        return Outcome(int(self.find_many(np.array([[x, y]]))[0]))

    def find_many(self, xy) -> np.ndarray:
        """:class:`Outcome` values (M,) int8 of points (M, 2) m, one compiled descent each."""
        xy = np.ascontiguousarray(np.asarray(xy, np.float64).reshape(-1, 2))
        out = np.empty(len(xy), np.int8)
        _find_points(xy, self.corner[0], self.corner[1], self.cell, self.depth, self.children, out)
        return out

    def occupied(self, xy) -> np.ndarray:
        """Whether points (M, 2) m lie in an occupied cell, bool (M,)."""
        return self.find_many(xy) == Outcome.OCCUPIED

    def __getitem__(self, rc):
        """Occupancy of grid cells ``[row, col]`` (ints or arrays), as ``mask[row, col]``."""
        rows, cols = (np.asarray(v, np.int64) for v in rc)
        ix, iy = np.ravel(cols + self.offset[1]), np.ravel(rows + self.offset[0])
        if np.any((ix < 0) | (iy < 0) | (ix >= 2**self.depth) | (iy >= 2**self.depth)):
            raise IndexError(f"cell outside the quadtree's {2**self.depth} x {2**self.depth} lattice")
        out = np.empty(len(ix), np.int8)
        _find_cells(ix, iy, self.depth, self.children, out)
        hit = (out == Outcome.OCCUPIED).reshape(np.broadcast(rows, cols).shape)
        return bool(hit) if hit.ndim == 0 else hit

    def quadrants(self, x: float, y: float) -> list[int]:
        """Children 1..4 (thesis numbering) on the way from the root to the cell of (x, y) m."""
        ix, iy = (int(v[0]) for v in self._lattice(np.array([[x, y]])))
        return [int(_digit((ix >> s) & 1, (iy >> s) & 1)) + 1 for s in range(self.depth - 1, -1, -1)]

    def cells(self) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
        """Lattice cells (ix, iy) (K,) of the occupied leaves, and the node ids of every level (breadth first)."""
        nodes, ix, iy, levels = np.zeros(1, np.int64), np.zeros(1, np.int64), np.zeros(1, np.int64), []
        for _ in range(self.depth):
            levels.append(nodes)
            parent, quad = np.nonzero(self.children[nodes] >= 0)  # row-major: parents in order, quadrants 0..3
            nodes = self.children[nodes[parent], quad].astype(np.int64)
            ix, iy = 2 * ix[parent] + _BX[quad], 2 * iy[parent] + _BY[quad]
        levels.append(nodes)
        return ix, iy, levels

    def to_mask(self) -> np.ndarray:
        """The occupied cells as a grid mask (H, W) bool of :attr:`shape`."""
        ix, iy, _ = self.cells()
        rows, cols = iy - self.offset[0], ix - self.offset[1]
        keep = (rows >= 0) & (cols >= 0) & (rows < self.shape[0]) & (cols < self.shape[1])
        mask = np.zeros(self.shape, bool)
        mask[rows[keep], cols[keep]] = True
        return mask

    # updates -----------------------------------------------------------------

    def insert(self, x: float, y: float) -> None:
        """Mark the cell of (x, y) m occupied, creating nodes down to the last level; outside the
        root, rebuild on the new extent + 200 % first."""
        if self.find(x, y) == Outcome.OUTSIDE:
            self._grow(x, y)
        ix, iy = (int(v[0]) for v in self._lattice(np.array([[x, y]])))
        node = 0
        for s in range(self.depth - 1, -1, -1):
            q = int(_digit((ix >> s) & 1, (iy >> s) & 1))
            if self.children[node, q] < 0:
                self.children[node, q] = self._alloc()
            node = self.children[node, q]

    def delete(self, x: float, y: float) -> bool:
        """Clear the cell of (x, y) m; a parent left without children goes too, up to the root.
        Returns whether the cell was occupied."""
        if self.find(x, y) != Outcome.OCCUPIED:
            return False
        ix, iy = (int(v[0]) for v in self._lattice(np.array([[x, y]])))
        path = [(0, -1)]
        for s in range(self.depth - 1, -1, -1):
            q = int(_digit((ix >> s) & 1, (iy >> s) & 1))
            path.append((int(self.children[path[-1][0], q]), q))
        for (parent, _), (node, q) in zip(path[-2::-1], path[:0:-1]):
            if (self.children[node] >= 0).any():
                break
            self.children[parent, q] = -1
            self._free.append(node)
        return True

    def _alloc(self) -> int:
        if self._free:
            node = self._free.pop()
        else:
            node = len(self.children)
            self.children = np.vstack([self.children, np.full((max(node, 4), 4), -1, np.int32)])
            self._free.extend(range(len(self.children) - 1, node, -1))
        self.children[node] = -1
        return node

    def _grow(self, x: float, y: float) -> None:
        """Rebuild around the stored cells plus (x, y) m: extent + 200 %, same cell lattice."""
        ix, iy, _ = self.cells()
        nx, ny = self._lattice(np.array([[x, y]], np.float64))
        ix, iy = np.append(ix, nx), np.append(iy, ny)
        lo = np.array([ix.min(), iy.min()])
        span = np.array([ix.max(), iy.max()]) - lo + 1
        depth = max(self.depth, math.ceil(math.log2(GROWTH * span.max())))
        shift = lo - (2**depth - span) // 2  # new lattice cell 0 in the old lattice
        corner = (self.corner[0] + shift[0] * self.cell, self.corner[1] + shift[1] * self.cell)
        offset = (self.offset[0] - shift[1], self.offset[1] - shift[0])
        self.__init__(corner, self.cell, depth, ix[:-1] - shift[0], iy[:-1] - shift[1], offset, self.shape)

    def _lattice(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Lattice cells (ix, iy) of points (M, 2) m (floor; may lie outside the root)."""
        return (np.floor((xy[:, 0] - self.corner[0]) / self.cell).astype(np.int64),
                np.floor((xy[:, 1] - self.corner[1]) / self.cell).astype(np.int64))

    # serialisation -------------------------------------------------------------

    def to_bytes(self) -> bytes:
        """Header (format, depth, corner, cell, grid offset and shape) + the tree breadth first, in the
        smaller of two forms: one 4-bit child mask per internal node (2 a byte), or, where blocks
        of cells are all occupied (a floor plan's dark surroundings), 2-bit codes per child
        (absent / all occupied / mixed, 4 a byte) with the all-occupied ones not expanded."""
        _, _, levels = self.cells()
        header = (self.depth, *self.corner, self.cell, *self.offset, *self.shape)
        masks = np.concatenate([self._child_masks(nodes) for nodes in levels[:-1]])
        codes = self._full_codes(levels)
        if len(codes) < 2 * len(masks):
            return _HEADER.pack(_MAGIC_FULL, *header) + _pack(codes, 2)
        return _HEADER.pack(_MAGIC, *header) + _pack(masks, 4)

    def _child_masks(self, nodes: np.ndarray) -> np.ndarray:
        """4-bit masks (K,) of which children ``nodes`` (K,) have."""
        bits = (self.children[nodes] >= 0).astype(np.uint8) << np.arange(4, dtype=np.uint8)
        return bits.sum(axis=1, dtype=np.uint8)

    def _full_codes(self, levels: list[np.ndarray]) -> np.ndarray:
        """The root's code, then each mixed node's four children's codes, breadth first
        (0 absent, 1 all occupied below, 2 mixed)."""
        full = np.zeros(len(self.children), bool)
        full[levels[-1]] = True
        for nodes in levels[-2::-1]:  # bottom-up: all four children there and full
            kids = self.children[nodes]
            full[nodes] = np.all(kids >= 0, axis=1) & np.all(full[np.maximum(kids, 0)], axis=1)
        codes = [np.array([1 if full[0] else 2], np.uint8)]
        frontier = np.zeros(0 if full[0] else 1, np.int64)
        for _ in range(self.depth):
            kids = self.children[frontier]
            code = np.where(kids < 0, 0, np.where(full[np.maximum(kids, 0)], 1, 2)).astype(np.uint8)
            codes.append(code.ravel())
            frontier = kids[code == 2].astype(np.int64)
        return np.concatenate(codes)

    @classmethod
    def from_bytes(cls, data: bytes) -> QuadTree:
        """The tree :meth:`to_bytes` wrote; ValueError on another format."""
        magic, depth, cx, cy, cell, oy, ox, h, w = _HEADER.unpack_from(data)
        if magic not in (_MAGIC, _MAGIC_FULL):
            raise ValueError("not a slam2d quadtree (bad magic)")
        packed = np.frombuffer(data, np.uint8, offset=_HEADER.size)
        decode = _decode_masks if magic == _MAGIC else _decode_full
        ix, iy = decode(packed, depth)
        return cls((cx, cy), cell, depth, ix, iy, offset=(oy, ox), shape=(h, w))

    def save(self, path) -> Path:
        path = Path(path)
        path.write_bytes(self.to_bytes())
        return path

    @classmethod
    def load(cls, path) -> QuadTree:
        return cls.from_bytes(Path(path).read_bytes())


def _build(ix: np.ndarray, iy: np.ndarray, depth: int) -> np.ndarray:
    """Children (N, 4) int32 of the tree whose leaves are lattice cells (ix, iy) in [0, 2**depth), breadth first."""
    if np.any((ix < 0) | (iy < 0) | (ix >= 2**depth) | (iy >= 2**depth)):
        raise ValueError(f"cells outside the {2**depth} x {2**depth} lattice")
    key = np.zeros(len(ix), np.int64)
    prev, start, links = np.zeros(1, np.int64), 0, []
    for s in range(depth - 1, -1, -1):
        key = key * 4 + _digit((ix >> s) & 1, (iy >> s) & 1)
        level = np.unique(key)
        first = start + len(prev)
        links.append((start + np.searchsorted(prev, level >> 2), level & 3, first + np.arange(len(level))))
        prev, start = level, first
    children = np.full((start + len(prev), 4), -1, np.int32)
    for parent, quad, node in links:
        children[parent, quad] = node
    return children


@njit(cache=True, inline="always")
def _descend(ix, iy, depth, children):
    """Outcome code of lattice cell (ix, iy) inside the root of a tree that is not empty."""
    node = 0
    for level in range(depth):
        s = depth - 1 - level
        bx, by = (ix >> s) & 1, (iy >> s) & 1
        child = children[node, (1 - bx) if by == 1 else (2 + bx)]
        if child < 0:
            return 1 if level == depth - 1 else 0
        node = child
    return 2


@njit(cache=True, nogil=True)
def _find_points(xy, x0, y0, cell, depth, children, out):
    n = 2**depth
    empty = children[0, 0] < 0 and children[0, 1] < 0 and children[0, 2] < 0 and children[0, 3] < 0
    for i in range(len(xy)):
        fx, fy = (xy[i, 0] - x0) / cell, (xy[i, 1] - y0) / cell
        if not (fx >= 0 and fy >= 0 and fx < n and fy < n):  # NaN fails too
            out[i] = -1
        else:
            out[i] = 0 if empty else _descend(int(fx), int(fy), depth, children)


@njit(cache=True, nogil=True)
def _find_cells(ix, iy, depth, children, out):
    empty = children[0, 0] < 0 and children[0, 1] < 0 and children[0, 2] < 0 and children[0, 3] < 0
    for i in range(len(ix)):
        out[i] = 0 if empty else _descend(ix[i], iy[i], depth, children)


# --------------------------------------------------------------------------- free / occupied / unknown

_TRI_MAGIC = b"QT3\x00"
def _pack(values: np.ndarray, bits: int) -> bytes:
    """``values`` (N,) of ``bits`` (2 or 4) bits each, packed low bits first."""
    per = 8 // bits
    v = np.append(values.astype(np.uint8), np.zeros(-len(values) % per, np.uint8))
    return np.bitwise_or.reduce([v[k::per] << (bits * k) for k in range(per)]).astype(np.uint8).tobytes()


def _unpack(packed: np.ndarray, bits: int) -> np.ndarray:
    """The values :func:`_pack` wrote (with its padding)."""
    return np.column_stack([(packed >> s) & (2**bits - 1) for s in range(0, 8, bits)]).ravel()


def _decode_masks(packed: np.ndarray, depth: int) -> tuple[np.ndarray, np.ndarray]:
    """Leaf cells (ix, iy) of a stream of 4-bit child masks."""
    masks = _unpack(packed, 4)
    ix, iy, start = np.zeros(1, np.int64), np.zeros(1, np.int64), 0
    for _ in range(depth):
        level = masks[start : start + len(ix)]
        if len(level) < len(ix):
            raise ValueError("truncated quadtree stream")
        start += len(ix)
        parent, quad = np.nonzero((level[:, None] >> np.arange(4)) & 1)
        ix, iy = 2 * ix[parent] + _BX[quad], 2 * iy[parent] + _BY[quad]
    return ix, iy


def _decode_full(packed: np.ndarray, depth: int) -> tuple[np.ndarray, np.ndarray]:
    """Leaf cells (ix, iy) of a stream of 2-bit child codes (all-occupied blocks expanded)."""
    codes = _unpack(packed, 2)
    if len(codes) == 0:
        raise ValueError("truncated quadtree stream")
    ix, iy, start = np.zeros(1, np.int64), np.zeros(1, np.int64), 1
    full_x, full_y = [ix] if codes[0] == 1 else [], [iy] if codes[0] == 1 else []
    full_level = [0] if codes[0] == 1 else []
    if codes[0] != 2:
        ix, iy = ix[:0], iy[:0]
    for level in range(1, depth + 1):
        code = codes[start : start + 4 * len(ix)]
        if len(code) < 4 * len(ix):
            raise ValueError("truncated quadtree stream")
        start += 4 * len(ix)
        cx = (2 * ix[:, None] + _BX).ravel()
        cy = (2 * iy[:, None] + _BY).ravel()
        full_x.append(cx[code == 1]), full_y.append(cy[code == 1]), full_level.append(level)
        ix, iy = cx[code == 2], cy[code == 2]
    out_x, out_y = [], []
    for bx, by, level in zip(full_x, full_y, full_level):  # a full block at level l: 2^(depth - l) cells a side
        n = 2 ** (depth - level)
        dx, dy = np.meshgrid(np.arange(n), np.arange(n))
        out_x.append((bx[:, None] * n + dx.ravel()).ravel())
        out_y.append((by[:, None] * n + dy.ravel()).ravel())
    if not out_x:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(out_x), np.concatenate(out_y)


_TRI_HEADER = struct.Struct("<4sB2i")  # magic, depth, H, W
MIXED = 3
"""Code of a node whose cells differ (it has four children); 0 free, 1 occupied, 2 unknown are uniform leaves."""


def encode_trinary(values) -> bytes:
    """A region quadtree of a trinary map ``values`` (H, W) uint8 in {0 free, 1 occupied, 2 unknown}, uniform
    children pruned (as OctoMap does in 3D), as a breadth-first stream of 2-bit node codes (4 a byte)."""
    values = np.asarray(values, np.uint8)
    if values.size and values.max() > 2:
        raise ValueError("trinary values must be 0 (free), 1 (occupied) or 2 (unknown)")
    h, w = values.shape
    depth = max(0, math.ceil(math.log2(max(h, w, 1))))
    levels = [np.full((2**depth, 2**depth), 2, np.uint8)]
    levels[0][:h, :w] = values
    for _ in range(depth):  # bottom-up: a 2 x 2 block of one uniform value becomes its parent's value
        a = levels[0]
        q = [a[1::2, 1::2], a[1::2, 0::2], a[0::2, 0::2], a[0::2, 1::2]]  # UR, UL, LL, LR
        same = (q[0] == q[1]) & (q[0] == q[2]) & (q[0] == q[3]) & (q[0] != MIXED)
        levels.insert(0, np.where(same, q[0], MIXED).astype(np.uint8))
    codes, ry, rx = [levels[0].ravel()], np.zeros(1, np.int64), np.zeros(1, np.int64)
    for level in range(depth):  # top-down: the four children of every mixed node, in order
        mixed = levels[level][ry, rx] == MIXED
        ry = (2 * ry[mixed, None] + _BY).ravel()
        rx = (2 * rx[mixed, None] + _BX).ravel()
        codes.append(levels[level + 1][ry, rx])
    c = np.concatenate(codes)
    c = np.append(c, np.zeros(-len(c) % 4, np.uint8))
    packed = c[0::4] | (c[1::4] << 2) | (c[2::4] << 4) | (c[3::4] << 6)
    return _TRI_HEADER.pack(_TRI_MAGIC, depth, h, w) + packed.tobytes()


def decode_trinary(data: bytes) -> np.ndarray:
    """The trinary map (H, W) uint8 that :func:`encode_trinary` wrote."""
    magic, depth, h, w = _TRI_HEADER.unpack_from(data)
    if magic != _TRI_MAGIC:
        raise ValueError("not a slam2d trinary quadtree (bad magic)")
    packed = np.frombuffer(data, np.uint8, offset=_TRI_HEADER.size)
    codes = np.column_stack([(packed >> s) & 3 for s in (0, 2, 4, 6)]).ravel()
    grid, ry, rx, start = codes[:1].reshape(1, 1), np.zeros(1, np.int64), np.zeros(1, np.int64), 1
    for _ in range(depth):  # each level: the parent's values doubled, then the mixed nodes' children read
        mixed = grid[ry, rx] == MIXED
        ry = (2 * ry[mixed, None] + _BY).ravel()
        rx = (2 * rx[mixed, None] + _BX).ravel()
        grid = np.repeat(np.repeat(grid, 2, axis=0), 2, axis=1)
        grid[ry, rx] = codes[start : start + len(ry)]
        start += len(ry)
    return grid[:h, :w].copy()


def trinary_values(grid, occupied_thresh: float = 0.65, free_thresh: float = 0.196) -> np.ndarray:
    """Trinary codes (H, W) uint8 of an occupancy grid: 1 occupied, 0 free, 2 unknown (map_server's classes)."""
    values = np.full(grid.shape, 2, np.uint8)
    values[grid.free_mask(free_thresh)] = 0
    values[grid.occupied_mask(occupied_thresh)] = 1
    return values


def draw_tree(tree: QuadTree, path, levels: int = 6, title: str | None = None) -> Path:
    """PNG of the node squares of the first ``levels`` levels over the occupied cells (the thesis's DrawTree)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure

    ix, iy, ids = tree.cells()
    fig = Figure(figsize=(7, 7), dpi=150)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    ax.scatter(tree.corner[0] + (ix + 0.5) * tree.cell, tree.corner[1] + (iy + 0.5) * tree.cell, s=0.3, c="k",
               marker="s", linewidths=0)
    qx, qy = np.zeros(1, np.int64), np.zeros(1, np.int64)
    for level in range(min(levels, tree.depth) + 1):
        size = tree.side / 2**level
        x, y = tree.corner[0] + qx * size, tree.corner[1] + qy * size
        boxes = np.stack([np.column_stack(c) for c in
                          ((x, y), (x + size, y), (x + size, y + size), (x, y + size), (x, y))], axis=1)
        ax.add_collection(LineCollection(boxes, linewidths=max(0.2, 1.5 - 0.25 * level), colors=f"C{level % 10}"))
        parent, quad = np.nonzero(tree.children[ids[level]] >= 0)
        qx, qy = 2 * qx[parent] + _BX[quad], 2 * qy[parent] + _BY[quad]
    ax.set_xlim(tree.corner[0], tree.corner[0] + tree.side)
    ax.set_ylim(tree.corner[1], tree.corner[1] + tree.side)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title or f"quadtree, levels 0-{min(levels, tree.depth)} of {tree.depth}, {tree.node_count} nodes")
    path = Path(path)
    fig.savefig(path, bbox_inches="tight")
    return path
