"""Navigation on a known map with the pose from Monte Carlo localisation.

``run_navigation(..., pose_source=MclPoseSource(...))`` drives on the filter's
estimate: every step's scan and wheel odometry go to the filter, and the navigator
gets the estimate (moved by the odometry since the last update). While the filter is not
``tracking`` the robot does not drive to the goal: while ambiguous it drives to the places
that tell its hypotheses apart, else it turns in place.
"""

from __future__ import annotations

import numpy as np

from slam2d.localization.active import disambiguating_goal
from slam2d.localization.base import register_localizer
from slam2d.localization.config import MclConfig
from slam2d.localization.maps import KnownMap
from slam2d.localization.mcl import ParticleFilter

__all__ = ["MclPoseSource"]


@register_localizer("mcl", takes=("range_max", "seed"))
class MclPoseSource:
    """A ``pose_source`` for :func:`slam2d.navigation.run_navigation`: tracking from the rough pose
    ``start`` (3,) (the config's initial spread unless ``sd_xy`` m / ``sd_theta`` rad are given).
    While the filter is not tracking the navigator holds; with ``active``, while it is ambiguous,
    it drives to places that tell the hypotheses apart (``goals`` keeps them)."""

    def __init__(self, known: KnownMap, start, cfg: MclConfig | None = None, range_max: float = 12.0,
                 seed: int = 0, sd_xy: float | None = None, sd_theta: float | None = None,
                 active: bool = True):  # fmt: skip
        self.filter = ParticleFilter(known, cfg, range_max, seed)
        self.filter.init_pose(start, sd_xy, sd_theta)
        self.estimates: list[np.ndarray] = []
        self.active = active
        self.goals: list = []  # disambiguating goals driven to
        self._goal: np.ndarray | None = None
        self._angles: np.ndarray | None = None  # the laser's beams (rad)

    def __call__(self, step) -> np.ndarray:
        """The pose (3,) after feeding ``step``'s scan (a :class:`slam2d.sim.robot.StepResult`)."""
        self.filter.add(step.scan)
        self._angles = step.scan.angles
        pose = self.filter.pose(step.scan.odom)
        self.estimates.append(pose)
        return pose

    def holding(self) -> bool:
        """Whether the navigator must not drive on the pose: the filter is ambiguous or lost."""
        return self.filter.state != "tracking"

    def looking(self) -> np.ndarray | None:
        """While ambiguous (with ``active``): the goal (x, y, heading) whose scans tell the hypotheses
        apart (:func:`slam2d.localization.active.disambiguating_goal`), kept until :meth:`looked`."""
        if not self.active or self.filter.state != "ambiguous":
            self._goal = None
            return None
        if self._goal is None:
            goal = disambiguating_goal(self.filter, seed=len(self.goals), angles=self._angles)
            if goal is None:
                return None
            self._goal = goal.pose
            self.goals.append(goal)
        return self._goal

    def looked(self) -> None:
        """The last goal was reached or given up: the next :meth:`looking` chooses again."""
        self._goal = None
