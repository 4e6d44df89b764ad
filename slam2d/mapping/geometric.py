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
(:data:`QUANTUM`) and the polylines ordered in a nearest-end tour. :class:`LineMap`
stores the polylines (compact binary, JSON, SVG over the grid, PNG); its
``segments`` are the thesis's endpoint table (eq. 12). :func:`line_scores`
measures a line map against true walls.
"""

from __future__ import annotations

import json
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["hough_segments", "contour_segments", "extract_line_map", "merge_collinear", "link_corners", "LineMap",
           "line_scores", "chamfer", "QUANTUM"]

QUANTUM = 0.5
"""Vertex lattice step of a line map, in cells: :func:`extract_line_map` snaps its vertices to it (moving
each by at most a quarter cell) and :meth:`LineMap.to_bytes` stores them as integers on it."""


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


# --------------------------------------------------------------------------- segment geometry


def _frame(seg: np.ndarray):
    """Unit directions (K, 2), lengths (K,) and midpoints (K, 2) of segments (K, 2, 2)."""
    d = seg[:, 1] - seg[:, 0]
    length = np.linalg.norm(d, axis=1)
    return d / np.maximum(length, 1e-12)[:, None], length, seg.mean(axis=1)


def _point_segment_distance(points: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """Distances (P, K) m from points (P, 2) to segments (K, 2, 2)."""
    a, d = seg[:, 0], seg[:, 1] - seg[:, 0]
    t = np.clip(((points[:, None, :] - a) * d).sum(-1) / np.maximum((d * d).sum(-1), 1e-24), 0.0, 1.0)
    return np.linalg.norm(points[:, None, :] - (a + t[..., None] * d), axis=-1)


def _nearest_segment(points: np.ndarray, seg: np.ndarray, chunk: int = 4096) -> tuple[np.ndarray, np.ndarray]:
    """Index (P,) and distance (P,) m of the segment nearest each point, in chunks of points."""
    idx, dist = np.zeros(len(points), np.int64), np.full(len(points), np.inf)
    if len(seg) == 0:
        return idx, dist
    for lo in range(0, len(points), chunk):
        d = _point_segment_distance(points[lo : lo + chunk], seg)
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


# --------------------------------------------------------------------------- merging


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
    u, _, _ = _frame(seg)
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

    _, length, _ = _frame(seg)
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
    u, length, mid = _frame(seg)
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
    u, _, _ = _frame(seg)
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


# --------------------------------------------------------------------------- the line map


@dataclass(eq=False)
class LineMap:
    """Wall polylines (list of (M, 2) m arrays) of a grid with ``resolution`` m/cell, ``origin`` (x, y) m
    and ``shape`` (H, W) cells."""

    polylines: list[np.ndarray]
    resolution: float
    origin: tuple[float, float]
    shape: tuple[int, int]
    params: dict = field(default_factory=dict)

    @property
    def segments(self) -> np.ndarray:
        """The thesis's endpoint table (K, 2, 2) m: consecutive polyline vertices."""
        parts = [np.stack([p[:-1], p[1:]], axis=1) for p in self.polylines if len(p) > 1]
        return np.concatenate(parts) if parts else np.zeros((0, 2, 2))

    def length(self) -> float:
        """Total wall length, m."""
        s = self.segments
        return float(np.linalg.norm(s[:, 1] - s[:, 0], axis=1).sum())

    def to_json(self) -> str:
        """Compact JSON, coordinates in millimetre-rounded metres."""
        return json.dumps({"format": "slam2d-lines/1", "units": "m", "resolution": self.resolution,
                           "origin": list(self.origin), "shape": list(self.shape), "params": self.params,
                           "polylines": [np.round(p, 3).tolist() for p in self.polylines]}, separators=(",", ":"))

    @classmethod
    def from_json(cls, text: str) -> LineMap:
        d = json.loads(text)
        if d.get("format") != "slam2d-lines/1":
            raise ValueError("not a slam2d line map (format)")
        return cls([np.asarray(p, float).reshape(-1, 2) for p in d["polylines"]], d["resolution"],
                   tuple(d["origin"]), tuple(d["shape"]), d.get("params", {}))

    def save(self, path) -> Path:
        """Write the binary form to a ``.bin`` path, JSON to any other."""
        path = Path(path)
        if path.suffix == ".bin":
            path.write_bytes(self.to_bytes())
        else:
            path.write_text(self.to_json())
        return path

    @classmethod
    def load(cls, path) -> LineMap:
        """Read a line map written by :meth:`save` (binary from ``.bin``, else JSON)."""
        path = Path(path)
        return cls.from_bytes(path.read_bytes()) if path.suffix == ".bin" else cls.from_json(path.read_text())

    def to_bytes(self) -> bytes:
        """Compact binary form: a 5-byte magic, then deflate (raw, filtered) of a header (resolution, origin,
        shape, lattice step m, polyline count), each polyline's vertex count (doubled, + 1 if closed: its last
        vertex is not stored) and every vertex as the difference from the one before on the :data:`QUANTUM`
        lattice, as zigzag varints. Lossless for vertices on the lattice (as :func:`extract_line_map` makes
        them)."""
        quantum = QUANTUM * self.resolution
        k = [_lattice(p, self.origin, quantum) for p in self.polylines]
        closed = np.array([len(p) > 2 and bool(np.all(p[0] == p[-1])) for p in k], bool)
        kept = [p[:-1] if c else p for p, c in zip(k, closed)]
        n = np.array([len(p) for p in kept], np.int64)
        xy = np.concatenate(kept) if kept else np.zeros((0, 2), np.int64)
        header = _BINARY.pack(self.resolution, *self.origin, *self.shape, quantum, len(n))
        steps = np.diff(xy, axis=0, prepend=np.zeros((1, 2), np.int64))  # the first from the origin
        body = _varints(np.concatenate([2 * n + closed, steps.ravel()]))
        deflate = zlib.compressobj(9, zlib.DEFLATED, -15, 9, zlib.Z_FILTERED)
        return _BINARY_MAGIC + deflate.compress(header + body) + deflate.flush()

    @classmethod
    def from_bytes(cls, data: bytes) -> LineMap:
        if data[: len(_BINARY_MAGIC)] != _BINARY_MAGIC:
            raise ValueError("not a slam2d binary line map (magic)")
        raw = zlib.decompress(data[len(_BINARY_MAGIC) :], -15)
        res, ox, oy, h, w, quantum, count = _BINARY.unpack_from(raw)
        codes = _read_varints(raw[_BINARY.size :])
        n, closed = codes[:count] >> 1, codes[:count] & 1 == 1
        xy = np.cumsum(codes[count:].reshape(-1, 2), axis=0)
        parts = np.split(xy, np.cumsum(n)[:-1]) if count else []
        parts = [np.vstack([p, p[:1]]) if c else p for p, c in zip(parts, closed)]
        return cls([_from_lattice(p, (ox, oy), quantum) for p in parts], res, (ox, oy), (h, w))

    def to_svg(self, grid_log_odds: np.ndarray | None = None, px_per_m: float = 20.0) -> str:
        """SVG (metres, y up, ``px_per_m`` px a metre) of the polylines over the grid (log-odds (H, W)) when given."""
        h, w = self.shape
        ox, oy = self.origin
        width, height = w * self.resolution, h * self.resolution
        parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width * px_per_m:.0f}" '
                 f'height="{height * px_per_m:.0f}" viewBox="{ox} {-oy - height} {width} {height}">',
                 '<g transform="scale(1 -1)">']  # y up; the grid image (row 0 = lowest y) is mirrored with it
        if grid_log_odds is not None:
            png = _grid_png_base64(grid_log_odds)
            parts.append(f'<image x="{ox}" y="{oy}" width="{width}" height="{height}" preserveAspectRatio="none" '
                         f'style="image-rendering:pixelated" href="data:image/png;base64,{png}"/>')
        parts.append(f'<g fill="none" stroke="#d62728" stroke-width="{2 * self.resolution}" stroke-linejoin="round">')
        parts += [f'<polyline points="{" ".join(f"{x:.3f},{y:.3f}" for x, y in p)}"/>' for p in self.polylines]
        return "\n".join(parts + ["</g>", "</g>", "</svg>", ""])

    def save_png(self, path, grid_log_odds: np.ndarray | None = None, title: str | None = None) -> Path:
        """PNG figure of the polylines (one colour each) over the grid, axes in metres."""
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.collections import LineCollection
        from matplotlib.figure import Figure

        h, w = self.shape
        ox, oy = self.origin
        fig = Figure(figsize=(8.0, float(np.clip(8.0 * h / max(w, 1), 3.0, 16.0))), dpi=150)
        FigureCanvasAgg(fig)
        ax = fig.add_subplot()
        if grid_log_odds is not None:
            ax.imshow(1.0 / (1.0 + np.exp(grid_log_odds.astype(float))), cmap="gray", vmin=0, vmax=1, origin="lower",
                      interpolation="nearest", extent=(ox, ox + w * self.resolution, oy, oy + h * self.resolution))
        ax.add_collection(LineCollection(self.polylines, colors=[f"C{i % 10}" for i in range(len(self.polylines))],
                                         linewidths=1.2))
        ax.set_xlim(ox, ox + w * self.resolution)
        ax.set_ylim(oy, oy + h * self.resolution)
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(title or f"{len(self.polylines)} polylines, {len(self.segments)} segments, {self.length():.0f} m")
        path = Path(path)
        fig.savefig(path, bbox_inches="tight")
        return path


