"""What every local planner shares: the command it returns and path helpers (its interface: ``base``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slam2d import geometry

__all__ = ["Command", "point_along", "path_ahead", "approach_speed", "stopping_speed", "in_robot_frame"]


@dataclass(frozen=True)
class Command:
    """Velocity command ``v`` (m/s) and ``w`` (rad/s); ``blocked`` when the planner sees no
    way forward along the path; ``state`` a short label of what it chose (for logs)."""

    v: float
    w: float
    blocked: bool = False
    state: str = ""


def point_along(path, s: float) -> np.ndarray:
    """The point (2,) at arc length ``s`` (m) along a polyline (L, 2); its end beyond that."""
    p = np.asarray(path, dtype=np.float64).reshape(-1, 2)
    if len(p) == 1:
        return p[0].copy()
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    if s >= cum[-1]:
        return p[-1].copy()
    i = int(np.searchsorted(cum, s, side="right") - 1)
    f = (s - cum[i]) / seg[i] if seg[i] > 0 else 0.0
    return p[i] + f * (p[i + 1] - p[i])


def path_ahead(path, xy, window: float = 2.0) -> np.ndarray:
    """The polyline (L', 2) from the point nearest ``xy`` among its first ``window`` metres on."""
    p = np.asarray(path, dtype=np.float64).reshape(-1, 2)
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    head = p[: max(1, int(np.searchsorted(cum, window, side="right")))]
    return p[int(np.argmin(np.hypot(*(head - np.asarray(xy)[:2]).T))) :]


def approach_speed(distance: float, decel: float) -> float:
    """Largest speed (m/s) that stops within ``distance`` (m) at deceleration ``decel`` (m/s^2)."""
    return float(np.sqrt(2.0 * decel * max(distance, 0.0)))


def stopping_speed(distance: float, speed: float, decel: float, period: float) -> float:
    """Speed (m/s) to command now so that the robot, moving at ``speed`` (m/s) and reaching the command within
    the control ``period`` (s), then braking at ``decel`` (m/s^2), stops after ``distance`` (m): the root of
    (speed + v) / 2 * period + v^2 / (2 decel) = distance (0 if even v = 0 goes further)."""
    rest = distance - 0.5 * abs(speed) * period
    if rest <= 0.0:
        return 0.0
    half = 0.5 * decel * period
    return float(-half + np.sqrt(half * half + 2.0 * decel * rest))


def in_robot_frame(pose, xy) -> np.ndarray:
    """World points ``xy`` (..., 2) in the frame of the robot at ``pose`` (3,)."""
    xy = np.asarray(xy, dtype=np.float64)
    return geometry.transform_points(geometry.inverse(pose), xy.reshape(-1, 2)).reshape(xy.shape)
