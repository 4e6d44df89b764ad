"""What a local planner and a recovery behaviour are (the Protocols), and both by name.

A local planner turns the laser's view and the remaining path into a velocity command
(``navigation.planner``, ``navigation.options.planner``); its parameters are the navigator
config's section of its name (``dwa``, ``fsm``, ``teb``). A recovery behaviour says which manoeuvres
the navigator makes when it is stuck (``navigation.options.recovery``).
"""

from __future__ import annotations

from typing import Protocol

from slam2d.navigation.common import Command
from slam2d.registry import Registry


class LocalPlanner(Protocol):
    """Turns the laser's view and the remaining path into a velocity command."""

    def command(self, pose, velocity, points, path, unmapped=None) -> Command:
        """Command from the robot ``pose`` (3,) (world), its ``velocity`` (v m/s, w rad/s),
        laser hit ``points`` (M, 2) in the robot frame (m) and the remaining ``path``
        (L, 2) world waypoints (m) from near the robot to the goal (its last point);
        ``unmapped`` (M,) bool marks points the map does not explain, if known."""
        ...

    def reset(self) -> None:
        """Forget any manoeuvre in progress (after a replan or a recovery)."""
        ...


class RecoveryBehaviour(Protocol):
    """What the navigator does when it is stuck: the manoeuvres of its ``level``-th recovery in a row."""

    def manoeuvres(self, navigator, level: int, pose, points) -> list[str]:
        """The manoeuvres, in order, among "back" (back off ``backoff`` m), "replan" (with the laser's
        ``points`` (M, 2), robot frame, in the map) and "turn" (to the path), from ``pose`` (3,)."""
        ...


LOCAL_PLANNERS = Registry(
    "local_planners", "local planner", key="navigation.planner", options_key="navigation.options",
    builtins={"dwa": "slam2d.navigation.dwa", "fsm": "slam2d.navigation.fsm", "teb": "slam2d.navigation.teb"})
"""The local planners by name: ``create(name, options, robot)`` (a :class:`slam2d.sim.robot.RobotConfig`)."""

RECOVERY_BEHAVIOURS = Registry("recovery_behaviours", "recovery behaviour", key="navigation.options.recovery",
                               builtins={"backoff": "slam2d.navigation.navigator"})
"""The recovery behaviours by name."""


def register_local_planner(name: str, **kw):
    """Decorator of a :class:`LocalPlanner` class built as ``cls(robot, config)``: ``navigation.planner: name``."""
    return LOCAL_PLANNERS.register(name, **kw)


def register_recovery(name: str, **kw):
    """Decorator of a :class:`RecoveryBehaviour` class: ``navigation.options.recovery: name``."""
    return RECOVERY_BEHAVIOURS.register(name, **kw)
