"""Time-optimal trajectories (toppra) and plan_on_map end to end."""

from __future__ import annotations

import json

import numpy as np
import pytest
from pydantic import ValidationError

from slam2d.errors import InputError
from slam2d.planning.timing import TrajectoryLimits, plot_profile, time_parametrize

TOL = 0.02  # limits are enforced at toppra's gridpoints; samples between them may exceed slightly


def check_limits(tp, lim: TrajectoryLimits) -> None:
    assert tp.speed.max() <= lim.v_max * (1 + 1e-3)
    assert np.abs(tp.accel).max() <= lim.a_max * (1 + TOL)
    assert np.abs(tp.omega).max() <= lim.omega_max * (1 + TOL)
    # the samples agree with their own finite differences
    v_fd = np.diff(tp.xy, axis=0) / np.diff(tp.t)[:, None]
    assert np.hypot(*v_fd.T).max() <= lim.v_max * (1 + TOL)
    a_fd = np.diff(tp.speed) / np.diff(tp.t)
    assert np.abs(a_fd).max() <= lim.a_max * (1 + TOL)


def test_limits_defaults_and_validation():
    lim = TrajectoryLimits()
    assert (lim.v_max, lim.a_max, lim.omega_max) == (0.4, 0.5, 0.3)
    with pytest.raises(ValidationError, match="extra"):
        TrajectoryLimits(v_max=0.3, jerk=1.0)
    with pytest.raises(ValidationError):
        TrajectoryLimits(a_max=0.0)


def test_straight_line_is_trapezoidal():
    tp = time_parametrize([[0.0, 0.0], [4.0, 0.0]])
    lim = tp.limits
    assert tp.duration == pytest.approx(4.0 / lim.v_max + lim.v_max / lim.a_max, rel=1e-3)
    assert tp.speed[0] == 0.0 and tp.speed[-1] == pytest.approx(0.0, abs=1e-6)
    assert np.allclose(tp.xy[[0, -1]], [[0, 0], [4, 0]], atol=1e-9)
    assert np.abs(tp.omega).max() < 1e-9
    check_limits(tp, lim)


@pytest.mark.parametrize(
    "limits", [TrajectoryLimits(), TrajectoryLimits(v_max=1.0, a_max=0.3, omega_max=1.0)], ids=["default", "fast"]
)
def test_polyline_respects_limits_and_rests_at_ends(limits, tmp_path):
    wp = np.array([[0, 0], [3, 0], [3, 2], [5, 4], [8, 4]], float)
    tp = time_parametrize(wp, limits)
    check_limits(tp, limits)
    assert tp.speed[0] == 0.0 and tp.speed[-1] == pytest.approx(0.0, abs=1e-6)
    assert np.allclose(tp.xy[0], wp[0]) and np.allclose(tp.xy[-1], wp[-1])
    length = np.hypot(*np.diff(wp, axis=0).T).sum()
    assert tp.length == pytest.approx(length, rel=0.01)
    assert tp.duration >= length / limits.v_max
    assert tp.max_deviation < 0.02  # the spline hugs the collision-checked polyline
    assert np.all(np.diff(tp.t) > 0) and len(tp.t) == len(tp.xy) == len(tp.velocity)
    # turning at the corners is bounded by the yaw rate: 90° at (3, 0) takes >= (pi / 2) / omega_max
    turning = np.abs(tp.omega) > 0.5 * limits.omega_max
    assert turning.any()
    fig = plot_profile(tp, tmp_path / "profile.png")
    assert (tmp_path / "profile.png").stat().st_size > 1000 and len(fig.axes) == 3


def test_single_point_and_duplicates():
    tp = time_parametrize([[1.0, 2.0], [1.0, 2.0]])
    assert tp.duration == 0.0 and tp.xy.tolist() == [[1.0, 2.0]]
    tp = time_parametrize([[0, 0], [0, 0], [1, 0], [1, 0]])
    assert tp.duration > 0 and np.allclose(tp.xy[-1], [1, 0])


# ---------------------------------------------------------------- plan_on_map


