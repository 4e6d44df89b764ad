"""``--viz-save FILE.rrd``: the recording read back holds every entity; for ``slam2d run`` one pose per
scan, the run's loop closures and its optimised trajectory; for ``localize`` the particles at each
filter update; for ``explore`` each goal and the frontiers of the growing map."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

from slam2d import config
from slam2d.datasets.g2o import odometry_mask, read_g2o
from slam2d.runs.run import run_experiment
from slam2d.viz import ENTITIES, EXPLORE_ENTITIES, MAP_EVERY, PARTICLE_ENTITIES, VIEW_PARTICLES

try:
    from rerun.chunk import RrdReader
except ImportError:  # CI installs the [viz] extra: there a missing rerun-sdk is a failure
    if os.environ.get("CI") == "true" or os.environ.get("SLAM2D_REQUIRE_DATA") == "1":
        raise
    pytest.skip("rerun-sdk is not installed: pip install -e '.[viz]'", allow_module_level=True)

SCANS = 400  # the simulator's route closes its first loops within these


def _read(path: Path) -> dict[str, list]:
    """Entity path -> its record batches, in the file's order."""
    batches = defaultdict(list)
    for chunk in RrdReader(path).stream():
        batches[chunk.entity_path.lstrip("/")].append(chunk.to_record_batch())
    return batches


def _last(batches: list, column: str):
    """The value of ``column`` in the row with the highest scan index."""
    rows = [(scan, value) for b in batches for scan, value in zip(b.column("scan").to_pylist(),
                                                                   b.column(column).to_pylist())]
    return max(rows, key=lambda r: r[0])[1]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("viz")
    cfg = config.load(None, [f"dataset.max_scans={SCANS}", "mapping.resolution=0.1", f"output.root={tmp}"])
    folder = run_experiment(cfg, quiet=True, viz=tmp / "run.rrd")
    return folder, _read(tmp / "run.rrd")


def test_recording_has_every_entity_and_one_pose_per_scan(recorded):
    folder, batches = recorded
    scans = json.loads((folder / "metrics.json").read_text())["scans"]
    assert scans == SCANS
    assert set(ENTITIES) <= set(batches)
    rows = {e: sum(b.num_rows for b in batches[e]) for e in ENTITIES}
    assert rows["world/robot"] == rows["world/scan"] == scans
    assert rows["world/map"] == scans // MAP_EVERY + 1  # refreshes, then the optimised map
    robot = [i for b in batches["world/robot"] for i in b.column("scan").to_pylist()]
    assert sorted(robot) == list(range(scans))


def test_recording_ends_with_the_runs_loops_and_trajectory(recorded):
    folder, batches = recorded
    graph = read_g2o(folder / "graph.g2o")
    loops = int(np.count_nonzero(~odometry_mask(graph)))
    assert loops > 0
    assert len(_last(batches["world/loops"], "LineStrips2D:strips")) == loops
    trajectory = np.array(_last(batches["world/trajectory"], "LineStrips2D:strips")[0])
    tum = np.loadtxt(folder / "trajectory.tum")
    np.testing.assert_allclose(trajectory, tum[:, 1:3], atol=1e-4)
    cells = np.array(_last(batches["world/map"], "Points2D:positions"))
    assert len(cells) > 100 and np.isfinite(cells).all()


def test_localize_recording_has_the_particles_of_each_update(tmp_path):
    from slam2d.localization.config import LocalizeConfig
    from slam2d.runs.localize import run_localize

    cfg = LocalizeConfig(map="office", seconds=8, output={"root": str(tmp_path), "figures": False})
    folder = run_localize(cfg, viz=tmp_path / "loc.rrd")
    metrics = json.loads((folder / "metrics.json").read_text())
    batches = _read(tmp_path / "loc.rrd")
    assert set(PARTICLE_ENTITIES) <= set(batches)
    rows = {e: sum(b.num_rows for b in batches[e]) for e in PARTICLE_ENTITIES}
    assert rows["world/robot"] == rows["world/truth"] == metrics["scans"]
    assert rows["world/particles"] == metrics["updates"] > 0
    first = np.array(batches["world/particles"][0].column("Points2D:positions").to_pylist()[0])
    assert len(first) == VIEW_PARTICLES  # global localisation: 20 000 particles, an even subset logged
    spread = np.ptp(first, axis=0)
    last = np.array(_last(batches["world/particles"], "Points2D:positions"))
    truth = np.loadtxt(folder / "ground_truth.tum")[-1, 1:3]
    assert spread.min() > 5.0  # spread over the office at first ...
    assert np.median(np.hypot(*(last - truth).T)) < 0.5  # ... gathered at the true pose in the end


def test_explore_recording_has_each_goal_and_the_frontiers(tmp_path):
    from test_exploration import two_rooms_png

    from slam2d.exploration import config as explore_config
    from slam2d.runs.explore import run_explore

    cfg = explore_config.load(None, {
        "output.root": str(tmp_path / "out"), "dataset.simulator.world": str(two_rooms_png(tmp_path)), "seed": 1,
        "exploration.strategy": "nearest_frontier", "exploration.start": [1.5, 2.0, 0.0],
        "exploration.max_time": 20, "exploration.animation": False, "output.figures": False})  # fmt: skip
    folder = run_explore(cfg, viz=tmp_path / "explore.rrd")
    goals = json.loads((folder / "goals.json").read_text())
    batches = _read(tmp_path / "explore.rrd")
    assert set(EXPLORE_ENTITIES) <= set(batches)
    logged = [g for b in batches["world/goal"] for g in b.column("Points2D:positions").to_pylist() if g]
    np.testing.assert_allclose([g[0] for g in logged], [g["position"] for g in goals], atol=1e-5)
    frontiers = [np.array(f) for b in batches["world/frontiers"] for f in b.column("Points2D:positions").to_pylist()]
    sizes = [len(f) for f in frontiers]
    assert len(sizes) >= 3 and max(sizes) > 10 and sizes[-1] < max(sizes)  # the last: the explored map's
    assert all(((f > 0) & (f < (9.0, 4.0))).all() for f in frontiers if len(f))  # inside the 9 m x 4 m world


def test_no_view_imports_nothing_of_rerun(tmp_path):
    code = ("import sys; from slam2d import config; from slam2d.runs.run import run_experiment; "
            f"run_experiment(config.load(None, ['dataset.max_scans=10', 'output.root={tmp_path}']), quiet=True); "
            "from slam2d.runs.localize import LocalizeConfig, run_localize; "
            f"run_localize(LocalizeConfig(map='office', seconds=2, output={{'root': '{tmp_path}'}})); "
            "assert not [m for m in sys.modules if m.startswith(('rerun', 'slam2d.viz'))], 'rerun imported'")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]


def test_bad_viz_target_is_one_line_error(tmp_path):
    from typer.testing import CliRunner

    from slam2d.cli import app

    root = f"output.root={tmp_path}"
    out = CliRunner().invoke(app, ["run", "--viz-save", str(tmp_path / "no" / "x.rrd"), "--set", root])
    assert out.exit_code == 2 and "--viz-save" in out.output and "FILE.rrd" in out.output
    out = CliRunner().invoke(app, ["run", "--viz", "--viz-save", str(tmp_path / "x.rrd")])
    assert out.exit_code == 2 and "not both" in out.output
