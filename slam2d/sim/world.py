"""Worlds: wall segments from polygons, an occupancy PNG or the built-in office.

A world is a set of wall segments ``(K, 2, 2)`` in metres with ``bounds``.
It answers ray casts (laser beams, against walls and optional transient
circles such as moving obstacles), point queries (occupied, distance, free)
and swept-disc contact (where a disc moving along a path first touches a wall,
the bounds or a circle). Moving obstacles are not part of a world: callers
pass them to the queries as circles.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from slam2d import geometry
from slam2d.errors import InputError, not_a_file
from slam2d.paths import find_data_path

__all__ = ["World", "Contact", "load_world"]

_PAIRS_PER_BATCH = 200_000  # beam x segment pairs per ray-casting batch
_EPS = 1e-9
UNMAPPED_MAX = 205  # grey: a PNG world's pixels from 128 up to this are unknown in the plan (map_server's 0.196)

# --------------------------------------------------------------------------- geometry helpers


def _cross(ax, ay, bx, by):
    return ax * by - ay * bx


_PAIRS = 2_000_000  # point-segment pairs measured at once (memory: ~50 bytes each)


def _point_segment_distance(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Distances (M, K) in metres from points (M, 2) to segments (K, 2, 2)."""
    p, e = segments[:, 0], segments[:, 1] - segments[:, 0]
    ee = np.einsum("ki,ki->k", e, e)
    w = points[:, None, :] - p[None]
    u = np.clip(np.einsum("mki,ki->mk", w, e) / np.where(ee > 0, ee, 1.0), 0.0, 1.0)
    return np.linalg.norm(w - u[..., None] * e, axis=-1)


def _segments_cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Whether segments a (L, 2, 2) and b (K, 2, 2) properly intersect, (L, K)."""
    a0, a1 = a[:, None, 0], a[:, None, 1]
    b0, b1 = b[None, :, 0], b[None, :, 1]
    da, db = a1 - a0, b1 - b0
    o1 = _cross(da[..., 0], da[..., 1], (b0 - a0)[..., 0], (b0 - a0)[..., 1])
    o2 = _cross(da[..., 0], da[..., 1], (b1 - a0)[..., 0], (b1 - a0)[..., 1])
    o3 = _cross(db[..., 0], db[..., 1], (a0 - b0)[..., 0], (a0 - b0)[..., 1])
    o4 = _cross(db[..., 0], db[..., 1], (a1 - b0)[..., 0], (a1 - b0)[..., 1])
    return (o1 * o2 < 0) & (o3 * o4 < 0)


def _segment_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Shortest distances (L, K) in metres between segments a (L, 2, 2) and b (K, 2, 2)."""
    d = np.minimum.reduce(
        [
            _point_segment_distance(a[:, 0], b),
            _point_segment_distance(a[:, 1], b),
            _point_segment_distance(b[:, 0], a).T,
            _point_segment_distance(b[:, 1], a).T,
        ]
    )
    return np.where(_segments_cross(a, b), 0.0, d)


