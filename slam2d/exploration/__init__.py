"""Autonomous exploration: frontiers (Yamauchi 1997, the 2018 thesis), Li et al.'s candidate goals,
their utility and the cached hybrid grid-topological map; ``run`` drives the simulated robot with
online SLAM in the loop (``slam2d explore``)."""

from slam2d.exploration.base import EXPLORATION_STRATEGIES, Strategy, register_strategy  # noqa: F401