_BINARY_MAGIC = b"SL2L\x01"
_BINARY = struct.Struct("<3d2Id I")  # resolution m, origin (x, y) m, shape (H, W), lattice step m, polylines


def _lattice(xy, origin, quantum: float) -> np.ndarray:
    """Integer lattice coordinates (..., 2) of points ``xy`` (..., 2) m on the grid of step ``quantum`` m
    through ``origin``."""
    return np.round((np.asarray(xy, float) - np.asarray(origin, float)) / quantum).astype(np.int64)


def _from_lattice(k, origin, quantum: float) -> np.ndarray:
    """Points (..., 2) m of integer lattice coordinates ``k`` (the inverse of :func:`_lattice`)."""
    return np.asarray(origin, float) + np.asarray(k, np.int64) * quantum


def _varints(values) -> bytes:
    """LEB128 bytes of the zigzag codes of int64 ``values`` (one byte for |v| < 64, two below 8192)."""
    v = np.asarray(values, np.int64)
    z = ((v << 1) ^ (v >> 63)).astype(np.uint64)
    shift = np.arange(10, dtype=np.uint64) * np.uint64(7)
    n = 1 + ((z[:, None] >> shift[1:]) > 0).sum(axis=1)
    more = np.arange(10) < (n - 1)[:, None]
    byte = ((z[:, None] >> shift) & np.uint64(0x7F)) | (more.astype(np.uint64) << np.uint64(7))
    return byte.astype(np.uint8)[np.arange(10) < n[:, None]].tobytes()


