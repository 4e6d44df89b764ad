"""slam2d compare: several runs (or a sweep's) in one table with their trajectories overlaid and their error
distributions side by side."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from slam2d.cli import app
from slam2d.runs.compare import position_errors


def _run(tmp_path, *sets):
    out = CliRunner().invoke(app, ["run", "-q", "-o", str(tmp_path / "res"), "--set", "dataset.max_scans=20",
                                   "--set", "frontend.name=odometry", *(a for s in sets for a in ("--set", s))])
    assert out.exit_code == 0, out.output
    return out.output.strip().split("results: ")[-1]


def test_compare_tables_runs_and_sweeps_and_overlays_their_trajectories(tmp_path):
    a = _run(tmp_path, "name=calm", "seed=1")
    b = _run(tmp_path, "name=noisy", "seed=2", "dataset.simulator.odometry.alpha3=0.2")
    runner = CliRunner()
    out = runner.invoke(app, ["compare", a, b, "-o", str(tmp_path / "cmp")])
    assert out.exit_code == 0, out.output
    header, _, first, second = out.output.splitlines()[:4]
    assert "| run |" in header and "ate.rmse" in header and "odometry_ate.rmse" in header
    assert first.startswith("| calm-") and second.startswith("| noisy-")
    (folder,) = (tmp_path / "cmp").glob("compare-*")
    assert (folder / "trajectories.png").stat().st_size > 1000 and (folder / "table.csv").is_file()
    assert (folder / "errors.png").stat().st_size > 1000
    page = (folder / "report.html").read_text()
    assert '<section id="table">' in page and 'alt="errors.png"' in page and "<th>calm-" in page
    errors = position_errors(Path(a))
    ate = json.loads((Path(a) / "metrics.json").read_text())["ate"]["rmse"]
    assert len(errors) == 20 and np.sqrt(np.mean(errors**2)) == pytest.approx(ate, rel=1e-6)
    only = runner.invoke(app, ["compare", a, b, "--metric", "scans"])
    assert only.exit_code == 0 and only.output.splitlines()[0] == "| run | scans |"
    bad = runner.invoke(app, ["compare", a, "--metric", "no.such"])
    assert bad.exit_code == 2 and "--metric: no run has 'no.such'" in bad.output
    sweep = tmp_path / "s.yaml"
    sweep.write_text(yaml.safe_dump({"config": {"dataset": {"max_scans": 10}, "frontend": {"name": "odometry"},
                                                "output": {"root": str(tmp_path / "sw")}}, "grid": {"seed": [0, 1]}}))
    assert runner.invoke(app, ["ablate", str(sweep), "-q"]).exit_code == 0
    (swept,) = (tmp_path / "sw").glob("ablate-s-*")
    rows = runner.invoke(app, ["compare", str(swept)]).output.splitlines()
    assert len(rows) == 4 and rows[2].startswith("| seed=0-")
    assert runner.invoke(app, ["compare", str(tmp_path)]).exit_code == 2
