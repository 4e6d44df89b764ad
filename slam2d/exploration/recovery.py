"""What an exploring robot does when it is stuck: back out of a tight spot where the local planner finds
no way (:func:`escape`), and drive its own path back out when its map has cut it off from the rest of the
known free space (:func:`way_out`, :func:`retrace`). The navigator's own recovery within a goal is the
``navigation.options.recovery`` behaviour (:data:`slam2d.navigation.base.RECOVERY_BEHAVIOURS`).

Each function takes the exploration loop's state (:class:`slam2d.exploration.loop` ``_Loop``): its SLAM
pose and grid view, the robot, and the escape / retrace it is in."""

from __future__ import annotations

import logging

import numpy as np

from slam2d import geometry
from slam2d.exploration.gridops import geodesic
from slam2d.navigation.common import Command

log = logging.getLogger(__name__)

ESCAPE_DISTANCE = 0.3  # m driven out of a tight spot
ESCAPE_TIME = 8.0  # s at most


def escape(loop, step, now: float):
    """Out of a spot where the local planner finds no way (the disc nearly touching walls): turn on the
    spot (a disc always can) to the heading with the longest free sweep, then drive ESCAPE_DISTANCE."""
    heading, start, since = loop.escape
    since = now if since is None else since
    loop.escape = heading, start, since
    pose = loop.slam.pose
    if np.hypot(*(step.pose[:2] - start)) >= ESCAPE_DISTANCE or now - since > ESCAPE_TIME:
        loop.escape = None
        return None
    points = step.scan.points_in_base()
    if heading is None:
        heading = pose[2] + open_heading(points, loop.body.radius)
        loop.escape = heading, start, since
        loop.escapes += 1
    err = heading_error(heading, pose)
    if abs(err) > 0.15:
        return towards(err, 0.0, "escape turn")
    if blocked_ahead(points, loop.body.radius, 0.25, 0.01):
        loop.escape = None, start, since  # blocked after all: choose again
        return Command(0.0, 0.0, False, "escape")
    return towards(err, 0.15, "escape")


TRAPPED_SHARE = 0.5  # the robot is trapped when its map lets it reach less than this share of the known free space
MAX_RETRACES = 3  # ways out driven in a run at most
RETRACE_SPACING = 0.1  # m between the points of a way out
RETRACE_LOOKAHEAD = 0.3  # m: the point of the way out steered at


def way_out(loop, est: list) -> np.ndarray | None:
    """When no goal is left: the robot's own way back (K, 2) m, latest first, to where it last was in the larger part
    of the known free space, if its map cuts it off from that part (a gap it drove through that the map has since
    drawn narrower than the robot: the robot can pass it, the planner no longer plans through it); else None."""
    if loop.retraces >= MAX_RETRACES:
        return None
    view = loop.view()
    passable = view.traversable(loop.body.radius)
    reach = np.isfinite(geodesic(passable, view.to_cell(loop.slam.pose[:2]), view.resolution))
    if reach.sum() >= TRAPPED_SHARE * passable.sum():
        return None
    path = np.array(est)[:, :2]
    cells = view.to_cell(path)
    inside = view.inside(cells)
    cut_off = np.zeros(len(path), dtype=bool)
    cut_off[inside] = (passable & ~reach)[cells[inside, 0], cells[inside, 1]]
    if not cut_off.any():
        return None
    k = int(np.nonzero(cut_off)[0][-1])
    i, way = len(path) - 1, []
    while i > k:  # back along the path; where it passed near here before, from its earliest pass (loops skipped)
        near = np.nonzero(np.hypot(*(path[k:i] - path[i]).T) < RETRACE_SPACING)[0]
        i = max(k + int(near[0]) - 1, k) if len(near) else i - 1
        way.append(path[i])
    if not way:  # cut off where it stands: nothing to drive back along
        return None
    way = np.array(way)
    loop.retraces += 1
    log.info("trapped at (%.2f, %.2f): driving %.1f m back the way the robot came", *path[-1],
             float(np.hypot(*np.diff(np.vstack([path[-1], way]), axis=0).T).sum()))  # fmt: skip
    return way


def retrace(loop, step, now: float):
    """Follow the way out (``way_out``): turn on the spot towards the point RETRACE_LOOKAHEAD m ahead on it, then
    drive at 0.15 m/s; None (and the way dropped) at its end, when a laser point blocks the disc, or after its time
    (20 s + 10 s a metre)."""
    way, since = loop.retrace
    pose = loop.slam.pose
    near = np.hypot(*(way - pose[:2]).T)
    if near[-1] < RETRACE_SPACING or now - since > 20.0 + 10.0 * RETRACE_SPACING * len(way):
        loop.retrace = None
        return None
    ahead = np.nonzero(near >= RETRACE_LOOKAHEAD)[0]
    ahead = ahead[ahead >= int(np.argmin(near))]
    target = way[ahead[0]] if len(ahead) else way[-1]
    err = heading_error(float(np.arctan2(target[1] - pose[1], target[0] - pose[0])), pose)
    if abs(err) > 0.3:
        return towards(err, 0.0, "retrace turn")
    if blocked_ahead(step.scan.points_in_base(), loop.body.radius, 0.15, 0.0):
        loop.retrace = None
        return None
    return towards(err, 0.15, "retrace")


def heading_error(heading: float, pose) -> float:
    """``heading`` (rad) less the pose's, wrapped to [-pi, pi)."""
    return float(geometry.wrap_angle(heading - pose[2]))


def towards(err: float, v: float, state: str):
    """Drive at ``v`` m/s, turning at twice the heading error ``err`` (rad), at most 1 rad/s."""
    return Command(v, float(np.clip(2.0 * err, -1.0, 1.0)), False, state)


def blocked_ahead(points: np.ndarray, radius: float, reach: float, margin: float) -> bool:
    """Whether a laser point (M, 2) (robot frame) lies in the disc's sweep up to ``reach`` m ahead, with ``margin``
    m to spare at its sides."""
    ahead = (points[:, 0] > 0) & (points[:, 0] < reach + radius)
    return bool((np.abs(points[ahead, 1]) < radius + margin).any())


def open_heading(points: np.ndarray, radius: float, reach: float = 1.0) -> float:
    """Heading (rad, robot frame) along which the disc sweeps farthest (up to ``reach`` m) without
    touching a laser point (M, 2); ties go to headings away from the nearest point."""
    angles = np.linspace(-np.pi, np.pi, 72, endpoint=False)
    c, s_ = np.cos(angles)[:, None], np.sin(angles)[:, None]
    along = c * points[:, 0] + s_ * points[:, 1]
    side = -s_ * points[:, 0] + c * points[:, 1]
    touching = (along > 0) & (np.abs(side) < radius + 0.01)
    free = np.where(touching, along - radius, reach).min(axis=1).clip(0, reach)
    nearest = points[np.argmin(np.hypot(*points.T))] if len(points) else np.zeros(2)
    away = np.cos(angles - np.arctan2(-nearest[1], -nearest[0]))
    return float(angles[np.argmax(free + 0.01 * away)])
