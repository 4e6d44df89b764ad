"""Autonomous exploration: frontiers (Yamauchi 1997, the 2018 thesis), Li et al.'s candidate goals, their
utility and the cached hybrid grid-topological map; :func:`explore` drives the simulated robot with online
SLAM in the loop (``slam2d explore`` writes its results). Strategies register in ``exploration.base``."""

from __future__ import annotations

from slam2d.exploration.base import EXPLORATION_STRATEGIES, Strategy, register_strategy  # noqa: F401
from slam2d.registry import lazy_exports

_EXPORTS = {
    "ExploreConfig": "config",
    "ExplorationConfig": "config",
    "explore": "loop",
    "ExplorationRun": "loop",
    "Explorer": "explorer",
    "Goal": "explorer",
    "Coverage": "coverage",
    "frontier_mask": "frontiers",
}
"""Public names imported on first use (so that importing the package stays light): name -> module."""

__all__ = sorted([*_EXPORTS, "EXPLORATION_STRATEGIES", "Strategy", "register_strategy"])

__getattr__ = lazy_exports(__name__, _EXPORTS)