def office(tmp_path, shape=(80, 120)):
    """A floor plan (0.05 m/px; 6 m x 4 m by default) of two rooms: a wall down the middle with a
    1 m door near the top of the image, as a PNG."""
    from PIL import Image

    h, w = shape
    img = np.full(shape, 255, np.uint8)
    img[[0, -1], :] = 0
    img[:, [0, -1]] = 0
    img[:, w // 2 : w // 2 + 2] = 0
    img[10:30, w // 2 : w // 2 + 2] = 255
    path = tmp_path / f"office_{h}x{w}.png"
    Image.fromarray(img).save(path)
    return path


@pytest.mark.parametrize("hierarchical", [None, "hpa", "rooms", "jps_plus", "subgoal"])
def test_plan_on_map_writes_figures_and_metrics(tmp_path, hierarchical):
    from slam2d.planning.query import plan_on_map
    from slam2d.runs.plan import write_plan

    plan = office(tmp_path)
    labels = None
    if hierarchical == "rooms":
        labels = np.zeros((80, 120), np.int32)  # grid rows go up: image row r is grid row 79 - r
        labels[:, :61] = 1
        labels[:, 61:] = 2
    out = tmp_path / f"out_{hierarchical}"
    m = write_plan(plan_on_map(plan, (0.5, 0.5), (5.5, 0.5), hierarchical, robot_radius=0.15, labels=labels), out)
    assert m["found"] and m["reason"] == ""
    for key in ("length_m", "duration_s", "nodes_expanded", "plan_ms", "build_ms", "grid_length_m"):
        assert key in m
    assert 5.0 < m["length_m"] <= m["grid_length_m"] + 1e-9
    assert m["length_m"] > 6.0  # around the wall through the door (the straight line is 5 m)
    assert m["duration_s"] > m["length_m"] / 0.4
    assert m["max_speed_mps"] <= 0.4 + 1e-3
    for name in ("path.png", "velocity.png", "metrics.json", "trajectory.csv"):
        assert (out / name).stat().st_size > 100
    assert json.loads((out / "metrics.json").read_text())["length_m"] == pytest.approx(m["length_m"])
    traj = np.loadtxt(out / "trajectory.csv", delimiter=",", skiprows=1)
    assert traj.shape[1] == 7 and traj[0, 5] == 0.0


def test_plan_on_map_failures_are_reported(tmp_path):
    from slam2d.planning.query import plan_on_map
    from slam2d.runs.plan import write_plan

    plan = office(tmp_path)
    m = write_plan(plan_on_map(plan, (0.5, 0.5), (0.02, 0.02), None), tmp_path / "blocked")
    assert not m["found"] and "goal cell" in m["reason"]
    assert (tmp_path / "blocked" / "metrics.json").exists() and (tmp_path / "blocked" / "path.png").exists()
    m = plan_on_map(plan, (1.5, 1.5), (4.5, 1.5), None, robot_radius=0.6).metrics
    assert not m["found"] and "unreachable" in m["reason"]  # the 1 m door is closed for a 1.2 m wide robot
    with pytest.raises(InputError, match="hierarchical"):
        plan_on_map(plan, (0.5, 0.5), (5.5, 0.5), "quadtree")
    with pytest.raises(InputError, match="start"):
        plan_on_map(plan, (0.5,), (5.5, 0.5), None)
    with pytest.raises(InputError, match="not found"):
        plan_on_map(tmp_path / "missing.yaml", (0.5, 0.5), (5.5, 0.5), None)


def test_plan_on_map_rooms_from_segmentation(tmp_path):
    from slam2d.planning.query import plan_on_map

    # two 8 m x 6 m rooms: too big together, and each within the room area bounds once the door closes
    plan = office(tmp_path, (120, 320))
    m = plan_on_map(plan, (0.5, 0.5), (15.5, 0.5), "rooms", robot_radius=0.15).metrics
    assert m["found"] and m["rooms"] == 2 and m["length_m"] > 15.0
    with pytest.raises(InputError, match="labels"):
        plan_on_map(office(tmp_path), (0.5, 0.5), (5.5, 0.5), "rooms", labels=np.zeros((3, 3), int))


def test_plan_on_movingai_map(tmp_path, data_file):
    from slam2d.planning.query import plan_on_map

    m = plan_on_map(data_file("movingai/arena.map"), (1.5, 11.5), (47.5, 44.5), "hpa", robot_radius=0.0,
                    cluster_size=10).metrics
    assert m["found"] and m["grid_length_m"] >= 40.0 and m["length_m"] <= m["grid_length_m"]


def test_room_labels_in_the_other_row_convention_are_rejected(tmp_path):
    from PIL import Image

    from slam2d.planning.query import plan_on_map

    img = np.zeros((40, 60), np.uint8)  # 0.05 m/px: the image's upper half solid, two rooms below
    img[20:39, 1:59] = 255
    Image.fromarray(img).save(tmp_path / "half.png")
    rooms = np.where(img == 255, np.where(np.arange(60) < 30, 1, 2), 0).astype(np.int32)  # row 0 the top
    with pytest.raises(InputError, match="labels: the room labels fit the map only upside down"):
        plan_on_map(tmp_path / "half.png", (0.5, 0.5), (2.5, 0.5), "rooms", robot_radius=0.0, labels=rooms)
    m = plan_on_map(tmp_path / "half.png", (0.5, 0.5), (2.5, 0.5), "rooms", robot_radius=0.0, labels=rooms[::-1])
    assert m.metrics["found"] and m.metrics["rooms"] == 2
