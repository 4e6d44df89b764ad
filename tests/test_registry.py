"""The one registry: every role's built-in names, plugins adding to any role (an exploration strategy and a
similarity measure from one plugin file, run by name), options checked before any work, defaults resolved."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from slam2d import config, registry
from slam2d.errors import InputError
from slam2d.exploration import config as explore_config
from slam2d.exploration.base import EXPLORATION_STRATEGIES
from slam2d.exploration.loop import explore
from slam2d.frontends.base import FRONTENDS
from slam2d.planning.base import GLOBAL_PLANNERS
from slam2d.registry import Registry, resolve_config
from slam2d.segmentation.base import SEGMENTATION_METHODS, SIMILARITY_MEASURES, register_method, segment
from slam2d.segmentation.config import SegmentConfig
from slam2d.segmentation.evaluate import label_rooms, load_floor_plan, score

PLUGIN = '''
import numpy as np
from pydantic import Field

from slam2d.config import Section
from slam2d.exploration import register_strategy
from slam2d.segmentation import register_similarity


@register_strategy("farthest_frontier")
class FarthestFrontier:
    """The frontier region farthest along the grid path."""

    class Config(Section):
        weight: float = Field(1.0, gt=0)

    def __init__(self, config):
        self.config, self.calls = config, 0

    def choose(self, explorer, pose, view, distance):
        self.calls += 1
        return explorer.frontier_goal(pose, view, distance, lambda f: -self.config.weight * f.path)


@register_similarity("centre_distance")
def centre_distance(obs, scale: float = 2.0):
    """exp(-d / scale) of the distance d (m) between the observations' viewpoints."""
    xy = obs.poses[:, :2]
    return np.exp(-np.hypot(*(xy[:, None] - xy[None]).transpose(2, 0, 1)) / scale)
