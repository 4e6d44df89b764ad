"""The world and a robot you can drive: the closed-loop simulation.

``World`` (walls, ray casting, collision queries), ``Robot`` (differential drive,
``step(v, w, dt)`` -> scan, wheel odometry, true pose, collision) and moving
obstacles the laser sees but the world does not hold.
"""

from slam2d.sim.obstacles import LoopingDisc, MovingObstacle, WanderingDisc, scatter_wanderers
from slam2d.sim.robot import ROBOT_RADIUS, Laser, Robot, RobotConfig, StepResult
from slam2d.sim.world import Contact, World, load_world

__all__ = [
    "World",
    "Contact",
    "load_world",
    "Robot",
    "RobotConfig",
    "StepResult",
    "Laser",
    "ROBOT_RADIUS",
    "MovingObstacle",
    "LoopingDisc",
    "WanderingDisc",
    "scatter_wanderers",
]
