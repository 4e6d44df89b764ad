"""Room-segmentation baselines of the ipa_room_segmentation benchmark.

Bormann, Jordan, Li, Hampp, Hägele, "Room segmentation: survey,
implementation, and analysis", ICRA 2016. Each method is
``f(free, resolution, **params) -> labels``:

- ``free`` (H, W) bool, True where the floor plan is free space;
- ``resolution`` m per cell;
- ``labels`` (H, W) int32, 0 on obstacles, 1..n rooms. Every free cell is
  labelled: seeds are grown back over the free space (breadth-first, 8-connected,
  as ipa's wavefront region growing), and a free component no seed reaches
  becomes a room of its own.

Parameters follow ipa_room_segmentation's defaults
(``ros/launch/room_segmentation_action_server_params.yaml``): room area bounds
0.8–47 m² (morphological), 0.35–163 m² (distance); the Voronoi method uses
its own critical-point and merging rules, see :func:`voronoi`.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from slam2d.segmentation.base import register_method

__all__ = ["morphological", "distance", "voronoi", "grow_regions", "BASELINES"]

EIGHT = np.ones((3, 3), bool)
"""8-connectivity structuring element."""


def _check(free, resolution) -> tuple[np.ndarray, float]:
    free = np.asarray(free)
    if free.ndim != 2:
        raise ValueError(f"free must be a 2-D mask, got shape {free.shape}")
    resolution = float(resolution)
    if not resolution > 0:
        raise ValueError(f"resolution must be > 0 m/cell, got {resolution}")
    return free.astype(bool), resolution


def _relabel(labels: np.ndarray) -> np.ndarray:
    """Labels renumbered 1..n in order of first appearance (raster order), 0 kept."""
    ids, first = np.unique(labels.ravel(), return_index=True)
    order = ids[ids > 0][np.argsort(first[ids > 0])]
    lut = np.zeros(int(labels.max()) + 1, np.int32)
    lut[order] = np.arange(1, len(order) + 1, dtype=np.int32)
    return lut[labels]


def grow_regions(seeds, free) -> np.ndarray:
    """Grow seed labels (H, W) int over ``free`` (H, W) bool; (H, W) int32, 0 off free.

    Breadth-first and 8-connected (a flat watershed), so every free cell joins
    the seed nearest to it along free space; free components holding no seed
    become new labels. Labels are renumbered 1..n.
    """
    from skimage.segmentation import watershed

    free = np.asarray(free, bool)
    seeds = np.where(free, np.asarray(seeds), 0).astype(np.int32)
    grown = watershed(np.zeros(free.shape, np.uint8), markers=seeds, mask=free, connectivity=2)
    rest, n = ndimage.label(free & (grown == 0), structure=EIGHT)
    grown = np.where(rest > 0, rest + grown.max(), grown)
    return _relabel(grown.astype(np.int32))


def _components(mask: np.ndarray, resolution: float, area_min: float, area_max: float):
    """8-connected components of ``mask``, which have an area strictly in (area_min, area_max) m², and
    which at most area_min (label 0, the background, is neither)."""
    lab, n = ndimage.label(mask, structure=EIGHT)
    area = np.bincount(lab.ravel(), minlength=n + 1) * resolution**2
    ok = (area > area_min) & (area < area_max)
    small = area <= area_min
    ok[0] = small[0] = False
    return lab, ok, small


@register_method("morphological")
def morphological(free, resolution, room_area_min=0.8, room_area_max=47.0, max_erosion=3.65) -> np.ndarray:
    """Erode the free space one cell at a time (3 x 3); a component whose area
    lies within (room_area_min, room_area_max) m² when it splits off is a room
    seed and is taken out; seeds are grown back (ipa: 73 erosions at 0.05 m,
    hence ``max_erosion`` 3.65 m).

    The components at one erosion lie inside those of the one before, so a component too small to be
    a room never holds one: it is dropped with the seeds, and each erosion labels only the bounding
    box of the cells still in play."""
    free, res = _check(free, resolution)
    depth = ndimage.distance_transform_cdt(free, metric="chessboard")  # erosions a cell survives
    seeds = np.zeros(free.shape, np.int32)
    live = free.copy()  # cells that may still join a seed
    box = (slice(0, free.shape[0]), slice(0, free.shape[1]))
    for k in range(1, int(round(max_erosion / res)) + 1):
        mask = (depth[box] > k) & live[box]
        inner = _bounding_box(mask)
        if inner is None:
            break
        mask = mask[inner]
        box = tuple(slice(outer.start + part.start, outer.start + part.stop) for outer, part in zip(box, inner))
        lab, ok, small = _components(mask, res, room_area_min, room_area_max)
        if ok.any():
            hit = ok[lab]
            seeds[box][hit] = lab[hit] + seeds.max()
        if ok.any() or small.any():
            live[box] &= ~(ok | small)[lab]
    return grow_regions(seeds, free)


def _bounding_box(mask: np.ndarray) -> tuple[slice, slice] | None:
    """The slices of the smallest box holding the True cells of ``mask``; None if there are none."""
    rows, cols = np.flatnonzero(mask.any(1)), np.flatnonzero(mask.any(0))
    if len(rows) == 0:
        return None
    return slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1)


@register_method("distance")
def distance(free, resolution, room_area_min=0.35, room_area_max=163.0) -> np.ndarray:
    """Threshold the distance-to-obstacle map (after one 3 x 3 erosion) at every
    level, one cell apart; keep the level (the lowest among ties) with the most
    components of area within [room_area_min, room_area_max] m²; those
    components are the room seeds, grown back."""
    free, res = _check(free, resolution)
    core = ndimage.binary_erosion(free, structure=EIGHT, border_value=1)
    dist = np.minimum(np.rint(ndimage.distance_transform_edt(core)), 255)  # cells, as an 8-bit image
    best, best_count = np.zeros(free.shape, np.int32), 0
    for t in range(int(dist.max()) - 1, 0, -1):
        lab, ok, _ = _components(dist > t, res, room_area_min * (1 - 1e-9), room_area_max * (1 + 1e-9))
        if ok.sum() >= best_count and ok.any():
            best, best_count = np.where(ok[lab], lab, 0), int(ok.sum())
    return grow_regions(best, free)


@register_method("voronoi")
def voronoi(
    free,
    resolution,
    spur_length=5.0,
    minimum_radius=0.5,
    min_angle_deg=120.0,
    opening_ratio=0.6,
    room_area_min=1.5,
    seed=0,
) -> np.ndarray:
    """Generalised-Voronoi-graph segmentation (Thrun 1998, as in ipa_room_segmentation).

    1. Voronoi graph: medial axis of the free space after a 3 x 3 opening;
       dead-end branches are pruned back to their junction, up to ``spur_length`` m
       (ipa: 100 pruning steps at 0.05 m).
    2. Critical points: graph cells (not end points) whose clearance (distance
       to the nearest obstacle) is the minimum within ``minimum_radius`` m
       along the graph; one per plateau of equal minima.
    3. Critical lines from each critical point to its nearest obstacle and to
       the nearest obstacle on the far side (the two directions at least
       ``min_angle_deg`` apart, the two obstacle cells farther apart than the
       clearance, as ipa's basis points); they cut the free space into regions.
    4. Merging, in the spirit of ipa's merging rules: neighbouring regions are
       merged, widest relative opening first, while the opening between them
       (summed critical-line length, m) is at least ``opening_ratio`` times the
       larger region's width (twice its largest clearance): a cut survives
       only where it is a narrowing such as a door. Then regions under
       ``room_area_min`` m² join the neighbour they share the widest opening with.

    ``minimum_radius`` and ``opening_ratio`` were chosen on the rooms/ benchmark
    (0.5 m and 0.6 of 0.25–1.5 m and 0.4–0.75); ``seed`` fixes the medial
    axis' tie-breaking, so runs repeat exactly.
    """
    free, res = _check(free, resolution)
    clearance, nearest = ndimage.distance_transform_edt(free, return_indices=True)
    graph = _voronoi_graph(free, int(round(spur_length / res)), seed)
    crit = _critical_points(graph, clearance, max(1, int(round(minimum_radius / res))))
    lines = _critical_lines(free, clearance, nearest, crit, np.deg2rad(min_angle_deg))
    cut = free.copy()
    for (r0, c0), (r1, c1), (r2, c2), _ in lines:
        _draw(cut, r0, c0, r1, c1)
        _draw(cut, r0, c0, r2, c2)
    four = ndimage.generate_binary_structure(2, 1)
    parts, _ = ndimage.label(cut, structure=four)  # 8-connected lines block 4-connected regions
    labels = grow_regions(parts, free)
    return _merge_regions(labels, clearance * res, lines, res, opening_ratio, room_area_min)


def _draw(mask, r0, c0, r1, c1):
    """Set the 8-connected digital segment (r0, c0)-(r1, c1) of ``mask`` to False."""
    from skimage.draw import line

    rr, cc = line(int(r0), int(c0), int(r1), int(c1))
    mask[rr, cc] = False


def _pixel_graph(mask: np.ndarray):
    """Cells of ``mask`` as graph nodes: (rows, cols) (n,), 8-neighbour edges src, dst (both directions)."""
    rows, cols = np.nonzero(mask)
    index = np.full((mask.shape[0] + 2, mask.shape[1] + 2), -1, np.int64)
    index[rows + 1, cols + 1] = np.arange(len(rows))
    src, dst = [], []
    for dr, dc in [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]:
        nb = index[rows + 1 + dr, cols + 1 + dc]
        ok = nb >= 0
        src.append(np.nonzero(ok)[0])
        dst.append(nb[ok])
    return rows, cols, np.concatenate(src), np.concatenate(dst)


def _voronoi_graph(free: np.ndarray, spur_cells: int, seed: int = 0):
    """Pruned medial axis of the opened free space: (rows, cols, src, dst) of the kept cells.

    ``seed`` fixes the medial axis' tie-breaking order, so runs repeat exactly.
    """
    from skimage.morphology import medial_axis

    opened = ndimage.binary_opening(free, structure=EIGHT)
    rows, cols, src, dst = _pixel_graph(medial_axis(opened, rng=seed))
    n = len(rows)
    junction = np.bincount(src, minlength=n) > 2
    alive = np.ones(n, bool)
    for _ in range(spur_cells):
        live = alive[src] & alive[dst]
        leaf = alive & ~junction & (np.bincount(src[live], minlength=n) <= 1)
        if not leaf.any():
            break
        alive &= ~leaf
    keep = alive[src] & alive[dst]
    new = np.cumsum(alive) - 1
    return rows[alive], cols[alive], new[src[keep]], new[dst[keep]]


def _critical_points(graph, clearance: np.ndarray, hops: int) -> np.ndarray:
    """(M, 2) (row, col) graph cells of degree >= 2 whose clearance is minimal within ``hops`` along the graph.

    A plateau of equal minima gives one point, its member nearest the plateau's mean.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rows, cols, src, dst = graph
    if len(rows) == 0:
        return np.zeros((0, 2), np.int64)
    d = clearance[rows, cols]
    low = d.copy()
    for _ in range(hops):
        nxt = low.copy()
        np.minimum.at(nxt, src, low[dst])
        low = nxt
    cand = (d <= low + 1e-9) & (np.bincount(src, minlength=len(rows)) >= 2)
    both = cand[src] & cand[dst]
    n = len(rows)
    adj = coo_matrix((np.ones(both.sum()), (src[both], dst[both])), shape=(n, n))
    _, comp = connected_components(adj, directed=False)
    idx = np.nonzero(cand)[0]
    comp = comp[idx]
    cnt = np.bincount(comp)
    mr = np.bincount(comp, rows[idx]) / np.maximum(cnt, 1)
    mc = np.bincount(comp, cols[idx]) / np.maximum(cnt, 1)
    off = (rows[idx] - mr[comp]) ** 2 + (cols[idx] - mc[comp]) ** 2
    order = np.lexsort((off, comp))
    first = order[np.r_[True, comp[order][1:] != comp[order][:-1]]]
    return np.column_stack([rows[idx[first]], cols[idx[first]]])


def _critical_lines(free, clearance, nearest, points, min_angle):
    """For each critical point c: (c, p1, p2, length m/res) with p1 its nearest obstacle cell and
    p2 the nearest obstacle cell at least clearance(c) from p1 whose direction from c
    makes an angle >= ``min_angle`` with that of p1. Points without such a p2 are dropped."""
    h, w = free.shape
    out = []
    for r, c in points:
        d = clearance[r, c]
        p1 = nearest[:, r, c]
        rad = int(np.ceil(2.5 * d)) + 2
        r0, c0 = max(r - rad, 0), max(c - rad, 0)
        orr, occ = np.nonzero(~free[r0 : r + rad + 1, c0 : c + rad + 1])
        orr, occ = orr + r0, occ + c0
        v1 = p1 - (r, c)
        vr, vc = orr - r, occ - c
        dist = np.hypot(vr, vc)
        cos = (vr * v1[0] + vc * v1[1]) / np.maximum(dist * np.hypot(*v1), 1e-9)
        ok = (np.hypot(orr - p1[0], occ - p1[1]) > d) & (cos <= np.cos(min_angle))
        if not ok.any():
            continue
        j = np.argmin(np.where(ok, dist, np.inf))
        out.append(((r, c), tuple(p1), (orr[j], occ[j]), np.hypot(*v1) + dist[j]))
    return out


def _touching(labels: np.ndarray) -> dict:
    """{(a, b): number of 4-adjacent cell pairs} for regions a < b that touch."""
    pairs = []
    for a, b in ((labels[:, :-1], labels[:, 1:]), (labels[:-1, :], labels[1:, :])):
        m = (a != b) & (a > 0) & (b > 0)
        pairs.append(np.column_stack([np.minimum(a[m], b[m]), np.maximum(a[m], b[m])]))
    pairs = np.concatenate(pairs)
    if len(pairs) == 0:
        return {}
    uniq, cnt = np.unique(pairs, axis=0, return_counts=True)
    return {(int(a), int(b)): int(k) for (a, b), k in zip(uniq, cnt)}


def _line_openings(labels: np.ndarray, lines, res: float) -> dict:
    """{(a, b): total length m of the critical lines separating regions a < b}."""
    h, w = labels.shape
    out: dict = {}
    for c, p1, p2, length in lines:
        u = np.subtract(p2, p1, dtype=float)
        n = np.array([-u[1], u[0]]) / max(np.hypot(*u), 1e-9)
        sides = []
        for sign in (1, -1):
            lab = 0
            for k in (2, 3, 4, 5):
                r, cc = np.rint(np.add(c, sign * k * n)).astype(int)
                if 0 <= r < h and 0 <= cc < w and labels[r, cc] > 0:
                    lab = int(labels[r, cc])
                    break
            sides.append(lab)
        a, b = min(sides), max(sides)
        if a > 0 and a != b:
            out[(a, b)] = out.get((a, b), 0.0) + length * res
    return out


def _merge_regions(labels, clearance_m, lines, res, opening_ratio, room_area_min) -> np.ndarray:
    """Merge regions across openings that are no narrowing, then merge small regions (see :func:`voronoi`)."""
    import heapq

    n = int(labels.max())
    area = np.bincount(labels.ravel(), minlength=n + 1) * res**2
    width = np.zeros(n + 1)
    np.maximum.at(width, labels.ravel(), 2.0 * clearance_m.ravel())
    opening = {k: v * res for k, v in _touching(labels).items()}
    opening.update(_line_openings(labels, lines, res))
    nbr: dict = {i: {} for i in range(1, n + 1)}
    for (a, b), v in opening.items():
        nbr[a][b] = nbr[b][a] = v
    parent = np.arange(n + 1)
    version = np.zeros(n + 1, np.int64)

    def merge(a, b):  # b into a
        parent[b] = a
        area[a] += area[b]
        width[a] = max(width[a], width[b])
        for m, v in nbr.pop(b).items():
            del nbr[m][b]
            if m != a:
                nbr[a][m] = nbr[m][a] = nbr[a].get(m, 0.0) + v
        version[a] += 1

    def ratio(a, b):
        return nbr[a][b] / max(max(width[a], width[b]), 1e-9)

    heap = [(-ratio(a, b), a, b, 0, 0) for a in nbr for b in nbr[a] if a < b]
    heapq.heapify(heap)
    while heap:
        r, a, b, va, vb = heapq.heappop(heap)
        if parent[a] != a or parent[b] != b or version[a] != va or version[b] != vb:
            continue
        if -r < opening_ratio:
            break
        merge(a, b)
        for m in nbr[a]:
            heapq.heappush(heap, (-ratio(a, m), a, m, version[a], version[m]))
    for a in np.argsort(area):
        if a > 0 and parent[a] == a and area[a] < room_area_min and nbr[a]:
            b = max(nbr[a], key=nbr[a].get)
            merge(b, a)
    while True:  # resolve chains
        nxt = parent[parent]
        if np.array_equal(nxt, parent):
            break
        parent = nxt
    return _relabel(parent[labels].astype(np.int32))


BASELINES = {fn.__name__: fn for fn in (morphological, distance, voronoi)}
"""Method name -> function of the baselines (all registered with the other methods in
:data:`slam2d.segmentation.base.SEGMENTATION_METHODS`)."""
