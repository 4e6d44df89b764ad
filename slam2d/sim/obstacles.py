"""Moving obstacles: discs on a waypoint loop or a seeded random walk in free space.

A :class:`~slam2d.sim.world.World` does not hold them; a
:class:`~slam2d.sim.robot.Robot` moves them in each step, its laser sees them
and a collision with one is reported. An obstacle never walks into the robot:
it stops where it would touch it (and walls, for the random walk). Obstacles
may overlap each other.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from slam2d.errors import InputError
from slam2d.sim.world import World

__all__ = ["MovingObstacle", "LoopingDisc", "WanderingDisc", "scatter_wanderers"]


class MovingObstacle(Protocol):
    """A disc of ``radius`` (m) at ``centre`` (2,) that moves when told."""

    centre: np.ndarray
    radius: float

    def advance(self, dt: float, rng: np.random.Generator, blocker) -> None:
        """Move for ``dt`` s, stopping short of ``blocker`` circles (centres (K, 2), radii (K,))."""
        ...


def _check_disc(radius: float, speed: float) -> None:
    if not (radius > 0 and speed >= 0 and np.isfinite([radius, speed]).all()):
        raise InputError("obstacle", f"needs radius > 0 m and speed >= 0 m/s, got {radius} and {speed}")


class LoopingDisc:
    """A disc going round the closed loop through ``waypoints`` (M, 2) m at ``speed`` m/s,
    from the first waypoint; it waits while the robot blocks its way."""

    def __init__(self, world: World, waypoints, radius: float = 0.25, speed: float = 0.5):
        _check_disc(radius, speed)
        wp = np.asarray(waypoints, dtype=np.float64)
        if wp.ndim != 2 or wp.shape[1] != 2 or len(wp) < 2 or not np.isfinite(wp).all():
            raise InputError("obstacle.waypoints", f"a loop needs >= 2 finite (x, y) waypoints, got shape {wp.shape}")
        loop = np.vstack([wp, wp[:1]])
        if world.segment_distance(np.stack([loop[:-1], loop[1:]], axis=1)).min() < radius:
            raise InputError("obstacle.waypoints", f"the loop passes closer than {radius} m to a wall of {world.name}")
        self.world, self.radius, self.speed = world, float(radius), float(speed)
        self._loop = loop
        self._arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(loop, axis=0), axis=1))])
        if not self._arc[-1] > 0:
            raise InputError("obstacle.waypoints", "the loop has zero length")
        self._s = 0.0  # m travelled
        self.centre = wp[0].copy()

    def advance(self, dt: float, rng: np.random.Generator, blocker) -> None:
        """Go ``speed * dt`` m further round the loop, or up to where ``blocker`` is touched."""
        s0, s1, length = self._s, self._s + self.speed * dt, self._arc[-1]
        laps = np.arange(np.floor(s0 / length), np.floor(s1 / length) + 1)
        knots = (laps[:, None] * length + self._arc[None]).ravel()
        arcs = np.concatenate([[s0], knots[(knots > s0) & (knots < s1)], [s1]])
        hit = self.world.sweep(self._at(arcs), self.radius, blocker)
        if hit is not None:
            s1 = arcs[hit.leg] + hit.fraction * (arcs[hit.leg + 1] - arcs[hit.leg])
        self._s = s1
        self.centre = self._at(np.array([s1]))[0]

    def _at(self, arcs: np.ndarray) -> np.ndarray:
        """Points (A, 2) at distances ``arcs`` (A,) m along the loop, lap after lap."""
        s = np.mod(arcs, self._arc[-1])
        return np.column_stack([np.interp(s, self._arc, self._loop[:, i]) for i in (0, 1)])


class WanderingDisc:
    """A disc on a random walk at ``speed`` m/s whose heading diffuses by ``turn_sd`` rad per
    sqrt(s); where it touches a wall, the bounds or the robot it stops and picks a new heading."""

    def __init__(self, world: World, start, radius: float = 0.25, speed: float = 0.5, turn_sd: float = 1.0):
        _check_disc(radius, speed)
        self.centre = np.asarray(start, dtype=np.float64).reshape(2).copy()
        if not world.free(self.centre, radius)[0]:
            x, y = self.centre
            raise InputError("obstacle.start", f"({x:.2f}, {y:.2f}) has no room for a {radius} m disc in {world.name}")
        self.world, self.radius, self.speed, self.turn_sd = world, float(radius), float(speed), float(turn_sd)
        self.heading: float | None = None  # rad; drawn at the first step

    def advance(self, dt: float, rng: np.random.Generator, blocker) -> None:
        """Walk ``speed * dt`` m along the diffused heading, or up to the first contact."""
        if self.heading is None:
            self.heading = rng.uniform(-np.pi, np.pi)
        self.heading += rng.normal(0.0, self.turn_sd * np.sqrt(dt))
        end = self.centre + self.speed * dt * np.array([np.cos(self.heading), np.sin(self.heading)])
        hit = self.world.sweep(np.stack([self.centre, end]), self.radius, blocker)
        if hit is None:
            self.centre = end
            return
        self.centre = self.centre + hit.fraction * (end - self.centre)
        self.heading = rng.uniform(-np.pi, np.pi)


def scatter_wanderers(
    world: World, count: int, rng: np.random.Generator, *, radius: float = 0.25, speed: float = 0.5, keep_clear=None
) -> list[WanderingDisc]:
    """``count`` wandering discs at random free places, at least a diameter apart and
    clear of ``keep_clear`` circles (centres (K, 2), radii (K,) m), e.g. the robot at its start."""
    centres, radii = keep_clear if keep_clear is not None else (np.zeros((0, 2)), np.zeros(0))
    centres, radii = np.asarray(centres, float).reshape(-1, 2), np.asarray(radii, float).reshape(-1)
    candidates = rng.uniform(world.bounds[0], world.bounds[1], (max(50 * count, 1), 2))
    chosen: list[np.ndarray] = []
    for c in candidates[world.free(candidates, radius)]:
        if len(chosen) == count:
            break
        clear = np.all(np.linalg.norm(centres - c, axis=1) >= radii + radius)
        if clear and all(np.linalg.norm(p - c) >= 2 * radius for p in chosen):
            chosen.append(c)
    if len(chosen) < count:
        raise InputError("obstacles", f"found room for {len(chosen)} of {count} discs of {radius} m in {world.name}")
    return [WanderingDisc(world, c, radius, speed) for c in chosen]
