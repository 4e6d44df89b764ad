"""Objects with heights in a 2D world: low boxes, tables, chairs and shelves as axis-aligned solid parts.

Floor plans stay 2D. An :class:`Objects3D` is a set of parts ``(x0, y0, z0, x1, y1, z1)`` in metres
(z up from the floor), grouped into objects. :func:`furnish` adds them to a
:class:`~slam2d.sim.world.World`: the parts crossing the laser's height become walls (so the
2D laser, the world's map and collisions see a table's legs, not its top, a low box or a shelf
board), and the world keeps them all in ``world.objects`` for the depth camera
(:mod:`slam2d.sim.depth`) and for collisions with the robot's body
(:class:`~slam2d.sim.robot.Robot`). Objects come from a list (:class:`slam2d.config.ObjectSpec`),
a YAML file, or are scattered by a seed (:func:`scatter_objects`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from pydantic import ValidationError

from slam2d.config import ObjectsConfig, ObjectSpec
from slam2d.errors import InputError, read_text
from slam2d.paths import find_data_path
from slam2d.sim.world import World, _box

__all__ = ["Objects3D", "furnish", "load_objects", "object_parts", "objects_from_config", "scatter_objects"]

LEG = 0.04  # m, side of a table or chair leg
TOP = 0.03  # m, thickness of a table top or a seat
PANEL = 0.02  # m, thickness of a shelf's end panel or a chair's back
DEFAULT_Z = {"box": (0.0, 0.04), "table": (0.0, 0.72), "chair": (0.0, 0.45), "shelf": (0.30, 0.34)}
CHAIR_BACK = 0.4  # m above the seat
_EPS = 1e-12


@dataclass(frozen=True, eq=False)
class Objects3D:
    """Solid axis-aligned ``parts`` (N, 6) ``x0, y0, z0, x1, y1, z1`` (m), ``owner`` (N,) the index
    of the object each belongs to, ``kinds`` the objects' kinds."""

    parts: np.ndarray
    owner: np.ndarray
    kinds: tuple[str, ...] = ()

    @classmethod
    def from_specs(cls, specs) -> Objects3D:
        """Objects from :class:`ObjectSpec` s."""
        pieces = [object_parts(s) for s in specs]
        parts = np.concatenate(pieces) if pieces else np.zeros((0, 6))
        owner = np.repeat(np.arange(len(pieces)), [len(p) for p in pieces]).astype(np.int64)
        return cls(parts, owner, tuple(s.kind for s in specs))

    def __len__(self) -> int:
        return len(self.kinds)

    def overlapping(self, lo: float, hi: float) -> np.ndarray:
        """Which parts (N,) share some height with [``lo``, ``hi``] m."""
        return (self.parts[:, 2] <= hi) & (self.parts[:, 5] >= lo)

    def footprints(self, mask=None) -> list[np.ndarray]:
        """Rings (4, 2) of the footprints of the parts in ``mask`` (all by default)."""
        p = self.parts if mask is None else self.parts[mask]
        return [_box(x0, y0, x1, y1) for x0, y0, _, x1, y1, _ in p]

    def raycast(self, origins, directions, max_range: float) -> np.ndarray:
        """Distance (R,) along rays from ``origins`` (3,) or (R, 3) in unit ``directions`` (R, 3) to the
        first part hit (slab method); inf if none within ``max_range`` m."""
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        o = np.broadcast_to(np.asarray(origins, dtype=np.float64).reshape(-1, 3), d.shape)
        out = np.full(len(d), np.inf)
        lo_xy, hi_xy = o[:, :2].min(0) - max_range, o[:, :2].max(0) + max_range
        near = np.all((self.parts[:, 3:5] >= lo_xy) & (self.parts[:, :2] <= hi_xy), axis=1)
        parts = self.parts[near]
        if len(parts) == 0 or len(d) == 0:
            return out
        inv = 1.0 / np.where(np.abs(d) < _EPS, _EPS, d)  # (R, 3)
        enter, leave = np.zeros((len(d), len(parts))), np.full((len(d), len(parts)), np.inf)
        for k in range(3):  # the slabs of x, y, z: (R, P) each
            a = (parts[None, :, k] - o[:, k : k + 1]) * inv[:, k : k + 1]
            b = (parts[None, :, k + 3] - o[:, k : k + 1]) * inv[:, k : k + 1]
            np.maximum(enter, np.minimum(a, b), out=enter)
            np.minimum(leave, np.maximum(a, b), out=leave)
        hit = (leave >= enter) & (enter > 0) & (enter <= max_range)
        return np.where(hit, enter, np.inf).min(axis=1)


