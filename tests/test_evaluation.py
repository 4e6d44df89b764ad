"""TUM files, ATE / RPE, and the relations metric."""

from __future__ import annotations

import numpy as np
import pytest

from slam2d import geometry
from slam2d.errors import InputError
from slam2d.evaluation.relations import Relations, format_relations, read_relations, relations_metric
from slam2d.evaluation.trajectory import align_se2, ate, read_tum, rpe, write_tum
from slam2d.types import Trajectory


def wiggly_path(n=200, seed=0):
    """A smooth (n, 3) path of a few tens of metres."""
    t = np.linspace(0, 4 * np.pi, n)
    x, y = 5 * np.cos(t) + 0.3 * t, 3 * np.sin(2 * t)
    th = np.arctan2(np.gradient(y), np.gradient(x))
    return np.column_stack([x, y, th])


# --- TUM ---------------------------------------------------------------------


def test_tum_round_trip(tmp_path):
    poses = wiggly_path(50)
    traj = Trajectory(976052905.167303 + np.arange(50) * 0.1234567, poses)
    path = write_tum(tmp_path / "t.tum", traj)
    back = read_tum(path)
    np.testing.assert_array_equal(back.stamps, traj.stamps)
    np.testing.assert_array_equal(back.poses[:, :2], poses[:, :2])
    np.testing.assert_allclose(geometry.wrap_angle(back.poses[:, 2] - poses[:, 2]), 0, atol=1e-12)


def test_tum_quaternion_encodes_yaw(tmp_path):
    yaw = 2.0
    path = write_tum(tmp_path / "t.tum", Trajectory([1.5], [[1.0, 2.0, yaw]]))
    rows = [line.split() for line in path.read_text().splitlines() if not line.startswith("#")]
    stamp, x, y, z, qx, qy, qz, qw = map(float, rows[0])
    assert (stamp, x, y, z, qx, qy) == (1.5, 1.0, 2.0, 0.0, 0.0, 0.0)
    assert qz == pytest.approx(np.sin(yaw / 2)) and qw == pytest.approx(np.cos(yaw / 2))


def test_read_tum_general_quaternion_yaw(tmp_path):
    # a quaternion with a non-unit norm and the same yaw of 90 degrees
    (tmp_path / "q.tum").write_text("# header\n\n0.0 1 2 0.5 0 0 2 2\n")
    assert read_tum(tmp_path / "q.tum").poses[0] == pytest.approx([1.0, 2.0, np.pi / 2])


@pytest.mark.parametrize(
    "bad", ["0.0 1 2 0 0 0 0", "0.0 1 2 0 0 0 0 x", "0.0 1 2 0 0 0 0 0", "0.0 1 2 0 0 0 nan 1"]
)
def test_read_tum_malformed_line(tmp_path, bad):
    path = tmp_path / "bad.tum"
    path.write_text("# stamp x y z qx qy qz qw\n0.0 0 0 0 0 0 0 1\n" + bad + "\n")
    with pytest.raises(InputError, match=r"bad\.tum:3"):
        read_tum(path)


def test_read_tum_stamps_going_back(tmp_path):
    path = tmp_path / "back.tum"
    path.write_text("1.0 0 0 0 0 0 0 1\n0.5 0 0 0 0 0 0 1\n")
    with pytest.raises(InputError, match=r"back\.tum:2"):
        read_tum(path)


# --- alignment, ATE, RPE ---------------------------------------------------------


def test_align_se2_recovers_transform():
    ref = wiggly_path()
    T = np.array([3.0, -1.5, 0.7])
    est = geometry.compose(geometry.inverse(T), ref)  # so that T ⊕ est = ref
    np.testing.assert_allclose(align_se2(est, ref), T, atol=1e-10)


def test_ate_rigid_offset():
    ref = wiggly_path()
    est = geometry.compose(np.array([1.0, 2.0, 0.0]), ref)  # shifted by (1, 2)
    aligned = ate(est, ref, align=True)
    assert aligned["rmse"] < 1e-9 and aligned["max"] < 1e-9
    raw = ate(est, ref, align=False)
    for key in ("rmse", "mean", "median", "max"):
        assert raw[key] == pytest.approx(np.sqrt(5.0))
    assert raw["std"] == pytest.approx(0.0, abs=1e-12)


def test_ate_rotated_estimate():
    ref = wiggly_path()
    est = geometry.compose(np.array([0.0, 0.0, 0.3]), ref)
    assert ate(est, ref)["rmse"] < 1e-9
    assert ate(est, ref, align=False)["rmse"] > 0.5


