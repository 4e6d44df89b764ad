"""slam2d.mapping: the occupancy grid, its one loader, and the layers made of it (the registry in
``mapping.base``)."""

from __future__ import annotations

from slam2d.mapping.base import MAP_LAYERS, MapLayer, register_layer  # noqa: F401
from slam2d.registry import lazy_exports

_EXPORTS = {
    "OccupancyGrid": "grid",
    "load_map": "maps",
    "build_grid": "occupancy",
    "save_map_server": "export",
    "load_map_server": "export",
    "save_map_png": "export",
    "extract_line_map": "geometric",
    "LineMap": "line_map",
    "QuadTree": "quadtree",
    "region_graph": "topological",
    "write_layers": "layers",
}
"""Public names imported on first use (so that importing the package stays light): name -> module."""

__all__ = sorted([*_EXPORTS, "MAP_LAYERS", "MapLayer", "register_layer"])

__getattr__ = lazy_exports(__name__, _EXPORTS)
