"""Active localisation: where to look to tell the filter's hypotheses apart.

After Burgard, Fox & Thrun, "Active mobile robot localization" (IJCAI 1997): while
the filter is ``ambiguous``, a place from which the scans predicted under each
hypothesis differ tells them apart. A goal is a pose relative to the best
hypothesis; under hypothesis h the robot would stand at h composed with that
relative pose. The scan predicted there under the best (ray cast in the map) is
scored under each other hypothesis as the filter would score it: the evidence one
scan would add. Only goals free in every hypothesis are offered (driving there is
safe whichever is true); the nearest by the way the robot drives (round walls, through
doors) whose evidence reaches GAIN (or, if none does, half the most any candidate
reaches) is chosen. :class:`Looker` steers a
robot without a navigation stack there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slam2d import geometry
from slam2d.localization.mcl import ParticleFilter
from slam2d.localization.sensor import BeamModel

__all__ = ["Goal", "Looker", "contenders", "disambiguating_goal", "gains", "separation", "way_length",
           "way_to"]

GAIN = 1.0  # log evidence per scan from which a goal is decisive (the nearest such is chosen)
WORTH = 0.1  # log evidence per scan below which no place separates the hypotheses (copies drawn a cell apart)

@dataclass(frozen=True)
class Goal:
    """A pose (3,) in the map as the best hypothesis sees it (heading: the way from the estimate), the
    evidence (log likelihood ratio) one scan there would add against the other hypotheses (weighted mean),
    and its straight distance (m) from the estimate."""

    pose: np.ndarray
    separation: float
    distance: float


def contenders(pf: ParticleFilter) -> list:
    """The compact hypotheses that keep the filter from tracking: the best and every other one whose
    weight is within the evidence threshold of it (heaviest first)."""
    est = pf.estimate
    if not est.hypotheses:
        return []
    floor = est.hypotheses[0].weight * np.exp(-min(pf.evidence_threshold, 50.0))
    return [h for h in est.hypotheses if h.weight >= floor and h.sd_xy < pf.cfg.converged_sd]


def separation(pf: ParticleFilter, goals: np.ndarray, angles: np.ndarray | None = None,
               clearance: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """For goals (G, 3) relative to the best compact hypothesis, the evidence (G,) one scan taken there
    would give it over the other :func:`contenders` (:func:`gains`, each capped at the evidence threshold,
    their mean weighted by the contenders' weights), and whether each goal is free under every hypothesis
    (G,)."""
    gain, weights, free = gains(pf, goals, angles, clearance)
    if len(weights) == 0:
        return np.zeros(len(goals)), free
    return (weights @ np.minimum(gain, pf.evidence_threshold)) / weights.sum(), free


def gains(pf: ParticleFilter, goals: np.ndarray, angles: np.ndarray | None = None,
          clearance: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per other contender k of the best compact hypothesis (:func:`contenders`, heaviest first) and goal
    (G, 3, relative to the best), the evidence (K, G) one scan taken there would give the best over k (log
    likelihood ratio as the filter weighs hypotheses: the scan predicted under one, its end points scored
    under the other on the smooth likelihood field, each beam raised to beam_weight; the smaller of the
    two ways, since whichever is true its scan must misfit the other); the contenders' weights (K,); and
    whether each goal is free, ``clearance`` m from walls (the filter's free_clearance by default), under
    every hypothesis (G,). ``angles`` (rad): the laser's beams (72 over the full turn by default)."""
    clearance = pf.cfg.free_clearance if clearance is None else clearance
    hyps, cfg, known = contenders(pf), pf.cfg, pf.map
    angles = np.linspace(-np.pi, np.pi, 72, endpoint=False) if angles is None else np.asarray(angles)
    relative = np.array([geometry.between(hyps[0].pose, g) for g in goals]) if hyps else goals
    dist = known.distance()
    free = np.ones(len(goals), dtype=bool)
    under = []
    for h in hyps:
        poses = np.array([geometry.compose(h.pose, r) for r in relative])
        cells = known.world_to_cell(poses[:, :2])
        inside = known.in_bounds(cells)
        ok = np.zeros(len(goals), dtype=bool)
        ok[inside] = known.free[cells[inside, 0], cells[inside, 1]] & (dist[cells[inside, 0], cells[inside, 1]]
                                                                        >= clearance)  # fmt: skip
        free &= ok
        under.append(poses)
    if len(hyps) < 2:
        return np.zeros((0, len(goals))), np.zeros(0), free
    model = BeamModel(known, cfg, pf.range_max)
    ranges = [model.expected_ranges(p, np.zeros(3), angles) for p in under]  # (G, n) each
    gain = np.array([np.minimum(_misfit(pf, ranges[0], under[i], angles), _misfit(pf, ranges[i], under[0], angles))
                     for i in range(1, len(hyps))])  # fmt: skip
    return gain, np.array([h.weight for h in hyps[1:]]), free


def _misfit(pf: ParticleFilter, ranges: np.ndarray, poses: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Log likelihood lost (G,) when the scans ``ranges`` (G, n) (no-return beams at range_max, skipped)
    are scored at ``poses`` (G, 3) instead of where they were cast (their end points on walls): the
    smooth field, each beam raised to beam_weight, the filter's beam count."""
    cfg, known = pf.cfg, pf.map
    returned = ranges < pf.range_max
    a = poses[:, 2, None] + angles
    cells = known.world_to_cell(np.stack([poses[:, 0, None] + ranges * np.cos(a),
                                          poses[:, 1, None] + ranges * np.sin(a)], axis=-1))  # fmt: skip
    d = np.full(ranges.shape, cfg.max_dist)
    inside = known.in_bounds(cells)
    d[inside] = np.minimum(known.distance()[cells[inside][:, 0], cells[inside][:, 1]], cfg.max_dist)
    floor = cfg.z_rand / pf.range_max
    loss = np.log(cfg.z_hit + floor) - np.log(cfg.z_hit * np.exp(-(d**2) / (2 * cfg.sigma_hit_uncertain**2)) + floor)
    mean = np.sum(loss * returned, axis=1) / np.maximum(returned.sum(axis=1), 1)
    return cfg.beam_weight * np.minimum(returned.sum(axis=1), cfg.beams) * mean


def disambiguating_goal(pf: ParticleFilter, candidates: int = 400, max_distance: float = 15.0,
                        clearance: float = 0.5, seed: int = 0, angles: np.ndarray | None = None) -> Goal | None:
    """The nearest of ``candidates`` free places (``clearance`` m from walls) within ``max_distance`` m
    of way (:func:`way_length`: the robot drives round walls, so a place behind one is as far as the way
    through the door) from the estimate (in the best hypothesis's map) whose scan would add GAIN of
    evidence (or half the most any candidate would) against the other hypotheses (:func:`separation`;
    ``angles``: the laser's); None when fewer than two compact hypotheses hold weight or no place is
    worth WORTH."""
    best = pf.estimate.hypotheses[0] if pf.estimate.hypotheses else None
    if best is None:
        return None
    rng = np.random.default_rng(seed)
    known = pf.map
    cells = known.free_cells(clearance)
    length = way_length(known, best.pose).ravel()[cells]
    cells, length = cells[length <= max_distance], length[length <= max_distance]
    if len(cells) == 0:
        return None
    pick = rng.choice(len(cells), min(candidates, len(cells)), replace=False)
    row, col = np.divmod(cells[pick], known.shape[1])
    xy = np.column_stack([known.origin[0] + (col + 0.5) * known.resolution,
                          known.origin[1] + (row + 0.5) * known.resolution])  # fmt: skip
    goals = np.column_stack([xy, np.arctan2(xy[:, 1] - best.pose[1], xy[:, 0] - best.pose[0])])
    sep, free = separation(pf, goals, angles, clearance)
    sep = np.where(free, sep, 0.0)
    if sep.max() < WORTH:
        return None
    distance = length[pick]
    good = np.flatnonzero(sep >= min(GAIN, 0.5 * sep.max()))
    i = good[np.argmin(distance[good])]
    return Goal(goals[i], float(sep[i]), float(distance[i]))


GOAL_REACHED = 0.5  # m from a goal (on the estimate) at which the next one is chosen
GOAL_PATIENCE = 20.0  # s driving to one goal before choosing another
STALL = 5.0  # s without PROGRESS along the way to a goal before choosing another
PROGRESS = 0.5  # m of way to the goal gained (geodesic, wall-free cells) that counts as progress
JUMP = 1.0  # m the estimate moves between two scans: another hypothesis leads, the way is another
RETRY = 2.0  # s after finding no goal before looking again
_LOOKAHEAD = 0.7  # m, the point on the way to the goal steered at
_WALL_COST = 0.4  # m: cells closer to walls cost 20 x (the way keeps off walls, starts near them still lead out)
_NARROW = 0.3  # m: cells closer to walls are no way (a gap the robot's lane does not fit through)


def way_to(known, goal: np.ndarray) -> np.ndarray:
    """Geodesic cost (H, W) of every free cell to ``goal`` (x, y) over the map's free space, walls
    avoided (inf where unreachable)."""
    dist = known.distance()
    cost = np.where(dist < _WALL_COST, 20.0, 1.0)
    cost[~known.free | (dist < _NARROW)] = np.inf
    cell = known.world_to_cell(np.asarray(goal[:2], dtype=np.float64)[None])[0]
    if not known.in_bounds(cell[None])[0] or not known.free[cell[0], cell[1]]:
        return np.full(known.shape, np.inf)
    return _costs_from(cost, cell)


def _costs_from(cost: np.ndarray, cell) -> np.ndarray:
    """Least geodesic cost (H, W) from ``cell`` (row, col) over the per-cell ``cost`` (inf: impassable)."""
    from skimage.graph import MCP_Geometric

    field, _ = MCP_Geometric(cost).find_costs([tuple(int(c) for c in cell)])
    return field


def way_length(known, start: np.ndarray) -> np.ndarray:
    """Length (m) (H, W) of the shortest way from ``start`` (x, y, ...) to every cell over the cells
    :func:`way_to` lets the robot pass (inf where none leads); the cells within ``_LOOKAHEAD`` m of the
    start are passable (the robot steers out from near a wall)."""
    cost = np.where(known.free & (known.distance() >= _NARROW), 1.0, np.inf)
    cell = known.world_to_cell(np.asarray(start[:2], dtype=np.float64)[None])[0]
    if not known.in_bounds(cell[None])[0]:
        return np.full(known.shape, np.inf)
    rows, cols = np.ogrid[:known.shape[0], :known.shape[1]]
    near = np.hypot(rows - cell[0], cols - cell[1]) <= _LOOKAHEAD / known.resolution
    cost[near & known.free] = 1.0
    return _costs_from(cost, cell) * known.resolution


def heading_to(known, field: np.ndarray, pose: np.ndarray) -> float | None:
    """Direction (rad, in the map) from ``pose`` (3,) towards the cell ``_LOOKAHEAD`` m round it with the
    lowest cost in ``field`` (:func:`way_to`); None when no cell there reaches the goal."""
    r = round(_LOOKAHEAD / known.resolution)
    cell = known.world_to_cell(pose[None, :2])[0]
    rows, cols = np.mgrid[-r:r + 1, -r:r + 1]
    ring = np.column_stack([rows.ravel(), cols.ravel()])
    ring = ring[np.hypot(ring[:, 0], ring[:, 1]) <= r] + cell
    ring = ring[known.in_bounds(ring)]
    cost = field[ring[:, 0], ring[:, 1]]
    if len(cost) == 0 or not np.isfinite(cost.min()):
        return None
    d = ring[int(np.argmin(cost))] - cell
    return float(np.arctan2(d[0], d[1]))  # rows run along y


def _way_left(known, field: np.ndarray, pose: np.ndarray) -> float:
    """The geodesic cost (:func:`way_to`'s units: cells) left from ``pose`` (3,); inf off the way."""
    cell = known.world_to_cell(pose[None, :2])[0]
    return float(field[cell[0], cell[1]]) if known.in_bounds(cell[None])[0] else np.inf


class Looker:
    """Active localisation for a robot without a navigation stack: while ``pf`` is ambiguous it steers
    (on the best hypothesis's pose) towards the :func:`disambiguating_goal`, the next one once it is
    within GOAL_REACHED m, when the estimate jumps JUMP m (another hypothesis leads), when the way left
    has not shrunk by PROGRESS m for STALL s (the robot turns or is held up where the hypotheses'
    maps differ), or after GOAL_PATIENCE s; ``goals`` keeps those chosen."""

    def __init__(self, pf: ParticleFilter):
        self.pf, self.goals = pf, []
        self._field: np.ndarray | None = None
        self._since = self._none_at = self._moved_at = -np.inf
        self._left, self._last = np.inf, None  # the least way left to the goal, the last pose

    def heading(self, pose: np.ndarray, scan) -> float | None:
        """Direction (rad, in the map, as the estimate ``pose`` (3,) sees it) to drive in when ``scan``
        comes, or None (no goal: the filter is not ambiguous or no place separates its hypotheses)."""
        last, self._last = self._last, pose
        if self.pf.state != "ambiguous":
            self._field = None
            return None
        stamp = scan.stamp
        if self._field is not None and not self._keep(pose, last, stamp):
            self._field = None
        if self._field is None:
            if stamp - self._none_at < RETRY:
                return None
            chosen = disambiguating_goal(self.pf, seed=len(self.goals), angles=scan.angles)
            if chosen is None:
                self._none_at = stamp
                return None
            self.goals.append(chosen)
            self._field, self._since = way_to(self.pf.map, chosen.pose), stamp
            self._left, self._moved_at = _way_left(self.pf.map, self._field, pose), stamp
        return heading_to(self.pf.map, self._field, pose)

    def _keep(self, pose: np.ndarray, last: np.ndarray | None, stamp: float) -> bool:
        """Whether to keep driving to the last goal (not reached, no jump, progress, patience left)."""
        known = self.pf.map
        if np.hypot(*(pose[:2] - self.goals[-1].pose[:2])) < GOAL_REACHED or stamp - self._since > GOAL_PATIENCE:
            return False
        if last is not None and np.hypot(*(pose[:2] - last[:2])) > JUMP:
            return False
        left = _way_left(known, self._field, pose)
        if left < self._left - PROGRESS / known.resolution:
            self._left, self._moved_at = left, stamp
        return stamp - self._moved_at <= STALL
