"""slam2d.planning: global planners on grids (the registry in ``planning.base``), planning on a map file,
smoothing and time-optimal timing."""

from __future__ import annotations

from slam2d.planning.base import GLOBAL_PLANNERS, GlobalPlanner, register_planner  # noqa: F401
from slam2d.registry import lazy_exports

_EXPORTS = {
    "AStar": "astar",
    "PlanResult": "astar",
    "path_length": "astar",
    "PlanningGrid": "grid",
    "load_grid": "grid",
    "load_movingai_map": "grid",
    "load_scenarios": "grid",
    "MapPlan": "query",
    "plan_on_map": "query",
    "plan_queries": "query",
    "make_planner": "query",
    "NoPathError": "query",
    "HPAStar": "hierarchical",
    "JPS": "jps",
    "JPSPlus": "jps_plus",
    "RoomGraphPlanner": "room_graph",
    "SubgoalGraph": "subgoal",
    "shortcut": "smoothing",
    "TrajectoryLimits": "timing",
    "time_parametrize": "timing",
}
"""Public names imported on first use (so that importing the package stays light): name -> module."""

__all__ = sorted([*_EXPORTS, "GLOBAL_PLANNERS", "GlobalPlanner", "register_planner"])

__getattr__ = lazy_exports(__name__, _EXPORTS)
