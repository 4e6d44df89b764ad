"""CARMEN logs: FLASER / RLASER / ROBOTLASER1 scans, ODOM odometry.

Line formats (whitespace-separated; times are IPC timestamps in seconds)::

    FLASER n r1..rn x y theta odom_x odom_y odom_theta ipc_timestamp ipc_hostname logger_timestamp
    ROBOTLASER1 laser_type start_angle fov angular_res max_range accuracy remission_mode
        n r1..rn m rem1..remm laser_x laser_y laser_theta robot_x robot_y robot_theta
        tv rv forward_safety side_safety turn_axis ipc_timestamp ipc_hostname logger_timestamp
    ODOM x y theta tv rv accel ipc_timestamp ipc_hostname logger_timestamp

``x y theta`` / ``laser_*`` is the laser pose and ``odom_*`` / ``robot_*`` the
robot pose, both in the odometry frame, so the mounting pose is their
difference. FLASER/RLASER beams span 180 degrees.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from slam2d import geometry
from slam2d.config import DatasetConfig
from slam2d.datasets.base import MAX_COORD, ScanSource, register_dataset
from slam2d.datasets.registry import log_path
from slam2d.errors import InputError, not_a_file
from slam2d.types import Scan

log = logging.getLogger(__name__)

LASER_TAGS = ("FLASER", "RLASER", "ROBOTLASER1")


class _BadLine(ValueError):
    """A line that does not match its message format."""


def _tag(line: str) -> str:
    """The message type of a log line ('' for a blank line)."""
    head = line.split(None, 1)
    return head[0] if head else ""


def _floats(tokens) -> np.ndarray:
    try:
        return np.array(tokens, dtype=np.float64)
    except ValueError:
        raise _BadLine("non-numeric field") from None


def _count(tokens, i: int) -> int:
    """The reading count at ``tokens[i]``: a non-negative integer."""
    if len(tokens) <= i or not tokens[i].isdigit():
        raise _BadLine("missing or invalid reading count")
    return int(tokens[i])


def _need(tokens, n: int) -> None:
    if len(tokens) != n:
        raise _BadLine(f"expected {n} fields, got {len(tokens)}")


def _parse_flaser(tokens, range_max: float):
    """FLASER/RLASER -> (stamp, ranges, angles, range_max, laser pose, robot pose)."""
    n = _count(tokens, 1)
    _need(tokens, n + 11)
    v = _floats(tokens[2:n + 9])
    angles = np.linspace(-np.pi / 2, np.pi / 2, n)
    return v[n + 6], v[:n], angles, range_max, v[n:n + 3], v[n + 3:n + 6]


def _parse_robotlaser(tokens, range_max: float):
    """ROBOTLASER1 -> (stamp, ranges, angles, range_max, laser pose, robot pose)."""
    n = _count(tokens, 8)
    m = _count(tokens, 9 + n)
    _need(tokens, n + m + 24)
    head = _floats(tokens[2:8])  # start_angle fov angular_res max_range accuracy remission_mode
    if not np.all(np.isfinite(head[[0, 2, 3]])):
        raise _BadLine("non-finite start angle, angular resolution or maximum range")
    ranges = _floats(tokens[9:9 + n])
    tail = _floats(tokens[10 + n + m:22 + n + m])  # laser pose, robot pose, tv rv ..., ipc_timestamp
    angles = head[0] + head[2] * np.arange(n)
    return tail[11], ranges, angles, float(head[3]), tail[0:3], tail[3:6]


class CarmenSource(ScanSource):
    """Laser scans from a CARMEN log file.

    Odometry at each scan comes from ODOM lines (interpolated at the scan's
    IPC timestamp) when the log has any, else from the robot pose in the laser
    line. ``range_max`` (m) applies to FLASER/RLASER, which carry no limit
    (81.9 m: a SICK's no-return value); ROBOTLASER1 carries its own.
    ``range_min`` (m) is a small positive value so that zero readings, which
    SICK lasers report for failed beams, are not hits.
    ``messages``: the laser message types to read (a log may carry the same
    scans as FLASER and ROBOTLASER1; RLASER is the rear laser).
    """

    name = "carmen"

    def __init__(self, path, max_scans: int | None = None, range_max: float = 81.9,
                 range_min: float = 1e-3, messages: tuple[str, ...] = ("FLASER", "ROBOTLASER1")):
        super().__init__()
        self.path = Path(path)
        self.max_scans = max_scans
        self.range_max, self.range_min = range_max, range_min
        self.messages = tuple(messages)
        unknown = set(self.messages) - set(LASER_TAGS)
        if unknown:
            raise ValueError(f"unknown CARMEN laser messages {sorted(unknown)}; known: {LASER_TAGS}")
        self.ignored: Counter[str] = Counter()  # lines of other message types, comments
        self.notes: Counter[str] = Counter()  # oddities in scans that were kept
        if not self.path.is_file():
            raise InputError(self.path, not_a_file(self.path) or "file not found")
        self._count = sum(1 for line in self._lines() if _tag(line) in self.messages)
        if not self._count:
            raise InputError(self.path, f"no {'/'.join(self.messages)} lines")

    def __len__(self) -> int:
        return self._count if self.max_scans is None else min(self._count, self.max_scans)

    def _lines(self) -> Iterator[str]:
        try:
            with open(self.path, encoding="ascii", errors="replace") as f:
                yield from f
        except OSError as err:
            raise InputError(self.path, f"cannot read ({err.strerror})") from err

    def _bad(self, lineno: int, tag: str, err: Exception) -> None:
        """Log the first bad line of ``tag``; count bad laser lines as skipped scans, bad ODOM lines as notes."""
        reason = f"malformed {tag} lines"
        counts = self.notes if tag == "ODOM" else self.skipped
        if not counts[reason]:
            log.warning("%s:%d: %s line skipped: %s", self.path, lineno, tag, err)
        if tag == "ODOM":
            self.notes[reason] += 1
        else:
            self.skip(reason)

    def _odometry(self):
        """(stamps (N,) s, poses (N, 3)) from ODOM lines, sorted by stamp; None if there are none."""
        rows = []
        for lineno, line in enumerate(self._lines(), 1):
            tokens = line.split()
            if tokens[:1] == ["ODOM"]:
                try:
                    _need(tokens, 10)
                    v = _floats(tokens[1:8])
                    if not np.all(np.isfinite(v)) or np.any(np.abs(v[:3]) >= MAX_COORD):
                        raise _BadLine("non-finite or absurd pose or timestamp")
                    rows.append(v[[6, 0, 1, 2]])
                except _BadLine as err:
                    self._bad(lineno, "ODOM", err)
        if not rows:
            return None
        rows = np.array(rows)
        rows = rows[np.argsort(rows[:, 0], kind="stable")]
        return rows[:, 0], rows[:, 1:]

    def _raw_scans(self) -> Iterator[Scan]:
        self.ignored, self.notes = Counter(), Counter()
        odom = self._odometry()
        mounts: dict[str, np.ndarray] = {}
        yielded = 0
        for lineno, line in enumerate(self._lines(), 1):
            tokens = line.split()
            tag = tokens[0] if tokens else ""
            if tag not in self.messages:
                if tag and tag != "ODOM":
                    self.ignored["comment lines" if tag.startswith("#") else f"{tag} lines"] += 1
                continue
            if self.max_scans is not None and yielded >= self.max_scans:
                break
            parse = _parse_robotlaser if tag == "ROBOTLASER1" else _parse_flaser
            try:
                stamp, ranges, angles, range_max, laser, robot = parse(tokens, self.range_max)
                if not np.all(np.isfinite(np.r_[laser, robot])):
                    raise _BadLine("non-finite pose")
            except _BadLine as err:
                self._bad(lineno, tag, err)
                continue
            yielded += 1
            yield Scan(
                stamp=stamp,
                ranges=ranges,
                angles=angles,
                range_min=self.range_min,
                range_max=range_max,
                sensor_pose=self._mount(mounts, tag, geometry.between(robot, laser)),
                odom=robot if odom is None else geometry.interpolate(*odom, stamp),
            )
        for what, count in sorted(self.ignored.items()):
            log.info("%s: ignored %d %s", self.path, count, what)
        for what, count in sorted(self.notes.items()):
            log.warning("%s: %d %s", self.path, count, what)

    def _mount(self, mounts: dict, tag: str, offset: np.ndarray) -> np.ndarray:
        """The fixed mounting pose of ``tag``'s laser: the first line's laser-robot offset.

        Logs with corrected laser poses make the offset drift; such lines are noted.
        """
        mount = mounts.setdefault(tag, offset)
        d = offset - mount
        if np.hypot(d[0], d[1]) > 0.01 or abs(geometry.wrap_angle(d[2])) > 0.01:
            self.notes[f"{tag} lines whose laser pose is not the first line's offset from the "
                       "robot pose (corrected poses?); first offset used"] += 1
        return mount


@register_dataset("carmen")
def open_carmen(cfg: DatasetConfig, seed: int) -> CarmenSource:
    """A CARMEN log's laser lines with their odometry (``dataset.path``)."""
    return CarmenSource(log_path(cfg), max_scans=cfg.max_scans)