def object_parts(spec: ObjectSpec) -> np.ndarray:
    """The solid parts (K, 6) of one object (see :class:`slam2d.config.ObjectSpec`)."""
    (cx, cy), (w, d) = spec.at, spec.size
    z0, z1 = spec.z if spec.z is not None else DEFAULT_Z[spec.kind]
    x0, y0, x1, y1 = cx - w / 2, cy - d / 2, cx + w / 2, cy + d / 2
    if spec.kind == "box":
        return np.array([[x0, y0, z0, x1, y1, z1]])
    if spec.kind == "shelf":
        panel = min(PANEL, w / 4)
        return np.array([[x0, y0, z0, x1, y1, z1], [x0, y0, 0.0, x0 + panel, y1, z1], [x1 - panel, y0, 0.0, x1, y1, z1]])
    leg = min(LEG, w / 3, d / 3)
    top = min(TOP, (z1 - z0) / 2)
    legs = [[x, y, z0, x + leg, y + leg, z1 - top] for x in (x0, x1 - leg) for y in (y0, y1 - leg)]
    parts = [*legs, [x0, y0, z1 - top, x1, y1, z1]]
    if spec.kind == "chair":
        parts.append([x0, y1 - min(PANEL, d / 4), z1, x1, y1, z1 + CHAIR_BACK])
    return np.array(parts, dtype=np.float64)


def load_objects(path) -> list[ObjectSpec]:
    """The objects listed in a YAML file (a list of :class:`ObjectSpec` mappings)."""
    path = find_data_path(path)
    data = yaml.safe_load(read_text(path)) or []
    if not isinstance(data, list):
        raise InputError(path, f"must hold a list of objects, got {type(data).__name__}")
    specs = []
    for i, item in enumerate(data):
        try:
            specs.append(ObjectSpec.model_validate(item))
        except ValidationError as err:
            first = err.errors()[0]
            key = ".".join(str(k) for k in first["loc"])
            raise InputError(path, f"object {i}{': ' + key if key else ''}: {first['msg']}") from None
    return specs


def _random_spec(kind: str, at, rng: np.random.Generator) -> ObjectSpec:
    """A ``kind`` object of random size (the ranges of :class:`slam2d.config.ObjectsConfig`) at ``at``."""
    if kind == "box":
        return ObjectSpec(kind=kind, at=at, size=tuple(rng.uniform(0.2, 0.4, 2)), z=(0.0, rng.uniform(0.03, 0.05)))
    if kind == "table":
        return ObjectSpec(kind=kind, at=at, size=(rng.uniform(0.8, 1.2), rng.uniform(0.6, 0.8)))
    if kind == "chair":
        return ObjectSpec(kind=kind, at=at, size=(0.45, 0.45))
    return ObjectSpec(kind=kind, at=at, size=(rng.uniform(0.8, 1.2), 0.3))


def _half_diagonal(spec: ObjectSpec) -> float:
    return float(np.hypot(*spec.size)) / 2


def _outline(spec: ObjectSpec, spacing: float = 0.05) -> np.ndarray:
    """Points (P, 2) on the edges of a footprint, at most ``spacing`` m apart, and its centre."""
    (cx, cy), (w, d) = spec.at, spec.size
    ring = _box(cx - w / 2, cy - d / 2, cx + w / 2, cy + d / 2)
    edges = [np.linspace(a, b, int(np.ceil(np.linalg.norm(b - a) / spacing)) + 1) for a, b in zip(ring, np.roll(ring, -1, 0))]
    return np.vstack([*edges, [spec.at]])


def _gap(a: ObjectSpec, b: ObjectSpec) -> float:
    """A lower bound (m) of the distance between two axis-aligned footprints."""
    dx = abs(a.at[0] - b.at[0]) - (a.size[0] + b.size[0]) / 2
    dy = abs(a.at[1] - b.at[1]) - (a.size[1] + b.size[1]) / 2
    return max(dx, dy)


