"""Every command is an experiment: it takes -c/--set/--out/-q, dumps its config, and runs in a sweep."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from PIL import Image
from typer.testing import CliRunner

from slam2d.cli import app
from slam2d.runs.commands import COMMANDS
from slam2d.runs.sweep import run_sweep


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_command_takes_the_same_options_and_dumps_its_config(command):
    runner = CliRunner()
    helped = runner.invoke(app, [command, "--help"], env={"COLUMNS": "200"})
    assert helped.exit_code == 0, helped.output
    for option in ("--config", "--set", "--out", "--quiet", "--json"):
        assert option in helped.output, f"{command} lacks {option}"
    swept = runner.invoke(app, ["ablate", "--help"], env={"COLUMNS": "200"})
    assert all(option in swept.output for option in ("--set", "--grid", "--out", "--quiet", "--dry-run", "--json"))
    dumped = runner.invoke(app, ["dump-config", "--command", command, "--set", "output.root=elsewhere"])
    assert dumped.exit_code == 0, dumped.output
    assert yaml.safe_load(dumped.output)["output"]["root"] == "elsewhere"
    described = runner.invoke(app, ["dump-config", "--command", command, "--set", "output.root=elsewhere",
                                     "--describe"])
    assert described.exit_code == 0 and yaml.safe_load(described.output) == yaml.safe_load(dumped.output)
    assert "  # results folders are created under this directory" in described.output
    unknown = runner.invoke(app, ["dump-config", "--command", command, "--set", "no_such_key=1"])
    assert unknown.exit_code == 2 and "unknown key 'no_such_key'" in unknown.output


def test_config_given_twice_is_an_error(tmp_path):
    cfg = tmp_path / "a.yaml"
    cfg.write_text("seed: 1\n")
    out = CliRunner().invoke(app, ["run", str(cfg), "-c", str(cfg)])
    assert out.exit_code == 2 and "--config: give the config once" in out.output


def _plan_png(path):
    img = np.full((40, 60), 255, np.uint8)
    img[[0, -1], :] = img[:, [0, -1]] = 0
    img[5, 5:55] = 0
    Image.fromarray(img).save(path)
    return path


def test_map_and_optimize_take_a_config_and_run_as_one_variant_sweeps(tmp_path, data_file):
    plan = _plan_png(tmp_path / "plan.png")
    (tmp_path / "map.yaml").write_text(yaml.safe_dump({"map": str(plan), "layers": ["quadtree"]}))
    out = CliRunner().invoke(app, ["map", "-c", str(tmp_path / "map.yaml"), "--set", "layers=[lines]",
                                   "-o", str(tmp_path / "m"), "-q"])
    assert out.exit_code == 0, out.output
    (folder,) = (tmp_path / "m").glob("map-plan-*")
    assert (folder / "lines.json").is_file() and not (folder / "map.quadtree").exists()
    assert yaml.safe_load((folder / "config.yaml").read_text())["layers"] == ["lines"]
    assert json.loads((folder / "metrics.json").read_text())["lines"]["bytes"] > 0

    graph = data_file("posegraphs/intel.g2o")
    for command, config in (("map", {"map": str(plan), "layers": ["sparse"]}),
                            ("optimize", {"graph": str(graph), "verify": False})):
        sweep = tmp_path / f"{command}.yaml"
        sweep.write_text(yaml.safe_dump({"command": command, "config": {**config, "output": {"root": str(tmp_path)}},
                                         "variants": [{"name": "only", "set": {"seed": 1}}]}))
        folder, rows = run_sweep(sweep, quiet=True)
        assert [r["variant"] for r in rows] == ["only"] and rows[0]["error"] == "", rows
        assert (folder / rows[0]["folder"] / "metrics.json").is_file()
        header = (folder / "table.md").read_text().splitlines()[0]
        main = {"map": "sparse.bytes", "optimize": "kept_edges_error"}[command]
        assert main in COMMANDS[command].main_metrics and main in header  # the command's main metric shown


def test_optimize_writes_strict_json(tmp_path, data_file):
    out = CliRunner().invoke(app, ["optimize", str(data_file("posegraphs/intel.g2o")), "--no-verify", "-o",
                                   str(tmp_path), "-q"])
    assert out.exit_code == 0, out.output
    (folder,) = tmp_path.glob("optimize-intel-*")
    text = (folder / "metrics.json").read_text()
    json.loads(text, parse_constant=lambda c: pytest.fail(f"{c} in metrics.json"))


def test_ablate_takes_set_and_grid_and_dry_runs(tmp_path):
    sweep = tmp_path / "s.yaml"
    sweep.write_text(yaml.safe_dump({"config": {"dataset": {"max_scans": 5}}, "grid": {"seed": [0, 1]}}))
    out = CliRunner().invoke(app, ["ablate", str(sweep), "--dry-run", "--grid", "frontend.name=odometry,icp",
                                   "--set", f"output.root={tmp_path / 'res'}"])
    assert out.exit_code == 0, out.output
    assert "4 variants checked; nothing run" in out.output and "name=odometry" in out.output
    assert not (tmp_path / "res").exists()
    ran = CliRunner().invoke(app, ["ablate", str(sweep), "--set", "frontend.name=odometry", "--set", "seed=2",
                                   "--grid", "seed=0", "--out", str(tmp_path / "res"), "-q"])
    assert ran.exit_code == 0, ran.output
    (folder,) = (tmp_path / "res").glob("ablate-s-*")
    assert (folder / "table.md").is_file() and len(list((folder / "runs").iterdir())) == 1
    bad = CliRunner().invoke(app, ["ablate", str(sweep), "--dry-run", "--grid", "frontend.name=odometry,nope"])
    assert bad.exit_code == 2 and "unknown frontend 'nope'" in bad.output
    both = tmp_path / "both.yaml"
    both.write_text(yaml.safe_dump({"base": "s.yaml", "config": {}, "grid": {"seed": [0]}}))
    out = CliRunner().invoke(app, ["ablate", str(both), "--dry-run"])
    assert out.exit_code == 2 and "'base' (a file) or 'config' (inline), not both" in out.output


def test_data_paths_resolve_against_slam2d_data_everywhere(tmp_path, data_file, monkeypatch):
    """A world PNG, a map and a pose graph named relative to SLAM2D_DATA are found from any folder."""
    from slam2d.sim.world import load_world

    data_file("rooms/office_a.png")
    monkeypatch.chdir(tmp_path)
    assert load_world("rooms/office_a.png").name
    out = CliRunner().invoke(app, ["map", "rooms/office_a.png", "--layers", "sparse", "-o", str(tmp_path), "-q"])
    assert out.exit_code == 0, out.output
    out = CliRunner().invoke(app, ["dump-config", "--command", "optimize", "--set", "graph=posegraphs/intel.g2o"])
    assert out.exit_code == 0 and "posegraphs/intel.g2o" in out.output
