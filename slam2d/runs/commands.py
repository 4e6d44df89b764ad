"""The command registry: each command's config model and the function that runs a config of it
into a results folder."""

from __future__ import annotations

import importlib
from pathlib import Path

from slam2d import config as config_mod
from slam2d.config import ExperimentConfig
from slam2d.errors import InputError
from slam2d.frontends.base import resolve_options
from slam2d.plugins import load_plugins


COMMANDS = {
    "run": ("slam2d.config:ExperimentConfig", "slam2d.runs.run:run_experiment"),
    "segment": ("slam2d.segmentation.config:SegmentConfig", "slam2d.runs.segment:run_segment"),
    "plan": ("slam2d.planning.config:PlanConfig", "slam2d.runs.plan:run_plan"),
    "navigate": ("slam2d.runs.navigate:NavigateConfig", "slam2d.runs.navigate:run_navigate"),
    "explore": ("slam2d.exploration.config:ExploreConfig", "slam2d.runs.explore:run_explore"),
    "localize": ("slam2d.localization.config:LocalizeConfig", "slam2d.runs.localize:run_localize"),
    "map": ("slam2d.runs.map:MapConfig", "slam2d.runs.map:run_map"),
    "optimize": ("slam2d.runs.optimize:OptimizeConfig", "slam2d.runs.optimize:run_optimize"),
}
"""Commands whose configs ``slam2d ablate`` sweeps: (config model, runner taking the config)."""


def _named(target: str):
    module, name = target.split(":")
    return getattr(importlib.import_module(module), name)


def command_model(command: str, key: str = "command"):
    """The config model of ``command`` (a key of :data:`COMMANDS`); InputError naming ``key`` otherwise."""
    if command not in COMMANDS:
        raise InputError(key, f"unknown command {config_mod.short_repr(command)} ({', '.join(COMMANDS)})")
    return _named(COMMANDS[command][0])


def run_command(cfg, quiet: bool = False) -> Path:
    """Run the config of any command of :data:`COMMANDS` into its results folder; return the folder."""
    if type(cfg) is ExperimentConfig:
        return _named(COMMANDS["run"][1])(cfg, quiet=quiet)
    for model, runner in COMMANDS.values():
        if type(cfg) is _named(model):
            return _named(runner)(cfg)
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
