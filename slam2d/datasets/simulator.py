"""Simulated dataset: the scripted route through a world, with ray-cast scans, noisy odometry, ground truth.

The embedded default is :meth:`World.office` driven along :func:`office_route`;
it needs no files. A robot turns in place and drives straight between waypoints;
at every scan period it casts its laser against the walls and integrates noisy
odometry (Thrun et al., *Probabilistic Robotics*, ``sample_motion_model_odometry``).
Worlds live in :mod:`slam2d.sim.world`, the laser and odometry models in
:mod:`slam2d.sim.robot`; this module scripts the route and replays it as a dataset.
The route is sampled at the scan stamps rather than driven through
``Robot.step`` (whose velocity ramps and incremental odometry draws would change
the stream), so the two share the world, the laser and the odometry sampling.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from slam2d import geometry
from slam2d.config import DatasetConfig, SimulatorConfig
from slam2d.datasets.base import ScanSource, register_dataset
from slam2d.errors import InputError
from slam2d.sim.robot import ROBOT_RADIUS, Laser, beam_angles, measure_ranges, sample_odometry
from slam2d.sim.world import World, load_world
from slam2d.types import Scan

__all__ = [
    "ROBOT_RADIUS",
    "World",
    "office_route",
    "route_start",
    "load_world",
    "check_route",
    "route_poses",
    "sample_odometry",
    "beam_angles",
    "measure_ranges",
    "SimulatorSource",
]

_ROUTE_KEY = "dataset.simulator.route"
_EPS = 1e-9


# --------------------------------------------------------------------------- the route


def office_route() -> np.ndarray:
    """Scripted waypoints (M, 2) in metres through the office, about 100 m.

    Starts in the south corridor, goes twice counter-clockwise round the
    corridor ring, enters five rooms and crosses the open-plan room, and ends
    at the start.
    """
    s, n = 4.225, 7.775  # centre lines of the south and north corridors
    lap1 = [
        (5.5, s), (7.5, s), (7.5, 2.2), (6.0, 2.2), (9.0, 2.2), (7.5, 2.2), (7.5, s),  # room B2
        (12.5, s), (12.5, 1.9), (12.5, s),  # room B3
        (17.3, s), (17.3, n), (12.0, n),
        (12.0, 9.5), (8.0, 9.5), (8.0, n),  # through the open-plan room T2
        (3.0, n), (3.0, s), (5.5, s),
    ]  # fmt: skip
    lap2 = [
        (17.3, s), (17.3, 1.9), (17.3, s),  # room B4
        (17.3, n), (17.0, n), (17.0, 10.2), (17.0, n),  # room T3
        (12.0, n), (12.0, 9.5), (8.0, 9.5), (8.0, n),  # T2 again
        (3.0, n), (3.0, 9.5), (3.0, n),  # room T1
        (3.0, s), (3.0, 1.9), (3.0, s),  # room B1
        (5.5, s),
    ]  # fmt: skip
    return np.array(lap1 + lap2, dtype=np.float64)


def check_route(world: World, waypoints, clearance: float = ROBOT_RADIUS) -> np.ndarray:
    """Waypoints (M, 2) as float array; InputError if one or a leg comes within ``clearance`` m of a wall."""
    wp = np.asarray(waypoints, dtype=np.float64)
    if wp.ndim != 2 or wp.shape[1] != 2 or len(wp) < 2 or not np.isfinite(wp).all():
        raise InputError(_ROUTE_KEY, f"a route needs at least two finite (x, y) waypoints, got shape {wp.shape}")
    (x0, y0), (x1, y1) = world.bounds
    outside = (wp[:, 0] < x0) | (wp[:, 0] > x1) | (wp[:, 1] < y0) | (wp[:, 1] > y1)
    inside = world.occupied(wp)
    near = world.distance(wp) < clearance
    for bad, what in ((outside, f"is outside {world.name}"), (inside, "is inside a wall")):
        if bad.any():
            i = int(np.argmax(bad))
            raise InputError(_ROUTE_KEY, f"waypoint {i} ({wp[i, 0]:.2f}, {wp[i, 1]:.2f}) {what}")
    if near.any():
        i = int(np.argmax(near))
        raise InputError(
            _ROUTE_KEY, f"waypoint {i} ({wp[i, 0]:.2f}, {wp[i, 1]:.2f}) is closer than {clearance} m to a wall"
        )
    near = world.segment_distance(np.stack([wp[:-1], wp[1:]], axis=1)) < clearance
    if near.any():
        i = int(np.argmax(near))
        (ax, ay), (bx, by) = wp[i], wp[i + 1]
        raise InputError(
            _ROUTE_KEY,
            f"leg {i} -> {i + 1} from ({ax:.2f}, {ay:.2f}) to ({bx:.2f}, {by:.2f}) "
            f"crosses a wall or passes closer than {clearance} m to one",
        )
    return wp


def route_poses(waypoints, speed: float, turn_rate: float, scan_rate: float) -> tuple[np.ndarray, np.ndarray]:
    """Ground truth along waypoints: turn in place at ``turn_rate`` (rad/s), then drive at ``speed`` (m/s).

    Returns stamps (N,) in seconds, one every ``1 / scan_rate``, and poses (N, 3).
    The robot starts at the first waypoint facing the second.
    """
    wp = np.asarray(waypoints, dtype=np.float64)
    wp = wp[np.r_[True, np.linalg.norm(np.diff(wp, axis=0), axis=1) > _EPS]]
    if len(wp) < 2:
        raise InputError(_ROUTE_KEY, "a route needs at least two distinct waypoints")
    d = np.diff(wp, axis=0)
    heading = np.arctan2(d[:, 1], d[:, 0])
    turns = geometry.wrap_angle(np.diff(heading, prepend=heading[0]))
    # knots: start, then per leg "turned at its start" and "arrived at its end"
    knots = np.empty((2 * len(d) + 1, 3))
    knots[0] = (*wp[0], heading[0])
    knots[1::2, :2], knots[2::2, :2] = wp[:-1], wp[1:]
    knots[1::2, 2] = knots[2::2, 2] = heading
    durations = np.column_stack([np.abs(turns) / turn_rate, np.linalg.norm(d, axis=1) / speed]).ravel()
    t_knots = np.concatenate([[0.0], np.cumsum(durations)])
    stamps = np.arange(int(np.floor(t_knots[-1] * scan_rate + _EPS)) + 1) / scan_rate
    return stamps, geometry.interpolate(t_knots, knots, stamps)


# --------------------------------------------------------------------------- the scan source


class SimulatorSource(ScanSource):
    """Scans of a simulated robot: ray-cast laser, noisy odometry, ground truth.

    ``world``, ``stamps`` (N,) s, ``ground_truth_poses`` (N, 3), ``odometry_poses``
    (N, 3) and ``beam_angles`` (n,) are available before iterating. The same
    ``seed`` gives identical scans, iteration after iteration.
    """

    name = "simulator"

    def __init__(self, cfg: SimulatorConfig, seed: int = 0, max_scans: int | None = None):
        super().__init__()
        if max_scans is not None and max_scans < 1:
            raise InputError("dataset.max_scans", f"must be >= 1, got {max_scans}")
        self.cfg = cfg
        self.world = load_world(cfg.world, cfg.resolution)
        self.name = f"simulator:{self.world.name}"
        self.waypoints = check_route(self.world, self._route())
        stamps, poses = route_poses(self.waypoints, cfg.speed, cfg.turn_rate, cfg.scan_rate)
        odom_seed, self._noise_seed, self._dropout_seed = np.random.SeedSequence(seed).spawn(3)
        odom = sample_odometry(poses, cfg.odometry, np.random.default_rng(odom_seed))
        n = len(stamps) if max_scans is None else min(max_scans, len(stamps))
        self.stamps, self.ground_truth_poses, self.odometry_poses = stamps[:n], poses[:n], odom[:n]
        self.beam_angles = beam_angles(cfg.laser)

    def _route(self) -> np.ndarray:
        if self.cfg.route is not None:
            return np.asarray(self.cfg.route, dtype=np.float64)
        if self.cfg.world == "office":
            return office_route()
        raise InputError(_ROUTE_KEY, f"world '{self.cfg.world}' has no scripted route; give waypoints")

    def __len__(self) -> int:
        return len(self.stamps)

    def _raw_scans(self, batch: int = 64) -> Iterator[Scan]:
        laser = Laser(self.cfg.laser, self._noise_seed, self._dropout_seed)
        for i in range(0, len(self), batch):
            truth = self.ground_truth_poses[i : i + batch]
            for k, r in enumerate(laser.read(self.world, truth), start=i):
                yield laser.scan(r, self.stamps[k], self.odometry_poses[k], self.ground_truth_poses[k], k)


def route_start(world: str) -> np.ndarray:
    """The start (x, y, heading) of the simulator's scripted route in ``world`` (only the office has one)."""
    if world != "office":
        raise InputError("navigation.start", f"needed for the world '{world}' (x, y, heading)")
    route = office_route()
    d = route[1] - route[0]
    return np.array([*route[0], np.arctan2(d[1], d[0])])


@register_dataset("simulator")
def open_simulator(cfg: DatasetConfig, seed: int) -> SimulatorSource:
    """A simulated robot driving a route through a world (``dataset.simulator``), ground truth included."""
    return SimulatorSource(cfg.simulator, seed=seed, max_scans=cfg.max_scans)