'''

BUILT_INS = {
    "datasets": ["simulator", "rosbag", "carmen"],
    "frontends": ["odometry", "icp", "lines", "corners", "fuzzy_vertex", "fused"],
    "backends": ["none", "pose_graph"],
    "global_planners": ["astar", "hpa", "rooms", "jps", "jps_plus", "subgoal"],
    "local_planners": ["dwa", "fsm", "teb"],
    "recovery_behaviours": ["backoff"],
    "exploration_strategies": ["nearest_frontier", "explore_lite", "nearest_candidate", "farthest_candidate",
                               "utility"],
    "similarity_measures": ["hausdorff", "nearest_neighbour", "feature_points", "visibility"],
    "segmentation_methods": ["spectral", "morphological", "distance", "voronoi"],
    "map_layers": ["grid", "sparse", "quadtree", "lines", "mesh"],
    "localizers": ["mcl"],
    "mcl_presets": ["slam2d", "amcl", "amcl_recovery"],
}


@pytest.fixture(scope="module")
def plugin(tmp_path_factory):
    path = tmp_path_factory.mktemp("plugin") / "my_parts.py"
    path.write_text(PLUGIN)
    return path


def floor_plan(folder):
    """Two 6 m x 6 m rooms (0.05 m/px) joined by a 0.9 m door, as a floor-plan PNG; its ground-truth rooms."""
    free = np.zeros((130, 255), bool)
    free[5:125, 5:125] = free[5:125, 130:250] = True
    free[51:69, 125:130] = True
    Image.fromarray(np.where(free, 255, 0).astype(np.uint8)).save(folder / "plan.png")
    gt = free.copy()
    gt[:, 125:130] = False
    return folder / "plan.png", label_rooms(gt)


def two_rooms_world(folder):
    """Two 4 x 3 m rooms side by side joined by a 1 m door, 5 cm pixels."""
    img = np.zeros((80, 180), dtype=np.uint8)
    img[10:70, 10:90] = img[10:70, 92:170] = img[30:50, 88:94] = 255
    Image.fromarray(img).save(folder / "two_rooms.png")
    return folder / "two_rooms.png"


# --------------------------------------------------------------------------- the registries


def test_every_role_lists_its_built_ins_with_a_description():
    catalog = registry.catalog()
    assert registry.roles()[:len(BUILT_INS)] == list(BUILT_INS)
    for role, names in BUILT_INS.items():  # the built-ins first, in their order (then what plugins added)
        assert list(catalog[role])[:len(names)] == names
        assert all(catalog[role][n] for n in names)  # one line each, from the docstring
    assert "\n" not in catalog["global_planners"]["hpa"]


def test_unknown_names_list_the_available_ones_and_aliases():
    with pytest.raises(InputError, match=r"^planning.hierarchy: unknown planner 'quad' \(available: astar, hpa, "
                                         r"rooms, jps, jps_plus, subgoal, none \(= astar\)\)$"):
        GLOBAL_PLANNERS.get("quad")
    assert SIMILARITY_MEASURES.canonical("knn") == "nearest_neighbour" and "knn" in SIMILARITY_MEASURES
    with pytest.raises(InputError, match=r"config: key 'exploration.strategy': unknown strategy 'greedy' "
                                         r"\(available: nearest_frontier, explore_lite"):
        explore_config.load(None, {"exploration.strategy": "greedy"})


def test_a_registry_takes_classes_and_functions_with_their_options():
    parts = Registry("parts", "part")

    @parts.register("scaled", aliases=("times",), takes=("log",))
    def scaled(x, factor: float = 2.0, log=None):
        """x times a factor."""
        if log is not None:
            log.append(factor)
        return x * factor

    @parts.register("shifted")
    class Shifted:
        """x plus a shift."""

        class Config(config.Section):
            shift: float = 1.0

        def __init__(self, config):
            self.shift = config.shift

    log = []
    assert parts.create("times", {"factor": 3}, 2.0, log=log, other=1) == 6.0 and log == [3.0]
    assert parts.create("shifted", {"shift": 0.5}).shift == 0.5
    assert parts.names() == ["scaled", "shifted"] and parts.describe("scaled") == "x times a factor."
    with pytest.raises(InputError, match=r"^parts.options.factr: unknown key \(valid: factor\)$"):
        parts.create("scaled", {"factr": 3}, 1.0)
    with pytest.raises(InputError, match=r"^parts.options.factor: Input should be a valid number"):
        parts.create("scaled", {"factor": "big"}, 1.0)


# --------------------------------------------------------------------------- options


def test_an_unknown_method_parameter_is_refused_before_any_work_naming_the_key_and_the_valid_ones():
    with pytest.raises(InputError, match=r"config: unknown key 'segmentation.params.foo' \(valid: spur_length, "
                                         r"minimum_radius, min_angle_deg, opening_ratio, room_area_min, seed\)"):
        config.load(None, ["segmentation.method=voronoi", "segmentation.params.foo=1"], SegmentConfig)
    with pytest.raises(InputError, match=r"key 'segmentation.params.k': Input should be greater than 0"):
        config.load(None, ["segmentation.params.k=0"], SegmentConfig)
    calls = []

    @register_method("recorded_for_test")
    def recorded(free, resolution, rooms: int = 1):
        """Every free cell one room (recording the call)."""
        calls.append(rooms)
        return free.astype(np.int32)

    free = np.ones((10, 10), bool)
    with pytest.raises(InputError, match=r"^segmentation.params.room: unknown key \(valid: rooms\)$"):
        segment(free, 0.05, "recorded_for_test", params={"room": 2})
    assert calls == []
    assert segment(free, 0.05, "recorded_for_test", params={"rooms": 2})["labels"].max() == 1 and calls == [2]


def test_resolve_options_fills_the_defaults():
    voronoi = SEGMENTATION_METHODS.resolve_options("voronoi", {"spur_length": 3.0})
    assert voronoi.model_dump() == {"spur_length": 3.0, "minimum_radius": 0.5, "min_angle_deg": 120.0,
                                    "opening_ratio": 0.6, "room_area_min": 1.5, "seed": 0}
    assert SIMILARITY_MEASURES.resolve_options("feature_points", {"window": 5}).model_dump()["window"] == 5
    cfg = config.load(None, ["segmentation.params.k=3"], SegmentConfig)
    assert cfg.segmentation.params == {"k": 3}  # the config keeps what was given ...
    params = resolve_config(cfg).segmentation.params  # ... its resolved form every default
    assert params["k"] == 3 and params["k_max"] == 60 and params["seed"] is None and "similarity" not in params
    run = config.load(None, ["frontend.name=icp", "frontend.options={min_points: 20}"])
    assert resolve_config(run).frontend.options == FRONTENDS.resolve_options("icp", {"min_points": 20}).model_dump()
    explore_cfg = explore_config.load(None, {"exploration.strategy": "nearest_frontier"})
    assert resolve_config(explore_cfg).exploration.strategy_options == {}  # the built-ins take none


# --------------------------------------------------------------------------- plugins


def test_a_plugin_strategy_explores_by_name(plugin, tmp_path):
    cfg = explore_config.load(None, {
        "plugins": [str(plugin)], "exploration.strategy": "farthest_frontier",
        "exploration.strategy_options": {"weight": 2.0}, "dataset.simulator.world": str(two_rooms_world(tmp_path)),
        "exploration.start": [1.5, 2.0, 0.0], "exploration.max_time": 20, "exploration.animation": False,
        "exploration.pockets": False, "seed": 1,
    })  # fmt: skip
    assert "farthest_frontier" in EXPLORATION_STRATEGIES
    run = explore(cfg)
    assert type(run.explorer.strategy).__name__ == "FarthestFrontier" and run.explorer.strategy.config.weight == 2.0
    assert run.explorer.strategy.calls >= 1 and run.goals and run.goals[0]["kind"] == "frontier"
    assert run.metrics["strategy"] == "farthest_frontier" and run.metrics["coverage"] > 0.2
    with pytest.raises(InputError, match=r"unknown key 'exploration.strategy_options.wieght' \(valid: weight\)"):
        explore_config.load(None, {"plugins": [str(plugin)], "exploration.strategy": "farthest_frontier",
                                   "exploration.strategy_options": {"wieght": 2.0}})


def test_a_plugin_similarity_measure_segments_a_floor_plan_by_name(plugin, tmp_path):
    path, gt = floor_plan(tmp_path)
    cfg = config.load(None, {"plugins": [str(plugin)], "map": str(path), "segmentation.similarity": "centre_distance",
                             "segmentation.params": {"k": 2, "similarity_params": {"scale": 3.0}}}, SegmentConfig)
    assert "centre_distance" in SIMILARITY_MEASURES
    free, resolution = load_floor_plan(path)
    seg = cfg.segmentation
    run = segment(free, resolution, seg.method, seg.similarity, seg.params, seed=cfg.seed)
    assert run["similarity"] == "centre_distance" and run["k"] == 2
    assert score(run["labels"], gt)["recall"] > 95
    with pytest.raises(InputError, match=r"^segmentation.params.similarity_params.scal: unknown key \(valid: scale\)"):
        segment(free, resolution, "spectral", "centre_distance", {"similarity_params": {"scal": 1.0}})


def test_plugin_parts_run_from_the_cli_and_in_a_sweep(plugin, tmp_path):
    """The plugin file's strategy and measure are listed by ``slam2d plugins``, chosen on the command line,
    and swapped in by a sweep whose variants run in worker processes (which import the plugin again)."""
    import yaml
    from typer.testing import CliRunner

    from slam2d.cli import app
    from slam2d.runs.sweep import run_sweep

    runner = CliRunner()
    listed = runner.invoke(app, ["plugins", "--plugin", str(plugin)])
    assert listed.exit_code == 0, listed.output
    assert "farthest_frontier" in listed.output and "centre_distance" in listed.output and "commands:" in listed.output
    path, _ = floor_plan(tmp_path)
    out = runner.invoke(app, ["segment", str(path), "--similarity", "centre_distance", "--set", f"plugins=[{plugin}]",
                              "--set", "segmentation.params={k: 2}", "-o", str(tmp_path / "seg"), "-q"])
    assert out.exit_code == 0, out.output
    explore = {"plugins": [str(plugin)], "dataset": {"simulator": {"world": str(two_rooms_world(tmp_path))}},
               "exploration": {"start": [1.5, 2.0, 0.0], "max_time": 15, "animation": False, "pockets": False},
               "output": {"root": str(tmp_path / "res"), "figures": False}}
    out = runner.invoke(app, ["explore", "--strategy", "farthest_frontier", "-c", str(_yaml(tmp_path, explore)),
                              "-q"])
    assert out.exit_code == 0, out.output
    for command, base, key, name in (
            ("explore", explore, "exploration.strategy", "farthest_frontier"),
            ("segment", {"plugins": [str(plugin)], "map": str(path), "segmentation": {"params": {"k": 2}},
                         "output": {"root": str(tmp_path / "res")}}, "segmentation.similarity", "centre_distance")):
        sweep = _yaml(tmp_path, {"command": command, "config": base, "workers": 1,
                                 "variants": [{"name": "plugin", "set": {key: name}}]}, f"{command}_sweep.yaml")
        folder, rows = run_sweep(sweep, quiet=True)
        assert rows[0]["error"] == "", rows
        metrics = yaml.safe_load((folder / rows[0]["folder"] / "metrics.json").read_text())
        assert metrics.get("strategy", metrics.get("similarity")) == name


def _yaml(folder, data, name="config.yaml"):
    import yaml

    (folder / name).write_text(yaml.safe_dump(data))
    return folder / name
