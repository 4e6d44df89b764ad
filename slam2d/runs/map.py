"""``slam2d map``: mapping layers (sparse, quadtree, line map, wall mesh) of an existing map, written as a
results folder: ``config.yaml``, the layers' files (:func:`slam2d.mapping.layers.write_layers`) and
``metrics.json`` (their sizes and counts, as ``layers.json``)."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field, field_validator

from slam2d import config as config_mod
from slam2d.config import CommandConfig, MappingConfig
from slam2d.errors import InputError
from slam2d.mapping.layers import LAYERS, write_layers
from slam2d.mapping.maps import load_map
from slam2d.paths import resolve_data_path
from slam2d.runs.results import json_text, results_folder

__all__ = ["MapConfig", "run_map"]

class MapConfig(CommandConfig):
    """``slam2d map``: the map (map.yaml or a floor-plan image) and the layers to make of it."""

    layers: list[str] = Field(["sparse", "quadtree", "lines", "mesh"], description=f"any of {', '.join(LAYERS)}")
    wall_height: float | None = Field(None, gt=0, description="wall height of the mesh, m (default 2.5)")

    @field_validator("layers")
    @classmethod
    def _known(cls, layers: list[str]) -> list[str]:
        unknown = [n for n in layers if n not in LAYERS]
        if unknown or not layers:
            raise ValueError(f"unknown layer '{unknown[0] if unknown else ''}' (one of {', '.join(LAYERS)})")
        return layers


def run_map(cfg: MapConfig, quiet: bool = False) -> Path:
    """Make ``cfg.layers`` of ``cfg.map`` into a new results folder under ``cfg.output.root``; return it."""
    if cfg.map is None:
        raise InputError("map", "no map given (map: FILE in the config, or slam2d map MAP)")
    map_path = resolve_data_path(cfg.map, key="map")
    grid = load_map(map_path, cfg.resolution)
    with results_folder(cfg.output.root, cfg.name or f"map-{map_path.stem}") as (work, published):
        (work / "config.yaml").write_text(config_mod.dump(cfg))
        stats = write_layers(grid, work, MappingConfig(layers=cfg.layers), cfg.output.figures, cfg.wall_height)
        (work / "metrics.json").write_text(json_text(stats) + "\n")
    return published[0]
