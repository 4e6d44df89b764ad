"""Scan readers: ROS bags and CARMEN logs, on real data and on small files written here."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from slam2d import geometry
from slam2d.datasets.carmen import CarmenSource
from slam2d.datasets.rosbag import RosbagSource
from slam2d.errors import InputError


def _check_first_scan(scan, n_beams: int):
    assert scan.ranges.shape == scan.angles.shape == (n_beams,)
    assert scan.angles[-1] - scan.angles[0] == pytest.approx(np.pi, abs=1e-3)
    assert np.all(np.isfinite(scan.odom)) and scan.odom.shape == (3,)
    np.testing.assert_allclose(scan.sensor_pose, 0.0, atol=1e-12)
    assert scan.hit_mask().sum() > n_beams // 4


# ---------------------------------------------------------------- real data


@pytest.mark.parametrize("name, count", [("intel", 13631), ("aces", 7374)])
def test_radish_bag(data_file, name, count):
    source = RosbagSource(data_file(f"radish/{name}.bag"))
    assert len(source) == count
    scans = list(source)
    assert len(scans) == count and not source.skipped
    _check_first_scan(scans[0], 180)
    # every ground-truth relation endpoint is a scan header stamp
    stamps = np.array([s.stamp for s in scans])
    ends = np.loadtxt(data_file(f"radish/{name}.relations"))[:, :2].ravel()
    k = np.clip(np.searchsorted(stamps, ends), 1, len(stamps) - 1)
    gap = np.minimum(abs(stamps[k] - ends), abs(stamps[k - 1] - ends))
    assert gap.max() < 1e-5


def test_radish_bag_max_scans(data_file):
    source = RosbagSource(data_file("radish/aces.bag"), max_scans=10)
    assert len(source) == 10 and len(list(source)) == 10


def test_mit_csail_log(data_file):
    source = CarmenSource(data_file("radish/mit-csail.clf"))
    assert len(source) == 1988
    scans = list(source)
    assert len(scans) == 1988 and not source.skipped
    assert source.ignored == {"comment lines": 3}
    _check_first_scan(scans[0], 361)
    assert np.diff(scans[0].angles) == pytest.approx(np.deg2rad(0.5))
    assert scans[0].stamp == pytest.approx(1134864629.895182)
    np.testing.assert_allclose(scans[0].odom, [576.536523, 0.106594, -2.255213])


# ---------------------------------------------------------------- ROS bags written here


def _ros_writer(kind: str, path):
    """(writer, typestore, serialize) for a ROS 1 or ROS 2 bag at ``path``."""
    from rosbags.typesys import Stores, get_typestore

    if kind == "ros1":
        from rosbags.rosbag1 import Writer

        from rosbags.typesys import get_types_from_msg

        ts = get_typestore(Stores.ROS1_NOETIC)  # has no tf2_msgs: add TFMessage
        ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
        return Writer(path), ts, ts.serialize_ros1
    from rosbags.rosbag2 import Writer

    ts = get_typestore(Stores.ROS2_HUMBLE)
    return Writer(path, version=9), ts, ts.serialize_cdr


def _write_bag(kind, path, scans=(), odoms=(), tf=(), scan_topic="/scan", compression=None, chunk_bytes=None):
    """scans: (stamp, ranges[, angle_increment or None[, header stamp]]); odoms: (stamp, (x, y, yaw));
    tf: (parent, child, (x, y, yaw)). ``compression``: a ROS 1 chunk compression format name ("BZ2", "LZ4");
    ``chunk_bytes``: a ROS 1 chunk's size (default 1 MB).
    """
    writer, ts, ser = _ros_writer(kind, path)
    if compression:
        writer.set_compression(writer.CompressionFormat[compression])
    if chunk_bytes:
        writer.chunk_threshold = chunk_bytes
    T = ts.types
    Time = T["builtin_interfaces/msg/Time"]

    def header(t, frame):
        stamp = Time(sec=int(t), nanosec=round((t % 1) * 1e9))
        if kind == "ros1":
            return T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def quat(yaw):
        return T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=np.sin(yaw / 2), w=np.cos(yaw / 2))

    def vec(x, y):
        return T["geometry_msgs/msg/Vector3"](x=x, y=y, z=0.0)

    with writer:
        topics = {}
        for topic, msgtype in [(scan_topic, "sensor_msgs/msg/LaserScan"), ("/odom", "nav_msgs/msg/Odometry"),
                               ("/tf_static", "tf2_msgs/msg/TFMessage")]:
            topics[topic] = writer.add_connection(topic, msgtype, typestore=ts)
        msgs = []
        for t, ranges, *extra in scans:
            n = len(ranges)
            increment = extra[0] if extra and extra[0] is not None else np.pi / (n - 1)
            msgs.append((scan_topic, t, T["sensor_msgs/msg/LaserScan"](
                header=header(extra[1] if len(extra) > 1 else t, "laser"), angle_min=-np.pi / 2,
                angle_max=np.pi / 2, angle_increment=increment, time_increment=0.0, scan_time=0.0, range_min=0.1,
                range_max=30.0, ranges=np.asarray(ranges, np.float32), intensities=np.zeros(0, np.float32))))
        cov = np.zeros(36)
        for t, (x, y, yaw) in odoms:
            pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                                               orientation=quat(yaw))
            twist = T["geometry_msgs/msg/Twist"](linear=vec(0.0, 0.0), angular=vec(0.0, 0.0))
            msgs.append(("/odom", t, T["nav_msgs/msg/Odometry"](
                header=header(t, "odom"), child_frame_id="base_link",
                pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=cov))))
        if tf:
            transforms = [T["geometry_msgs/msg/TransformStamped"](
                header=header(0.0, parent), child_frame_id=child,
                transform=T["geometry_msgs/msg/Transform"](translation=T["geometry_msgs/msg/Vector3"](
                    x=x, y=y, z=0.0), rotation=quat(yaw))) for parent, child, (x, y, yaw) in tf]
            msgs.append(("/tf_static", 0.0, T["tf2_msgs/msg/TFMessage"](transforms=transforms)))
        for topic, t, msg in sorted(msgs, key=lambda m: m[1]):
            # record time lags the header stamp: the reader must use the header
            writer.write(topics[topic], int((t + 0.05) * 1e9), ser(msg, msg.__msgtype__))
    return path


def _bag_path(kind, tmp_path):
    return tmp_path / ("tiny.bag" if kind == "ros1" else "tiny_ros2")


@pytest.mark.parametrize("kind", ["ros1", "ros2"])
def test_bag_odometry_and_mount(kind, tmp_path, caplog):
    ranges = np.full(5, 2.0)
    ranges[1] = np.nan
    path = _write_bag(
        kind, _bag_path(kind, tmp_path),
        scans=[(9.0, ranges), (10.5, ranges), (11.75, ranges)],
        odoms=[(10.0, (0.0, 0.0, 0.0)), (11.0, (1.0, 0.0, np.pi / 2)), (12.0, (1.0, 2.0, np.pi))],
        tf=[("base_link", "mount", (0.2, 0.0, 0.0)), ("mount", "laser", (0.0, 0.1, np.pi / 2))],
    )
    source = RosbagSource(path)
    assert len(source) == 3
    with caplog.at_level(logging.WARNING):
        scans = list(source)
    assert [s.stamp for s in scans] == pytest.approx([9.0, 10.5, 11.75])
    np.testing.assert_allclose(scans[0].odom, [0.0, 0.0, 0.0], atol=1e-12)  # clamped
    np.testing.assert_allclose(scans[1].odom, [0.5, 0.0, np.pi / 4], atol=1e-9)
    np.testing.assert_allclose(scans[2].odom, [1.0, 1.5, 7 * np.pi / 8], atol=1e-9)
    assert sum(source.notes.values()) == 1 and "odometry time span" in caplog.text
    np.testing.assert_allclose(scans[1].sensor_pose, [0.2, 0.1, np.pi / 2], atol=1e-9)
    np.testing.assert_allclose(scans[1].angles[[0, -1]], [-np.pi / 2, np.pi / 2], atol=1e-6)
    assert (scans[1].range_min, scans[1].range_max) == pytest.approx((0.1, 30.0))
    assert np.isnan(scans[1].ranges[1]) and source.invalid_beams == 3 and not source.skipped


def test_bag_without_tf_static_uses_identity(tmp_path):
    path = _write_bag("ros1", tmp_path / "a.bag", scans=[(1.0, [1.0, 1.0, 1.0])], odoms=[(1.0, (3.0, 4.0, 0.5))])
    (scan,) = RosbagSource(path)
    np.testing.assert_array_equal(scan.sensor_pose, np.zeros(3))
    np.testing.assert_allclose(scan.odom, [3.0, 4.0, 0.5])


def test_bag_errors(tmp_path):
    path = _write_bag("ros1", tmp_path / "a.bag", scans=[(1.0, [1.0, 1.0])], odoms=[(1.0, (0, 0, 0))],
                      scan_topic="/base_scan")
    assert RosbagSource(path).scan_topic == "/base_scan"  # the only LaserScan topic
    with pytest.raises(InputError, match=r"'/laser' not in bag.*/base_scan \(sensor_msgs/msg/LaserScan\)"):
        RosbagSource(path, scan_topic="/laser")
    with pytest.raises(InputError, match="a.bag.*topic '/odom' is nav_msgs/msg/Odometry, expected"):
        RosbagSource(path, scan_topic="/odom")
    with pytest.raises(InputError, match="no messages on odometry topic"):
        RosbagSource(_write_bag("ros1", tmp_path / "b.bag", scans=[(1.0, [1.0, 1.0])]))
    with pytest.raises(InputError, match="file not found"):
        RosbagSource(tmp_path / "missing.bag")
    (tmp_path / "junk.bag").write_bytes(b"not a bag\n" * 100)
    with pytest.raises(InputError, match="junk.bag: not a readable ROS bag"):
        RosbagSource(tmp_path / "junk.bag")


def test_bag_without_odometry_topic(tmp_path):
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    path = tmp_path / "scan_only.bag"
    with Writer(path) as writer:
        writer.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=get_typestore(Stores.ROS1_NOETIC))
    with pytest.raises(InputError, match="no nav_msgs/msg/Odometry topics.*/scan"):
        RosbagSource(path)


# ---------------------------------------------------------------- CARMEN logs written here


def _flaser(ranges, t, odom=(0.0, 0.0, 0.0), laser=None, tag="FLASER"):
    laser = odom if laser is None else laser
    nums = " ".join(str(v) for v in [*ranges, *laser, *odom, t])
    return f"{tag} {len(ranges)} {nums} host 0.0"


def test_carmen_corrupted_lines(tmp_path, caplog):
    good = [1.0, 2.0, 3.0, 4.0]
    lines = [
        "# a comment",
        "PARAM robot_front_laser_offset 0.0",
        _flaser(good, 1.0),
        _flaser(good, 2.0).replace(" 2.0 3.0", " 2.0 3..0", 1),  # garbled number (line 4)
        _flaser([np.nan, -1.0, 3.0, 4.0], 3.0),  # two invalid beams
        _flaser([0.0, 0.0, 0.0, 0.0], 4.0),  # all zero: empty
        _flaser(good, 5.0),
        _flaser(good, 6.0).replace("FLASER 4", "FLASER 5"),  # count does not match
        "SYNC x",
        _flaser(good, 7.0, odom=(1.0, 2.0, 3.0))[:-12],  # truncated last line
    ]
    path = tmp_path / "bad.clf"
    path.write_text("\n".join(lines))
    source = CarmenSource(path)
    source.max_skipped = 1.0  # 4 of 7 lines are bad
    assert len(source) == 7
    with caplog.at_level(logging.WARNING):
        scans = list(source)
    assert [s.stamp for s in scans] == [1.0, 3.0, 5.0]
    assert [s.index for s in scans] == [0, 1, 2]
    assert source.skipped == {
        "malformed FLASER lines": 3,
        "empty scans (no valid beam)": 1,
    }
    assert source.invalid_beams == 2
    assert source.ignored == {"comment lines": 1, "PARAM lines": 1, "SYNC lines": 1}
    assert f"{path}:4: FLASER line skipped: non-numeric field" in caplog.text
    assert np.isnan(scans[1].ranges[:2]).all()
    np.testing.assert_allclose(scans[0].angles, np.linspace(-np.pi / 2, np.pi / 2, 4))


def test_carmen_odom_lines_and_robotlaser(tmp_path):
    laser = geometry.compose([1.0, 0.0, 0.0], [0.1, 0.0, np.pi])  # rear-facing laser 0.1 m ahead
    ranges = [1.0, 2.0, 3.0]
    robotlaser = ("ROBOTLASER1 0 -1.0 2.0 1.0 20.0 0.01 0 3 " + " ".join(map(str, ranges)) + " 2 5 5 "
                  + " ".join(map(str, [*laser, 1.0, 0.0, 0.0])) + " 0.1 0.0 0.5 0.5 0.0 0.5 host 0.5")
    lines = [
        "ODOM 0.0 0.0 0.0 0 0 0 0.0 host 0.0",
        "ODOM 2.0 0.0 1.0 0 0 0 1.0 host 1.0",
        robotlaser,
        _flaser(ranges, 0.75, odom=(9.0, 9.0, 9.0)),  # pose in the line is ignored when ODOM exists
        "ODOM 2.0 0.0 abc 0 0 0 1.5 host 1.5",
    ]
    path = tmp_path / "odom.log"
    path.write_text("\n".join(lines) + "\n")
    source = CarmenSource(path)
    rl, fl = list(source)
    assert not source.skipped and source.notes == {"malformed ODOM lines": 1}  # not a scan
    np.testing.assert_allclose(rl.odom, [1.0, 0.0, 0.5])
    np.testing.assert_allclose(rl.sensor_pose, [0.1, 0.0, -np.pi], atol=1e-12)
    np.testing.assert_allclose(rl.angles, [-1.0, 0.0, 1.0])
    assert rl.range_max == 20.0 and fl.range_max == 81.9
    np.testing.assert_allclose(fl.odom, [1.5, 0.0, 0.75])
    np.testing.assert_allclose(fl.sensor_pose, 0.0)
    assert len(list(CarmenSource(path, max_scans=1))) == 1


def test_carmen_errors(tmp_path):
    path = tmp_path / "odom_only.log"
    path.write_text("ODOM 0 0 0 0 0 0 0.0 host 0.0\n")
    with pytest.raises(InputError, match="odom_only.log: no FLASER/ROBOTLASER1 lines"):
        CarmenSource(path)
    with pytest.raises(InputError, match="file not found"):
        CarmenSource(tmp_path / "missing.log")