def scatter_objects(world: World, counts: dict[str, int], rng: np.random.Generator, *, keep_clear=None,
                    along=None, spread: float = 0.6, passage: float = 0.7, tries: int = 500) -> list[ObjectSpec]:  # fmt: skip
    """Objects of random size, ``counts`` per kind ("box", "table", "chair", "shelf"), at random free
    places: each footprint at least ``passage`` m from every wall and from the others (so that a robot
    narrower than that passes everywhere), clear of ``keep_clear`` circles (centres (K, 2), radii (K,) m),
    and, given ``along`` (L, 2) a polyline, with its centre within ``spread`` m of it. An object with no
    such place in ``tries`` draws is left out (``len`` of the result tells)."""
    centres, radii = keep_clear if keep_clear is not None else (np.zeros((0, 2)), np.zeros(0))
    centres, radii = np.asarray(centres, float).reshape(-1, 2), np.asarray(radii, float).reshape(-1)
    kinds = [k for k in ("table", "shelf", "chair", "box") for _ in range(counts.get(k, 0))]  # big ones first
    chosen: list[ObjectSpec] = []
    for kind in kinds:
        for _ in range(tries):
            spec = _random_spec(kind, _candidate(world, rng, along, spread), rng)
            if np.any(np.hypot(*(centres - spec.at).T) < radii + _half_diagonal(spec)):
                continue
            if all(_gap(spec, o) >= passage for o in chosen) and world.free(_outline(spec), passage).all():
                chosen.append(spec)
                break
    return chosen


def _candidate(world: World, rng: np.random.Generator, along, spread: float) -> tuple[float, float]:
    """A random point (x, y) in the world's bounds, or within ``spread`` m of the polyline ``along``."""
    if along is None or len(along) < 2:
        return tuple(float(v) for v in rng.uniform(world.bounds[0], world.bounds[1]))
    path = np.asarray(along, dtype=np.float64)
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    i = rng.choice(len(seg), p=seg / seg.sum())
    p = path[i] + rng.uniform() * (path[i + 1] - path[i])
    r, a = spread * np.sqrt(rng.uniform()), rng.uniform(-np.pi, np.pi)
    return float(p[0] + r * np.cos(a)), float(p[1] + r * np.sin(a))


def furnish(world: World, objects: Objects3D, laser_height: float) -> World:
    """``world`` with ``objects``: the footprints of the parts crossing ``laser_height`` (m) are walls
    and obstacles of the new world (the laser and the map see them); all parts in ``world.objects``."""
    rings = objects.footprints(objects.overlapping(laser_height, laser_height))
    added = np.concatenate([np.stack([r, np.roll(r, -1, axis=0)], axis=1) for r in rings]) if rings else None
    segments = world.segments if added is None else np.concatenate([world.segments, added])
    out = World(segments, world.bounds, solids=[*world.solids, *rings], grid=_grid_with(world, rings),
                unmapped=world.unmapped, name=world.name)  # fmt: skip
    out.objects = objects
    return out


def _grid_with(world: World, rings) -> tuple[np.ndarray, float] | None:
    """A PNG world's occupancy cells with every cell a ring's box overlaps occupied."""
    if world.grid is None or not rings:
        return world.grid
    occ, res = world.grid
    occ = occ.copy()
    for r in rings:
        (c0, r0), (c1, r1) = np.floor(r.min(0) / res).astype(int), np.floor(r.max(0) / res).astype(int) + 1
        occ[max(r0, 0) : max(r1, 0), max(c0, 0) : max(c1, 0)] = True
    return occ, res


def objects_from_config(cfg: ObjectsConfig, world: World, rng: np.random.Generator, *, keep_clear=None,
                        along=None) -> Objects3D:  # fmt: skip
    """The objects ``cfg`` lists, reads from its file and scatters (with ``rng``)."""
    specs = list(cfg.items) + (load_objects(Path(cfg.file)) if cfg.file else [])
    counts = {"box": cfg.boxes, "table": cfg.tables, "chair": cfg.chairs, "shelf": cfg.shelves}
    if any(counts.values()):
        specs += scatter_objects(world, counts, rng, keep_clear=keep_clear, along=along if cfg.along_path else None,
                                 spread=cfg.spread)  # fmt: skip
    return Objects3D.from_specs(specs)
