"""Simulated localisation runs: a robot wandering a world (optionally kidnapped), its scan
stream replayed through particle filters, and the measures of convergence and recovery.

The stream is recorded once and replayed through every filter, so that all of them
see the same scans, odometry and truth. The wanderer steers by its own laser
only (forwards towards open space, turning in place before walls), so the stream
does not depend on any filter.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from slam2d import geometry
from slam2d.localization.maps import KnownMap
from slam2d.localization.mcl import ParticleFilter
from slam2d.types import Scan

__all__ = ["Stream", "Track", "active_run", "converged_at", "false_convergence", "final_state", "random_free_pose", "replay",
           "wander"]

SPEED = 0.5  # m/s, the wanderer's cruise speed
PERIOD = 0.1  # s between scans
_CLEARANCE = 0.4  # m, starts and kidnap targets this far from walls
_LANE = 0.3  # m, half-width of the lane ahead the wanderer keeps clear
_STOP = 0.7  # m, obstacle distance ahead that makes it turn in place


@dataclass
class Stream:
    """Scans (with odometry and ground truth), true poses (N, 3), distance travelled (N,) m, and the
    scan index of each kidnapping."""

    scans: list[Scan]
    truth: np.ndarray
    travelled: np.ndarray
    kidnaps: list[int] = field(default_factory=list)

    @property
    def stamps(self) -> np.ndarray:
        return np.array([s.stamp for s in self.scans])


def random_free_pose(world, known: KnownMap, rng: np.random.Generator, away_from=None, min_jump: float = 0.0):
    """A pose (3,) in the map's free space with room for the robot, at least ``min_jump`` m from ``away_from``."""
    cells = known.free_cells(_CLEARANCE)
    for _ in range(10_000):
        c = cells[rng.integers(len(cells))]
        row, col = divmod(int(c), known.shape[1])
        xy = np.array(known.origin) + (np.array([col, row]) + 0.5) * known.resolution
        if away_from is not None and math.hypot(*(xy - away_from[:2])) < min_jump:
            continue
        if world.free(xy, _CLEARANCE)[0]:
            return np.array([xy[0], xy[1], rng.uniform(-math.pi, math.pi)])
    raise RuntimeError(f"no free pose found in {known.name}")


def wander_command(scan: Scan, turning: float) -> tuple[float, float, float]:
    """(v m/s, w rad/s, turning direction) steering by the laser: towards open space, turning in
    place when the lane ahead (the robot's width plus a margin) is blocked within _STOP m, in one
    direction until 0.5 m more is clear."""
    r = np.where(np.isfinite(scan.ranges), scan.ranges, scan.range_max)
    a = scan.angles
    x, y = r * np.cos(a), r * np.sin(a)
    reach = _STOP + 0.5 if turning else _STOP
    if np.any((x > 0) & (x < reach) & (np.abs(y) < _LANE)):
        if turning == 0.0:
            turning = 1.0 if r[(a > 0) & (a < 2.0)].mean() >= r[(a < 0) & (a > -2.0)].mean() else -1.0
        return 0.0, 1.0 * turning, turning
    wide = np.abs(a) < 1.0
    smooth = np.convolve(r, np.ones(15) / 15, mode="same")
    target = a[wide][np.argmax(smooth[wide])]
    return SPEED, float(np.clip(1.5 * target, -1.0, 1.0)), 0.0


def wander(world, known: KnownMap, seconds: float, seed: int, kidnap_at=(), min_jump: float = 5.0,
           start=None, robot_config=None) -> Stream:  # fmt: skip
    """Drive a wandering robot for ``seconds`` s from ``start`` (a random free pose by default);
    at each time in ``kidnap_at`` (s) teleport it to a random free pose at least ``min_jump`` m away."""
    from slam2d.sim import Robot

    rng = np.random.default_rng(seed)
    start = random_free_pose(world, known, rng) if start is None else np.asarray(start, dtype=np.float64)
    robot = Robot(world, start, robot_config, seed=seed)
    step = robot.step(0.0, 0.0, 0.0)
    scans, truth, kidnaps, turning = [step.scan], [step.pose], [], 0.0
    pending = sorted(kidnap_at)
    for k in range(1, round(seconds / PERIOD) + 1):
        _kidnap_due(robot, world, known, rng, pending, k, kidnaps, min_jump)
        v, w, turning = wander_command(step.scan, turning)
        step = robot.step(v, w, PERIOD)
        scans.append(step.scan)
        truth.append(step.pose)
    return _stream(scans, truth, kidnaps)


