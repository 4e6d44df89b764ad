"""``slam2d plan`` config: a map, a planner, one query or many, and how rooms are found."""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, model_validator

from slam2d.config import CommandConfig, Section
from slam2d.planning.timing import TrajectoryLimits
from slam2d.registry import Choice
from slam2d.segmentation.config import SegmentationConfig


class PlanningConfig(Section):
    """Which planner, on which query (or on ``queries`` random ones beside A*)."""

    hierarchy: Annotated[str, Choice("global_planners", canonical=False)] = Field(
        "none", description="none (A*), jps (Jump Point Search), jps_plus (JPS over precomputed jump distances), "
        "subgoal (Simple Subgoal Graph over obstacle corners), hpa (square clusters) or rooms (the room graph of a "
        "segmentation)"
    )
    cluster_size: int = Field(16, gt=1, le=4096, description="HPA* cluster side, cells")
    corridor: bool = Field(
        True, description="rooms: one A* over the route's rooms and those up to three portals from them (exact on "
        "the ten floor plans) instead of one A* per room (faster, with detours)"
    )
    robot_radius: float = Field(0.2, ge=0, description="obstacle inflation, m")
    labels: str | None = Field(
        None, description="rooms: label image (labels.png of slam2d segment) or .npy; None: the map is "
        "segmented as the segmentation section says"
    )
    start: tuple[float, float] | None = Field(None, description="x, y in m (with goal: one query)")
    goal: tuple[float, float] | None = Field(None, description="x, y in m")
    queries: int = Field(
        0, ge=0, le=100_000, description="instead of start and goal: this many seeded random start-goal pairs that A* "
        "connects, each planned by A* and by the chosen planner (suboptimality, speed-up)"
    )
    min_distance: float = Field(10.0, ge=0, description="m; preferred straight-line distance between a query's ends")
    limits: TrajectoryLimits = TrajectoryLimits()

    @model_validator(mode="after")
    def _one_query_or_many(self):
        if self.queries == 0 and (self.start is None) != (self.goal is None):
            raise ValueError("give both start and goal (or queries > 0)")
        return self


class PlanConfig(CommandConfig):
    """``slam2d plan``: the map, the planning section and the segmentation behind the room graph."""

    planning: PlanningConfig = PlanningConfig()
    segmentation: SegmentationConfig = SegmentationConfig(method="morphological")
