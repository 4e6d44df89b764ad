"""Mapping layers of a grid written to a results folder: the one place that names their files.

``grid`` is ``map.pgm`` + ``map.yaml`` (written by the caller, always);
``sparse`` ``map_sparse.npz`` (the COO table); ``quadtree`` ``map.quadtree``
(occupied cells; + ``quadtree.png``, the first six levels) and
``map_trinary.quadtree`` (free / occupied / unknown, uniform children pruned); ``lines`` ``lines.bin`` (the
compact form) + ``lines.json`` + ``lines.svg`` (+ ``lines.png``); ``mesh`` ``walls.ply`` + ``walls.png``.
Sizes and counts go to ``layers.json``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import get_args

import numpy as np

from slam2d.config import MappingConfig
from slam2d.mapping.occupancy import OccupancyGrid

__all__ = ["LAYERS", "write_layers", "load_grid"]

LAYERS = get_args(get_args(MappingConfig.model_fields["layers"].annotation)[0])
"""Layer names of ``mapping.layers`` (declared by the config)."""


def load_grid(path, resolution: float = 0.05) -> OccupancyGrid:
    """A map_server YAML, or a floor-plan image at ``resolution`` m/px (origin its lower-left corner): pixels
    darker than 128 occupied, 250 and lighter free, the rest unknown."""
    from slam2d.mapping.export import LOADED_LOG_ODDS, load_map_server
    from slam2d.mapping.image import read_grey

    path = Path(path)
    if path.suffix.lower() in (".yaml", ".yml"):
        return load_map_server(path)
    grey = read_grey(path)[::-1]  # rows up in y
    lo = np.where(grey < 128, LOADED_LOG_ODDS, np.where(grey >= 250, -LOADED_LOG_ODDS, 0.0))
    return OccupancyGrid(lo.astype(np.float32), resolution, (0.0, 0.0))


def write_layers(grid: OccupancyGrid, folder, cfg: MappingConfig, figures: bool = True,
                 wall_height: float | None = None) -> dict:
    """Write the layers ``cfg.layers`` of ``grid`` (classified by ``cfg``'s thresholds) into ``folder``; returns
    (and writes to ``layers.json``) their file sizes (``bytes``) and counts. ``wall_height`` m defaults to
    :data:`slam2d.mapping.mesh.WALL_HEIGHT`."""
    folder, layers = Path(folder), cfg.layers
    occupied = grid.occupied_mask(cfg.occupied_thresh)
    stats: dict = {"grid": {"shape": list(grid.shape), "resolution": grid.resolution,
                            "dense_uint8_bytes": int(grid.log_odds.size),
                            "occupied_share": float(occupied.mean()) if occupied.size else 0.0}}
    if "sparse" in layers:
        stats["sparse"] = _sparse(grid, folder, cfg.occupied_thresh)
    if "quadtree" in layers:
        stats["quadtree"] = _quadtree(grid, occupied, folder, figures)
        stats["quadtree"]["trinary_bytes"] = _trinary(grid, folder, cfg)
    if "lines" in layers or "mesh" in layers:
        from slam2d.mapping.geometric import extract_line_map

        lines = extract_line_map(occupied, grid.resolution, grid.origin)
        if "lines" in layers:
            stats["lines"] = _lines(lines, grid, folder, figures)
        if "mesh" in layers:
            stats["mesh"] = _mesh(lines, grid, folder, figures, wall_height)
    (folder / "layers.json").write_text(json.dumps(stats, indent=2) + "\n")
    return stats


def _sparse(grid: OccupancyGrid, folder: Path, occupied_thresh: float) -> dict:
    from slam2d.mapping.sparse import Triplets, sparsity

    t = Triplets.from_grid(grid)
    np.savez_compressed(folder / "map_sparse.npz", rows=t.rows, cols=t.cols, values=t.values,
                        shape=np.array(t.shape), resolution=t.resolution, origin=np.array(t.origin))
    return {"file": "map_sparse.npz", "triplets": len(t), "bytes": (folder / "map_sparse.npz").stat().st_size,
            "table_bytes": t.nbytes, **sparsity(grid, occupied_thresh)}


def _quadtree(grid: OccupancyGrid, occupied: np.ndarray, folder: Path, figures: bool) -> dict:
    from slam2d.mapping.quadtree import QuadTree, draw_tree

    tree = QuadTree.from_mask(occupied, grid.resolution, grid.origin)
    size = tree.save(folder / "map.quadtree").stat().st_size
    if figures:
        draw_tree(tree, folder / "quadtree.png")
    return {"file": "map.quadtree", "bytes": size, "nodes": tree.node_count, "depth": tree.depth,
            "node_share": tree.node_count / 4.0**tree.depth}


def _trinary(grid: OccupancyGrid, folder: Path, cfg: MappingConfig) -> int:
    from slam2d.mapping.quadtree import encode_trinary, trinary_values

    data = encode_trinary(trinary_values(grid, cfg.occupied_thresh, cfg.free_thresh))
    (folder / "map_trinary.quadtree").write_bytes(data)
    return len(data)


def _lines(lines, grid: OccupancyGrid, folder: Path, figures: bool) -> dict:
    size = lines.save(folder / "lines.bin").stat().st_size
    json_size = lines.save(folder / "lines.json").stat().st_size
    (folder / "lines.svg").write_text(lines.to_svg(grid.log_odds))
    if figures:
        lines.save_png(folder / "lines.png", grid.log_odds)
    return {"file": "lines.bin", "bytes": size, "grid_to_lines": grid.log_odds.size / size, "json_file": "lines.json",
            "json_bytes": json_size, "polylines": len(lines.polylines), "segments": len(lines.segments),
            "length_m": lines.length()}


def _mesh(lines, grid: OccupancyGrid, folder: Path, figures: bool, wall_height: float | None) -> dict:
    from slam2d.mapping.mesh import WALL_HEIGHT, render_mesh, save_mesh, wall_mesh

    h = WALL_HEIGHT if wall_height is None else wall_height
    mesh = wall_mesh(lines.segments, h, floor_extent=grid.extent)
    save_mesh(mesh, folder / "walls.ply")
    if figures:
        render_mesh(mesh, folder / "walls.png")
    return {"file": "walls.ply", "wall_height_m": h, "vertices": len(mesh.vertices), "triangles": len(mesh.triangles)}