def _read_varints(data: bytes) -> np.ndarray:
    """int64 values of the zigzag LEB128 bytes ``data`` (the inverse of :func:`_varints`)."""
    b = np.frombuffer(data, np.uint8)
    last = b < 0x80
    which = np.cumsum(last) - last  # value index of each byte
    first = np.concatenate([[0], np.flatnonzero(last)[:-1] + 1])
    shift = (7 * (np.arange(len(b)) - first[which])).astype(np.uint64)
    z = np.zeros(int(last.sum()), np.uint64)
    np.add.at(z, which, (b & 0x7F).astype(np.uint64) << shift)
    return (z >> np.uint64(1)).astype(np.int64) ^ -(z & np.uint64(1)).astype(np.int64)


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


def _grid_png_base64(log_odds: np.ndarray) -> str:
    """Base64 PNG of a grid (image row 0 = grid row 0), grey 255 (1 - p)."""
    import base64
    import io

    from PIL import Image

    grey = np.round(255.0 / (1.0 + np.exp(np.asarray(log_odds, float)))).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(grey).save(buf, format="PNG", optimize=True)
    return base64.b64encode(buf.getvalue()).decode("ascii")


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
    _, length, _ = _frame(seg)
    seg = merge_collinear(seg[length >= p["min_length"]], angle_tol_deg, p["offset_tol"], p["gap"])
    quantum = QUANTUM * resolution
    lines = [_from_lattice(_lattice(q, origin, quantum), origin, quantum) for q in link_corners(seg, p["corner_gap"])]
    params = dict(method=method, angle_tol_deg=angle_tol_deg, seed=seed, quantum=quantum, **p)
    return LineMap(_tour(lines), resolution, tuple(map(float, origin)), occupied.shape, params)


