"""Acting on a map: a global path (``slam2d.planning``) followed by a local planner.

``dwa`` (dynamic window, the default), ``fsm`` (the 2016 thesis's avoidance
state machine) and ``teb`` (timed elastic band, a GTSAM factor graph) turn a laser scan, a pose and the remaining path into a velocity
command; ``navigator`` plans, replans, recovers and reports "unreachable" (its
parameters: ``config``); ``run_navigation`` (``drive``) drives a :class:`slam2d.sim.Robot` to a goal.
"""

from slam2d.navigation.base import (
    LOCAL_PLANNERS,
    RECOVERY_BEHAVIOURS,
    LocalPlanner,
    RecoveryBehaviour,
    register_local_planner,
    register_recovery,
)
from slam2d.navigation.common import Command
from slam2d.navigation.config import NavigatorConfig
from slam2d.navigation.drive import NavigationResult, run_navigation
from slam2d.navigation.dwa import DwaConfig, DynamicWindow
from slam2d.navigation.fsm import AvoidanceStateMachine, FsmConfig
from slam2d.navigation.maps import free_mask, world_grid
from slam2d.navigation.navigator import Navigator
from slam2d.navigation.teb import TebConfig, TimedElasticBand

__all__ = [
    "Command",
    "LocalPlanner",
    "LOCAL_PLANNERS",
    "RecoveryBehaviour",
    "RECOVERY_BEHAVIOURS",
    "register_local_planner",
    "register_recovery",
    "DwaConfig",
    "DynamicWindow",
    "FsmConfig",
    "AvoidanceStateMachine",
    "TebConfig",
    "TimedElasticBand",
    "world_grid",
    "free_mask",
    "Navigator",
    "NavigatorConfig",
    "NavigationResult",
    "run_navigation",
]
