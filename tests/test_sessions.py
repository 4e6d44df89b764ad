"""Sessions that continue and merge: a half run continued gives the full run; a second half started at an
unknown pose is placed in the first half's map and merges with it. On the simulator's office (two laps),
at half the scan rate and beams to stay fast."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from slam2d import config, geometry
from slam2d.cli import app
from slam2d.datasets.registry import open_dataset
from slam2d.errors import InputError
from slam2d.evaluation.map_accuracy import free_space_iou
from slam2d.evaluation.trajectory import read_tum
from slam2d.mapping.occupancy import build_grid
from slam2d.pipeline import SlamPipeline
from slam2d.runs.run import run_experiment
from slam2d.runs.slam_outputs import SESSION_FILE, read_session

QUICK = {"dataset.simulator.scan_rate": 2.5, "dataset.simulator.laser.beams": 180}
CUT = 350  # scans in the first session: about the first lap
OFFSET = np.array([7.3, -4.1, 2.2])  # the second session's odometry frame, unknown to the run (m, m, rad)


def slam(session=None, localize=False, offset=None, **overrides):
    """A SLAM run of the quick simulator (``overrides``: dataset keys) from ``session``; the SlamResult."""
    cfg = config.load(None, QUICK | {f"dataset.{k}": v for k, v in overrides.items()})
    scans = open_dataset(cfg.dataset, seed=cfg.seed)
    if offset is not None:
        scans = [replace(s, odom=geometry.compose(offset, s.odom)) for s in scans]
    return SlamPipeline(cfg).run(scans, session=session, localize=localize), cfg


@pytest.fixture(scope="module")
def full():
    return slam()


@pytest.fixture(scope="module")
def first():
    return slam(max_scans=CUT)[0]


def test_a_continued_half_run_is_the_full_run(full, first):
    full, _ = full
    rest, _ = slam(session=first.session, first_scan=CUT)
    np.testing.assert_array_equal(rest.stamps, full.stamps)
    assert abs(rest.graph.num_keyframes - full.graph.num_keyframes) <= 0.02 * full.graph.num_keyframes
    assert abs(rest.graph.num_loops - full.graph.num_loops) <= 0.1 * full.graph.num_loops
    assert rest.graph.num_loops > first.graph.num_loops + 20  # the second lap closed loops with the first
    apart = np.hypot(*(rest.poses[:, :2] - full.poses[:, :2]).T)
    assert apart.max() < 0.03, apart.max()
    assert np.hypot(*(rest.poses[:, :2] - rest.ground_truth[:, :2]).T).max() < 0.04


def test_a_second_session_from_an_unknown_start_merges(full, first):
    full, cfg = full
    merged, _ = slam(session=first.session, localize=True, offset=OFFSET, first_scan=CUT)
    assert merged.stats["sessions placed"] == 1
    second = slice(CUT, None)
    error = np.hypot(*(merged.poses[second, :2] - merged.ground_truth[second, :2]).T)
    assert error.max() < 0.05, error.max()  # placed in the first session's frame, a few cm at most
    assert merged.graph.num_loops > first.graph.num_loops + 20  # loops between the sessions
    merged_map = build_grid(merged.poses, merged.scans, cfg.mapping)
    assert free_space_iou(merged_map, build_grid(full.poses, full.scans, cfg.mapping)) >= 0.98


def test_a_session_outside_the_saved_map_is_not_placed():
    corner, _ = slam(max_scans=5)  # the saved map: what the start sees
    with pytest.raises(InputError, match=r"matched the saved map unambiguously \([1-9]\d* global searches\)"):
        slam(session=corner.session, localize=True, first_scan=150, max_scans=30)


def test_results_folder_holds_the_session_to_go_on_from(tmp_path):
    quick = [f"{k}={v}" for k, v in QUICK.items()] + [f"output.root={tmp_path}", "output.figures=false"]
    one = run_experiment(config.load(None, [*quick, "name=one", "dataset.max_scans=40"]), quiet=True)
    saved = read_session(one)
    assert len(saved) == 40 and saved.num_keyframes == len(np.unique(saved.keyframe))
    sets = [a for kv in [*quick, "name=two", "dataset.first_scan=40", "dataset.max_scans=30"] for a in ("--set", kv)]
    res = CliRunner().invoke(app, ["run", "-q", *sets, "--continue", str(one)])
    assert res.exit_code == 0, res.output
    two = Path(res.stdout.split("results:")[-1].strip())
    assert len(read_tum(two / "trajectory.tum")) == 70
    assert len(read_session(two / SESSION_FILE)) == 70
    assert str(one) in (two / "config.yaml").read_text()
    res = CliRunner().invoke(app, ["run", "-q", "--continue", str(one), "--localize-in", str(one)])
    assert res.exit_code == 2 and "exclude each other" in res.output
    with pytest.raises(InputError, match="no saved session"):
        read_session(tmp_path)
    for damaged in (b"", (one / "config.yaml").read_bytes(), (one / SESSION_FILE).read_bytes()[:1000]):
        (tmp_path / SESSION_FILE).write_bytes(damaged)
        with pytest.raises(InputError, match="not a readable session"):
            read_session(tmp_path)


def test_one_saved_session_at_a_time():
    with pytest.raises(InputError, match="exclude each other"):
        config.load(None, ["session.continue_from=a", "session.localize_in=b"])


def test_a_window_of_a_log():
    whole = [s.stamp for s in open_dataset(config.load(None, ["dataset.max_scans=30"]).dataset)]
    window = open_dataset(config.load(None, ["dataset.first_scan=10", "dataset.max_scans=20"]).dataset)
    assert window.expected() == 20
    assert [s.stamp for s in window] == whole[10:]
