"""slam2d.planning: global planners on grids (``planning.base``), smoothing and timing."""

from slam2d.planning.base import GLOBAL_PLANNERS, GlobalPlanner, register_planner  # noqa: F401
