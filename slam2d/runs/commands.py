"""The command registry: each command's config model and the function that runs a config of it
into a results folder."""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from pathlib import Path

from slam2d import config as config_mod
from slam2d.config import ExperimentConfig
from slam2d.errors import InputError
from slam2d.frontends.base import resolve_options
from slam2d.plugins import load_plugins


@dataclass(frozen=True)
class Command:
    """A command: its config model and runner (``"module:name"``, imported when used) and the metrics its
    tables show first (dotted keys of its metrics.json)."""

    model: str
    runner: str
    main_metrics: tuple[str, ...]

    def config_model(self) -> type:
        return _named(self.model)


COMMANDS = {
    "run": Command("slam2d.config:ExperimentConfig", "slam2d.runs.run:run_experiment", (
        "relations.trans_abs_mean", "relations.trans_abs_std", "relations.rot_abs_mean", "relations.rot_abs_std",
        "odometry_relations.trans_abs_mean", "ate.rmse", "odometry_ate.rmse", "rpe.trans_rmse", "rpe.rot_rmse_deg",
        "cpu_ms_per_scan", "slam.loop closures kept", "slam.loop closures rejected", "frontend_fallbacks", "scans",
        "runtime_s", "peak_rss_mb")),
    "segment": Command("slam2d.segmentation.config:SegmentConfig", "slam2d.runs.segment:run_segment", (
        "recall", "precision", "rooms_found", "rooms_gt", "rooms", "k", "seconds", "cpu_seconds")),
    "plan": Command("slam2d.planning.config:PlanConfig", "slam2d.runs.plan:run_plan", (
        "found", "length_m", "duration_s", "plan_ms", "nodes_expanded", "queries", "failures", "mean_subopt_pct",
        "max_subopt_pct", "median_speedup", "segmentation_s")),
    "navigate": Command("slam2d.runs.navigate:NavigateConfig", "slam2d.runs.navigate:run_navigate", (
        "success", "status", "time", "path_length", "length_ratio", "goal_error", "heading_error", "collisions",
        "min_clearance", "pose_rmse", "planner_hz", "wall_s")),
    "explore": Command("slam2d.exploration.config:ExploreConfig", "slam2d.runs.explore:run_explore", (
        "coverage", "distance_to_99", "time_to_99", "distance_to_90", "map_iou", "ate_rmse", "collisions",
        "min_clearance", "path_repetition", "decision_ms_median", "stop_reason", "wall_s")),
    "localize": Command("slam2d.localization.config:LocalizeConfig", "slam2d.runs.localize:run_localize", (
        "position_rmse", "heading_rmse_deg", "converged_s", "false_convergence", "position_rmse_converged",
        "particles_median", "update_ms_median")),
    "map": Command("slam2d.runs.map:MapConfig", "slam2d.runs.map:run_map", (
        "grid.dense_uint8_bytes", "sparse.bytes", "quadtree.bytes", "quadtree.trinary_bytes", "lines.bytes",
        "mesh.bytes")),
    "optimize": Command("slam2d.runs.optimize:OptimizeConfig", "slam2d.runs.optimize:run_optimize", (
        "gtsam_error", "iterations", "seconds", "verified", "certified", "loops_rejected", "precision", "recall",
        "rmse_to_reference")),
}
"""Every command that writes a results folder, by name; ``slam2d ablate`` sweeps any of them."""


def _named(target: str):
    module, name = target.split(":")
    return getattr(importlib.import_module(module), name)


def command_of(command: str, key: str = "command") -> Command:
    """The :class:`Command` named ``command``; InputError naming ``key`` otherwise."""
    if command not in COMMANDS:
        raise InputError(key, f"unknown command {config_mod.short_repr(command)} ({', '.join(COMMANDS)})")
    return COMMANDS[command]


def command_model(command: str, key: str = "command"):
    """The config model of ``command`` (a key of :data:`COMMANDS`); InputError naming ``key`` otherwise."""
    return command_of(command, key).config_model()


def run_command(cfg, quiet: bool = False) -> Path:
    """Run the config of any command of :data:`COMMANDS` into its results folder; return the folder."""
    for command in COMMANDS.values():
        if type(cfg) is command.config_model():
            runner = _named(command.runner)
            return runner(cfg, quiet=quiet) if command is COMMANDS["run"] else runner(cfg)
    raise TypeError(f"not a command config: {type(cfg).__name__}")


def resolved(cfg):
    """``cfg`` with the frontend's options completed by its defaults (its plugins imported first);
    the config of another command as it is."""
    if not isinstance(cfg, ExperimentConfig):
        return cfg
    load_plugins(cfg.plugins)
    params = resolve_options(cfg.frontend.name, cfg.frontend.options)
    if params is None:
        return cfg
    return cfg.model_copy(update={"frontend": cfg.frontend.model_copy(update={"options": params.model_dump()})})
