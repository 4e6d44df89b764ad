"""Spans across a world's rooms, with their true wall faces, for the map-accuracy measure
(:mod:`slam2d.evaluation.map_accuracy`): named ones in the office, seeded ones in any world."""

from __future__ import annotations

import numpy as np

from slam2d.errors import InputError
from slam2d.evaluation.map_accuracy import Span
from slam2d.sim.world import World

__all__ = ["OFFICE_SPANS", "RANDOM_SPANS", "random_spans", "span_between_faces", "spans_of", "world_spans"]

MAX_SPAN = 25.0  # m, the longest span looked for
RANDOM_SPANS = 12  # spans drawn in a world without named ones
# (name, origin (x, y) m, axis) across the office's rooms, clear of furniture and doorways
OFFICE_SPANS = [
    ("B1 east-west", (2.5, 2.0), "x"),
    ("B1 north-south", (4.0, 2.0), "y"),
    ("B2 east-west", (7.5, 2.0), "x"),
    ("B3 east-west", (12.5, 3.0), "x"),
    ("B4 east-west", (17.5, 3.0), "x"),
    ("west lobby north-south", (2.0, 6.0), "y"),
    ("east lobby north-south", (18.0, 6.0), "y"),
    ("south corridor, end to end", (10.0, 4.2), "x"),
    ("T1 east-west", (3.0, 9.3), "x"),
    ("T2 east-west", (8.0, 9.5), "x"),
    ("T3 north-south", (16.0, 10.0), "y"),
]


def span_between_faces(world: World, name: str, origin, axis: str) -> Span:
    """The span from ``origin`` (m, free) along ``axis`` ("x" or "y") to the world's first faces both ways."""
    if axis not in ("x", "y"):
        raise InputError(f"span {name!r}", f"axis must be 'x' or 'y', got {axis!r}")
    if world.occupied([origin])[0]:
        raise InputError(f"span {name!r}", f"origin ({origin[0]:g}, {origin[1]:g}) m lies inside an obstacle of {world.name}")
    angle = 0.0 if axis == "x" else np.pi / 2
    far, near = world.raycast(origin, [angle, angle + np.pi], MAX_SPAN)
    if max(near, far) >= MAX_SPAN:
        raise InputError(f"span {name!r}", f"no wall within {MAX_SPAN:g} m of ({origin[0]:g}, {origin[1]:g}) along {axis}")
    unit = (1.0, 0.0) if axis == "x" else (0.0, 1.0)
    return Span(name, (float(origin[0]), float(origin[1])), unit, float(near), float(far))


def world_spans(world: World, definitions=None) -> list[Span]:
    """Spans of ``definitions`` ((name, origin, axis), default :data:`OFFICE_SPANS`) in ``world``."""
    return [span_between_faces(world, *d) for d in (OFFICE_SPANS if definitions is None else definitions)]


def spans_of(world: World, seed: int = 0) -> list[Span]:
    """The office's named spans, or :data:`RANDOM_SPANS` seeded ones in any other world."""
    return world_spans(world) if world.name == "office" else random_spans(world, RANDOM_SPANS, seed)


def random_spans(world: World, count: int, seed: int = 0, min_length: float = 1.5, clearance: float = 0.3,
                 attempts: int = 10_000) -> list[Span]:
    """``count`` seeded axis-aligned spans of at least ``min_length`` m from free points ``clearance`` m from
    any wall, for worlds without named spans (floor plans)."""
    rng = np.random.default_rng(seed)
    (x0, y0), (x1, y1) = world.bounds
    spans: list[Span] = []
    for _ in range(attempts):
        if len(spans) == count:
            break
        origin = rng.uniform((x0, y0), (x1, y1))
        if not world.free([origin], clearance)[0] or _unmapped(world, origin):
            continue
        axis = "xy"[len(spans) % 2]
        try:
            span = span_between_faces(world, f"{axis} span {len(spans) + 1}", origin, axis)
        except InputError:  # open to one side (a plan's pinholes)
            continue
        if span.length >= min_length:
            spans.append(span)
    return spans


def _unmapped(world: World, point) -> bool:
    """Whether ``point`` (m) falls on a cell the plan leaves unknown (outside a scanned plan)."""
    if world.unmapped is None:
        return False
    col, row = np.floor(np.asarray(point) / world.grid[1]).astype(int)
    h, w = world.unmapped.shape
    return not (0 <= row < h and 0 <= col < w) or bool(world.unmapped[row, col])