# --------------------------------------------------------------------------- evaluation


def _samples(seg: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points (S, 2) every ``step`` m along segments (K, 2, 2) (at piece centres), their segment (S,) and weight m."""
    _, length, _ = _frame(seg)
    n = np.maximum(1, np.ceil(length / step).astype(int))
    owner = np.repeat(np.arange(len(seg)), n)
    t = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n) + 0.5) / np.repeat(n, n)
    return seg[owner, 0] + t[:, None] * (seg[owner, 1] - seg[owner, 0]), owner, (length / n)[owner]


def _matched(points, owner, seg_p, seg_q, tol, angle_tol) -> np.ndarray:
    """Whether each sample point (of seg_p[owner]) lies within ``tol`` m of a seg_q segment at most ``angle_tol``
    rad off."""
    u_p, _, _ = _frame(seg_p)
    u_q, _, _ = _frame(seg_q)
    ok = np.zeros(len(points), bool)
    for lo in range(0, len(points), 2048):
        d = _point_segment_distance(points[lo : lo + 2048], seg_q)
        along = np.abs(u_p[owner[lo : lo + 2048]] @ u_q.T) >= np.cos(angle_tol)
        ok[lo : lo + 2048] = ((d <= tol) & along).any(axis=1)
    return ok


def line_scores(found, truth, *, tol: float = 0.05, angle_tol_deg: float = 1.0, step: float = 0.01,
                occupied=None) -> dict:
    """Precision and recall of wall length of segments ``found`` against ``truth`` (each (K, 2, 2) m).

    A piece of a segment counts when it lies within ``tol`` m of a segment of the
    other set whose direction is within ``angle_tol_deg``. ``occupied`` (points
    (M, 2) -> bool, e.g. ``World.occupied``) keeps only the true pieces that bound
    free space (occupied on one side, free on the other).
    """
    found, truth = (np.asarray(s, float).reshape(-1, 2, 2) for s in (found, truth))
    angle_tol = np.deg2rad(angle_tol_deg)
    pt, ot, wt = _samples(truth, step)
    if occupied is not None:
        u, _, _ = _frame(truth)
        n = np.column_stack([-u[ot, 1], u[ot, 0]]) * (tol / 2)
        keep = occupied(pt + n) != occupied(pt - n)
        pt, ot, wt = pt[keep], ot[keep], wt[keep]
    pf, of, wf = _samples(found, step)
    rec = _matched(pt, ot, truth, found, tol, angle_tol) if len(found) else np.zeros(len(pt), bool)
    pre = _matched(pf, of, found, truth, tol, angle_tol) if len(truth) else np.zeros(len(pf), bool)
    return {"precision": float(wf[pre].sum() / max(wf.sum(), 1e-12)),
            "recall": float(wt[rec].sum() / max(wt.sum(), 1e-12)),
            "found_m": float(wf.sum()), "truth_m": float(wt.sum())}


def chamfer(segments, occupied, resolution: float, origin=(0.0, 0.0)) -> float:
    """Symmetric mean distance (m) between points along ``segments`` (K, 2, 2) m and the centres of the
    boundary cells of ``occupied`` (H, W) bool (occupied cells with a non-occupied 4-neighbour); NaN if
    either is empty."""
    from scipy.ndimage import binary_erosion
    from scipy.spatial import cKDTree

    occupied = np.asarray(occupied, bool)
    rows, cols = np.nonzero(occupied & ~binary_erosion(occupied))
    cells = (np.column_stack([cols, rows]) + 0.5) * resolution + np.asarray(origin, float)
    segments = np.asarray(segments, float).reshape(-1, 2, 2)
    if len(segments) == 0 or len(cells) == 0:
        return float("nan")
    pts, _, _ = _samples(segments, resolution / 2)
    return float((cKDTree(cells).query(pts)[0].mean() + _nearest_segment(cells, segments)[1].mean()) / 2)
