"""``slam2d explore`` config: the experiment config plus an ``exploration`` section."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, field_validator

from slam2d import config as config_mod
from slam2d.config import MAX_BEAMS, ExperimentConfig, Section
from slam2d.exploration.base import EXPLORATION_STRATEGIES
from slam2d.registry import Choice

STRATEGY_HELP = ("goal choice: Yamauchi's nearest frontier, explore_lite's cost, Li et al.'s candidates "
                 "(nearest, farthest, utility), a global tour over subspaces with local coverage (tour), "
                 "or a plugin's strategy")
STRATEGIES = EXPLORATION_STRATEGIES
"""The strategies by name (iterating gives the names)."""


class TourConfig(Section):
    """The ``tour`` strategy: a global tour over subspaces holding frontier, local viewpoints by set cover."""

    cell: float = Field(4.0, gt=0, description="m, side of the square subspaces the known space is split into")
    view_range: float = Field(3.0, gt=0, description="m: a viewpoint covers the frontier cells in line of sight "
                                                      "this close")  # fmt: skip
    spacing: float = Field(0.3, gt=0, description="m between the viewpoints tried in the local subspace")
    min_cover: float = Field(0.2, ge=0, description="m of frontier (cells × resolution) a viewpoint must cover "
                                                    "to be chosen")  # fmt: skip
    max_cells: int = Field(400, gt=0, description="frontier cells of the local subspace covered at most (evenly "
                                                  "thinned beyond)")  # fmt: skip
    horizon: float = Field(8.0, ge=0, description="m of path from the robot: the subspaces this close are toured "
                                                 "before the others (TARE's local horizon)")  # fmt: skip
    solver_ms: float = Field(10.0, gt=0, description="ms the TSP solver's local search may take per tour")
    refresh: int = Field(10, ge=1, description="decisions a subspace's travel costs are kept before they are "
                                               "measured again on the map")  # fmt: skip


class ExplorationConfig(Section):
    """Where the robot explores, how it picks goals, and the limits of a run."""

    strategy: Annotated[str, Choice("exploration_strategies", options="strategy_options")] = Field(
        "utility", description=STRATEGY_HELP)
    strategy_options: dict[str, Any] = Field(
        default_factory=dict, description="the strategy's own parameters (its Config: a plugin's; the built-ins "
        "take theirs from this section)")
    start: tuple[float, float, float] | None = Field(
        None, description="x, y (m), heading (rad); None: the office route's start, or a seeded open cell of a PNG world"
    )
    bounds: list[tuple[float, float]] | None = Field(None, description="bounding polygon (x, y) m; None: no bound")
    max_time: float = Field(1800.0, gt=0, description="s of simulated time at most")
    max_distance: float = Field(1000.0, gt=0, description="m driven at most")
    check_period: float = Field(1.0, gt=0, description="s between checks that the current goal is still worth it")
    goal_timeout: float = Field(20.0, gt=0, description="s without 0.3 m of progress: the goal is inaccessible")
    goal_reached: float = Field(0.3, gt=0, description="m from the goal that counts as reached")
    safety_margin: float = Field(0.05, ge=0, description="m kept between the robot's disc and walls or people: the "
                                 "explorer, the navigator and its local planner plan and drive with the radius grown "
                                 "by this (the coverage still counts from the robot's own radius)")  # fmt: skip
    goal_clearance: float = Field(0.2, ge=0, description="m kept between the robot's disc and the map's "
                                                         "obstacles at a goal")  # fmt: skip
    avoid_radius: float = Field(0.5, gt=0, description="m: goals this close to a visited or inaccessible one are skipped")
    min_frontier: float | None = Field(None, gt=0, description="m, shortest frontier region; None: the robot's width")
    pockets: bool = Field(True, description="with no frontier (or candidate) left, visit places that see hidden "
                                           "unknown pockets (behind furniture, openings narrower than a frontier "
                                           "region or touching an obstacle)")  # fmt: skip
    pocket_gain: float = Field(0.1, ge=0, description="m² of hidden cells a place must see to be visited")
    # Li et al.
    node_step: float = Field(0.9, gt=0, description="m of travel between topological nodes (S_tep)")
    box_width: float = Field(0.6, gt=0, description="m, width of the three-ray box (> the robot's width)")
    delta: float = Field(0.1, gt=0, description="m, A-type goals this far short of the range limit")
    safe_margin: float = Field(0.05, ge=0, description="m: safe_d = safe_dis = half the robot's width + this")
    d_tho: float = Field(0.5, gt=0, description="m, nearest A-type goal from the sensor")
    k1: float = Field(1.0, ge=0, description="1/m, distance weight of the utility")
    k2: float = Field(0.5, ge=0, description="1/rad, heading weight of the utility")
    distance: Literal["path", "euclidean", "tour"] = Field(
        "tour", description="L of the utility: grid path, straight line, or how much later (m driven, mean over the "
                            "goals' hidden cells) a tour through all goals reaches them when this one is first (tour)")  # fmt: skip
    gain_range: float = Field(6.0, gt=0, description="m, reach of the rays counting hidden cells (information gain)")
    gain_rays: int = Field(120, gt=3, le=MAX_BEAMS, description="rays cast for the information gain")
    min_gain: float = Field(0.5, ge=0, description="m² of hidden area (unknown, no known cell beside it) a "
                                                   "candidate must still see to stay open")  # fmt: skip
    backtrack: Literal["graph", "grid"] = Field("graph", description="to an old candidate: over the topological graph "
                                                                     "(the paper) or the grid path alone")  # fmt: skip
    fallback_frontiers: bool = Field(True, description="nearest / farthest candidate: with no candidate left, "
                                                       "take the nearest frontier (else stop)")  # fmt: skip
    tour: TourConfig = Field(default_factory=TourConfig, description="the tour strategy's parameters")
    # explore_lite
    potential_scale: float = Field(3.0, ge=0, description="explore_lite: weight of the distance")
    gain_scale: float = Field(1.0, ge=0, description="explore_lite: weight of the frontier size")
    animation: bool = Field(True, description="an animated GIF of the exploration in the results folder")
    snapshot_period: float = Field(5.0, gt=0, description="s between map snapshots kept for the animation")
    options: dict[str, Any] = Field(default_factory=dict, description="navigator parameters (NavigatorConfig)")

    @field_validator("bounds")
    @classmethod
    def _a_polygon(cls, bounds):
        """At least three finite vertices enclosing some area (shoelace formula)."""
        if bounds is None:
            return bounds
        if len(bounds) < 3 or not all(math.isfinite(v) for p in bounds for v in p):
            raise ValueError(f"a polygon needs at least 3 finite (x, y) vertices, got {len(bounds)}")
        area = sum(x0 * y1 - x1 * y0 for (x0, y0), (x1, y1) in zip(bounds, bounds[1:] + bounds[:1])) / 2
        if abs(area) < 1e-9:
            raise ValueError("the polygon encloses no area")
        return bounds


class ExploreConfig(ExperimentConfig):
    """An experiment config with the ``exploration`` section."""

    name: str = Field("explore", description="results folder name: no '/' or '\\', no leading '.'")

    exploration: ExplorationConfig = ExplorationConfig()


def load(path: str | Path | None = None, overrides: list[str] | dict[str, Any] = ()) -> ExploreConfig:
    """The explore config in ``path`` (defaults when None) with ``overrides`` (``a.b=value`` or a dict)."""
    return config_mod.load(path, overrides, ExploreConfig)
