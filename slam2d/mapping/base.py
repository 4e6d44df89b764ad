"""What a map layer is (the Protocol) and the layers by name (``mapping.layers``)."""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

from slam2d.registry import Registry


class MapLayer(Protocol):
    """Writes one layer of a grid map (its own files) into a results folder."""

    def __call__(self, maps, folder: Path) -> dict:
        """Write the layer of ``maps`` (a :class:`slam2d.mapping.layers.LayerInputs`: the grid, the mapping
        config, its occupied cells and line map) into ``folder``; return its stats (file sizes and counts)."""
        ...


MAP_LAYERS = Registry("map_layers", "layer", key="mapping.layers", builtins=dict.fromkeys(
    ("grid", "sparse", "quadtree", "lines", "mesh"), "slam2d.mapping.layers"))
"""The map layers by name: ``create(name, None, maps, folder)`` writes one."""


def register_layer(name: str, **kw):
    """Decorator of a :class:`MapLayer` function: ``mapping.layers: [..., name]``."""
    return MAP_LAYERS.register(name, **kw)