def _kidnap_due(robot, world, known: KnownMap, rng, pending: list, k: int, kidnaps: list, min_jump: float) -> None:
    """Before scan ``k``: if the first time in ``pending`` (s, sorted) has come, teleport ``robot`` to a
    random free pose at least ``min_jump`` m away and note ``k`` in ``kidnaps``."""
    if pending and k * PERIOD >= pending[0]:
        pending.pop(0)
        robot.pose = random_free_pose(world, known, rng, robot.pose, min_jump)
        robot.velocity = np.zeros(2)
        kidnaps.append(k)


def _stream(scans: list, truth: list, kidnaps: list) -> Stream:
    """The stream of ``scans`` with true poses ``truth``; a teleport is no travel."""
    truth = np.array(truth)
    moved = np.hypot(*np.diff(truth[:, :2], axis=0).T)
    moved[np.array(kidnaps, dtype=np.int64) - 1] = 0.0
    return Stream(scans, truth, np.concatenate([[0.0], np.cumsum(moved)]), kidnaps)


@dataclass
class Track:
    """A filter's replay of a stream: estimates (N, 3), their errors (N,) m and (N,) rad, particle
    counts (N,), the heaviest cluster's share (N,) and position sd (N,) m, ms per update, the
    filter's state (N,) (tracking / ambiguous / lost) and the scans' stamps (N,) s."""

    estimates: np.ndarray
    position_error: np.ndarray
    heading_error: np.ndarray
    particles: np.ndarray
    share: np.ndarray
    sd_xy: np.ndarray
    update_ms: np.ndarray
    snapshots: dict = field(default_factory=dict)
    state: np.ndarray | None = None
    stamps: np.ndarray | None = None  # None: scans PERIOD s apart

    def tracking(self) -> np.ndarray:
        """(N,) bool: the filter claimed its pose (every scan if no state was recorded)."""
        return np.ones(len(self.estimates), bool) if self.state is None else self.state == "tracking"


SNAPSHOT_PARTICLES = 400  # particles kept per snapshot (an even subset)


class _Recorder:
    """Per-scan estimates of a filter (what :class:`Track` holds), gathered while the scans come."""

    def __init__(self):
        self.est, self.count, self.share, self.sd, self.state, self.ms, self.stamps = [], [], [], [], [], [], []

    def add(self, pf: ParticleFilter, scan: Scan) -> np.ndarray:
        """Feed ``scan`` to ``pf`` and record its estimate; the pose (3,) moved to the scan's odometry."""
        t0 = time.perf_counter()
        if pf.add(scan):
            self.ms.append((time.perf_counter() - t0) * 1000)
        e = pf.estimate
        pose = pf.pose(scan.odom)
        self.est.append(pose)
        self.count.append(e.particles)
        self.share.append(e.share)
        self.sd.append(e.sd_xy)
        self.state.append(e.state)
        self.stamps.append(scan.stamp)
        return pose

    def track(self, truth: np.ndarray, snapshots: dict | None = None) -> Track:
        est = np.array(self.est)
        err = np.hypot(*(est[:, :2] - truth[:, :2]).T)
        head = np.abs(geometry.wrap_angle(est[:, 2] - truth[:, 2]))
        return Track(est, err, head, np.array(self.count), np.array(self.share), np.array(self.sd),
                     np.array(self.ms), snapshots or {}, np.array(self.state, dtype=str),
                     np.array(self.stamps, dtype=np.float64))  # fmt: skip


def replay(pf: ParticleFilter, stream: Stream, snapshot_at=(), view=None, progress=None) -> Track:
    """Feed every scan of ``stream`` to ``pf`` (initialised). At the scan indices ``snapshot_at``
    (or at every update for ``"updates"``) keep up to SNAPSHOT_PARTICLES particles, their weights
    and the estimate. ``view`` (a :class:`slam2d.viz.ParticleView`) logs each scan's step;
    ``progress(done)``, if given, is told the scans done after each."""
    rec, snaps = _Recorder(), {}
    for i, scan in enumerate(stream.scans):
        updates = pf.updates
        pose = rec.add(pf, scan)
        updated = pf.updates != updates
        if view is not None:
            view.step(i, scan.stamp - stream.scans[0].stamp, pf, pose, stream.truth[i], updated)
        if (updated and snapshot_at == "updates") or (snapshot_at != "updates" and i in snapshot_at):
            keep = np.linspace(0, len(pf.particles) - 1, min(SNAPSHOT_PARTICLES, len(pf.particles))).astype(int)
            snaps[i] = (pf.particles[keep].copy(), np.exp(pf.log_w[keep]), pose.copy())
        if progress is not None:
            progress(i + 1)
    return rec.track(stream.truth, snaps)


