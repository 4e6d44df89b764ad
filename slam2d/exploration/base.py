"""What an exploration strategy is (the Protocol) and the strategies by name (``exploration.strategy``)."""

from __future__ import annotations

from typing import Protocol

from slam2d.registry import Registry


class Strategy(Protocol):
    """Chooses the next exploration goal among what the :class:`slam2d.exploration.explorer.Explorer` offers:
    its frontier regions (``frontiers``, ``frontier_goal``), Li et al.'s candidates (``candidate_goal``) and
    their utility (``utility_goal``); the explorer's ``cfg`` is the ``exploration`` section."""

    def choose(self, explorer, pose, view, distance):
        """The :class:`slam2d.exploration.explorer.Goal` from ``pose`` (3,) on ``view`` (a GridView), or None
        when the strategy sees nothing left; ``distance`` (H, W) m: the path length to every cell (inf: out of
        reach or no room for the robot). With None the explorer still looks for pockets."""
        ...


EXPLORATION_STRATEGIES = Registry(
    "exploration_strategies", "strategy", key="exploration.strategy", options_key="exploration.strategy_options",
    builtins=dict.fromkeys(("nearest_frontier", "explore_lite", "nearest_candidate", "farthest_candidate", "utility",
                                        "tour"),
                           "slam2d.exploration.strategies"))
"""The exploration strategies by name; ``create(name, options)`` is one (its options: ``strategy_options``)."""


def register_strategy(name: str, **kw):
    """Decorator of a :class:`Strategy` class: ``exploration.strategy: name``."""
    return EXPLORATION_STRATEGIES.register(name, **kw)
