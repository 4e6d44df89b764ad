"""ROS 1 and ROS 2 bags: sensor_msgs/LaserScan + nav_msgs/Odometry + /tf_static.

Read with the pure-Python ``rosbags`` package; no ROS installation needed.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from slam2d import geometry
from slam2d.config import DatasetConfig
from slam2d.datasets.base import MAX_COORD, ScanSource, register_dataset
from slam2d.datasets.registry import log_path
from slam2d.errors import InputError, not_a_file
from slam2d.types import Scan

log = logging.getLogger(__name__)

LASER_TYPE = "sensor_msgs/msg/LaserScan"
ODOM_TYPE = "nav_msgs/msg/Odometry"
TF_TYPE = "tf2_msgs/msg/TFMessage"


def _stamp(t) -> float:
    """ROS time -> seconds (float64)."""
    return t.sec + 1e-9 * t.nanosec


def _yaw(q) -> float:
    """Heading (rad) of a quaternion about z."""
    return float(np.arctan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z)))


def _reason(err: Exception) -> str:
    """The first line of an error from rosbags, at most 120 characters."""
    text = (str(err).strip().splitlines() or [type(err).__name__])[0]
    return text if len(text) <= 120 else text[:117] + "..."


def _finite(*values) -> bool:
    """Whether every value is finite and below MAX_COORD in magnitude."""
    return all(abs(v) < MAX_COORD for v in values)


def _pick_topic(path, topics, msgtype: str, name: str | None, default: str) -> str:
    """The topic to read: ``name`` if given, else the only one of ``msgtype``, else ``default``."""
    listing = ", ".join(f"{t} ({info.msgtype})" for t, info in sorted(topics.items())) or "none"
    if name is not None:
        if name not in topics:
            raise InputError(path, f"topic {name!r} not in bag; topics: {listing}")
        if topics[name].msgtype != msgtype:
            raise InputError(path, f"topic {name!r} is {topics[name].msgtype}, expected {msgtype}")
        return name
    typed = [t for t, info in topics.items() if info.msgtype == msgtype]
    if len(typed) == 1:
        return typed[0]
    if default in typed:
        return default
    if not typed:
        raise InputError(path, f"no {msgtype} topics; topics: {listing}")
    raise InputError(path, f"several {msgtype} topics and none is {default!r}; name one of: {listing}")


class RosbagSource(ScanSource):
    """Laser scans from a ROS 1 ``.bag`` file or a ROS 2 bag (directory, .mcap, .db3).

    Each scan's odometry is the base pose interpolated at the scan's header
    stamp (s); the laser mounting pose comes from /tf_static (identity if absent).
    Ranges in metres, angles in radians, limits from the message. Opening
    reads the bag's index only; the odometry and /tf_static are read when the
    scans are first read (or ``odom`` is asked for).
    """

    name = "rosbag"

    def __init__(self, path, scan_topic: str | None = None, odom_topic: str | None = None,
                 max_scans: int | None = None):
        super().__init__()
        self.path = Path(path)
        self.max_scans = max_scans
        self.notes: Counter[str] = Counter()
        self.damaged: dict[str, Counter[str]] = {}  # per topic: messages lost to damage (see _messages)
        if not self.path.exists():
            raise InputError(self.path, "file not found")
        if not self.path.is_dir() and (kind := not_a_file(self.path)):  # a ROS 2 bag is a folder
            raise InputError(self.path, kind)
        with self._open() as reader:
            topics = reader.topics
            self.scan_topic = _pick_topic(self.path, topics, LASER_TYPE, scan_topic, "/scan")
            self.odom_topic = _pick_topic(self.path, topics, ODOM_TYPE, odom_topic, "/odom")
            self._count = topics[self.scan_topic].msgcount
            if not topics[self.odom_topic].msgcount:
                raise InputError(self.path, f"no messages on odometry topic {self.odom_topic!r}")
        self._odom: tuple[np.ndarray, np.ndarray] | None = None
        self._static_tf: dict[str, tuple[str, np.ndarray]] = {}
        self._mounts: dict[str, np.ndarray] = {}

    @property
    def odom(self) -> tuple[np.ndarray, np.ndarray]:
        """All odometry: stamps (N,) s and base poses (N, 3), sorted by stamp (read on first use)."""
        if self._odom is None:
            with self._open() as reader:
                self._odom = self._read_odometry(reader)
                self._static_tf = self._read_static_tf(reader, reader.topics)
        return self._odom

    def __len__(self) -> int:
        return self._count if self.max_scans is None else min(self._count, self.max_scans)

    @contextmanager
    def _open(self):
        """The bag opened with AnyReader; unreadable input becomes an InputError."""
        from rosbags.highlevel import AnyReader

        try:
            reader = AnyReader([self.path])
            reader.open()
        except Exception as err:  # rosbags raises many types for a corrupt file
            raise InputError(self.path, f"not a readable ROS bag ({_reason(err)})") from err
        try:
            yield reader
        finally:
            reader.close()

    def _messages(self, reader, topic: str):
        """(index, deserialised message) of ``topic`` in bag order, read as far as the bag is good: a message
        that does not deserialise is skipped, a damaged chunk ends the stream; both are counted in
        ``damaged[topic]`` (a Counter of "undecodable" and "unread") and logged."""
        conns = [c for c in reader.connections if c.topic == topic]
        stream = reader.messages(connections=conns)
        damaged = self.damaged.setdefault(topic, Counter())
        damaged.clear()
        index = 0
        while True:
            try:
                item = next(stream, None)
            except Exception as err:  # rosbags raises many types for a corrupt chunk
                total = sum(c.msgcount for c in conns)
                damaged["unread"] = max(total - index, 1)
                log.warning("%s: %s message %d on: unreadable (%s); read as far as the bag is good (%d of %d "
                            "messages)", self.path, topic, index, _reason(err), index, total)
                return
            if item is None:
                return
            try:
                msg = reader.deserialize(item[2], item[0].msgtype)
            except Exception as err:  # noqa: BLE001 - rosbags raises many types for a corrupt message
                if not damaged["undecodable"]:
                    log.warning("%s: %s message %d: unreadable (%s); skipped", self.path, topic, index, _reason(err))
                damaged["undecodable"] += 1
            else:
                yield index, msg
            index += 1

    def _read_odometry(self, reader):
        """All odometry as (stamps (N,) s, poses (N, 3)), sorted by stamp; sets the base frame."""
        stamps, poses, child, dropped = [], [], "", 0
        for i, msg in self._messages(reader, self.odom_topic):
            p = msg.pose.pose
            stamp, pose = _stamp(msg.header.stamp), (p.position.x, p.position.y, _yaw(p.orientation))
            if not (math.isfinite(stamp) and _finite(*pose)):
                if not dropped:
                    log.warning("%s: %s message %d: non-finite or absurd pose or stamp; dropped",
                                self.path, self.odom_topic, i)
                dropped += 1
                continue
            stamps.append(stamp)
            poses.append(pose)
            child = msg.child_frame_id
        if dropped:
            log.warning("%s: dropped %d odometry messages with a non-finite or absurd pose or stamp",
                        self.path, dropped)
        if not stamps:
            raise InputError(self.path, f"no usable messages on odometry topic {self.odom_topic!r}")
        self.base_frame = child.lstrip("/") or "base_link"
        stamps, poses = np.asarray(stamps), np.asarray(poses, dtype=np.float64)
        order = np.argsort(stamps, kind="stable")
        return stamps[order], poses[order]

    def _read_static_tf(self, reader, topics) -> dict[str, tuple[str, np.ndarray]]:
        """child frame -> (parent frame, planar pose of child in parent) from /tf_static."""
        tf = {}
        for topic in ("/tf_static", "tf_static"):
            if topic in topics and topics[topic].msgtype == TF_TYPE:
                for _, msg in self._messages(reader, topic):
                    for t in msg.transforms:
                        tr = t.transform
                        pose = np.array([tr.translation.x, tr.translation.y, _yaw(tr.rotation)])
                        tf[t.child_frame_id.lstrip("/")] = (t.header.frame_id.lstrip("/"), pose)
        return tf

    def mounting_pose(self, frame: str) -> np.ndarray:
        """Pose (3,) of ``frame`` in the base frame, chained through /tf_static; identity if unknown."""
        frame = frame.lstrip("/")
        if frame not in self._mounts:
            pose, f = np.zeros(3), frame
            for _ in range(64):  # bounded: a cyclic tree must not hang
                if f == self.base_frame or f not in self._static_tf:
                    break
                parent, p = self._static_tf[f]
                pose, f = geometry.compose(p, pose), parent
            if f != self.base_frame:
                log.info("%s: no /tf_static chain %s -> %r; laser at the base origin",
                         self.path, self.base_frame, frame)
                pose = np.zeros(3)
            self._mounts[frame] = pose
        return self._mounts[frame]

    def _bad_scan(self, index: int) -> None:
        """Skip scan message ``index``, whose angle or range limits are not finite numbers."""
        reason = "scans with a non-finite angle or range limit"
        if not self.skipped[reason]:
            log.warning("%s: %s message %d skipped: non-finite angle or range limit", self.path, self.scan_topic, index)
        self.skip(reason)

    def _raw_scans(self) -> Iterator[Scan]:
        self.notes = Counter()
        t_odom, p_odom = self.odom  # before mounting_pose: sets the base frame and /tf_static
        count = 0
        with self._open() as reader:
            for i, msg in self._messages(reader, self.scan_topic):
                if i >= len(self):
                    if len(self) == self.max_scans:
                        break
                    raise self._corrupt_index("more")
                count += 1
                stamp = _stamp(msg.header.stamp)
                if not _finite(msg.angle_min, msg.angle_increment, msg.range_min, msg.range_max):
                    self._bad_scan(i)
                    continue
                if not t_odom[0] <= stamp <= t_odom[-1]:
                    self.notes["scans outside the odometry time span (odometry clamped)"] += 1
                ranges = np.asarray(msg.ranges, dtype=np.float64)
                yield Scan(
                    stamp=stamp,
                    ranges=ranges,
                    angles=msg.angle_min + msg.angle_increment * np.arange(len(ranges)),
                    range_min=float(msg.range_min),
                    range_max=float(msg.range_max),
                    sensor_pose=self.mounting_pose(msg.header.frame_id),
                    odom=geometry.interpolate(t_odom, p_odom, stamp),
                )
        damaged = self.damaged[self.scan_topic]
        for _ in range(damaged["undecodable"]):
            self.skip("scans that do not decode (damaged bag)")
        for _ in range(min(damaged["unread"], len(self) - count - damaged["undecodable"])):
            self.skip("scans in an unreadable part of the bag")
        if count + damaged["undecodable"] + damaged["unread"] < len(self):
            raise self._corrupt_index(str(count))
        for what, n in self.notes.items():
            log.warning("%s: %d %s", self.path, n, what)

    def _corrupt_index(self, found: str) -> InputError:
        return InputError(self.path, f"corrupt index: it lists {self._count} messages on {self.scan_topic}, "
                          f"the bag holds {found}")


@register_dataset("rosbag")
def open_rosbag(cfg: DatasetConfig, seed: int) -> RosbagSource:
    """A ROS 1 or ROS 2 bag's LaserScan and Odometry topics (``dataset.path``, ``scan_topic``, ``odom_topic``)."""
    return RosbagSource(log_path(cfg), scan_topic=cfg.scan_topic, odom_topic=cfg.odom_topic, max_scans=cfg.max_scans)
