"""The parameters of a navigation run (:class:`NavigatorConfig`: global planning, goal
tolerances, recovery, the time budget and the local planners' sections) and their
validation from a run's options (:func:`navigator_config`).
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import Field, ValidationError

from slam2d.config import Section
from slam2d.navigation.dwa import DwaConfig
from slam2d.navigation.fsm import FsmConfig
from slam2d.navigation.teb import TebConfig
from slam2d.registry import Choice, validation_error
from slam2d.sim.depth import DepthCameraConfig

__all__ = ["NavigatorConfig", "navigator_config"]


class NavigatorConfig(Section):
    """Global planning, goal tolerances, recovery and the time budget of a navigation run."""

    planner: Annotated[str, Choice("local_planners")] = Field(
        "dwa", description="local planner: dwa, fsm, teb (its parameters: the section of that name)")
    recovery: Annotated[str, Choice("recovery_behaviours")] = Field(
        "backoff", description="what a recovery does (slam2d.navigation.base.RECOVERY_BEHAVIOURS)")
    period: float = Field(0.1, gt=0, description="s, control period")
    inflation_margin: float = Field(0.05, ge=0, description="m; a cell where the disc comes this close costs `tight_weight`")
    tight_weight: float = Field(20.0, ge=0, description="extra step cost at the radius (lethal), falling to 0 over the margin")
    touch: bool = Field(False, description="a cell where the disc would touch the centre of a blocked cell fits it "
                        "(exploration's tight stretches: a map of 5 cm cells draws a door's faces up to a cell into it)")
    wall_distance: float = Field(0.3, gt=0, description="m beyond the margin over which a soft cost falls to 0")
    wall_weight: float = Field(1.0, ge=0, description="extra step cost at the margin's edge (1 = double)")
    unknown_free: bool = Field(False, description="occupancy maps: unknown cells are free for planning")
    goal_tolerance: float = Field(0.03, gt=0, description="m; stopped within this of the goal is arrived")
    goal_precision: float = Field(0.005, gt=0, description="m; the final approach stops once this close (or "
                                  "once the goal, within goal_tolerance, is abeam)")
    yaw_tolerance: float = Field(0.035, gt=0, description="rad, when the goal has a heading")
    final_approach: float = Field(0.2, ge=0, description="m from the goal where a point controller takes over")
    stuck_time: float = Field(6.0, gt=0, description="s without `progress` m of progress -> recovery")
    progress: float = Field(0.2, gt=0, description="m")
    blocked_time: float = Field(1.5, gt=0, description="s the local planner reports blocked -> recovery")
    max_recoveries: int = Field(4, ge=0, description="recoveries in a row without 1 m of progress")
    mark_range: float = Field(2.5, gt=0, description="m, laser points put into the map when replanning after a block")
    backoff: float = Field(0.3, ge=0, description="m backed off in a recovery (if the rear is clear)")
    off_path: float = Field(1.0, gt=0, description="m from the path that triggers a replan")
    max_time: float = Field(300.0, gt=0, description="s of simulated time, the budget of a run")
    blocked_goal_reach: float = Field(
        1.5, ge=0, description="m; on a map being built (unknown_free) a goal the map blocks is approached "
        "to the nearest free cell within this, replanning at every new map, before it is unreachable"
    )
    dwa: DwaConfig = DwaConfig()
    fsm: FsmConfig = FsmConfig()
    depth_camera: DepthCameraConfig = Field(
        DepthCameraConfig(), description="a depth camera whose obstacles (3D: what the laser misses) the local "
        "planner and replanning avoid (slam2d.navigation.depth_layer)")
    teb: TebConfig = TebConfig()


def navigator_config(options: dict[str, Any], slam: bool, section: str = "navigation.options"):
    """The NavigatorConfig of ``options`` from the config's ``section`` (named in an error); ``slam``: the map
    is being built (unknown cells plan as free unless the options say otherwise)."""
    merged = {"unknown_free": slam, **options}  # a map being built is mostly unknown: plan through it
    try:
        return NavigatorConfig.model_validate(merged)
    except ValidationError as err:
        raise validation_error(err, section, model=NavigatorConfig) from None
