"""A differential-drive robot in a :class:`~slam2d.sim.world.World`: ``step(v, w, dt)``
returns the laser scan, the wheel odometry and the true pose, and reports collisions.

The robot is a disc with speed and acceleration limits. A step ramps the
velocity towards the clipped command, integrates the arcs in short sub-steps
and sweeps the disc along them: on contact with a wall, the world's bounds or
a moving obstacle it stops there and the step says what it hit. The laser
(:class:`LaserModel`) and the wheel odometry (four-alpha :class:`OdometryNoise`)
are the models the scripted-route dataset uses too.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import Field

from slam2d import geometry
from slam2d.config import LaserModel, OdometryNoise, Section
from slam2d.errors import InputError
from slam2d.sim.world import World
from slam2d.types import Scan

__all__ = [
    "ROBOT_RADIUS",
    "RobotConfig",
    "Robot",
    "StepResult",
    "Laser",
    "beam_angles",
    "measure_ranges",
    "sample_odometry",
    "odometry_step",
]

ROBOT_RADIUS = 0.2  # m
_MAX_CHORD = 0.05  # m, longest straight piece of a sub-stepped arc
_MAX_TURN = 0.05  # rad, largest heading change within one sub-step
_EPS = 1e-9


class RobotConfig(Section):
    """A differential-drive disc robot with a laser at its centre and wheel odometry."""

    radius: float = Field(ROBOT_RADIUS, gt=0, description="m")
    max_speed: float = Field(1.0, gt=0, description="m/s, forwards and backwards")
    max_turn_rate: float = Field(2.0, gt=0, description="rad/s")
    max_accel: float = Field(1.0, gt=0, description="m/s^2")
    max_turn_accel: float = Field(3.0, gt=0, description="rad/s^2")
    height: float = Field(0.45, gt=0, description="m, top of the body: parts of 3D objects below it are in its way")
    ground_clearance: float = Field(0.01, ge=0, description="m under the body: parts of 3D objects below it are not")
    laser: LaserModel = LaserModel()
    odometry: OdometryNoise = OdometryNoise()


# --------------------------------------------------------------------------- sensor models


def beam_angles(laser: LaserModel) -> np.ndarray:
    """Beam angles (n,) in rad in the sensor frame, spread over ``fov_deg`` centred on the heading."""
    if laser.fov_deg >= 360.0:
        return np.linspace(-np.pi, np.pi, laser.beams, endpoint=False)
    half = np.deg2rad(laser.fov_deg) / 2
    return np.linspace(-half, half, laser.beams)


def measure_ranges(true_ranges, laser: LaserModel, noise, dropped) -> np.ndarray:
    """Laser readings from true ranges (m): ``noise`` (m) added to hits, ``dropped`` beams NaN.

    Beams that hit nothing before ``range_max`` read exactly ``range_max`` (no return);
    hits closer than ``range_min`` are NaN.
    """
    r = np.asarray(true_ranges, dtype=np.float64)
    out = np.where(r < laser.range_max, np.minimum(r + noise, laser.range_max), laser.range_max)
    out[(r < laser.range_min) | dropped] = np.nan
    return out


class Laser:
    """A :class:`LaserModel` with its seeded range-noise and dropout streams.

    Readings drawn for P poses at once equal those drawn pose by pose.
    """

    def __init__(self, model: LaserModel, noise_seed, dropout_seed):
        self.model = model
        self.angles = beam_angles(model)
        self._noise = np.random.default_rng(noise_seed)
        self._dropout = np.random.default_rng(dropout_seed)

    def read(self, world: World, poses, circles=None) -> np.ndarray:
        """Readings (P, n) in metres from sensor poses (P, 3): walls and ``circles`` ray cast, noise, dropouts."""
        true = world.raycast_poses(poses, self.angles, self.model.range_max, circles)
        noise = self._noise.normal(0.0, self.model.range_noise, true.shape)
        dropped = self._dropout.random(true.shape) < self.model.dropout
        return measure_ranges(true, self.model, noise, dropped)

    def scan(self, ranges, stamp: float, odom, truth, index: int) -> Scan:
        """The :class:`Scan` of readings ``ranges`` (n,) at ``stamp`` (s), laser at the base centre."""
        return Scan(
            stamp=float(stamp),
            ranges=ranges,
            angles=self.angles.copy(),
            range_min=self.model.range_min,
            range_max=self.model.range_max,
            sensor_pose=np.zeros(3),
            odom=np.array(odom, dtype=np.float64),
            ground_truth=np.array(truth, dtype=np.float64),
            index=index,
        )


def _noise_turn(rot: np.ndarray) -> np.ndarray:
    """|rot| (rad) with a half turn taken off backward motion, so that reversing is not
    read as turning round (as ROS amcl's odometry model)."""
    a = np.abs(rot)
    return np.minimum(a, np.pi - a)


def sample_odometry(poses, noise: OdometryNoise, rng: np.random.Generator) -> np.ndarray:
    """Odometry poses (N, 3) starting at the true start pose, from ground-truth poses (N, 3).

    Every step between consecutive poses is split into (rot1, trans, rot2) and
    perturbed as in ``sample_motion_model_odometry``: var(rot1) = a1 rot1^2 + a2 trans^2,
    var(trans) = a3 trans^2 + a4 (rot1^2 + rot2^2), var(rot2) = a1 rot2^2 + a2 trans^2,
    where a backward step's rotations count without their half turn.
    Variances grow with the square of each step, so the drift over a route also
    depends on the scan rate (finer steps, less drift).
    """
    poses = geometry.as_pose(poses).reshape(-1, 3)
    d = np.diff(poses[:, :2], axis=0)
    trans = np.hypot(d[:, 0], d[:, 1])
    moving = trans > _EPS
    rot1 = np.where(moving, geometry.wrap_angle(np.arctan2(d[:, 1], d[:, 0]) - poses[:-1, 2]), 0.0)
    rot2 = geometry.wrap_angle(np.diff(poses[:, 2]) - rot1)
    a1, a2, a3, a4 = noise.alpha1, noise.alpha2, noise.alpha3, noise.alpha4
    e = rng.standard_normal((3, len(d)))
    turn1, turn2 = _noise_turn(rot1), _noise_turn(rot2)
    sd_rot1 = np.sqrt(a1 * turn1**2 + a2 * trans**2)
    sd_trans = np.sqrt(a3 * trans**2 + a4 * (turn1**2 + turn2**2))
    sd_rot2 = np.sqrt(a1 * turn2**2 + a2 * trans**2)
    rot1, trans, rot2 = rot1 - e[0] * sd_rot1, trans - e[1] * sd_trans, rot2 - e[2] * sd_rot2
    theta = poses[0, 2] + np.concatenate([[0.0], np.cumsum(rot1 + rot2)])
    direction = theta[:-1] + rot1
    steps = trans[:, None] * np.column_stack([np.cos(direction), np.sin(direction)])
    xy = poses[0, :2] + np.vstack([np.zeros((1, 2)), np.cumsum(steps, axis=0)])
    return np.column_stack([xy, geometry.wrap_angle(theta)])


def odometry_step(odom, before, after, noise: OdometryNoise, rng: np.random.Generator) -> np.ndarray:
    """Wheel odometry pose (3,) after the true motion ``before`` -> ``after`` (3,), from odometry pose ``odom``."""
    sampled = sample_odometry(np.stack([before, after]), noise, rng)[1]
    return geometry.compose(odom, geometry.between(before, sampled))


# --------------------------------------------------------------------------- the robot


@dataclass(frozen=True, eq=False)
class StepResult:
    """One step: the laser ``scan`` at its end, the wheel ``odom`` pose and true ``pose`` (3,)
    there, the ``velocity`` (v m/s, w rad/s) reached, and ``contact``: None, or "wall"
    (walls and the world's bounds), "obstacle" (a moving one) or "object" (a part of a 3D object at
    the body's height, ``world.objects``) when a collision stopped the robot."""

    scan: Scan
    odom: np.ndarray
    pose: np.ndarray
    velocity: np.ndarray
    contact: str | None = None

    @property
    def collision(self) -> bool:
        """Whether the robot hit something during the step."""
        return self.contact is not None


class Robot:
    """A differential-drive disc robot in ``world``, starting at rest at true ``pose`` (3,).

    ``obstacles`` are moving discs (:mod:`slam2d.sim.obstacles`): they move before
    the robot in every step, the laser sees them, the world does not hold them.
    The same world, pose, config, obstacles, seed and commands give the same results.
    """

    def __init__(self, world: World, pose, config: RobotConfig | None = None, *, obstacles=(), seed: int = 0):
        self.world, self.cfg = world, config or RobotConfig()
        self.pose = geometry.as_pose(pose).reshape(3).copy()
        self.obstacles = list(obstacles)
        self._check_start()
        self.odom = self.pose.copy()
        self.velocity = np.zeros(2)
        self.time = 0.0
        self.scans = 0
        odom_seed, noise_seed, dropout_seed, obstacle_seed = np.random.SeedSequence(seed).spawn(4)
        self.laser = Laser(self.cfg.laser, noise_seed, dropout_seed)
        self._odom_rng = np.random.default_rng(odom_seed)
        self._obstacle_rng = np.random.default_rng(obstacle_seed)
        self._body = self._body_world()

    def _body_world(self) -> World | None:
        """The footprints of the world's 3D object parts at the body's height, as walls (None without any)."""
        objects = self.world.objects
        if objects is None or len(objects) == 0:
            return None
        rings = objects.footprints(objects.overlapping(self.cfg.ground_clearance, self.cfg.height))
        if not rings:
            return None
        edges = np.concatenate([np.stack([r, np.roll(r, -1, axis=0)], axis=1) for r in rings])
        return World(edges, self.world.bounds + [[-1e3], [1e3]], name="objects")  # bounds far: the world's are walls

    def _check_start(self) -> None:
        x, y, r = self.pose[0], self.pose[1], self.cfg.radius
        if not self.world.free(self.pose[:2], r)[0]:
            raise InputError("robot.pose", f"({x:.2f}, {y:.2f}) has no room for a {r} m robot in {self.world.name}")
        centres, radii = self.obstacle_circles()
        if np.any(np.hypot(centres[:, 0] - x, centres[:, 1] - y) < radii + r):
            raise InputError("robot.obstacles", f"an obstacle overlaps the robot at ({x:.2f}, {y:.2f})")

    def obstacle_circles(self) -> tuple[np.ndarray, np.ndarray]:
        """Centres (K, 2) and radii (K,) in metres of the moving obstacles now."""
        centres = np.array([ob.centre for ob in self.obstacles], dtype=np.float64).reshape(-1, 2)
        return centres, np.array([ob.radius for ob in self.obstacles], dtype=np.float64)

    def step(self, v: float, w: float, dt: float) -> StepResult:
        """Drive with command ``v`` (m/s) and ``w`` (rad/s) for ``dt`` (s), then sense.

        The command is clipped to the speed limits and approached within the
        acceleration limits. On contact the robot stops there and its velocity
        drops to zero. ``step(0, 0, 0)`` senses without moving.
        """
        v, w, dt = _checked_command(v, w, dt)
        blocker = (self.pose[None, :2], np.array([self.cfg.radius]))
        for ob in self.obstacles:
            ob.advance(dt, self._obstacle_rng, blocker)
        path, velocity = self._motion(v, w, dt)
        pose, contact = self._stop_at_contact(path)
        self.odom = odometry_step(self.odom, self.pose, pose, self.cfg.odometry, self._odom_rng)
        self.pose, self.time = pose, self.time + dt
        self.velocity = np.zeros(2) if contact else velocity
        return StepResult(self._scan(), self.odom.copy(), self.pose.copy(), self.velocity.copy(), contact)

    def _motion(self, v: float, w: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """True poses (n + 1, 3) at the sub-steps of a step, and the velocity (2,) at its end."""
        cfg = self.cfg
        limit = np.array([cfg.max_speed, cfg.max_turn_rate])
        accel = np.array([cfg.max_accel, cfg.max_turn_accel])
        change = np.clip([v, w], -limit, limit) - self.velocity
        reach = np.maximum(np.abs(self.velocity), np.abs(self.velocity + change)) * dt
        n = max(1, int(np.ceil(max(reach[0] / _MAX_CHORD, reach[1] / _MAX_TURN))))
        mid = (np.arange(n)[:, None] + 0.5) * (dt / n)  # the ramp's mean over a sub-step is its midpoint value
        velocities = self.velocity + np.clip(change, -accel * mid, accel * mid)
        return _integrate(self.pose, velocities, dt / n), self.velocity + np.clip(change, -accel * dt, accel * dt)

    def _stop_at_contact(self, path: np.ndarray) -> tuple[np.ndarray, str | None]:
        """The pose (3,) where the robot's disc first touches something along ``path``, and what it touched."""
        hit = self.world.sweep(path[:, :2], self.cfg.radius, self.obstacle_circles())
        kind = None if hit is None else "wall" if hit.circle is None else "obstacle"
        body = self._body.sweep(path[:, :2], self.cfg.radius) if self._body is not None else None
        if body is not None and (hit is None or (body.leg, body.fraction) <= (hit.leg, hit.fraction)):
            hit, kind = body, "object"  # a part of a 3D object at the body's height (a table leg: also a wall)
        if hit is None:
            return path[-1].copy(), None
        a, b, f = path[hit.leg], path[hit.leg + 1], hit.fraction
        theta = geometry.wrap_angle(a[2] + f * geometry.wrap_angle(b[2] - a[2]))
        return np.array([*(a[:2] + f * (b[:2] - a[:2])), theta]), kind

    def _scan(self) -> Scan:
        ranges = self.laser.read(self.world, self.pose, self.obstacle_circles())[0]
        scan = self.laser.scan(ranges, self.time, self.odom, self.pose, self.scans)
        self.scans += 1
        return scan


def _checked_command(v, w, dt) -> tuple[float, float, float]:
    v, w, dt = float(v), float(w), float(dt)
    if not (np.isfinite([v, w, dt]).all() and dt >= 0):
        raise InputError("Robot.step", f"needs finite v, w and dt >= 0, got v={v}, w={w}, dt={dt}")
    return v, w, dt


def _integrate(pose: np.ndarray, velocities: np.ndarray, h: float) -> np.ndarray:
    """Poses (n + 1, 3) from ``pose`` (3,) along n arcs of ``h`` seconds at ``velocities`` (n, 2) (v, w)."""
    turn = velocities[:, 1] * h
    theta = pose[2] + np.concatenate([[0.0], np.cumsum(turn)])
    chord = velocities[:, 0] * h * np.sinc(turn / (2 * np.pi))  # arc length x sin(turn / 2) / (turn / 2)
    heading = theta[:-1] + turn / 2
    steps = chord[:, None] * np.column_stack([np.cos(heading), np.sin(heading)])
    xy = pose[:2] + np.vstack([np.zeros((1, 2)), np.cumsum(steps, axis=0)])
    return np.column_stack([xy, geometry.wrap_angle(theta)])
