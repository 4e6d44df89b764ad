"""Look-alike places of a known map: rigid transforms (turns by a multiple of 90° and shifts) that
take the walls around a place onto the walls around another one.

A laser cannot tell such places apart until it sees a difference, so a filter that settles on one
of them must test its look-alikes before it claims the pose. :func:`look_alikes` correlates the
map's walls with themselves turned by 0, 90, 180 and 270° (FFT over every shift, on a grid coarsened
to ``ANALYSIS_CELL``); each correlation peak is a candidate transform, and its *region* holds the
free cells where, within ``radius`` m, at least ``min_match`` of the walls land on walls in both
directions. Transforms whose region covers at least ``min_area`` m² are the map's look-alikes.

The regions count every wall within the radius, those the laser cannot see from the place included
(furniture in the rooms behind a corridor's walls); :meth:`LookAlikes.seen` judges a pose by what the
laser sees instead: the scans predicted at the pose and at its image under each transform.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.special import logsumexp

from slam2d import geometry
from slam2d.localization.clusters import same_place
from slam2d.localization.maps import KnownMap
from slam2d.localization.sensor import expected_ranges

__all__ = ["LookAlike", "LookAlikes", "add_lookalikes", "look_alikes"]

ANALYSIS_CELL = 0.1  # m, grid of the analysis
TOLERANCE = 1  # cells of ANALYSIS_CELL: a wall landing this close to a wall matches (copies drawn off by a cell)
PEAK_SEPARATION = 1.0  # m between two candidate shifts of one turn
MAX_CANDIDATES = 12  # candidate shifts per turn
BLOCK = 5  # cells of the analysis grid per block over which the match is judged
SEEN_BEAMS = 72  # beams over the full turn of the scans compared by LookAlikes.seen
SEEN_TOLERANCE = 0.15  # m: two predicted ranges this close agree
SEEN_AGREE = 0.9  # share of the beams that must agree for the laser to see the same at two places
_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


@dataclass(frozen=True)
class LookAlike:
    """A transform (x m, y m, angle rad) of the map frame taking places onto look-alike places,
    the free cells (H, W) of the map where it holds, and its matching wall share there."""

    transform: np.ndarray
    region: np.ndarray
    match: float

    def image(self, poses: np.ndarray) -> np.ndarray:
        """The look-alike poses (P, 3) of ``poses`` (P, 3)."""
        c, s = math.cos(self.transform[2]), math.sin(self.transform[2])
        out = np.empty_like(poses)
        out[:, 0] = self.transform[0] + c * poses[:, 0] - s * poses[:, 1]
        out[:, 1] = self.transform[1] + s * poses[:, 0] + c * poses[:, 1]
        out[:, 2] = geometry.wrap_angle(poses[:, 2] + self.transform[2])
        return out


@dataclass(frozen=True)
class LookAlikes:
    """The look-alike transforms of a map and how many places look alike at most."""

    items: list[LookAlike]
    known: KnownMap

    @property
    def places(self) -> int:
        """The most places one place looks like, itself included (1: no look-alikes)."""
        if not self.items:
            return 1
        return 1 + int(np.max(np.sum([a.region for a in self.items], axis=0)))

    def at(self, pose) -> list[LookAlike]:
        """The look-alikes whose region holds ``pose`` (3,)."""
        cell = self.known.world_to_cell(np.asarray(pose, dtype=np.float64)[None, :2])
        if not self.known.in_bounds(cell)[0]:
            return []
        r, c = int(cell[0, 0]), int(cell[0, 1])
        return [a for a in self.items if a.region[r, c]]

    def seen(self, pose, range_max: float) -> list[LookAlike]:
        """The look-alikes under which the laser sees the same at ``pose`` (3,) and at its image: the image
        stands on a free cell and the ranges predicted at both (ray cast, SEEN_BEAMS over the full turn, up
        to ``range_max`` m) agree within SEEN_TOLERANCE m on SEEN_AGREE of the beams. Only what the laser
        sees counts, unlike :meth:`at` (office_c: the rooms behind the corridor's walls, furnished apart,
        keep the regions of its 13.7 m shifts to a quarter of the free cells; the laser sees the same at 82 %)."""
        pose = np.asarray(pose, dtype=np.float64).reshape(1, 3)
        if not self.items:
            return []
        angles = np.linspace(-math.pi, math.pi, SEEN_BEAMS, endpoint=False)
        images = np.concatenate([a.image(pose) for a in self.items])
        cells = self.known.world_to_cell(images[:, :2])
        free = np.zeros(len(images), dtype=bool)
        inside = self.known.in_bounds(cells)
        free[inside] = self.known.free[cells[inside, 0], cells[inside, 1]]
        ranges = expected_ranges(self.known, np.concatenate([pose, images]), np.zeros(3), angles, range_max)
        agree = np.mean(np.abs(ranges[1:] - ranges[0]) < SEEN_TOLERANCE, axis=1)
        return [a for a, ok in zip(self.items, free & (agree >= SEEN_AGREE)) if ok]

    def alike(self, pose, range_max: float) -> list[LookAlike]:
        """The look-alikes of ``pose`` (3,): those whose region holds it (:meth:`at`) and those under which
        the laser sees the same (:meth:`seen`, ``range_max`` m)."""
        held = {id(a) for a in [*self.at(pose), *self.seen(pose, range_max)]}
        return [a for a in self.items if id(a) in held]

    def summary(self) -> str:
        """One line: how many places look alike and by which transforms."""
        if not self.items:
            return f"{self.known.name}: no look-alike places"
        moves = ", ".join(f"({a.transform[0]:.1f} m, {a.transform[1]:.1f} m, {math.degrees(a.transform[2]):.0f}°)"
                          for a in self.items)  # fmt: skip
        return f"{self.known.name}: up to {self.places} look-alike places; transforms {moves}"


def _walls(known: KnownMap, factor: int) -> np.ndarray:
    """Wall faces (occupied cells next to free ones) on a grid ``factor`` times coarser, (h, w) bool."""
    face = known.occupied & ndimage.binary_dilation(known.free)
    h, w = (face.shape[0] // factor) * factor, (face.shape[1] // factor) * factor
    if factor > 1:
        face = face[:h, :w].reshape(h // factor, factor, w // factor, factor).any(axis=(1, 3))
    return face


def _turn(k: int) -> np.ndarray:
    """Rotation by k x 90° as it acts on (row, col) offsets of a grid whose rows run along y."""
    c, s = round(math.cos(k * math.pi / 2)), round(math.sin(k * math.pi / 2))
    return np.array([[c, s], [-s, c]], dtype=np.float64)


def _pull(a: np.ndarray, m: np.ndarray, centre: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """``a`` (n, n), n odd, read through u -> m (u - centre) + centre + shift: out[u] = a[T u] (False
    outside); ``m`` a turn by a multiple of 90° about the centre cell, ``shift`` whole cells."""
    turned = next(b for k in range(4) if np.array_equal(_rot90_matrix(k), m) for b in [np.rot90(a, k)])
    s = np.rint(m.T @ shift).astype(int)  # out[u] = turned[u + s]
    out = np.zeros(a.shape, dtype=bool)
    n = a.shape[0]
    if abs(s[0]) < n and abs(s[1]) < n:
        out[max(0, -s[0]):n - max(0, s[0]), max(0, -s[1]):n - max(0, s[1])] = \
            turned[max(0, s[0]):n - max(0, -s[0]), max(0, s[1]):n - max(0, -s[1])]
    return out


def _rot90_matrix(k: int) -> np.ndarray:
    """The m with np.rot90(a, k)[u] = a[m (u - centre) + centre] for a square array."""
    m = {0: [[1, 0], [0, 1]], 1: [[0, 1], [-1, 0]], 2: [[-1, 0], [0, -1]], 3: [[0, -1], [1, 0]]}[k]
    return np.array(m, dtype=np.float64)


def _peaks(corr: np.ndarray, count: int, separation: int, floor: float) -> list[tuple[int, int]]:
    """Up to ``count`` local maxima (index) of ``corr`` at least ``floor``, ``separation`` cells apart."""
    top = ndimage.maximum_filter(corr, size=2 * separation + 1, mode="wrap")
    cand = np.argwhere((corr == top) & (corr >= floor))
    order = np.argsort(-corr[cand[:, 0], cand[:, 1]])
    return [tuple(int(v) for v in cand[i]) for i in order[:count]]


def look_alikes(known: KnownMap, radius: float = 4.0, min_match: float = 0.8, min_area: float = 4.0) -> LookAlikes:
    """The map's look-alike transforms (cached per map): turns by 90° multiples and shifts under which
    the walls within ``radius`` m of at least ``min_area`` m² of free cells land on walls (and back)
    for ``min_match`` of them."""
    key = (radius, min_match, min_area)
    cached = _CACHE.setdefault(known, {})
    if key not in cached:
        cached[key] = LookAlikes(_find(known, radius, min_match, min_area), known)
    return cached[key]


def _find(known: KnownMap, radius: float, min_match: float, min_area: float) -> list[LookAlike]:
    factor = max(1, round(ANALYSIS_CELL / known.resolution))
    res = known.resolution * factor
    walls = _walls(known, factor)
    n = max(walls.shape) + 2 * math.ceil(radius / res) + 1
    n += 1 - n % 2  # odd: the centre is a cell, turns by 90° are exact
    off = (np.array([n, n]) - walls.shape) // 2
    w = np.zeros((n, n), dtype=bool)
    w[off[0]:off[0] + walls.shape[0], off[1]:off[1] + walls.shape[1]] = walls
    near = ndimage.binary_dilation(w, iterations=TOLERANCE)
    centre = np.array([(n - 1) / 2, (n - 1) / 2])
    free = np.zeros((n, n), dtype=bool)
    free_small = known.free[:walls.shape[0] * factor, :walls.shape[1] * factor]
    free_small = free_small.reshape(walls.shape[0], factor, walls.shape[1], factor).all(axis=(1, 3))
    free[off[0]:off[0] + walls.shape[0], off[1]:off[1] + walls.shape[1]] = free_small
    box = 2 * math.ceil(radius / res) + 1
    visible = _block_box_sum(w, box) >= 2 * radius / res  # at least a wall as long as the radius in view
    spectrum_near = np.fft.rfft2(near, s=(2 * n, 2 * n))
    floor = 4 * radius / res  # cells of matching wall: a room's at least
    found: list[LookAlike] = []
    for k in range(4):
        m = _turn(k)
        turned = _pull(w, m.T, centre, np.zeros(2))  # turned[x] = w[T^-1 x]
        corr = np.fft.irfft2(spectrum_near * np.conj(np.fft.rfft2(turned, s=(2 * n, 2 * n))), s=(2 * n, 2 * n))
        tried = [np.zeros(2)] if k == 0 else []  # the identity
        for peak in _peaks(corr, 4 * MAX_CANDIDATES, round(PEAK_SEPARATION / res), floor):
            shift = np.array([p if p < n else p - 2 * n for p in peak], dtype=np.float64)
            if len(tried) > MAX_CANDIDATES or any(np.abs(shift - t).max() * res < PEAK_SEPARATION for t in tried):
                continue
            tried.append(shift)
            shift = _refine(w, m, centre, shift)
            region, match = _region(w, near, free, visible, m, centre, shift, box, min_match)
            if region.sum() * res**2 < min_area:
                continue
            found.append(_in_map_frame(known, region, match, k, shift, centre, off, factor))
    return found


def _refine(w: np.ndarray, m: np.ndarray, centre: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """The shift within a cell of ``shift`` under which the most walls land exactly on walls."""
    steps = [shift + (dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1)]
    return max(steps, key=lambda s: int(np.count_nonzero(w & _pull(w, m, centre, s))))


def _region(w, near, free, visible, m, centre, shift, box, min_match) -> tuple[np.ndarray, float]:
    """Free cells (padded analysis grid) where the transform holds, and the matching share over them."""
    w_t, near_t, free_t = (_pull(a, m, centre, shift) for a in (w, near, free))  # a[T u]

    def share(hit: np.ndarray, total: np.ndarray) -> np.ndarray:
        t = _block_box_sum(total, box)
        return np.where(t > 0, _block_box_sum(hit, box) / np.maximum(t, 1), 0.0)

    forward = share(w & near_t, w)  # walls near u that land on walls near T u
    backward = share(w_t & near, w_t)  # walls near T u that come from walls near u
    score = np.minimum(forward, backward)
    region = free & free_t & visible & _pull(visible, m, centre, shift) & (score >= min_match)
    return region, float(score[region].mean()) if region.any() else 0.0


def _block_box_sum(a: np.ndarray, box: int) -> np.ndarray:
    """:func:`_box_sum` evaluated on blocks of BLOCK x BLOCK cells (each cell gets its block's value)."""
    n0, n1 = (-(-a.shape[0] // BLOCK)) * BLOCK, (-(-a.shape[1] // BLOCK)) * BLOCK
    padded = np.zeros((n0, n1), dtype=np.int32)
    padded[:a.shape[0], :a.shape[1]] = a
    blocks = padded.reshape(n0 // BLOCK, BLOCK, n1 // BLOCK, BLOCK).sum(axis=(1, 3))
    sums = _box_sum(blocks, 2 * (box // (2 * BLOCK)) + 1)
    return np.repeat(np.repeat(sums, BLOCK, axis=0), BLOCK, axis=1)[:a.shape[0], :a.shape[1]]


def _box_sum(a: np.ndarray, box: int) -> np.ndarray:
    """Sum of ``a`` (h, w) over the box x box window (box odd) centred on every cell (zeros outside), int."""
    h = box // 2
    c = np.zeros((a.shape[0] + box, a.shape[1] + box), dtype=np.int32)
    c[h + 1:h + 1 + a.shape[0], h + 1:h + 1 + a.shape[1]] = a
    c = c.cumsum(axis=0).cumsum(axis=1)
    return c[box:, box:] - c[:-box, box:] - c[box:, :-box] + c[:-box, :-box]


def _in_map_frame(known: KnownMap, region, match, k, shift, centre, off, factor) -> LookAlike:
    """The transform in metres of the map frame, its region on the map's own grid."""
    res = known.resolution * factor
    # analysis cell (r, c) of the padded grid -> map (x, y) of its centre
    c_xy = np.array([known.origin[0] + (centre[1] - off[1] + 0.5) * res,
                     known.origin[1] + (centre[0] - off[0] + 0.5) * res])  # fmt: skip
    angle = k * math.pi / 2
    rot = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    move = np.array([shift[1] * res, shift[0] * res])
    t = c_xy + move - rot @ c_xy
    small = region[off[0]:off[0] + (known.shape[0] // factor), off[1]:off[1] + (known.shape[1] // factor)]
    full = np.zeros(known.shape, dtype=bool)
    up = np.repeat(np.repeat(small, factor, axis=0), factor, axis=1)
    full[:up.shape[0], :up.shape[1]] = up
    return LookAlike(np.array([t[0], t[1], float(geometry.wrap_angle(angle))]), full & known.free, match)


def add_lookalikes(pf, est, raise_held: bool = True) -> int:
    """Give the best hypothesis of filter ``pf`` (its estimate ``est``) weight at its look-alike places:
    with ``raise_held`` a hypothesis already there is raised to it (before the pose was compact, the weights told how many global
    candidates fell near each place more than how the scans fit; once another hypothesis takes the
    lead they tell the evidence, which is kept), elsewhere its particles are copied there; how many
    places."""
    best = est.hypotheses[0]
    inside = pf._labels == pf._best_label
    source, source_w = pf.particles[inside], pf.log_w[inside]
    best_mass = logsumexp(source_w)
    images, raised = [], 0
    for place in pf.lookalikes.alike(best.pose, pf.range_max):
        image = place.image(best.pose[None])[0]
        held = [i for i, h in enumerate(est.hypotheses) if same_place(image, h.pose)]
        if not held:
            images.append(place.image(source))
        elif held[0] > 0 and raise_held:
            members = pf._labels == pf._hypothesis_labels[held[0]]
            pf.log_w[members] += best_mass - logsumexp(pf.log_w[members])
            raised += 1
    if images:
        pf.particles = np.concatenate([pf.particles, *images])
        pf.log_w = np.concatenate([pf.log_w, *[source_w] * len(images)])
    if images or raised:
        pf.log_w -= logsumexp(pf.log_w)
    return len(images) + raised