def test_rpe_identical_and_rigidly_moved():
    ref = wiggly_path()
    for est in (ref, geometry.compose(np.array([4.0, -2.0, 1.0]), ref)):
        m = rpe(est, ref, delta_m=1.0)
        assert m["pairs"] > 100
        assert max(m["trans_rmse"], m["trans_mean"], m["rot_rmse_deg"], m["rot_mean_deg"]) < 1e-9


def test_rpe_scaled_estimate():
    # straight line at 0.15 m steps, estimate 10 % too long: pairs 1.05 m apart (7 steps) err by 0.105 m;
    # near the end no pose lies within 10 % of 1.05 m further on, so only 30 - 7 pairs are kept
    ref = np.column_stack([np.arange(30) * 0.15, np.zeros(30), np.zeros(30)])
    est = ref * [1.1, 1.0, 1.0]
    m = rpe(est, ref, delta_m=1.05)
    assert m["trans_mean"] == pytest.approx(0.105) and m["rot_mean_deg"] == 0.0
    assert m["pairs"] == 23


def test_rpe_no_pairs():
    ref = wiggly_path()[:2]
    assert rpe(ref, ref, delta_m=1e3)["pairs"] == 0


# --- relations -------------------------------------------------------------------


def hand_case():
    """Trajectory and relations whose errors are worked out by hand.

    poses: p0 = (0, 0, 0), p1 = (1, 0, 0), p2 = (1, 1, pi/2), p3 = (1, 1, pi/2 + 0.2)
    R1 0 -> 1.0005: between = (1, 0, 0), delta (0.9, 0, 0) -> error (0.1, 0, 0)
    R2 1 -> 2: between = (0, 1, pi/2), delta (0, 1.2, pi/2) -> error (0, -0.2, 0)
    R3 2 -> 3: between = (0, 0, 0.2), delta (0, 0, 0.15) -> error (0, 0, 0.05)
    R4 1 -> 0 (t1 > t2): between = (-1, 0, 0), delta (-1, 0, 0) -> error 0
    R5 3.5 -> 0: no stamp within tolerance -> unmatched
    """
    stamps = np.array([0.0, 1.0, 2.0, 3.0])
    poses = np.array([[0, 0, 0], [1, 0, 0], [1, 1, np.pi / 2], [1, 1, np.pi / 2 + 0.2]])
    rel = Relations(
        t1=np.array([0.0, 1.0, 2.0, 1.0, 3.5]),
        t2=np.array([1.0005, 2.0, 3.0, 0.0, 0.0]),
        delta=np.array([[0.9, 0, 0], [0, 1.2, np.pi / 2], [0, 0, 0.15], [-1, 0, 0], [0, 0, 0]]),
    )
    return stamps, poses, rel


def test_relations_metric_hand_computed():
    stamps, poses, rel = hand_case()
    m = relations_metric(stamps, poses, rel, tolerance=1e-3)
    assert (m["matched"], m["unmatched"]) == (4, 1)
    # translational errors [0.1, 0.2, 0, 0]: mean 0.075, sum of squared deviations 0.0275
    assert m["trans_abs_mean"] == pytest.approx(0.075)
    assert m["trans_abs_std"] == pytest.approx(np.sqrt(0.0275 / 3))
    # squared [0.01, 0.04, 0, 0]: mean 0.0125, sum of squared deviations 0.001075
    assert m["trans_sq_mean"] == pytest.approx(0.0125)
    assert m["trans_sq_std"] == pytest.approx(np.sqrt(0.001075 / 3))
    # rotational [0, 0, d, 0] deg with d = 0.05 rad: mean d/4, sample std d/2
    d = 0.05 * 180 / np.pi
    assert m["rot_abs_mean"] == pytest.approx(d / 4)
    assert m["rot_abs_std"] == pytest.approx(d / 2)
    assert m["rot_sq_mean"] == pytest.approx(d**2 / 4)
    assert m["rot_sq_std"] == pytest.approx(d**2 / 2)


def test_relations_metric_tolerance_and_unsorted_stamps():
    stamps, poses, rel = hand_case()
    strict = relations_metric(stamps, poses, rel, tolerance=1e-4)  # R1's 1.0005 no longer matches
    assert (strict["matched"], strict["unmatched"]) == (3, 2)
    order = np.array([2, 0, 3, 1])
    shuffled = relations_metric(stamps[order], poses[order], rel)
    assert shuffled == relations_metric(stamps, poses, rel)


def test_relations_metric_all_unmatched():
    stamps, poses, rel = hand_case()
    m = relations_metric(stamps + 100.0, poses, rel)
    assert (m["matched"], m["unmatched"]) == (0, 5)
    assert np.isnan(m["trans_abs_mean"])


