"""Geometric map: wall polylines from an occupancy grid (Tian 2016, section 3.2).

The thesis blurs the occupied cells, runs Canny and the Hough transform and
merges the segments (its merge left as future work). Two segment sources
(:data:`EXTRACTORS`), measured on the simulator office (benchmarks/mapping_layers.py):

- ``contour`` (default): marching-squares contours of the occupied cells (on
  the cell edges), split at Douglas-Peucker vertices, each piece refitted by
  total least squares (:func:`contour_segments`);
- ``hough``: Canny + probabilistic Hough (:func:`hough_segments`, the one grid
  Hough extractor; the line frontend's ``lines_from_grid`` calls it).

Then, the merge: pieces shorter than ``min_length`` dropped; collinear segments
that overlap or touch joined (:func:`merge_collinear`); ends of non-parallel
segments whose lines meet close to both snapped to the corner and linked into
polylines (:func:`link_corners`); vertices snapped to a half-cell lattice
(``line_map.QUANTUM``) and the polylines ordered in a nearest-end tour. A
``line_map.LineMap`` stores the polylines (compact binary, JSON, SVG over the grid,
PNG); its ``segments`` are the thesis's endpoint table (eq. 12). ``line_scores``
measures a line map against true walls.
"""

from __future__ import annotations

import numpy as np

from slam2d.mapping.line_map import QUANTUM, LineMap, from_lattice, to_lattice

__all__ = ["hough_segments", "contour_segments", "extract_line_map", "merge_collinear", "link_corners",
           "segment_frame", "point_segment_distance", "nearest_segment", "EXTRACTORS"]


def hough_segments(occupied, resolution: float, origin=(0.0, 0.0), *, canny_sigma: float = 1.0,
                   threshold: int = 10, min_length: float = 0.5, max_gap: float = 0.15,
                   use_canny: bool = True, seed: int = 0) -> np.ndarray:
    """Segments (K, 2, 2) m of a grid's occupied cells by Canny and the probabilistic Hough transform.

    ``occupied`` (H, W) bool, row = y, cell [0, 0] with its lower-left corner at
    ``origin`` m; ``min_length`` and ``max_gap`` m pass to Hough, ``threshold``
    is its vote count; ``use_canny=False`` runs Hough on the occupied cells.
    Ends are cell centres.
    """
    from skimage.feature import canny
    from skimage.transform import probabilistic_hough_line

    occupied = np.asarray(occupied, bool)
    edges = canny(occupied.astype(float), sigma=canny_sigma) if use_canny else occupied
    raw = probabilistic_hough_line(edges, threshold=threshold, line_length=max(2, int(round(min_length / resolution))),
                                   line_gap=max(1, int(round(max_gap / resolution))), rng=seed)
    if not raw:
        return np.zeros((0, 2, 2))
    return (np.asarray(raw, float) + 0.5) * resolution + np.asarray(origin, float)  # (K, 2, 2) as (x, y)


def segment_frame(seg: np.ndarray):
    """Unit directions (K, 2), lengths (K,) and midpoints (K, 2) of segments (K, 2, 2)."""
    d = seg[:, 1] - seg[:, 0]
    length = np.linalg.norm(d, axis=1)
    return d / np.maximum(length, 1e-12)[:, None], length, seg.mean(axis=1)


