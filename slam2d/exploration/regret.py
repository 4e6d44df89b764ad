"""The utility's path term (:mod:`slam2d.exploration.explorer`): how much later a greedy tour through all open
goals reaches the hidden cells when a given goal is visited first."""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["mean_arrivals", "tour_regret"]


@njit(cache=True)
def mean_arrivals(first, between, weight):
    """Mean distance (P,) driven before each goal is reached, weighted by ``weight`` (P,), on a greedy open
    tour through all P goals starting at each: ``first`` (P,) the cost to reach each goal, then always the
    nearest goal not yet visited by ``between`` (P, P)."""
    n = len(first)
    out = np.empty(n)
    total_weight = max(weight.sum(), 1e-9)
    for s in range(n):
        seen = np.zeros(n, dtype=np.bool_)
        seen[s] = True
        cur, driven = s, first[s]
        late = weight[s] * driven
        for _ in range(n - 1):
            best, nxt = np.inf, -1
            for j in range(n):
                if not seen[j] and between[cur, j] < best:
                    best, nxt = between[cur, j], j
            if nxt < 0:
                break
            seen[nxt] = True
            driven += best
            late += weight[nxt] * driven
            cur = nxt
        out[s] = late / total_weight
    return out


def tour_regret(goals, path, gain) -> np.ndarray:
    """How much later (P,) m, on average over the hidden cells (``gain`` (P,) each goal's), the robot reaches
    them when each goal is visited first: path (P,) m from the robot to it, then a greedy tour through the
    rest (nearest next), minus the best such first goal. Between two goals the distance is its lower bound
    max(straight line, difference of their path lengths from the robot): no grid search per goal."""
    goals, path = np.asarray(goals, dtype=np.float64).reshape(-1, 2), np.asarray(path, dtype=np.float64)
    between = np.maximum(np.hypot(*(goals[:, None] - goals[None]).transpose(2, 0, 1)), np.abs(path[:, None] - path))
    arrival = mean_arrivals(path, between, np.asarray(gain, dtype=np.float64))
    return arrival - arrival.min()