def test_format_relations():
    stamps, poses, rel = hand_case()
    text = format_relations(relations_metric(stamps, poses, rel))
    lines = text.splitlines()
    assert lines[0] == f"Abs translational error 0.07500 +/- {np.sqrt(0.0275 / 3):.5f} m"
    assert lines[1].startswith("Sqr translational error 0.01250 +/- ") and lines[1].endswith(" m^2")
    assert lines[2].startswith("Abs rotational error 0.71620 +/- 1.43239") and lines[2].endswith(" deg")
    assert lines[3].startswith("Sqr rotational error ") and lines[3].endswith(" deg^2")


def test_read_relations_malformed(tmp_path):
    path = tmp_path / "r.relations"
    path.write_text("1 2 0.1 0 0 0 0 0.1\n1 2 0.1 0 0 0 0\n")
    with pytest.raises(InputError, match=r"r\.relations:2"):
        read_relations(path)
    path.write_text("1 2 0.1 0 0 0 0 0.1\n\n1 2 0.1 zero 0 0 0 0.1\n")
    with pytest.raises(InputError, match=r"r\.relations:3"):
        read_relations(path)


def test_read_relations_intel(data_file):
    path = data_file("radish/intel.relations")
    rel = read_relations(path)
    lines = [line for line in path.read_text().splitlines() if line.strip()]
    assert len(rel) == len(lines) == 2984
    first = [float(v) for v in lines[0].split()]
    assert (rel.t1[0], rel.t2[0]) == (first[0], first[1])
    np.testing.assert_allclose(rel.delta[0], [first[2], first[3], first[7]], rtol=0, atol=1e-12)
    assert np.all(np.isfinite(rel.delta)) and np.all(np.abs(rel.delta[:, 2]) <= np.pi)
    assert np.sum(rel.t1 > rel.t2) == 6  # kept as written, not swapped
    # every endpoint matches a stamp of a trajectory made of the relation stamps
    stamps = np.unique(np.concatenate([rel.t1, rel.t2]))
    m = relations_metric(stamps, np.zeros((len(stamps), 3)), rel)
    assert (m["matched"], m["unmatched"]) == (2984, 0)


def _turning_run(mount):
    """A robot that drives and turns (1 s steps) with a laser at ``mount``; true odometry."""
    t = np.arange(40.0)
    theta = np.cumsum(np.where(t % 4 < 2, 0.0, 0.6))
    xy = np.cumsum(0.3 * np.column_stack([np.cos(theta), np.sin(theta)]), axis=0)
    return t, np.column_stack([xy, theta]), np.tile(mount, (len(t), 1))


@pytest.mark.parametrize("frame", ["base", "laser"])
def test_relations_frame_is_the_one_the_odometry_agrees_with(frame):
    from slam2d import geometry
    from slam2d.evaluation.relations import relations_frame

    t, odom, mounts = _turning_run([0.25, 0.0, 0.0])
    truth = odom if frame == "base" else geometry.compose(odom, mounts)
    i = np.arange(len(t) - 2)
    rel = Relations(t[i], t[i + 2], geometry.between(truth[i], truth[i + 2]))
    found, evidence = relations_frame(t, odom, mounts, rel)
    assert found == frame and evidence["tested"] > 5
    assert evidence[f"{frame}_median_m"] < 1e-9 < evidence[f"{'laser' if frame == 'base' else 'base'}_median_m"]


def test_relations_frame_defaults_to_the_laser_when_the_frames_coincide():
    from slam2d import geometry
    from slam2d.evaluation.relations import relations_frame

    t, odom, mounts = _turning_run([0.0, 0.0, 0.0])
    rel = Relations(t[:-2], t[2:], geometry.between(odom[:-2], odom[2:]))
    assert relations_frame(t, odom, mounts, rel)[0] == "laser"


@pytest.mark.parametrize("log, frame", [("fr-clinic", "base"), ("fr079", "laser")])
def test_radish_relations_frames(data_file, log, frame):
    """The clinic's relations relate robot poses (its laser sits 0.22 m ahead), FR079's the laser's."""
    from slam2d.datasets.rosbag import RosbagSource as Bag
    from slam2d.evaluation.relations import relations_frame

    rel = read_relations(data_file(f"radish/{log}.relations"))
    scans = list(Bag(data_file(f"radish/{log}.bag")))
    stamps = np.array([s.stamp for s in scans])
    odom, mounts = np.array([s.odom for s in scans]), np.array([s.sensor_pose for s in scans])
    found, evidence = relations_frame(stamps, odom, mounts, rel)
    assert found == frame, evidence