def _ring_segments(ring) -> np.ndarray:
    """Edges (M, 2, 2) of a closed ring of vertices (M, 2)."""
    v = np.asarray(ring, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 2 or len(v) < 3 or not np.isfinite(v).all():
        raise InputError("World.from_polygons", f"a ring needs >= 3 finite (x, y) vertices, got shape {v.shape}")
    return np.stack([v, np.roll(v, -1, axis=0)], axis=1)


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Runs of True along each row of ``mask``: (row, start, end) with end exclusive."""
    d = np.diff(np.pad(mask.astype(np.int8), ((0, 0), (1, 1))), axis=1)
    rows, starts = np.nonzero(d == 1)
    _, ends = np.nonzero(d == -1)
    return rows, starts, ends


def _grid_boundaries(occ: np.ndarray, resolution: float) -> np.ndarray:
    """Boundary segments (K, 2, 2) of occupied cells; ``occ[row, col]`` with row 0 at y = 0.

    Cell edges between an occupied and a free cell (outside the grid is free)
    are merged into maximal straight runs.
    """
    p = np.pad(occ, 1)
    horizontal = p[:-1, 1:-1] != p[1:, 1:-1]  # (H+1, W): line y = row
    vertical = p[1:-1, :-1] != p[1:-1, 1:]  # (H, W+1): line x = col
    y, x0, x1 = _runs(horizontal)
    x, y0, y1 = _runs(vertical.T)
    h = np.stack([np.column_stack([x0, y]), np.column_stack([x1, y])], axis=1)
    v = np.stack([np.column_stack([x, y0]), np.column_stack([x, y1])], axis=1)
    return np.concatenate([h, v]).astype(np.float64).reshape(-1, 2, 2) * resolution


# --------------------------------------------------------------------------- worlds


class Contact(NamedTuple):
    """First contact of a swept disc: on leg ``leg`` of the path, at ``fraction`` in [0, 1]
    along it; ``circle`` is the index of the circle touched, None for a wall or the bounds."""

    leg: int
    fraction: float
    circle: int | None


class World:
    """Walls as segments ``(K, 2, 2)`` in metres; ``bounds`` is ``[[xmin, ymin], [xmax, ymax]]``.

    ``solids`` (closed rings whose interior is obstacle) and ``grid`` (occupancy
    cells, resolution) only serve :meth:`occupied`; ray casting uses the segments,
    swept-disc contact the segments and the bounds. ``circles`` arguments are
    transient obstacles, ``(centres (C, 2), radii (C,))`` in metres.
    """

    def __init__(self, segments, bounds=None, *, solids=(), grid=None, unmapped=None, name: str = "world"):
        self.segments = np.asarray(segments, dtype=np.float64).reshape(-1, 2, 2)
        if bounds is None:
            pts = self.segments.reshape(-1, 2)
            bounds = [pts.min(0), pts.max(0)] if len(pts) else [[0.0, 0.0], [0.0, 0.0]]
        self.bounds = np.asarray(bounds, dtype=np.float64).reshape(2, 2)
        self.solids = [np.asarray(r, dtype=np.float64) for r in solids]
        self.grid = grid
        self.unmapped = unmapped  # (H, W) bool on ``grid``'s cells: free to the laser, unknown in the plan
        self.name = name
        self.objects = None  # objects with heights (slam2d.sim.objects3d.furnish), if any

    def __repr__(self) -> str:
        (x0, y0), (x1, y1) = self.bounds
        return f"World({self.name!r}, {len(self.segments)} walls, [{x0:g}, {x1:g}] x [{y0:g}, {y1:g}] m)"

    # construction ---------------------------------------------------------

    @classmethod
    def from_polygons(cls, polygons, *, solid: bool = False, name: str = "polygons") -> World:
        """World from closed rings of vertices (M, 2) in metres.

        With ``solid`` the inside of every ring is an obstacle (for :meth:`occupied`).
        """
        rings = list(polygons)
        segments = np.concatenate([_ring_segments(r) for r in rings]) if rings else np.zeros((0, 2, 2))
        return cls(segments, solids=rings if solid else (), name=name)

    @classmethod
    def from_png(cls, path, resolution: float = 0.05) -> World:
        """World from an occupancy PNG: pixels darker than 128 are obstacles.

        ``resolution`` is metres per pixel; the origin is the image's lower-left
        corner (image row 0 is the top, at the largest y). The other pixels not
        lighter than ``UNMAPPED_MAX`` (map_server's unknown grey, 205) are free
        to the laser but marked ``unmapped``: wall interiors and the outside of
        a scanned plan, which its pinholes let the laser see.
        """
        path = Path(path)
        if not path.is_file():
            raise InputError(path, not_a_file(path) or "world PNG not found")
        if not resolution > 0:
            raise InputError(path, f"resolution must be > 0 m per pixel, got {resolution}")
        from slam2d.mapping.image import read_grey

        grey = read_grey(path)[::-1]
        occ = grey < 128
        h, w = occ.shape
        return cls(
            _grid_boundaries(occ, resolution),
            bounds=[[0.0, 0.0], [w * resolution, h * resolution]],
            grid=(occ, float(resolution)),
            unmapped=~occ & (grey <= UNMAPPED_MAX),
            name=path.stem,
        )

    @classmethod
    def office(cls) -> World:
        """Built-in office, 20 m x 12 m: a ring corridor around a service core,
        seven rooms off it (doorways 1.0 m), desks, shelves and pillars."""
        rings = [_box(*b) for b in _office_walls()] + [_box(*b) for b in _OFFICE_FURNITURE]
        return cls.from_polygons(rings, solid=True, name="office")

    # queries --------------------------------------------------------------

    def occupied(self, points) -> np.ndarray:
        """Whether points (M, 2) lie inside an obstacle (solid ring or occupied cell)."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        out = np.zeros(len(pts), dtype=bool)
        if self.grid is not None:
            occ, res = self.grid
            col, row = np.floor(pts / res).astype(np.int64).T
            ok = (col >= 0) & (row >= 0) & (col < occ.shape[1]) & (row < occ.shape[0])
            out[ok] = occ[row[ok], col[ok]]
        if self.solids:
            out |= _inside_any(pts, self.solids)
        return out

    def distance(self, points) -> np.ndarray:
        """Distance (M,) in metres from points (M, 2) to the nearest wall (inf without walls)."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if len(self.segments) == 0:
            return np.full(len(pts), np.inf)
        chunk = max(1, _PAIRS // len(self.segments))  # points per block: a plan's thousands of segments
        return np.concatenate([_point_segment_distance(pts[i:i + chunk], self.segments).min(axis=1)
                               for i in range(0, len(pts), chunk)] or [np.zeros(0)])  # fmt: skip

    def segment_distance(self, segments) -> np.ndarray:
        """Shortest distance (L,) in metres from segments (L, 2, 2) to the walls; 0 where one crosses a wall."""
        segs = np.asarray(segments, dtype=np.float64).reshape(-1, 2, 2)
        if len(self.segments) == 0:
            return np.full(len(segs), np.inf)
        return _segment_distance(segs, self.segments).min(axis=1)

    def free(self, points, radius: float = 0.0) -> np.ndarray:
        """Whether discs of ``radius`` (m) centred at points (M, 2) fit: inside the bounds,
        not in an obstacle, at least ``radius`` from every wall."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        (x0, y0), (x1, y1) = self.bounds
        inside = (pts[:, 0] >= x0 + radius) & (pts[:, 0] <= x1 - radius)
        inside &= (pts[:, 1] >= y0 + radius) & (pts[:, 1] <= y1 - radius)
        return inside & ~self.occupied(pts) & (self.distance(pts) >= radius)

    def sweep(self, path, radius: float, circles=None) -> Contact | None:
        """Where a disc of ``radius`` (m) moved along ``path`` (M, 2) first touches a wall,
        the bounds or one of ``circles``; None if never.

        Contact is exact along every straight leg, so no wall is tunnelled through
        however long a leg is. A disc already touching something may move away
        from it, not into it.
        """
        path = np.asarray(path, dtype=np.float64).reshape(-1, 2)
        starts, moves = path[:-1], np.diff(path, axis=0)
        walls = np.concatenate([self._segments_near(path, radius), _ring_segments(_box(*self.bounds.ravel()))])
        s = np.stack([_capsule_entry(starts, moves, walls, radius), np.full(len(starts), np.inf)])
        which = np.full(len(starts), -1)
        if (c := _as_circles(circles)) is not None:
            entry = _circle_entry(starts, moves, c[0], c[1] + radius)  # (M - 1, C)
            s[1], which = entry.min(axis=1), entry.argmin(axis=1)
        legs = np.flatnonzero(s.min(axis=0) <= 1.0)
        if len(legs) == 0:
            return None
        k = legs[0]
        by_circle = s[1, k] < s[0, k]
        return Contact(int(k), float(s[:, k].min()), int(which[k]) if by_circle else None)

    def raycast(self, origin, angles, max_range: float, circles=None) -> np.ndarray:
        """Ranges (n,) in metres from ``origin`` (2,) along world-frame ``angles`` (n,) rad.

        A beam that hits nothing within ``max_range`` returns ``max_range``.
        """
        origin = np.asarray(origin, dtype=np.float64).reshape(1, 2)
        angles = np.asarray(angles, dtype=np.float64).reshape(1, -1)
        return self.raycast_many(origin, angles, max_range, circles)[0]

    def raycast_poses(self, poses, beam_angles, max_range: float, circles=None) -> np.ndarray:
        """Ranges (P, n) from sensor poses (P, 3) along beam angles (n,) in the sensor frame."""
        poses = geometry.as_pose(poses).reshape(-1, 3)
        angles = poses[:, 2:3] + np.asarray(beam_angles, dtype=np.float64)[None]
        return self.raycast_many(poses[:, :2], angles, max_range, circles)

    def raycast_many(self, origins, angles, max_range: float, circles=None) -> np.ndarray:
        """Ranges (P, n) from origins (P, 2) along world-frame angles (P, n), capped at ``max_range``.

        Beams see ``circles`` as well as the walls.
        """
        origins = np.asarray(origins, dtype=np.float64).reshape(-1, 2)
        angles = np.asarray(angles, dtype=np.float64).reshape(len(origins), -1)
        out = np.full(angles.shape, float(max_range))
        if (c := _as_circles(circles)) is not None and angles.size:
            out = np.minimum(out, _cast_circles(*c, origins, angles))
        if len(self.segments) == 0 or angles.size == 0:
            return out
        step = max(1, _PAIRS_PER_BATCH // (angles.shape[1] * len(self.segments)))
        for i in range(0, len(origins), step):
            sl = slice(i, i + step)
            segs = self._segments_near(origins[sl], max_range)
            if len(segs):
                out[sl] = np.minimum(out[sl], _cast(segs, origins[sl], angles[sl]))
        return out

    def _segments_near(self, origins: np.ndarray, max_range: float) -> np.ndarray:
        """Segments whose bounding box comes within ``max_range`` (m) of the origins' box."""
        lo, hi = origins.min(0) - max_range, origins.max(0) + max_range
        smin, smax = self.segments.min(axis=1), self.segments.max(axis=1)
        keep = np.all((smax >= lo) & (smin <= hi), axis=1)
        return self.segments[keep]


def _cast(segments: np.ndarray, origins: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Nearest hit distances (P, n) of rays (origins (P, 2), angles (P, n)) on segments (K, 2, 2); inf if none.

    Ray o + t d meets segment p + u e where t = (a x e) / (d x e), u = (a x d) / (d x e), a = p - o.
    """
    ex, ey = (segments[:, 1] - segments[:, 0]).T  # (K,)
    a = segments[None, :, 0] - origins[:, None]  # (P, K, 2)
    ax, ay = a[..., 0][:, None], a[..., 1][:, None]  # (P, 1, K)
    dx, dy = np.cos(angles)[..., None], np.sin(angles)[..., None]  # (P, n, 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = dx * ey  # (P, n, K), computed in place: d x e, then t
        t -= dy * ex
        np.reciprocal(t, out=t)
        u = ax * dy
        u -= ay * dx
        u *= t
        t *= ax * ey - ay * ex
        miss = u < -_EPS
        miss |= u > 1 + _EPS
        miss |= ~(t > 0)
    t[miss] = np.inf
    return t.min(axis=-1)


def _as_circles(circles) -> tuple[np.ndarray, np.ndarray] | None:
    """``circles`` as centres (C, 2) and radii (C,) float arrays; None for none."""
    if circles is None or len(circles[0]) == 0:
        return None
    return np.asarray(circles[0], dtype=np.float64).reshape(-1, 2), np.asarray(circles[1], dtype=np.float64).reshape(-1)


def _cast_circles(centres: np.ndarray, radii: np.ndarray, origins: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Nearest hit distances (P, n) of rays (origins (P, 2), angles (P, n)) on circles; inf if none.

    Ray o + t d meets circle (c, R) at t = b - sqrt(b^2 - |c - o|^2 + R^2), b = d . (c - o);
    a circle holding the origin is not seen.
    """
    a = centres[None] - origins[:, None]  # (P, C, 2)
    dx, dy = np.cos(angles)[..., None], np.sin(angles)[..., None]  # (P, n, 1)
    b = dx * a[:, None, :, 0] + dy * a[:, None, :, 1]  # (P, n, C)
    c = (np.einsum("pci,pci->pc", a, a) - radii**2)[:, None]  # (P, 1, C)
    with np.errstate(invalid="ignore"):
        t = b - np.sqrt(b * b - c)
    return np.where((c > 0) & (t > 0), t, np.inf).min(axis=-1)


def _circle_entry(starts: np.ndarray, moves: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Fractions s (L, C) where points ``starts + s * moves`` (L, 2) enter circles (C, 2), radii (C,);
    inf if not in [0, 1].

    A start inside a circle counts as entering at 0 when moving inwards.
    """
    a = starts[:, None] - centres[None]  # (L, C, 2)
    dd = np.einsum("li,li->l", moves, moves)[:, None]  # (L, 1)
    b = np.einsum("lci,li->lc", a, moves)
    c = np.einsum("lci,lci->lc", a, a) - radii**2
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (-b - np.sqrt(b * b - dd * c)) / dd
    s = np.where((c >= 0) & (b < 0) & (s <= 1.0), s, np.inf)  # s >= 0 then holds
    return np.where((c < 0) & (b < 0), 0.0, s)


def _capsule_entry(starts: np.ndarray, moves: np.ndarray, segments: np.ndarray, radius: float) -> np.ndarray:
    """Fractions s (L,) where points ``starts + s * moves`` (L, 2) first come within ``radius`` of any
    segment (K, 2, 2); inf if not in [0, 1]. Sides of each capsule, then its end caps."""
    if len(starts) == 0:
        return np.zeros(0)
    p, e = segments[:, 0], segments[:, 1] - segments[:, 0]  # (K, 2)
    ee = np.einsum("ki,ki->k", e, e)
    with np.errstate(divide="ignore", invalid="ignore"):
        n = np.column_stack([-e[:, 1], e[:, 0]]) / np.sqrt(ee)[:, None]  # unit normals
        a = starts[:, None] - p[None]  # (L, K, 2)
        h0, hd = np.einsum("lki,ki->lk", a, n), moves @ n.T  # signed distance to the line, its rate
        side = np.sign(h0)
        s = (side * radius - h0) / hd
        u = np.einsum("lki,ki->lk", a + s[..., None] * moves[:, None], e) / ee  # foot along the segment
        u0 = np.einsum("lki,ki->lk", a, e) / ee
    enter = (np.abs(h0) >= radius) & (side * hd < 0) & (s <= 1.0) & (u >= 0) & (u <= 1)
    touching = (np.abs(h0) < radius) & (h0 * hd < 0) & (u0 >= 0) & (u0 <= 1)
    sides = np.where(touching, 0.0, np.where(enter, s, np.inf)).min(axis=1)
    ends = np.concatenate([segments[:, 0], segments[:, 1]])
    caps = _circle_entry(starts, moves, ends, np.full(len(ends), float(radius))).min(axis=1)
    return np.minimum(sides, caps)


def _inside_any(points: np.ndarray, rings: list[np.ndarray]) -> np.ndarray:
    """Even-odd point-in-polygon for every ring at once; True where inside any ring."""
    edges = np.concatenate([_ring_segments(r) for r in rings])
    starts = np.cumsum([0] + [len(r) for r in rings[:-1]])
    (x0, y0), (x1, y1) = edges[:, 0].T, edges[:, 1].T
    px, py = points[:, :1], points[:, 1:]
    straddle = (y0 > py) != (y1 > py)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_cross = x0 + (py - y0) * (x1 - x0) / (y1 - y0)
    crossings = (straddle & (px < x_cross)).astype(np.int64)
    return (np.add.reduceat(crossings, starts, axis=1) % 2 == 1).any(axis=1)


def _box(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    """Counter-clockwise ring (4, 2) of an axis-aligned rectangle."""
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=np.float64)


# --------------------------------------------------------------------------- the office

_WALL = 0.1  # m, wall thickness
# (fixed coordinate, start, end, doorways (from, to)) of wall centre lines, metres
_OFFICE_H_WALLS = [
    (0.0, 0.0, 20.0, []),
    (12.0, 0.0, 20.0, []),
    (3.4, 0.0, 20.0, [(2.5, 3.5), (7.0, 8.0), (12.0, 13.0), (16.8, 17.8)]),
    (8.6, 0.0, 20.0, [(2.5, 3.5), (7.5, 8.5), (11.5, 12.5), (16.5, 17.5)]),
]
_OFFICE_V_WALLS = [
    (0.0, 0.0, 12.0, []),
    (20.0, 0.0, 12.0, []),
    (5.0, 0.0, 3.4, []),
    (10.0, 0.0, 3.4, []),
    (15.0, 0.0, 3.4, []),
    (6.0, 8.6, 12.0, []),
    (14.0, 8.6, 12.0, []),
]
# axis-aligned boxes (xmin, ymin, xmax, ymax), metres
_OFFICE_FURNITURE = [
    (4.0, 5.0, 16.0, 7.0),  # service core inside the corridor ring
    (9.85, 4.85, 10.15, 7.15),  # columns on the core's faces
    (1.0, 5.8, 1.4, 6.2),  # pillar in the west lobby
    (18.6, 5.2, 19.4, 6.8),  # reception desk, east lobby
    (0.5, 0.5, 2.0, 1.1),  # room B1: desk, cabinet
    (4.3, 0.3, 4.9, 1.5),
    (5.6, 0.5, 6.8, 1.1),  # room B2: two desks, a table
    (8.4, 0.5, 9.6, 1.1),
    (7.1, 0.7, 7.9, 1.3),
    (10.6, 1.2, 11.8, 2.4),  # room B3: desk cluster, bookshelf
    (14.5, 0.4, 14.9, 2.6),
    (18.6, 0.4, 19.6, 2.8),  # room B4: long desk
    (1.2, 10.0, 4.2, 11.0),  # room T1: meeting table
    (7.0, 10.6, 9.0, 11.2),  # room T2 (open plan): desk rows, a pillar
    (11.0, 10.6, 13.0, 11.2),
    (9.8, 10.2, 10.2, 10.6),
    (18.8, 9.2, 19.6, 11.4),  # room T3: sofa, plant
    (14.8, 11.1, 15.2, 11.5),
]


def _wall_pieces(start: float, end: float, doors) -> list[tuple[float, float]]:
    """Intervals of a wall from ``start`` to ``end`` between its doorways; wall ends overlap by half a thickness."""
    cuts = [start - _WALL / 2] + [c for d in sorted(doors) for c in d] + [end + _WALL / 2]
    return list(zip(cuts[::2], cuts[1::2]))


def _office_walls() -> list[tuple[float, float, float, float]]:
    """Wall boxes (xmin, ymin, xmax, ymax) of the office."""
    h = _WALL / 2
    boxes = [(a, y - h, b, y + h) for y, s, e, d in _OFFICE_H_WALLS for a, b in _wall_pieces(s, e, d)]
    boxes += [(x - h, a, x + h, b) for x, s, e, d in _OFFICE_V_WALLS for a, b in _wall_pieces(s, e, d)]
    return boxes


def load_world(world: str, resolution: float = 0.05) -> World:
    """A built-in world by name (``office``) or an occupancy PNG at that path (here, else under SLAM2D_DATA)."""
    if world == "office":
        return World.office()
    return World.from_png(find_data_path(world), resolution)


