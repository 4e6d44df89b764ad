"""`slam2d navigate`: a closed-loop run as an experiment — online SLAM, the navigator, a results folder."""

from __future__ import annotations

import json

import numpy as np
import pytest

from slam2d import config
from slam2d.errors import InputError
from slam2d.runs.navigate import run_navigate


def navigate(tmp_path, *overrides):
    cfg = config.load(None, [f"output.root={tmp_path}", "navigation.goal=[10.0, 4.5]", *overrides])
    folder = run_navigate(cfg)
    return folder, json.loads((folder / "metrics.json").read_text())


def test_slam_in_the_loop_reaches_the_goal_and_writes_the_run(tmp_path):
    folder, m = navigate(tmp_path, "navigation.animation=true")
    assert m["success"] and m["status"] == "reached" and m["slam"]
    assert m["collisions"] == 0
    assert m["goal_error"] <= 0.05  # the true pose at the stop
    assert m["pose_rmse"] < 0.05  # the pose the navigator drove on was SLAM's, close to the truth
    assert 0.9 < m["length_ratio"] < 1.3
    for name in ("config.yaml", "trajectory.tum", "ground_truth.tum", "map.png", "velocity.png", "run.gif"):
        assert (folder / name).stat().st_size > 0, name
    page = (folder / "report.html").read_text()
    assert 'alt="velocity.png"' in page and 'alt="run.gif"' in page and "<th>success</th>" in page
    true = np.loadtxt(folder / "ground_truth.tum")
    est = np.loadtxt(folder / "trajectory.tum")
    assert len(true) == len(est) + 1 or len(true) == len(est)


def test_known_map_and_state_machine(tmp_path):
    _, m = navigate(tmp_path, "navigation.slam=false", "navigation.planner=fsm", "navigation.animation=false",
                    "output.figures=false")
    assert m["success"] and not m["slam"] and m["planner"] == "fsm"
    assert m["pose_rmse"] == 0.0  # the true pose


def test_unreachable_goal_is_a_result_not_a_hang(tmp_path):
    _, m = navigate(tmp_path, "navigation.goal=[0.0, 6.0]", "navigation.slam=false", "output.figures=false")
    assert not m["success"] and m["status"] == "unreachable"


def test_navigate_exits_3_when_the_goal_is_not_reached_and_still_writes_its_results(tmp_path):
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", "slam2d.cli", "navigate", "--goal", "0.0,6.0", "-o", str(tmp_path),
                           "--set", "navigation.slam=false", "--set", "output.figures=false", "-q"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 3, done.stderr
    assert "goal not reached: unreachable" in done.stderr
    (folder,) = tmp_path.iterdir()
    assert done.stdout == f"results: {folder}\n" and (folder / "metrics.json").is_file()


def test_bad_navigation_input_is_a_one_line_error(tmp_path):
    with pytest.raises(InputError, match="navigation.goal"):
        run_navigate(config.load(None, [f"output.root={tmp_path}"]))
    with pytest.raises(InputError, match="navigation.options"):
        navigate(tmp_path, "navigation.options={max_time: -1}")
    assert not [p for p in tmp_path.iterdir()]  # no folder left behind


def test_a_goal_beyond_a_map_being_built_is_planned_through_unknown_space():
    """The live map covers only what the robot has seen; with unknown cells free the goal beyond it
    is planned to, not reported unreachable (it was, at the first step of SLAM runs)."""
    from slam2d.mapping.grid import OccupancyGrid
    from slam2d.navigation import Navigator, NavigatorConfig

    seen = OccupancyGrid(np.full((40, 40), -1.0, dtype=np.float32), 0.05, (0.0, 0.0))  # 2 m x 2 m, all free
    nav = Navigator([6.0, 5.0], config=NavigatorConfig(unknown_free=True))
    nav.update_map(seen)
    assert nav.plan(np.array([1.0, 1.0, 0.0])) == ""
    assert np.hypot(*(np.asarray(nav.path)[-1, :2] - [6.0, 5.0])) < 0.1
    blocked = Navigator([6.0, 5.0], config=NavigatorConfig(unknown_free=False))
    blocked.update_map(seen)
    assert blocked.plan(np.array([1.0, 1.0, 0.0])) != ""  # unknown is blocked: no way there


def test_a_person_drawn_into_the_live_map_still_counts_as_unmapped():
    """A live SLAM map takes in people where the laser saw them; laser points on such fresh cells
    still get the local planner's margin for things that move (two runs in ten touched a person
    when they did not). Cells of the first map, and cells blocked long enough, explain points."""
    from slam2d.navigation import Navigator
    from slam2d.planning.grid import PlanningGrid

    free = np.ones((80, 80), dtype=bool)
    free[:, 60] = False  # a wall at x = 3.0 m, in the first map
    nav = Navigator([1.0, 3.5])
    nav.update_map(PlanningGrid(free, 0.05, (0.0, 0.0)), now=0.0)
    pose = np.array([1.0, 1.0, 0.0])
    points = np.array([[2.02, 0.0], [1.0, 1.0]])  # robot frame: the wall at (3.02, 1), the person at (2, 2)
    seen = free.copy()
    seen[38:42, 38:42] = False  # the person at (2, 2), taken into the map at t = 10 s
    nav.update_map(PlanningGrid(seen, 0.05, (0.0, 0.0)), now=10.0)
    assert nav.unmapped(pose, points).tolist() == [False, True]
    grown = np.ones((100, 100), dtype=bool)  # the map grows 1 m to the left and below: same cells, new origin
    grown[20:, 20:] = seen
    nav.update_map(PlanningGrid(grown, 0.05, (-1.0, -1.0)), now=11.0)
    assert nav.unmapped(pose, points).tolist() == [False, True]
    nav.update_map(PlanningGrid(grown, 0.05, (-1.0, -1.0)), now=14.0)  # standing there for 4 s: settled
    assert nav.unmapped(pose, points).tolist() == [False, False]
