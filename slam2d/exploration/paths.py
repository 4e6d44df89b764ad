"""Geodesic distances from the robot, settled only as far as a decision asks (:class:`Paths`).

Which cells the robot can reach is one breadth-first pass over its 4-connected component (a diagonal step
never cuts a corner, so the 8-connected paths reach the same cells). The distances are Dijkstra's with a
bucket queue one cell wide (Dial): every step is at least one cell long, so once the buckets below k are
done every cell nearer than k cells is final. The search is resumed, not restarted, when more is asked:
the nearest of some cells needs the buckets up to the nearest one's only; all of them, up to the farthest;
the whole grid only for :meth:`Paths.dense`. The values are those of a full search to the last bit.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["Paths", "Scratch", "as_paths", "path_lengths"]

RUN_ALL, RUN_UNTIL_ALL, RUN_UNTIL_ANY = 0, 1, 2  # how far :func:`_dial` runs


@njit(cache=True)
def _reach(flat, w, start, seen, dist, queue):
    """Mark ``seen`` the cells 4-connected to ``start`` over ``flat`` (bool, a grid of rows ``w`` cells long whose
    border cells are all False, so that no step leaves it), breadth first (``queue``: room for every cell), and set
    their ``dist`` inf. Returns how many."""
    seen[start], dist[start] = True, np.inf
    queue[0], head, tail = start, 0, 1
    while head < tail:
        v = queue[head]
        head += 1
        for u in (v - w, v + w, v - 1, v + 1):
            if flat[u] and not seen[u]:
                seen[u], dist[u] = True, np.inf
                queue[tail] = u
                tail += 1
    return tail


@njit(cache=True)
def _dial(w, dist, queue, sizes, k, target, left, mode):
    """Process buckets from ``k`` (cells nearer than k are final) of the search held in ``dist`` cells (rows of ``w``
    cells; -1 in cells it never enters: not passable, or not 4-connected to the start, and the grid's frame), ``queue`` (3, cap) of three buckets in turn with their
    ``sizes`` (a cell is queued in the bucket of its tentative length). ``target`` (bool) marks cells asked for,
    ``left`` of them not yet final. ``mode``: to the end (RUN_ALL), until no target is left (RUN_UNTIL_ALL) or one
    is final (RUN_UNTIL_ANY); a bucket is always finished. Returns (k, left)."""
    diag = 1.4142135623730951
    start_left = left
    while sizes[0] + sizes[1] + sizes[2] > 0:
        if (mode == RUN_UNTIL_ALL and left == 0) or (mode == RUN_UNTIL_ANY and left < start_left):
            break
        b, b1, b2 = k % 3, (k + 1) % 3, (k + 2) % 3
        n1, n2 = sizes[b1], sizes[b2]  # a step of 1 or sqrt(2) from bucket k lands in bucket k + 1 or k + 2
        for i in range(sizes[b]):
            v = queue[b, i]
            d = dist[v]
            if int(d) != k:  # queued before a shorter way put it in a lower bucket: done already
                continue
            if target[v]:
                left -= 1
            # blocked cells hold -1: no step enters them; corners are not cut
            up, dn, lf, rt = dist[v - w] >= 0.0, dist[v + w] >= 0.0, dist[v - 1] >= 0.0, dist[v + 1] >= 0.0
            d1, d2 = d + 1.0, d + diag
            if dist[v - w] > d1:
                old, dist[v - w] = dist[v - w], d1
                if int(d1) == k + 1:
                    if old == np.inf or int(old) != k + 1:  # else queued in that bucket already
                        queue[b1, n1] = v - w
                        n1 += 1
                elif old == np.inf or int(old) != k + 2:
                    queue[b2, n2] = v - w
                    n2 += 1
            if dist[v + w] > d1:
                old, dist[v + w] = dist[v + w], d1
                if int(d1) == k + 1:
                    if old == np.inf or int(old) != k + 1:  # else queued in that bucket already
                        queue[b1, n1] = v + w
                        n1 += 1
                elif old == np.inf or int(old) != k + 2:
                    queue[b2, n2] = v + w
                    n2 += 1
            if dist[v - 1] > d1:
                old, dist[v - 1] = dist[v - 1], d1
                if int(d1) == k + 1:
                    if old == np.inf or int(old) != k + 1:  # else queued in that bucket already
                        queue[b1, n1] = v - 1
                        n1 += 1
                elif old == np.inf or int(old) != k + 2:
                    queue[b2, n2] = v - 1
                    n2 += 1
            if dist[v + 1] > d1:
                old, dist[v + 1] = dist[v + 1], d1
                if int(d1) == k + 1:
                    if old == np.inf or int(old) != k + 1:  # else queued in that bucket already
                        queue[b1, n1] = v + 1
                        n1 += 1
                elif old == np.inf or int(old) != k + 2:
                    queue[b2, n2] = v + 1
                    n2 += 1
            if up and lf and dist[v - w - 1] > d2:
                old, dist[v - w - 1] = dist[v - w - 1], d2
                if int(d2) == k + 1:
                    if old == np.inf or int(old) != k + 1:  # else queued in that bucket already
                        queue[b1, n1] = v - w - 1
                        n1 += 1
                elif old == np.inf or int(old) != k + 2:
                    queue[b2, n2] = v - w - 1
                    n2 += 1
            if up and rt and dist[v - w + 1] > d2:
                old, dist[v - w + 1] = dist[v - w + 1], d2
                if int(d2) == k + 1:
                    if old == np.inf or int(old) != k + 1:  # else queued in that bucket already
                        queue[b1, n1] = v - w + 1
                        n1 += 1
                elif old == np.inf or int(old) != k + 2:
                    queue[b2, n2] = v - w + 1
                    n2 += 1
            if dn and lf and dist[v + w - 1] > d2:
                old, dist[v + w - 1] = dist[v + w - 1], d2
                if int(d2) == k + 1:
                    if old == np.inf or int(old) != k + 1:  # else queued in that bucket already
                        queue[b1, n1] = v + w - 1
                        n1 += 1
                elif old == np.inf or int(old) != k + 2:
                    queue[b2, n2] = v + w - 1
                    n2 += 1
            if dn and rt and dist[v + w + 1] > d2:
                old, dist[v + w + 1] = dist[v + w + 1], d2
                if int(d2) == k + 1:
                    if old == np.inf or int(old) != k + 1:  # else queued in that bucket already
                        queue[b1, n1] = v + w + 1
                        n1 += 1
                elif old == np.inf or int(old) != k + 2:
                    queue[b2, n2] = v + w + 1
                    n2 += 1
        sizes[b], sizes[b1], sizes[b2] = 0, n1, n2
        k += 1
    return k, left


class Scratch:
    """The buffers of a :class:`Paths` search, reused by the next search of a grid of the same shape made with them
    (page faults on fresh arrays cost as much as the search): a Paths is not to be asked again once the next one is
    made with the same Scratch."""

    def __init__(self):
        self.size = -1

    def take(self, size: int) -> tuple:
        """(padded passable, dist, seen, target, queue) of ``size`` cells: all False, -1, False, False, any."""
        if size != self.size:
            self.size = size
            self.arrays = (np.zeros(size, dtype=np.bool_), np.empty(size), np.empty(size, dtype=np.bool_),
                           np.zeros(size, dtype=np.bool_), np.empty(3 * size + 3, dtype=np.int32))  # fmt: skip
        _, dist, seen, target, _ = self.arrays
        dist.fill(-1.0)
        seen.fill(False)
        target.fill(False)
        return self.arrays


class Paths:
    """Shortest 8-connected path lengths (m) from ``start_cell`` over ``passable`` (H, W) bool, no corner
    cutting, computed as far as asked. A start outside ``passable`` is moved to the nearest passable cell
    within ``snap_cells`` (the rest of that distance added). ``allowed`` (H, W) bool: the cells a length is
    reported for (others inf, as unreachable), e.g. those with room for a goal; paths still cross the rest.

    ``reach`` (H, W) bool: the allowed cells the robot can reach. ``lengths(cells)``: their lengths, settled
    to the farthest (or with ``nearest``, to the nearest one: the others then a lower bound). ``dense()``: the
    whole (H, W) array (also what ``np.asarray`` and indexing give)."""

    def __init__(self, passable, start_cell, resolution: float, snap_cells: int = 10, allowed=None,
                 scratch: Scratch | None = None):
        passable = np.asarray(passable, dtype=np.bool_)
        self.shape = passable.shape
        self.resolution = float(resolution)
        h, w = self.shape
        self._w = w + 2  # the search runs on the grid framed by a border of cells it never enters
        padded, self._dist, seen, self._target, queue = (scratch or Scratch()).take((h + 2) * self._w)
        padded.reshape(h + 2, w + 2)[1:-1, 1:-1] = passable  # the frame stays False
        start = _snap(passable, np.asarray(start_cell, dtype=np.int64), snap_cells)
        self._extra, self._k, self._left = 0.0, 0, 0
        self._sizes = np.zeros(3, dtype=np.int64)
        if start is not None:
            cell, self._extra = start
            s = (int(cell[0]) + 1) * self._w + int(cell[1]) + 1
            n = _reach(padded, self._w, s, seen, self._dist, queue)
            self._dist[s] = 0.0
            self._queue = queue[: 3 * (n + 1)].reshape(3, n + 1)
            self._queue[0, 0], self._sizes[0] = s, 1
        seen = seen.reshape(h + 2, w + 2)[1:-1, 1:-1]
        self.reach = seen.copy() if allowed is None else seen & np.asarray(allowed, dtype=bool)

    def _run(self, mode: int) -> None:
        if self._sizes.sum():
            self._k, self._left = _dial(self._w, self._dist, self._queue, self._sizes, self._k,
                                        self._target, self._left, mode)  # fmt: skip

    def _metres(self, cells_dist) -> np.ndarray:
        out = np.asarray(cells_dist, dtype=np.float64) + self._extra  # as a full search: (cells + snap) · resolution
        out *= self.resolution
        return out

    def lengths(self, cells, nearest: bool = False) -> np.ndarray:
        """Path lengths (K,) m to ``cells`` (K, 2) (row, col); inf where out of ``reach``. With ``nearest``, the
        search stops once the nearest of them is final: every cell no farther than it is exact, the others
        hold a lower bound (larger than the nearest's length)."""
        cells = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
        h, w = self.shape
        ok = (cells[:, 0] >= 0) & (cells[:, 0] < h) & (cells[:, 1] >= 0) & (cells[:, 1] < w)
        ok[ok] = self.reach[cells[ok, 0], cells[ok, 1]]
        flat = (cells[ok, 0] + 1) * self._w + cells[ok, 1] + 1
        out = np.full(len(cells), np.inf)
        pending = flat[self._dist[flat] >= self._k]  # not final yet
        if len(pending):
            self._target[pending] = True
            self._left = int(np.count_nonzero(self._target[pending]))  # each cell once
            self._run(RUN_UNTIL_ANY if nearest else RUN_UNTIL_ALL)
            self._target[pending] = False
        d = self._dist[flat]
        out[ok] = self._metres(np.where(d < self._k, d, self._k))  # beyond the buckets done: the lower bound
        return out

    def dense(self) -> np.ndarray:
        """The path length (H, W) m to every cell, inf out of ``reach``."""
        self._left = 0
        self._run(RUN_ALL)
        h, w = self.shape
        out = self._metres(self._dist.reshape(h + 2, w + 2)[1:-1, 1:-1])
        out[~self.reach] = np.inf
        return out

    def __array__(self, dtype=None, copy=None):
        out = self.dense()
        return out if dtype is None else out.astype(dtype)

    def __getitem__(self, index):
        return self.dense()[index]


class _Dense:
    """:class:`Paths`' interface over an array of path lengths (H, W) m computed elsewhere."""

    def __init__(self, distance):
        self._d = np.asarray(distance, dtype=np.float64)
        self.shape, self.reach = self._d.shape, np.isfinite(self._d)

    def lengths(self, cells, nearest: bool = False) -> np.ndarray:
        cells = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
        return self._d[cells[:, 0], cells[:, 1]]

    def dense(self) -> np.ndarray:
        return self._d

    def __array__(self, dtype=None, copy=None):
        return self._d if dtype is None else self._d.astype(dtype)

    def __getitem__(self, index):
        return self._d[index]


def as_paths(distance):
    """``distance`` as :class:`Paths` (a Paths is returned as it is; an (H, W) array of lengths is wrapped)."""
    return distance if isinstance(distance, (Paths, _Dense)) else _Dense(distance)


def path_lengths(view, distance, points, reach: float) -> tuple[np.ndarray, np.ndarray]:
    """Path length (P,) m to each point and where to drive (P, 2) m: the point's cell, else the nearest
    reachable cell within ``reach`` m (the gap added); inf if none. ``distance``: a Paths or an (H, W) array m."""
    distance = as_paths(distance)
    cells = view.to_cell(points)
    inside = view.inside(cells)
    target = np.array(points, dtype=np.float64).reshape(-1, 2)
    k = int(np.ceil(reach / view.resolution))
    h, w = view.shape
    ends, gaps, which = [], [], []  # the cell driven to, the gap to it (m), for which point
    for i in np.nonzero(inside)[0]:
        r, c = cells[i]
        if distance.reach[r, c]:
            ends.append((r, c)), gaps.append(None), which.append(i)
            continue
        r0, r1, c0, c1 = max(r - k, 0), min(r + k + 1, h), max(c - k, 0), min(c + k + 1, w)
        rr, cc = np.nonzero(distance.reach[r0:r1, c0:c1])
        if len(rr):
            gap = np.hypot(rr + r0 - r, cc + c0 - c) * view.resolution
            j = int(np.argmin(gap))
            if gap[j] <= reach:
                ends.append((rr[j] + r0, cc[j] + c0)), gaps.append(gap[j]), which.append(i)
                target[i] = view.to_world(np.array(ends[-1]))
    out = np.full(len(points), np.inf)
    if ends:
        lengths = distance.lengths(np.array(ends))
        out[which] = [d if g is None else d + g for d, g in zip(lengths, gaps)]
    return out, target


def _snap(passable, cell, within: int):
    """The passable cell nearest ``cell`` within ``within`` cells and its distance (cells); None if none."""
    h, w = passable.shape
    if 0 <= cell[0] < h and 0 <= cell[1] < w and passable[cell[0], cell[1]]:  # the cell itself, at 0
        return np.array([cell[0], cell[1]]), 0.0
    r0, r1 = max(cell[0] - within, 0), min(cell[0] + within + 1, h)
    c0, c1 = max(cell[1] - within, 0), min(cell[1] + within + 1, w)
    rows, cols = np.nonzero(passable[r0:r1, c0:c1])
    if len(rows) == 0:
        return None
    d = np.hypot(rows + r0 - cell[0], cols + c0 - cell[1])
    k = int(np.argmin(d))
    return np.array([rows[k] + r0, cols[k] + c0]), float(d[k])
