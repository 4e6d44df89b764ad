"""The command registry: each command's config model and the function that runs a config of it
into a results folder."""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from pathlib import Path

from slam2d.plugins import load_plugins
from slam2d.registry import Registry, resolve_config


@dataclass(frozen=True)
class Command:
    """A command: its config model and runner (``"module:name"``, imported when used) and the metrics its
    tables show first (dotted keys of its metrics.json). The runner takes a config of the model (and
    ``quiet``: no progress output) and returns the results folder it wrote."""

    model: str
    runner: str
    main_metrics: tuple[str, ...]
    about: str = ""

    def __post_init__(self):
        object.__setattr__(self, "__doc__", self.about)  # what ``slam2d plugins`` lists

    def config_model(self) -> type:
        return _named(self.model)


COMMANDS = Registry("commands", "command", key="command")
"""Every command that writes a results folder, by name; ``slam2d ablate`` sweeps any of them."""


def register_command(name: str, command: Command) -> None:
    """Make ``command`` available as ``slam2d ablate``'s ``command: name`` (and to :func:`run_command`)."""
    COMMANDS.add(name, command)


for _name, _command in {
    "run": Command("slam2d.config:ExperimentConfig", "slam2d.runs.run:run_experiment", (
        "relations.trans_abs_mean", "relations.trans_abs_std", "relations.rot_abs_mean", "relations.rot_abs_std",
        "odometry_relations.trans_abs_mean", "ate.rmse", "odometry_ate.rmse", "rpe.trans_rmse", "rpe.rot_rmse_deg",
        "cpu_ms_per_scan", "slam.loop_closures_kept", "slam.loop_closures_rejected", "frontend_fallbacks", "scans",
        "map_accuracy.points.mean_abs_error_m", "runtime_s", "peak_rss_mb"), 'SLAM on a dataset: trajectory, map, graph, ATE/RPE and the relations metric.'),
    "segment": Command("slam2d.segmentation.config:SegmentConfig", "slam2d.runs.segment:run_segment", (
        "recall", "precision", "rooms_found", "rooms_gt", "rooms", "k", "seconds", "cpu_seconds"), 'Rooms of a map: labels, region graph, recall and precision against a ground truth.'),
    "plan": Command("slam2d.planning.config:PlanConfig", "slam2d.runs.plan:run_plan", (
        "found", "length_m", "duration_s", "plan_ms", "nodes_expanded", "queries", "failures", "mean_subopt_pct",
        "max_subopt_pct", "median_speedup", "segmentation_s"), 'A path on a map (A* or a hierarchy), shortened and timed; or seeded queries against A*.'),
    "navigate": Command("slam2d.runs.navigate:NavigateConfig", "slam2d.runs.navigate:run_navigate", (
        "success", "status", "time", "path_length", "length_ratio", "goal_error", "heading_error", "collisions",
        "min_clearance", "pose_rmse", "planner_hz", "wall_s"), 'Drive the simulated robot to a goal on online SLAM (or a known map).'),
    "explore": Command("slam2d.exploration.config:ExploreConfig", "slam2d.runs.explore:run_explore", (
        "coverage", "distance_to_99", "time_to_99", "distance_to_90", "map_iou", "ate_rmse", "collisions",
        "min_clearance", "path_repetition", "decision_ms_median", "map_accuracy.mean_abs_error_m", "stop_reason",
        "wall_s"), 'Explore a simulated world from nothing with SLAM in the loop.'),
    "localize": Command("slam2d.localization.config:LocalizeConfig", "slam2d.runs.localize:run_localize", (
        "position_rmse", "heading_rmse_deg", "converged_s", "false_convergence", "final_state", "position_rmse_converged",
        "particles_median", "update_ms_median"), 'Monte Carlo localisation on a known map: tracking, global localisation, kidnapping.'),
    "map": Command("slam2d.runs.map:MapConfig", "slam2d.runs.map:run_map", (
        "grid.dense_uint8_bytes", "sparse.bytes", "quadtree.bytes", "quadtree.trinary_bytes", "lines.bytes",
        "mesh.bytes"), 'Mapping layers of a map: sparse grid, quadtrees, line map, wall mesh.'),
    "optimize": Command("slam2d.runs.optimize:OptimizeConfig", "slam2d.runs.optimize:run_optimize", (
        "kept_edges_error", "robust_cost", "iterations", "seconds", "verified", "certified", "loops_rejected",
        "precision", "recall", "rmse_to_reference"), 'One batch optimisation of a g2o / TORO pose graph, with false loops if asked.'),
}.items():
    register_command(_name, _command)


def _named(target: str):
    module, name = target.split(":")
    return getattr(importlib.import_module(module), name)


def command_of(command: str, key: str = "command") -> Command:
    """The :class:`Command` named ``command``; InputError naming ``key`` otherwise."""
    return COMMANDS.get(command, key)


def command_model(command: str, key: str = "command"):
    """The config model of ``command`` (a key of :data:`COMMANDS`); InputError naming ``key`` otherwise."""
    return command_of(command, key).config_model()


def run_command(cfg, quiet: bool = False) -> Path:
    """Run the config of any command of :data:`COMMANDS` into its results folder (its plugins imported
    first, as in a sweep's worker process); return the folder."""
    load_plugins(getattr(cfg, "plugins", ()))
    for name in COMMANDS:
        command = COMMANDS.get(name)
        if type(cfg) is command.config_model():
            runner = _named(command.runner)
            return runner(cfg, quiet=quiet)
    raise TypeError(f"not a command config: {type(cfg).__name__}")


def resolved(cfg):
    """``cfg`` with the options of every implementation it names (frontend, segmentation method,
    exploration strategy...) completed by their defaults, its plugins imported first."""
    load_plugins(getattr(cfg, "plugins", ()))
    return resolve_config(cfg)
