"""Nothing overflows: size-like config values are bounded, huge maps and images are refused in one line
before they are allocated, and points outside the map are input errors."""

from __future__ import annotations

import numpy as np
import pytest

from slam2d import config
from slam2d.errors import InputError
from slam2d.runs.commands import command_model


@pytest.mark.parametrize("command, override, message", [
    ("run", "mapping.resolution=1e12", r"key 'mapping.resolution': Input should be less than or equal to 10"),
    ("run", "mapping.resolution=1e-9", r"key 'mapping.resolution': Input should be greater than or equal to 0.001"),
    ("run", "mapping.resolution=.nan", r"key 'mapping.resolution': Input should be a finite number"),
    ("run", "dataset.simulator.resolution=1e9", r"key 'dataset.simulator.resolution'"),
    ("run", "backend.loop_closure.resolution=0", r"key 'backend.loop_closure.resolution'"),
    ("run", "dataset.simulator.laser.beams=100000",
     r"key 'dataset.simulator.laser.beams': .*less than or equal to 10000"),
    ("run", "mapping.log_odds_hit=.inf", r"key 'mapping.log_odds_hit': Input should be a finite number"),
    ("navigate", "navigation.people=1000000", r"key 'navigation.people'"),
    ("plan", "planning.queries=10000000", r"key 'planning.queries': .*less than or equal to 100000"),
    ("plan", "resolution=1e-9", r"key 'resolution'"),
    ("segment", "resolution=100", r"key 'resolution'"),
    ("optimize", "outliers=100000000", r"key 'outliers': .*less than or equal to 1000000"),
    ("run", "frontend.options={map_voxel_size: 1.0e-9}", r"frontend.options.map_voxel_size: .*greater than or equal"),
    ("run", "frontend.options={voxel_size: 100}", r"frontend.options.voxel_size: .*less than or equal to 10"),
    ("segment", "segmentation.params={label_cell_m: 1.0e-6}", r"label_cell_m"),
])
def test_size_like_config_values_are_bounded(command, override, message):
    from slam2d.runs.commands import resolved

    with pytest.raises(InputError, match=message):
        resolved(config.load(None, [override], command_model(command)))  # resolved: a frontend's own options


def test_particle_counts_are_bounded():
    cfg = config.load(None, ["localization.mcl={max_particles: 100000000}"], command_model("localize"))
    with pytest.raises(InputError, match=r"max_particles.*less than or equal to 1000000"):
        cfg.filter_config()