def point_segment_distance(points: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """Distances (P, K) m from points (P, 2) to segments (K, 2, 2)."""
    a, d = seg[:, 0], seg[:, 1] - seg[:, 0]
    t = np.clip(((points[:, None, :] - a) * d).sum(-1) / np.maximum((d * d).sum(-1), 1e-24), 0.0, 1.0)
    return np.linalg.norm(points[:, None, :] - (a + t[..., None] * d), axis=-1)


def nearest_segment(points: np.ndarray, seg: np.ndarray, chunk: int = 4096) -> tuple[np.ndarray, np.ndarray]:
    """Index (P,) and distance (P,) m of the segment nearest each point, in chunks of points."""
    idx, dist = np.zeros(len(points), np.int64), np.full(len(points), np.inf)
    if len(seg) == 0:
        return idx, dist
    for lo in range(0, len(points), chunk):
        d = point_segment_distance(points[lo : lo + chunk], seg)
        idx[lo : lo + chunk] = d.argmin(axis=1)
        dist[lo : lo + chunk] = d[np.arange(len(d)), idx[lo : lo + chunk]]
    return idx, dist


def _fit_groups(points: np.ndarray, group: np.ndarray, k: int, extent=None) -> np.ndarray:
    """Total-least-squares segments (k, 2, 2) of points (P, 2) by group (P,) in [0, k), spanning
    the projections of ``extent`` (points, groups) (default: the same); NaN for groups of < 2 points."""
    w = np.ones(len(points))
    n = np.bincount(group, w, k)
    safe = np.maximum(n, 1e-12)
    c = np.column_stack([np.bincount(group, w * points[:, i], k) for i in range(2)]) / safe[:, None]
    p = points - c[group]
    sxx, syy, sxy = (np.bincount(group, w * a * b, k) for a, b in ((p[:, 0], p[:, 0]), (p[:, 1], p[:, 1]),
                                                                  (p[:, 0], p[:, 1])))
    phi = 0.5 * np.arctan2(2 * sxy, sxx - syy)
    u = np.column_stack([np.cos(phi), np.sin(phi)])
    n_fit = np.bincount(group, minlength=k)
    if extent is not None:
        points, group = extent
        p = points - c[group]
    t = (p * u[group]).sum(1)
    lo, hi = np.full(k, np.inf), np.full(k, -np.inf)
    np.minimum.at(lo, group, t)
    np.maximum.at(hi, group, t)
    seg = np.stack([c + lo[:, None] * u, c + hi[:, None] * u], axis=1)
    seg[n_fit < 2] = np.nan
    return seg


def merge_collinear(seg, angle_tol_deg: float = 3.0, offset_tol: float = 0.05, gap: float = 0.1) -> np.ndarray:
    """Segments (K', 2, 2) m after joining collinear ones that overlap or touch.

    Two segments join when their directions differ by at most ``angle_tol_deg``,
    each one's ends lie within ``offset_tol`` m of the other's line, and they
    overlap or their nearest ends are at most ``gap`` m apart; joined groups
    (transitively) become one segment along their length-weighted direction
    spanning every end. Repeated until nothing joins.
    """
    seg = np.asarray(seg, float).reshape(-1, 2, 2)
    while len(seg) > 1:
        group, k = _collinear_groups(seg, np.deg2rad(angle_tol_deg), offset_tol, gap)
        if k == len(seg):
            return seg
        seg = _join(seg, group, k)
    return seg


def _collinear_groups(seg, angle_tol, offset_tol, gap) -> tuple[np.ndarray, int]:
    """Connected components (K,) and their number of the 'joins' relation of :func:`merge_collinear`."""
    from scipy.sparse import coo_array
    from scipy.sparse.csgraph import connected_components

    i, j = _close_pairs(seg, gap)
    u, _, _ = segment_frame(seg)
    parallel = np.abs(np.abs((u[i] * u[j]).sum(1))) >= np.cos(angle_tol)
    normal = np.column_stack([-u[:, 1], u[:, 0]])
    off_j = np.abs(((seg[j] - seg[i][:, :1]) * normal[i][:, None]).sum(-1)).max(1)
    off_i = np.abs(((seg[i] - seg[j][:, :1]) * normal[j][:, None]).sum(-1)).max(1)
    keep = parallel & (off_i <= offset_tol) & (off_j <= offset_tol)
    adj = coo_array((np.ones(keep.sum()), (i[keep], j[keep])), shape=(len(seg), len(seg)))
    k, group = connected_components(adj, directed=False)
    return group, k


def _close_pairs(seg: np.ndarray, gap: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i < j) of segments that come within ``gap`` m of each other (points sampled every gap / 2)."""
    from scipy.spatial import cKDTree

    _, length, _ = segment_frame(seg)
    step = max(gap, 1e-3) / 2
    n = np.maximum(2, np.ceil(length / step).astype(int) + 1)
    owner = np.repeat(np.arange(len(seg)), n)
    t = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n - 1, n)
    pts = seg[owner, 0] + t[:, None] * (seg[owner, 1] - seg[owner, 0])
    pairs = cKDTree(pts).query_pairs(gap + step, output_type="ndarray")
    a, b = owner[pairs[:, 0]], owner[pairs[:, 1]]
    keep = a != b
    ab = np.unique(np.sort(np.column_stack([a[keep], b[keep]]), axis=1), axis=0)
    return ab[:, 0], ab[:, 1]


def _join(seg: np.ndarray, group: np.ndarray, k: int) -> np.ndarray:
    """One segment per group: length-weighted mean direction through the weighted midpoint, spanning every end."""
    u, length, mid = segment_frame(seg)
    w = np.maximum(length, 1e-9)
    sin2, cos2 = 2 * u[:, 0] * u[:, 1], u[:, 0] ** 2 - u[:, 1] ** 2  # doubled angles: directions, not signs
    phi2 = np.arctan2(np.bincount(group, w * sin2, k), np.bincount(group, w * cos2, k))
    d = np.column_stack([np.cos(phi2 / 2), np.sin(phi2 / 2)])
    c = np.column_stack([np.bincount(group, w * mid[:, i], k) for i in range(2)]) / np.bincount(group, w, k)[:, None]
    t = ((seg - c[group][:, None]) * d[group][:, None]).sum(-1)  # (K, 2)
    lo, hi = np.full(k, np.inf), np.full(k, -np.inf)
    np.minimum.at(lo, group, t.min(1))
    np.maximum.at(hi, group, t.max(1))
    return np.stack([c + lo[:, None] * d, c + hi[:, None] * d], axis=1)


def link_corners(seg, corner_gap: float = 0.15, min_angle_deg: float = 30.0) -> list[np.ndarray]:
    """Polylines (list of (M, 2) m; closed ones repeat their first vertex) from segments (K, 2, 2).

    Two ends of different segments at most ``corner_gap`` m apart, whose lines
    cross at more than ``min_angle_deg`` at a point within ``corner_gap`` m of
    both ends, are snapped to that point and linked (closest pairs first, each
    end at most once).
    """
    seg = np.array(seg, float).reshape(-1, 2, 2)
    link = np.full(2 * len(seg), -1)
    for a, b, corner in _corner_candidates(seg, corner_gap, min_angle_deg):
        if link[a] < 0 and link[b] < 0:
            link[a], link[b] = b, a
            seg[a // 2, a % 2] = seg[b // 2, b % 2] = corner
    return _walk(seg, link)


def _corner_candidates(seg, corner_gap, min_angle_deg):
    """(end a, end b, corner (2,)) of linkable end pairs, closest first; end e is seg[e // 2, e % 2]."""
    from scipy.spatial import cKDTree

    ends = seg.reshape(-1, 2)
    pairs = cKDTree(ends).query_pairs(corner_gap, output_type="ndarray")
    pairs = pairs[pairs[:, 0] // 2 != pairs[:, 1] // 2]
    if len(pairs) == 0:
        return []
    a, b = pairs[:, 0], pairs[:, 1]
    u, _, _ = segment_frame(seg)
    ua, ub = u[a // 2], u[b // 2]
    cross = ua[:, 0] * ub[:, 1] - ua[:, 1] * ub[:, 0]
    ok = np.abs(cross) >= np.sin(np.deg2rad(min_angle_deg))
    pa, pb = ends[a], ends[b]
    s = ((pb - pa)[:, 0] * ub[:, 1] - (pb - pa)[:, 1] * ub[:, 0]) / np.where(ok, cross, 1.0)
    corner = pa + s[:, None] * ua
    ok &= (np.linalg.norm(corner - pa, axis=1) <= corner_gap) & (np.linalg.norm(corner - pb, axis=1) <= corner_gap)
    order = np.argsort(np.linalg.norm(pa - pb, axis=1)[ok], kind="stable")
    return list(zip(a[ok][order], b[ok][order], corner[ok][order]))


def _walk(seg: np.ndarray, link: np.ndarray) -> list[np.ndarray]:
    """Chains of segments joined end to end by ``link`` (end -> linked end, -1 none)."""
    seen = np.zeros(len(seg), bool)
    starts = [e for e in range(2 * len(seg)) if link[e] < 0] + list(range(0, 2 * len(seg), 2))  # open chains first
    lines = []
    for e in starts:
        if seen[e // 2]:
            continue
        pts, end = [seg[e // 2, e % 2]], e
        while not seen[end // 2]:
            seen[end // 2] = True
            other = end ^ 1
            pts.append(seg[other // 2, other % 2])
            end = link[other]
            if end < 0:
                break
        lines.append(np.array(pts))
    return lines


def _tour(polylines: list[np.ndarray]) -> list[np.ndarray]:
    """The polylines in a greedy nearest-end tour from the first vertex of the first, each entered at its
    nearer end (reversed if need be): short jumps between them, cheap in :meth:`LineMap.to_bytes`."""
    if not polylines:
        return []
    ends = np.array([[p[0], p[-1]] for p in polylines])  # (N, 2 ends, 2)
    todo, here, out = np.ones(len(polylines), bool), ends[0, 0], []
    for _ in polylines:
        d = np.where(todo[:, None], np.linalg.norm(ends - here, axis=2), np.inf)
        i, end = np.unravel_index(np.argmin(d), d.shape)
        todo[i] = False
        out.append(polylines[i][::-1] if end else polylines[i])
        here = out[-1][-1]
    return out


def contour_segments(occupied, resolution: float, origin=(0.0, 0.0), simplify_tol: float = 0.05) -> np.ndarray:
    """Segments (K, 2, 2) m of the boundaries of a grid's occupied cells.

    Marching-squares contours (on the cell edges) are split at their
    Douglas-Peucker vertices (tolerance ``simplify_tol`` m); each piece is the
    total-least-squares line of its contour points without the two vertices
    (so a cut corner does not tilt it), spanning all of them.
    """
    from skimage.measure import approximate_polygon, find_contours

    padded = np.pad(np.asarray(occupied, bool), 1).astype(np.float32)  # every contour closes
    points, fit_group, span_group, k = [], [], [], 0
    for c in find_contours(padded, 0.5):
        v = approximate_polygon(c, simplify_tol / resolution)  # a subset of c, in order
        key, scale = c[:, 0] * (padded.shape[1] + 2) + c[:, 1], padded.shape[1] + 2
        idx = np.flatnonzero(np.isin(key, v[:, 0] * scale + v[:, 1]))
        idx = np.unique(np.concatenate([[0], idx, [len(c) - 1]]))
        n = np.diff(idx) + 1  # points of each piece, both vertices included
        piece = np.repeat(np.arange(len(n)), n)
        at = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)  # position within the piece
        inner = (at > 0) & (at < np.repeat(n, n) - 1) | np.repeat(n <= 3, n)
        points.append(c[np.repeat(idx[:-1], n) + at])
        fit_group.append(np.where(inner, piece + k, -1))
        span_group.append(piece + k)
        k += len(n)
    if k == 0:
        return np.zeros((0, 2, 2))
    rc = np.concatenate(points) - 0.5  # padded (row, col) -> cell units from the origin
    xy = rc[:, ::-1] * resolution + np.asarray(origin, float)
    fit, span = np.concatenate(fit_group), np.concatenate(span_group)
    seg = _fit_groups(xy[fit >= 0], fit[fit >= 0], k, extent=(xy, span))
    return seg[np.isfinite(seg).all(axis=(1, 2))]


EXTRACTORS = ("contour", "hough")
"""Segment sources of :func:`extract_line_map`: cell-boundary contours (default, measured better on the
simulator office) or the thesis's Canny + probabilistic Hough."""


def extract_line_map(occupied, resolution: float, origin=(0.0, 0.0), *, method: str = "contour",
                     simplify_tol: float | None = None, min_length: float | None = None, angle_tol_deg: float = 3.0,
                     offset_tol: float | None = None, gap: float | None = None, corner_gap: float | None = None,
                     seed: int = 0) -> LineMap:
    """The line map of a grid's occupied cells ``occupied`` (H, W) bool (row = y); lengths in m.

    Segments from ``method`` (see :data:`EXTRACTORS`; contours simplified to
    ``simplify_tol`` (2 cells: a wall's one-cell jags are not corners), Hough
    with its 0.15 m gap); pieces shorter than ``min_length`` (2 cells) dropped;
    collinear ones within ``offset_tol`` (1 cell) and ``gap`` (2 cells) merged;
    corners within ``corner_gap`` (3 cells) linked; vertices snapped to the
    :data:`QUANTUM` lattice, polylines in a nearest-end tour.
    """
    occupied = np.asarray(occupied, bool)
    cells = dict(simplify_tol=2.0, min_length=2.0, offset_tol=1.0, gap=2.0, corner_gap=3.0)
    given = dict(simplify_tol=simplify_tol, min_length=min_length, offset_tol=offset_tol, gap=gap,
                 corner_gap=corner_gap)
    p = {k: cells[k] * resolution if v is None else float(v) for k, v in given.items()}
    if method == "contour":
        seg = contour_segments(occupied, resolution, origin, p["simplify_tol"])
    elif method == "hough":
        seg = hough_segments(occupied, resolution, origin, min_length=max(p["min_length"], 2 * resolution),
                             seed=seed)
    else:
        raise ValueError(f"unknown line extractor {method!r} (one of {', '.join(EXTRACTORS)})")
    _, length, _ = segment_frame(seg)
    seg = merge_collinear(seg[length >= p["min_length"]], angle_tol_deg, p["offset_tol"], p["gap"])
    quantum = QUANTUM * resolution
    lines = [from_lattice(to_lattice(q, origin, quantum), origin, quantum) for q in link_corners(seg, p["corner_gap"])]
    params = dict(method=method, angle_tol_deg=angle_tol_deg, seed=seed, quantum=quantum, **p)
    return LineMap(_tour(lines), resolution, tuple(map(float, origin)), occupied.shape, params)
