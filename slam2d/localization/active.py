"""Active localisation: where to look to tell the filter's hypotheses apart.

After Burgard, Fox & Thrun, "Active mobile robot localization" (IJCAI 1997): while
the filter is ``ambiguous``, a place from which the scans predicted under each
hypothesis differ tells them apart. A goal is a pose relative to the best
hypothesis; under hypothesis h the robot would stand at h composed with that
relative pose, so the predicted ranges (ray cast in the map) at those poses are
compared. Only goals free in every hypothesis are offered (driving there is safe
whichever is true); the nearest whose separation reaches half the most any
candidate reaches is chosen.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slam2d import geometry
from slam2d.localization.mcl import ParticleFilter
from slam2d.localization.sensor import BeamModel

__all__ = ["Goal", "disambiguating_goal", "separation"]

MIN_WEIGHT = 0.01  # hypotheses lighter than this are not looked at


@dataclass(frozen=True)
class Goal:
    """A pose (3,) in the map as the best hypothesis sees it, the mean range difference (m) its scans
    would show between the hypotheses (weighted), and its straight distance (m) from the estimate."""

    pose: np.ndarray
    separation: float
    distance: float


def separation(pf: ParticleFilter, goals: np.ndarray, beams: int = 72, clearance: float | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
    """For goals (G, 3) relative to the best compact hypothesis, the weighted mean range difference (G,) m
    between the scans predicted under it and under the other compact hypotheses, and whether each goal is
    free, ``clearance`` m from walls (the filter's free_clearance by default), under every hypothesis (G,)."""
    clearance = pf.cfg.free_clearance if clearance is None else clearance
    hyps = [h for h in pf.estimate.hypotheses if h.weight >= MIN_WEIGHT and h.sd_xy < pf.cfg.converged_sd]
    known, model = pf.map, BeamModel(pf.map, pf.cfg, pf.range_max)
    angles = np.linspace(-np.pi, np.pi, beams, endpoint=False)
    relative = np.array([geometry.between(hyps[0].pose, g) for g in goals]) if hyps else goals
    free = np.ones(len(goals), dtype=bool)
    ranges, weights = [], []
    for h in hyps:
        poses = np.array([geometry.compose(h.pose, r) for r in relative])
        cells = known.world_to_cell(poses[:, :2])
        inside = known.in_bounds(cells)
        ok = np.zeros(len(goals), dtype=bool)
        ok[inside] = known.free[cells[inside, 0], cells[inside, 1]]
        ok[inside] &= known.distance()[cells[inside, 0], cells[inside, 1]] >= clearance
        free &= ok
        ranges.append(model.expected_ranges(poses, np.zeros(3), angles))
        weights.append(h.weight)
    if len(hyps) < 2:
        return np.zeros(len(goals)), free
    diff = np.array([np.mean(np.abs(r - ranges[0]), axis=1) for r in ranges[1:]])  # (H-1, G)
    w = np.array(weights[1:])
    return (w @ diff) / w.sum(), free


def disambiguating_goal(pf: ParticleFilter, candidates: int = 400, max_distance: float = 15.0,
                        clearance: float = 0.5, seed: int = 0) -> Goal | None:  # fmt: skip
    """The nearest of ``candidates`` free places (``clearance`` m from walls) within ``max_distance`` m
    of the estimate (in the best hypothesis's map) whose scans tell the hypotheses apart at least half
    as well as the best of them; None when fewer than two compact hypotheses hold weight or no place
    separates them."""
    best = pf.estimate.hypotheses[0] if pf.estimate.hypotheses else None
    if best is None:
        return None
    rng = np.random.default_rng(seed)
    known = pf.map
    cells = known.free_cells(clearance)
    row, col = np.divmod(cells, known.shape[1])
    xy = np.column_stack([known.origin[0] + (col + 0.5) * known.resolution,
                          known.origin[1] + (row + 0.5) * known.resolution])  # fmt: skip
    near = xy[np.hypot(*(xy - best.pose[:2]).T) <= max_distance]
    if len(near) == 0:
        return None
    pick = near[rng.choice(len(near), min(candidates, len(near)), replace=False)]
    goals = np.column_stack([pick, np.full(len(pick), best.pose[2])])
    sep, free = separation(pf, goals, clearance=clearance)
    sep = np.where(free, sep, 0.0)
    if sep.max() <= 0.0:
        return None
    distance = np.hypot(*(goals[:, :2] - best.pose[:2]).T)
    good = np.flatnonzero(sep >= 0.5 * sep.max())
    i = good[np.argmin(distance[good])]
    return Goal(goals[i], float(sep[i]), float(distance[i]))
