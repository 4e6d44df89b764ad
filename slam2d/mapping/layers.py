"""Mapping layers of a grid written to a results folder: the one place that names their files
(each layer registered in :data:`slam2d.mapping.base.MAP_LAYERS`).

``grid`` is ``map.pgm`` + ``map.yaml`` (written by the caller, always);
``sparse`` ``map_sparse.npz`` (the COO table); ``quadtree`` ``map.quadtree``
(occupied cells; + ``quadtree.png``, the first six levels) and
``map_trinary.quadtree`` (free / occupied / unknown, uniform children pruned); ``lines`` ``lines.bin`` (the
compact form) + ``lines.json`` + ``lines.svg`` (+ ``lines.png``); ``mesh`` ``walls.ply`` + ``walls.png``.
Sizes and counts go to ``layers.json``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from slam2d.config import MappingConfig
from slam2d.mapping.base import MAP_LAYERS, register_layer
from slam2d.mapping.grid import OccupancyGrid

__all__ = ["LAYERS", "LayerInputs", "write_layers"]

LAYERS = MAP_LAYERS
"""Layer names of ``mapping.layers`` (the registry: iterating gives the names)."""


@dataclass(eq=False)
class LayerInputs:
    """What the layers are made of: the grid, the mapping config (its thresholds), whether figures are drawn,
    the mesh's wall height (m; None: :data:`slam2d.mapping.mesh.WALL_HEIGHT`); the occupied cells and the
    line map are computed once, when a layer first asks for them."""

    grid: OccupancyGrid
    cfg: MappingConfig
    figures: bool = True
    wall_height: float | None = None

    @cached_property
    def occupied(self) -> np.ndarray:
        return self.grid.occupied_mask(self.cfg.occupied_thresh)

    @cached_property
    def lines(self):
        from slam2d.mapping.geometric import extract_line_map

        return extract_line_map(self.occupied, self.grid.resolution, self.grid.origin)


def write_layers(grid: OccupancyGrid, folder, cfg: MappingConfig, figures: bool = True,
                 wall_height: float | None = None) -> dict:
    """Write the layers ``cfg.layers`` (the grid's stats always) of ``grid`` (classified by ``cfg``'s thresholds)
    into ``folder``, in the registry's order; returns (and writes to ``layers.json``) their file sizes (``bytes``)
    and counts. ``wall_height`` m defaults to :data:`slam2d.mapping.mesh.WALL_HEIGHT`."""
    folder, chosen = Path(folder), {"grid", *cfg.layers}
    maps = LayerInputs(grid, cfg, figures, wall_height)
    stats = {name: MAP_LAYERS.create(name, None, maps, folder) for name in MAP_LAYERS.names() if name in chosen}
    (folder / "layers.json").write_text(json.dumps(stats, indent=2) + "\n")
    return stats


@register_layer("grid")
def grid_layer(maps: LayerInputs, folder: Path) -> dict:
    """The occupancy grid (map.pgm and map.yaml, written by the run itself): its shape and occupied share."""
    grid, occupied = maps.grid, maps.occupied
    return {"shape": list(grid.shape), "resolution": grid.resolution, "dense_uint8_bytes": int(grid.log_odds.size),
            "occupied_share": float(occupied.mean()) if occupied.size else 0.0}


@register_layer("sparse")
def sparse_layer(maps: LayerInputs, folder: Path) -> dict:
    """The grid's known cells as a COO table (map_sparse.npz)."""
    from slam2d.mapping.sparse import Triplets, sparsity

    grid, occupied_thresh = maps.grid, maps.cfg.occupied_thresh
    t = Triplets.from_grid(grid)
    np.savez_compressed(folder / "map_sparse.npz", rows=t.rows, cols=t.cols, values=t.values,
                        shape=np.array(t.shape), resolution=t.resolution, origin=np.array(t.origin))
    return {"file": "map_sparse.npz", "triplets": len(t), "bytes": (folder / "map_sparse.npz").stat().st_size,
            "table_bytes": t.nbytes, **sparsity(grid, occupied_thresh)}


@register_layer("quadtree")
def quadtree_layer(maps: LayerInputs, folder: Path) -> dict:
    """Quadtrees of the occupied cells (map.quadtree, quadtree.png) and of the three states (map_trinary.quadtree)."""
    from slam2d.mapping.quadtree import QuadTree, draw_tree

    grid = maps.grid
    tree = QuadTree.from_mask(maps.occupied, grid.resolution, grid.origin)
    size = tree.save(folder / "map.quadtree").stat().st_size
    if maps.figures:
        draw_tree(tree, folder / "quadtree.png")
    return {"file": "map.quadtree", "bytes": size, "nodes": tree.node_count, "depth": tree.depth,
            "node_share": tree.node_count / 4.0**tree.depth, "trinary_bytes": _trinary(grid, folder, maps.cfg)}


def _trinary(grid: OccupancyGrid, folder: Path, cfg: MappingConfig) -> int:
    from slam2d.mapping.quadtree import encode_trinary, trinary_values

    data = encode_trinary(trinary_values(grid, cfg.occupied_thresh, cfg.free_thresh))
    (folder / "map_trinary.quadtree").write_bytes(data)
    return len(data)


@register_layer("lines")
def lines_layer(maps: LayerInputs, folder: Path) -> dict:
    """The line map of the walls (lines.bin, lines.json, lines.svg, lines.png)."""
    lines, grid, figures = maps.lines, maps.grid, maps.figures
    size = lines.save(folder / "lines.bin").stat().st_size
    json_size = lines.save(folder / "lines.json").stat().st_size
    (folder / "lines.svg").write_text(lines.to_svg(grid.log_odds))
    if figures:
        lines.save_png(folder / "lines.png", grid.log_odds)
    return {"file": "lines.bin", "bytes": size, "grid_to_lines": grid.log_odds.size / size, "json_file": "lines.json",
            "json_bytes": json_size, "polylines": len(lines.polylines), "segments": len(lines.segments),
            "length_m": lines.length()}


@register_layer("mesh")
def mesh_layer(maps: LayerInputs, folder: Path) -> dict:
    """A 3D mesh of the walls of the line map (walls.ply, walls.png)."""
    from slam2d.mapping.mesh import WALL_HEIGHT, render_mesh, save_mesh, wall_mesh

    lines, grid, figures = maps.lines, maps.grid, maps.figures
    h = WALL_HEIGHT if maps.wall_height is None else maps.wall_height
    mesh = wall_mesh(lines.segments, h, floor_extent=grid.extent)
    save_mesh(mesh, folder / "walls.ply")
    if figures:
        render_mesh(mesh, folder / "walls.png")
    return {"file": "walls.ply", "wall_height_m": h, "vertices": len(mesh.vertices), "triangles": len(mesh.triangles)}
