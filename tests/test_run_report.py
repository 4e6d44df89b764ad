"""Every command's results folder holds report.html: main metrics, figures embedded, every metric, the config;
a SLAM run with ground truth adds the APE figure (over time and along the trajectory), one with loop closures
their timeline."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from test_report import _dom

from slam2d import config
from slam2d.runs.run import run_experiment
from slam2d.runs.segment import run_segment
from slam2d.segmentation.config import SegmentConfig


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory):
    root = tmp_path_factory.mktemp("run")
    return run_experiment(config.load(None, ["dataset.max_scans=300", f"output.root={root}"]), quiet=True)


def test_a_run_report_holds_its_metrics_figures_and_config(run_folder):
    page = (run_folder / "report.html").read_text()
    for section in ("main-metrics", "figures", "all-metrics", "config"):
        assert f'<section id="{section}">' in page, section
    assert re.search(r"<th>ate\.rmse</th><td class=\"num\">0\.0\d+</td>", page)
    assert 'alt="ape.png"' in page and 'alt="map.png"' in page and "data:image/png;base64," in page
    assert "frontend:" in page  # the resolved config
    with Image.open(run_folder / "ape.png") as im:
        assert im.size[0] > 800


def test_a_run_lists_and_draws_its_loop_closures(run_folder):
    loops = np.loadtxt(run_folder / "loops.csv", delimiter=",", skiprows=1, ndmin=2)
    slam = json.loads((run_folder / "metrics.json").read_text())["slam"]
    assert len(loops) == slam["loop_closures_added"] > 0
    assert int(loops[:, 4].sum()) == slam["loop_closures_kept"]
    assert (loops[:, 2] < loops[:, 3]).all()  # closed from a later keyframe to an earlier one, times in s
    assert 'alt="loops.png"' in (run_folder / "report.html").read_text()


def test_a_simulator_run_measures_its_map_against_the_plan(run_folder):
    acc = json.loads((run_folder / "metrics.json").read_text())["map_accuracy"]
    rows = (run_folder / "spans.csv").read_text().splitlines()
    assert len(rows) == 1 + acc["points"]["spans"] == 1 + acc["grid"]["spans"] == 12
    assert acc["points"]["seen"] >= 3 and acc["points"]["mean_abs_error_m"] < 0.01
    assert acc["grid"]["max_abs_error_m"] < 0.055  # each face within half a 5 cm cell, and the alignment


def test_the_run_report_renders_in_a_browser(run_folder, tmp_path):
    dom = _dom((run_folder / "report.html").as_uri(), tmp_path)
    assert "Main metrics" in dom and dom.count("<figure>") >= 2 and "ate.rmse" in dom


def test_other_commands_write_a_report_too(tmp_path):
    plan = tmp_path / "plan.png"
    img = Image.new("L", (60, 40), 255)
    img.paste(0, (0, 0, 60, 1))
    img.save(plan)
    folder = run_segment(SegmentConfig(map=str(plan), segmentation={"method": "morphological"},
                                       output={"root": str(tmp_path)}))
    page = (folder / "report.html").read_text()
    assert "<th>rooms</th>" in page and 'alt="rooms.png"' in page


def test_a_localisation_report_shows_the_particles_converging(tmp_path):
    from slam2d.localization.config import LocalizeConfig
    from slam2d.runs.localize import run_localize

    folder = run_localize(LocalizeConfig(map="office", seconds=3, output={"root": str(tmp_path)}), quiet=True)
    page = (folder / "report.html").read_text()
    assert 'alt="error_particles.png"' in page and "particle convergence" in page
    assert re.search(r'alt="cloud_\w+\.png"', page)


def test_a_run_with_relations_writes_their_errors_and_histogram(tmp_path, data_file):
    data_file("radish/mit-csail.clf")
    cfg = config.load(Path(__file__).parents[1] / "experiments/csail.yaml",
                      ["dataset.max_scans=500", f"output.root={tmp_path}"])
    folder = run_experiment(cfg, quiet=True)
    table = np.loadtxt(folder / "relations.csv", delimiter=",", skiprows=1, ndmin=2)
    metrics = json.loads((folder / "metrics.json").read_text())["relations"]
    assert len(table) == metrics["matched"] > 10
    assert np.mean(table[:, 2]) == pytest.approx(metrics["trans_abs_mean"], rel=1e-5)  # the metric's own errors
    assert 'alt="relations.png"' in (folder / "report.html").read_text()
