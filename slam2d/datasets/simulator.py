"""Simulated dataset: wall worlds, ray-cast laser scans, noisy odometry, ground truth.

The embedded default is :meth:`World.office` driven along :func:`office_route`;
it needs no files. A world is a set of wall segments ``(K, 2, 2)`` in metres.
A robot turns in place and drives straight between waypoints; at every scan
period it casts its laser against the walls and integrates noisy odometry
(Thrun et al., *Probabilistic Robotics*, ``sample_motion_model_odometry``).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from slam2d import geometry
from slam2d.config import LaserModel, OdometryNoise, SimulatorConfig
from slam2d.datasets.base import ScanSource
from slam2d.errors import InputError
from slam2d.types import Scan

__all__ = [
    "ROBOT_RADIUS",
    "World",
    "office_route",
    "load_world",
    "check_route",
    "route_poses",
    "sample_odometry",
    "beam_angles",
    "measure_ranges",
    "SimulatorSource",
]

ROBOT_RADIUS = 0.2  # m; a route must keep at least this far from every wall
_ROUTE_KEY = "dataset.simulator.route"
_PAIRS_PER_BATCH = 200_000  # beam x segment pairs per ray-casting batch
_EPS = 1e-9


# --------------------------------------------------------------------------- geometry helpers


def _cross(ax, ay, bx, by):
    return ax * by - ay * bx


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


class World:
    """Walls as segments ``(K, 2, 2)`` in metres; ``bounds`` is ``[[xmin, ymin], [xmax, ymax]]``.

    ``solids`` (closed rings whose interior is obstacle) and ``grid`` (occupancy
    cells, resolution) only serve :meth:`occupied`; ray casting uses the segments.
    """

    def __init__(self, segments, bounds=None, *, solids=(), grid=None, name: str = "world"):
        self.segments = np.asarray(segments, dtype=np.float64).reshape(-1, 2, 2)
        if bounds is None:
            pts = self.segments.reshape(-1, 2)
            bounds = [pts.min(0), pts.max(0)] if len(pts) else [[0.0, 0.0], [0.0, 0.0]]
        self.bounds = np.asarray(bounds, dtype=np.float64).reshape(2, 2)
        self.solids = [np.asarray(r, dtype=np.float64) for r in solids]
        self.grid = grid
        self.name = name

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
        corner (image row 0 is the top, at the largest y).
        """
        path = Path(path)
        if not path.is_file():
            raise InputError(path, "world PNG not found")
        if not resolution > 0:
            raise InputError(path, f"resolution must be > 0 m per pixel, got {resolution}")
        from PIL import Image, UnidentifiedImageError

        try:
            with Image.open(path) as img:
                gray = np.asarray(img.convert("L"))
        except (OSError, UnidentifiedImageError) as err:
            raise InputError(path, f"not a readable image ({err})") from None
        occ = gray[::-1] < 128
        h, w = occ.shape
        return cls(
            _grid_boundaries(occ, resolution),
            bounds=[[0.0, 0.0], [w * resolution, h * resolution]],
            grid=(occ, float(resolution)),
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
        return _point_segment_distance(pts, self.segments).min(axis=1)

    def raycast(self, origin, angles, max_range: float) -> np.ndarray:
        """Ranges (n,) in metres from ``origin`` (2,) along world-frame ``angles`` (n,) rad.

        A beam that hits nothing within ``max_range`` returns ``max_range``.
        """
        origin = np.asarray(origin, dtype=np.float64).reshape(1, 2)
        angles = np.asarray(angles, dtype=np.float64).reshape(1, -1)
        return self.raycast_many(origin, angles, max_range)[0]

    def raycast_poses(self, poses, beam_angles, max_range: float) -> np.ndarray:
        """Ranges (P, n) from sensor poses (P, 3) along beam angles (n,) in the sensor frame."""
        poses = geometry.as_pose(poses).reshape(-1, 3)
        angles = poses[:, 2:3] + np.asarray(beam_angles, dtype=np.float64)[None]
        return self.raycast_many(poses[:, :2], angles, max_range)

    def raycast_many(self, origins, angles, max_range: float) -> np.ndarray:
        """Ranges (P, n) from origins (P, 2) along world-frame angles (P, n), capped at ``max_range``."""
        origins = np.asarray(origins, dtype=np.float64).reshape(-1, 2)
        angles = np.asarray(angles, dtype=np.float64).reshape(len(origins), -1)
        out = np.full(angles.shape, float(max_range))
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
        """Segments whose bounding box comes within ``max_range`` of the origins' box."""
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


def office_route() -> np.ndarray:
    """Scripted waypoints (M, 2) in metres through the office, about 100 m.

    Starts in the south corridor, goes twice counter-clockwise round the
    corridor ring, enters five rooms and crosses the open-plan room, and ends
    at the start.
    """
    s, n = 4.225, 7.775  # centre lines of the south and north corridors
    lap1 = [
        (5.5, s), (7.5, s), (7.5, 2.2), (6.0, 2.2), (9.0, 2.2), (7.5, 2.2), (7.5, s),  # room B2
        (12.5, s), (12.5, 1.9), (12.5, s),  # room B3
        (17.3, s), (17.3, n), (12.0, n),
        (12.0, 9.5), (8.0, 9.5), (8.0, n),  # through the open-plan room T2
        (3.0, n), (3.0, s), (5.5, s),
    ]  # fmt: skip
    lap2 = [
        (17.3, s), (17.3, 1.9), (17.3, s),  # room B4
        (17.3, n), (17.0, n), (17.0, 10.2), (17.0, n),  # room T3
        (12.0, n), (12.0, 9.5), (8.0, 9.5), (8.0, n),  # T2 again
        (3.0, n), (3.0, 9.5), (3.0, n),  # room T1
        (3.0, s), (3.0, 1.9), (3.0, s),  # room B1
        (5.5, s),
    ]  # fmt: skip
    return np.array(lap1 + lap2, dtype=np.float64)


def load_world(world: str, resolution: float = 0.05) -> World:
    """A built-in world by name (``office``) or an occupancy PNG at that path."""
    if world == "office":
        return World.office()
    return World.from_png(world, resolution)


# --------------------------------------------------------------------------- motion and sensing


def check_route(world: World, waypoints, clearance: float = ROBOT_RADIUS) -> np.ndarray:
    """Waypoints (M, 2) as float array; InputError if one or a leg comes within ``clearance`` m of a wall."""
    wp = np.asarray(waypoints, dtype=np.float64)
    if wp.ndim != 2 or wp.shape[1] != 2 or len(wp) < 2 or not np.isfinite(wp).all():
        raise InputError(_ROUTE_KEY, f"a route needs at least two finite (x, y) waypoints, got shape {wp.shape}")
    (x0, y0), (x1, y1) = world.bounds
    outside = (wp[:, 0] < x0) | (wp[:, 0] > x1) | (wp[:, 1] < y0) | (wp[:, 1] > y1)
    inside = world.occupied(wp)
    near = world.distance(wp) < clearance
    for bad, what in ((outside, f"is outside {world.name}"), (inside, "is inside a wall")):
        if bad.any():
            i = int(np.argmax(bad))
            raise InputError(_ROUTE_KEY, f"waypoint {i} ({wp[i, 0]:.2f}, {wp[i, 1]:.2f}) {what}")
    if near.any():
        i = int(np.argmax(near))
        raise InputError(
            _ROUTE_KEY, f"waypoint {i} ({wp[i, 0]:.2f}, {wp[i, 1]:.2f}) is closer than {clearance} m to a wall"
        )
    if len(world.segments):
        legs = np.stack([wp[:-1], wp[1:]], axis=1)
        near = _segment_distance(legs, world.segments).min(axis=1) < clearance
        if near.any():
            i = int(np.argmax(near))
            (ax, ay), (bx, by) = wp[i], wp[i + 1]
            raise InputError(
                _ROUTE_KEY,
                f"leg {i} -> {i + 1} from ({ax:.2f}, {ay:.2f}) to ({bx:.2f}, {by:.2f}) "
                f"crosses a wall or passes closer than {clearance} m to one",
            )
    return wp


def route_poses(waypoints, speed: float, turn_rate: float, scan_rate: float) -> tuple[np.ndarray, np.ndarray]:
    """Ground truth along waypoints: turn in place at ``turn_rate`` (rad/s), then drive at ``speed`` (m/s).

    Returns stamps (N,) in seconds, one every ``1 / scan_rate``, and poses (N, 3).
    The robot starts at the first waypoint facing the second.
    """
    wp = np.asarray(waypoints, dtype=np.float64)
    wp = wp[np.r_[True, np.linalg.norm(np.diff(wp, axis=0), axis=1) > _EPS]]
    if len(wp) < 2:
        raise InputError(_ROUTE_KEY, "a route needs at least two distinct waypoints")
    d = np.diff(wp, axis=0)
    heading = np.arctan2(d[:, 1], d[:, 0])
    turns = geometry.wrap_angle(np.diff(heading, prepend=heading[0]))
    # knots: start, then per leg "turned at its start" and "arrived at its end"
    knots = np.empty((2 * len(d) + 1, 3))
    knots[0] = (*wp[0], heading[0])
    knots[1::2, :2], knots[2::2, :2] = wp[:-1], wp[1:]
    knots[1::2, 2] = knots[2::2, 2] = heading
    durations = np.column_stack([np.abs(turns) / turn_rate, np.linalg.norm(d, axis=1) / speed]).ravel()
    t_knots = np.concatenate([[0.0], np.cumsum(durations)])
    stamps = np.arange(int(np.floor(t_knots[-1] * scan_rate + _EPS)) + 1) / scan_rate
    return stamps, geometry.interpolate(t_knots, knots, stamps)


def sample_odometry(poses, noise: OdometryNoise, rng: np.random.Generator) -> np.ndarray:
    """Odometry poses (N, 3) starting at the true start pose, from ground-truth poses (N, 3).

    Every step between consecutive poses is split into (rot1, trans, rot2) and
    perturbed as in ``sample_motion_model_odometry``: var(rot1) = a1 rot1^2 + a2 trans^2,
    var(trans) = a3 trans^2 + a4 (rot1^2 + rot2^2), var(rot2) = a1 rot2^2 + a2 trans^2.
    Variances grow with the square of each step, so the drift over a route also
    depends on the scan rate (finer steps, less drift).
    """
    poses = geometry.as_pose(poses).reshape(-1, 3)
    d = np.diff(poses[:, :2], axis=0)
    trans = np.hypot(d[:, 0], d[:, 1])
    moving = trans > _EPS
    rot1 = np.where(moving, geometry.wrap_angle(np.arctan2(d[:, 1], d[:, 0]) - poses[:-1, 2]), 0.0)
    rot2 = geometry.wrap_angle(np.diff(poses[:, 2]) - rot1)
    a1, a2, a3, a4 = noise.alpha1, noise.alpha2, noise.alpha3, noise.alpha4
    e = rng.standard_normal((3, len(d)))
    sd_rot1 = np.sqrt(a1 * rot1**2 + a2 * trans**2)
    sd_trans = np.sqrt(a3 * trans**2 + a4 * (rot1**2 + rot2**2))
    sd_rot2 = np.sqrt(a1 * rot2**2 + a2 * trans**2)
    rot1, trans, rot2 = rot1 - e[0] * sd_rot1, trans - e[1] * sd_trans, rot2 - e[2] * sd_rot2
    theta = poses[0, 2] + np.concatenate([[0.0], np.cumsum(rot1 + rot2)])
    direction = theta[:-1] + rot1
    steps = trans[:, None] * np.column_stack([np.cos(direction), np.sin(direction)])
    xy = poses[0, :2] + np.vstack([np.zeros((1, 2)), np.cumsum(steps, axis=0)])
    return np.column_stack([xy, geometry.wrap_angle(theta)])


def beam_angles(laser: LaserModel) -> np.ndarray:
    """Beam angles (n,) in rad in the sensor frame, spread over ``fov_deg`` centred on the heading."""
    if laser.fov_deg >= 360.0:
        return np.linspace(-np.pi, np.pi, laser.beams, endpoint=False)
    half = np.deg2rad(laser.fov_deg) / 2
    return np.linspace(-half, half, laser.beams)


def measure_ranges(true_ranges, laser: LaserModel, noise, dropped) -> np.ndarray:
    """Laser readings from true ranges (m): ``noise`` (m) added to hits, ``dropped`` beams NaN.

    Beams that hit nothing before ``range_max`` read exactly ``range_max`` (no return);
    hits closer than ``range_min`` are NaN.
    """
    r = np.asarray(true_ranges, dtype=np.float64)
    out = np.where(r < laser.range_max, np.minimum(r + noise, laser.range_max), laser.range_max)
    out[(r < laser.range_min) | dropped] = np.nan
    return out


# --------------------------------------------------------------------------- the scan source


class SimulatorSource(ScanSource):
    """Scans of a simulated robot: ray-cast laser, noisy odometry, ground truth.

    ``world``, ``stamps`` (N,) s, ``ground_truth_poses`` (N, 3), ``odometry_poses``
    (N, 3) and ``beam_angles`` (n,) are available before iterating. The same
    ``seed`` gives identical scans, iteration after iteration.
    """

    name = "simulator"

    def __init__(self, cfg: SimulatorConfig, seed: int = 0, max_scans: int | None = None):
        super().__init__()
        if max_scans is not None and max_scans < 1:
            raise InputError("dataset.max_scans", f"must be >= 1, got {max_scans}")
        self.cfg = cfg
        self.world = load_world(cfg.world, cfg.resolution)
        self.name = f"simulator:{self.world.name}"
        self.waypoints = check_route(self.world, self._route())
        stamps, poses = route_poses(self.waypoints, cfg.speed, cfg.turn_rate, cfg.scan_rate)
        odom_seed, self._noise_seed, self._dropout_seed = np.random.SeedSequence(seed).spawn(3)
        odom = sample_odometry(poses, cfg.odometry, np.random.default_rng(odom_seed))
        n = len(stamps) if max_scans is None else min(max_scans, len(stamps))
        self.stamps, self.ground_truth_poses, self.odometry_poses = stamps[:n], poses[:n], odom[:n]
        self.beam_angles = beam_angles(cfg.laser)

    def _route(self) -> np.ndarray:
        if self.cfg.route is not None:
            return np.asarray(self.cfg.route, dtype=np.float64)
        if self.cfg.world == "office":
            return office_route()
        raise InputError(_ROUTE_KEY, f"world '{self.cfg.world}' has no scripted route; give waypoints")

    def __len__(self) -> int:
        return len(self.stamps)

    def _raw_scans(self, batch: int = 64) -> Iterator[Scan]:
        laser, n = self.cfg.laser, len(self)
        shape = (n, len(self.beam_angles))
        noise = np.random.default_rng(self._noise_seed).normal(0.0, laser.range_noise, shape)
        dropped = np.random.default_rng(self._dropout_seed).random(shape) < laser.dropout
        sensor_pose = np.zeros(3)
        for i in range(0, n, batch):
            sl = slice(i, i + batch)
            true = self.world.raycast_poses(self.ground_truth_poses[sl], self.beam_angles, laser.range_max)
            ranges = measure_ranges(true, laser, noise[sl], dropped[sl])
            for k, r in enumerate(ranges, start=i):
                yield Scan(
                    stamp=float(self.stamps[k]),
                    ranges=r,
                    angles=self.beam_angles.copy(),
                    range_min=laser.range_min,
                    range_max=laser.range_max,
                    sensor_pose=sensor_pose.copy(),
                    odom=self.odometry_poses[k].copy(),
                    ground_truth=self.ground_truth_poses[k].copy(),
                    index=k,
                )
