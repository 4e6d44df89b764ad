"""The whole chain: config -> reader -> poses -> map -> metrics -> results folder -> table."""

import csv
import json
import re

import pytest
import yaml
from typer.testing import CliRunner

from slam2d import config
from slam2d.cli import app
from slam2d.errors import InputError
from slam2d.runs.commands import resolved
from slam2d.runs.run import run_experiment
from slam2d.runs.sweep import load_sweep, run_sweep

SMALL = ["dataset.max_scans=40", "mapping.resolution=0.1"]


def small_cfg(tmp_path, *extra):
    return config.load(None, [*SMALL, f"output.root={tmp_path / 'results'}", *extra])


def test_run_writes_complete_results_folder(tmp_path):
    folder = run_experiment(small_cfg(tmp_path), quiet=True)
    for name in ("config.yaml", "trajectory.tum", "map.pgm", "map.yaml", "map.png", "metrics.json", "run.log"):
        assert (folder / name).is_file(), name
    metrics = json.loads((folder / "metrics.json").read_text())
    assert metrics["scans"] == 40
    assert metrics["ate"]["rmse"] >= 0 and "odometry_ate" in metrics
    assert metrics["cpu_ms_per_scan"] > 0 and 0 <= metrics["frontend_fallbacks"] < 40
    counted = [*metrics["slam"], *metrics["skipped"]]  # snake_case keys: usable as columns and selectors
    assert "keyframes" in " ".join(counted) and all(re.fullmatch(r"[0-9A-Za-z_]+", k) for k in counted), counted
    # the resolved config reproduces the run's config
    assert config.load(folder / "config.yaml") == resolved(small_cfg(tmp_path))
    assert len([l for l in (folder / "trajectory.tum").read_text().splitlines() if not l.startswith("#")]) == 40


def test_runs_never_overwrite(tmp_path):
    a = run_experiment(small_cfg(tmp_path), quiet=True)
    b = run_experiment(small_cfg(tmp_path), quiet=True)
    assert a != b and a.is_dir() and b.is_dir()


def test_failed_run_leaves_no_folder(tmp_path):
    cfg = small_cfg(tmp_path, "dataset.kind=carmen", f"dataset.path={tmp_path / 'missing.clf'}")
    with pytest.raises(InputError, match="missing.clf"):
        run_experiment(cfg, quiet=True)
    assert list((tmp_path / "results").iterdir()) == []


def test_same_seed_same_numbers(tmp_path):
    a = json.loads((run_experiment(small_cfg(tmp_path), quiet=True) / "metrics.json").read_text())
    b = json.loads((run_experiment(small_cfg(tmp_path), quiet=True) / "metrics.json").read_text())
    assert a["odometry_ate"] == b["odometry_ate"]


def test_ablate_two_variants_table(tmp_path):
    base = tmp_path / "base.yaml"
    base.write_text(yaml.safe_dump({"dataset": {"max_scans": 30}, "output": {"root": str(tmp_path / "res")}}))
    sweep = tmp_path / "sweep.yaml"
    sweep.write_text(
        yaml.safe_dump({"base": "base.yaml", "workers": 2, "grid": {"dataset.simulator.odometry.alpha3": [0.0, 0.2]}})
    )
    folder, rows = run_sweep(sweep, quiet=True)
    assert [r["error"] for r in rows] == ["", ""]
    with (folder / "table.csv").open() as fh:
        table = list(csv.DictReader(fh))
    assert len(table) == 2
    assert {"variant", "dataset.simulator.odometry.alpha3", "odometry_ate.rmse", "cpu_ms_per_scan",
            "frontend_fallbacks"} <= set(table[0])
    # more odometry noise, larger odometry error: the table carries real numbers per variant
    assert float(table[1]["odometry_ate.rmse"]) > float(table[0]["odometry_ate.rmse"])
    assert "| variant |" in (folder / "table.md").read_text()


def test_sweep_rejects_bad_variant_before_running(tmp_path):
    sweep = tmp_path / "sweep.yaml"
    sweep.write_text(yaml.safe_dump({"config": {}, "variants": [{"name": "x", "set": {"mapping.nope": 1}}]}))
    with pytest.raises(InputError, match="variant 'x'.*unknown key 'mapping.nope'"):
        load_sweep(sweep)


def test_cli_run_and_errors(tmp_path):
    runner = CliRunner()
    res = runner.invoke(app, ["run", "-q", *sum((["--set", s] for s in SMALL), []), "--set", f"output.root={tmp_path}"])
    assert res.exit_code == 0, res.output
    assert "results:" in res.output
    bad = runner.invoke(app, ["run", "-q", "--set", "frontend.nmae=x"])
    assert bad.exit_code == 2
    assert "unknown key 'frontend.nmae'" in bad.output