def _map_yaml(tmp_path, resolution):
    from PIL import Image

    pixels = np.full((10, 10), 254, np.uint8)
    pixels[0] = 0  # a wall along the top
    Image.fromarray(pixels).save(tmp_path / "map.pgm")
    path = tmp_path / "map.yaml"
    path.write_text(f"image: map.pgm\nresolution: {resolution}\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n"
                    "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    return path


@pytest.mark.parametrize("resolution", ["1.0e+12", "1.0e-9"])
def test_map_yaml_resolution_out_of_range_is_refused_at_load(tmp_path, resolution):
    from slam2d.mapping.maps import load_map

    with pytest.raises(InputError, match=r"map.yaml: key 'resolution': expected 0.001 to 10 m per pixel"):
        load_map(_map_yaml(tmp_path, resolution))


def test_floor_plan_resolution_out_of_range_is_refused(tmp_path):
    from slam2d.mapping.maps import load_map

    _map_yaml(tmp_path, 0.05)
    (tmp_path / "map.pgm").rename(tmp_path / "plan.png")
    with pytest.raises(InputError, match=r"resolution: expected 0.001 to 10 m/px, got 1e-09"):
        load_map(tmp_path / "plan.png", resolution=1e-9)


def test_decompression_bomb_is_an_input_error(tmp_path):
    from PIL import Image

    from slam2d.mapping.maps import load_map

    path = tmp_path / "bomb.png"
    Image.new("1", (20_000, 20_000), 1).save(path)  # 400 M pixels in a few kB
    with pytest.raises(InputError, match=r"bomb.png: image too large"):
        load_map(path)


def test_memory_ceiling_refuses_the_map_grid_and_the_particles(tmp_path, monkeypatch):
    from slam2d.localization.config import MclConfig
    from slam2d.localization.maps import KnownMap
    from slam2d.localization.mcl import ParticleFilter
    from slam2d.mapping.maps import load_map
    from slam2d.mapping.occupancy import _empty_grid

    known = KnownMap.from_occupancy(load_map(_map_yaml(tmp_path, 0.1)))
    monkeypatch.setenv("SLAM2D_MAX_MEMORY_GB", "0.01")
    with pytest.raises(InputError, match=r"mapping.resolution: a 2001 x 2001 map grid at 0.05 m would need 0.048 GB "
                                         r"of memory, more than the 0.01 GB of SLAM2D_MAX_MEMORY_GB"):
        _empty_grid(np.array([[0.0, 0.0], [99.0, 99.0]]), 0.05)
    with pytest.raises(InputError, match=r"localization.mcl.max_particles: weighing 5000000 particles on 60 beams"):
        ParticleFilter(known, MclConfig(max_particles=1_000_000))
    with pytest.raises(InputError, match=r"map.pgm: a 10 x 10 pixel map would need"):
        monkeypatch.setenv("SLAM2D_MAX_MEMORY_GB", "1e-9")
        load_map(tmp_path / "map.yaml")


def test_start_and_goal_outside_the_map_are_input_errors(tmp_path):
    from slam2d.planning.query import plan_on_map

    path = _map_yaml(tmp_path, 0.1)
    with pytest.raises(InputError, match=r"^start: \(1000, 1000\) is outside the map: x from 0 to 1 m, y from 0 to 1 "):
        plan_on_map(path, (1000, 1000), (0.5, 0.5))
    with pytest.raises(InputError, match=r"^goal: \(-3, 0.5\) is outside the map"):
        plan_on_map(path, (0.5, 0.5), (-3, 0.5))


def test_navigate_goal_outside_the_world_is_an_input_error(tmp_path):
    from slam2d.runs.navigate import run_navigate

    cfg = config.load(None, ["navigation.goal=[1000, 1000]", f"output.root={tmp_path}", "navigation.slam=false"],
                      command_model("navigate"))
    with pytest.raises(InputError, match=r"^navigation.goal: \(1000, 1000\) is outside the world 'office'"):
        run_navigate(cfg, quiet=True)
    assert list(tmp_path.iterdir()) == []


def test_localize_initial_pose_outside_the_map_is_an_input_error(tmp_path):
    from slam2d.runs.localize import run_localize

    cfg = config.load(None, ["map=office", "localization.mode=tracking", "localization.initial_pose=[500, 0, 0]",
                             "localization.seconds=2", f"output.root={tmp_path}", "output.figures=false"],
                      command_model("localize"))
    with pytest.raises(InputError, match=r"^initial_pose: \(500, 0\) is outside the map"):
        run_localize(cfg, quiet=True)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("workers", [0, -2, 100_000])
def test_sweep_workers_are_bounded(tmp_path, workers):
    import yaml

    from slam2d.runs.sweep import run_sweep

    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump({"config": {"output": {"root": str(tmp_path / "res")}},
                                    "variants": [{"name": "a", "set": {"seed": 1}}]}))
    with pytest.raises(InputError, match=r"^--workers: expected a positive integer up to 256"):
        run_sweep(path, workers=workers, quiet=True)
    path.write_text(path.read_text() + f"workers: {workers}\n")
    with pytest.raises(InputError, match=r"sweep.yaml: workers: expected a positive integer up to 256"):
        run_sweep(path, quiet=True)
    assert not (tmp_path / "res").exists()
