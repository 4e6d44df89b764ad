"""What a global planner is (the Protocol) and the planners by name (``planning.hierarchy``)."""

from __future__ import annotations

from typing import Protocol

from slam2d.registry import Registry


class GlobalPlanner(Protocol):
    """Plans grid paths on the (inflated) :class:`slam2d.planning.grid.PlanningGrid` it was built on."""

    def plan(self, start, goal):
        """The :class:`slam2d.planning.astar.PlanResult` from the ``start`` to the ``goal`` cell (row, col)."""
        ...


GLOBAL_PLANNERS = Registry(
    "global_planners", "planner", key="planning.hierarchy", options_key="planning",
    builtins={"astar": "slam2d.planning.astar", "hpa": "slam2d.planning.hierarchical",
              "rooms": "slam2d.planning.room_graph", "jps": "slam2d.planning.jps",
              "jps_plus": "slam2d.planning.jps_plus", "subgoal": "slam2d.planning.subgoal"},
    aliases={"none": "astar"})
"""The global planners by name: ``create(name, options, grid, labels=..., graph=...)`` builds one on
``grid``; the room-graph planner takes the room ``labels`` (H, W) aligned with the grid (rows up) and
an optional region ``graph`` (``takes``). ``planning.hierarchy: none`` is A*."""


def register_planner(name: str, **kw):
    """Decorator of a function building a :class:`GlobalPlanner` on a grid: ``planning.hierarchy: name``."""
    return GLOBAL_PLANNERS.register(name, **kw)