def active_run(world, known: KnownMap, pf: ParticleFilter, seconds: float, seed: int, kidnap_at=(),
               min_jump: float = 5.0) -> tuple[Stream, Track]:  # fmt: skip
    """Localisation with active moves: the robot of :func:`wander` (same start, noise and kidnappings
    for the same ``seed``, ``kidnap_at`` s and ``min_jump`` m), but while ``pf`` (initialised) is
    ambiguous it drives towards the places that tell its hypotheses apart
    (:class:`slam2d.localization.active.Looker`, on the estimate), keeping off what its laser sees
    ahead; otherwise it wanders. Until the first kidnapping, or while the filter tracks, the stream is
    :func:`wander`'s. The stream it drove and the filter's track."""
    from slam2d.localization.active import Looker
    from slam2d.sim import Robot

    rng = np.random.default_rng(seed)
    robot = Robot(world, random_free_pose(world, known, rng), seed=seed)
    looker, rec = Looker(pf), _Recorder()
    step = robot.step(0.0, 0.0, 0.0)
    scans, truth, kidnaps, turning = [step.scan], [step.pose], [], 0.0
    pending = sorted(kidnap_at)
    pose = rec.add(pf, step.scan)
    for k in range(1, round(seconds / PERIOD) + 1):
        _kidnap_due(robot, world, known, rng, pending, k, kidnaps, min_jump)
        heading = looker.heading(pose, step.scan)
        toward = None if heading is None else _towards(step.scan, float(geometry.wrap_angle(heading - pose[2])))
        if toward is not None:
            (v, w), turning = toward, 0.0
        else:
            v, w, turning = wander_command(step.scan, turning)
        step = robot.step(v, w, PERIOD)
        scans.append(step.scan)
        truth.append(step.pose)
        pose = rec.add(pf, step.scan)
    stream = _stream(scans, truth, kidnaps)
    return stream, rec.track(stream.truth)


def _towards(scan: Scan, bearing: float) -> tuple[float, float] | None:
    """(v m/s, w rad/s) heading for ``bearing`` rad (robot frame): turning in place while it is more
    than 0.5 rad off, else driving while steering; None when the lane ahead is blocked within 0.4 m
    (the wanderer's turn then leads out)."""
    r = np.where(np.isfinite(scan.ranges), scan.ranges, scan.range_max)
    x, y = r * np.cos(scan.angles), r * np.sin(scan.angles)
    if abs(bearing) > 0.5:
        return 0.0, math.copysign(1.0, bearing)
    if np.any((x > 0) & (x < 0.4) & (np.abs(y) < _LANE)):
        return None
    return SPEED, float(np.clip(1.5 * bearing, -1.0, 1.0))


def _held(ok: np.ndarray, from_index: int, stamps: np.ndarray | None) -> int | None:
    """First index >= from_index from which ``ok`` holds for HOLD s in a row (from that scan to the end of the
    last one's period; ``stamps`` (N,) s, None: scans PERIOD s apart, so that a log's own scan rate counts)."""
    stamps = np.arange(len(ok)) * PERIOD if stamps is None else np.asarray(stamps, dtype=np.float64)
    period = float(np.median(np.diff(stamps))) if len(stamps) > 1 else PERIOD
    start = None
    for i in range(from_index, len(ok)):
        if not ok[i]:
            start = None
            continue
        start = i if start is None else start
        if stamps[i] - stamps[start] + period >= HOLD - 1e-6:
            return start
    return None


POSITION_OK = 0.2  # m
HEADING_OK = math.radians(5.0)
HOLD = 5.0  # s


def converged_at(track: Track, from_index: int = 0) -> int | None:
    """First scan (>= from_index) from which the filter is tracking with an error below 0.2 m and
    5 degrees for 5 s."""
    ok = (track.position_error < POSITION_OK) & (track.heading_error < HEADING_OK) & track.tracking()
    return _held(ok, from_index, track.stamps)


WRONG = 0.5  # m


def false_convergence(track: Track, from_index: int = 0) -> bool:
    """Whether the filter claimed its pose (state tracking) while more than 0.5 m wrong, for 5 s,
    after ``from_index``."""
    ok = track.tracking() & (track.position_error > WRONG)
    return _held(ok, from_index, track.stamps) is not None


def final_state(track: Track) -> str:
    """The filter's state at the last scan."""
    return "tracking" if track.state is None else str(track.state[-1])


HELD_HEADING = math.radians(10.0)  # rad: a hypothesis's mean this close to the true heading (and WRONG m) holds it


def truth_rank(hypotheses, truth) -> int | None:
    """Rank (0: the best) of the heaviest hypothesis whose mean lies within WRONG m and HELD_HEADING of the
    true pose ``truth`` (3,), None when none does: tells a run whose filter holds the true place but has not
    told it from the others (rank > 0, or 0 below the evidence threshold) from one that lost or never
    found it."""
    for i, h in enumerate(hypotheses):
        if (math.hypot(h.pose[0] - truth[0], h.pose[1] - truth[1]) < WRONG
                and abs(float(geometry.wrap_angle(h.pose[2] - truth[2]))) < HELD_HEADING):  # fmt: skip
            return i
    return None
