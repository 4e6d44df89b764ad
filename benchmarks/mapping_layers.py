"""Mapping layers on real maps: storage, quadtree query speed, line-map size and fit.

For each map (the ten floor plans of the rooms benchmark, 0.05 m/px, dark
pixels < 128 occupied, white >= 250 free; plus any map.yaml given) the
occupied cells are stored four ways, each lossless (checked): dense uint8
(1 B a cell), COO triplets (row, col int32 + float32 value), a hash table
(CPython dict) and the quadtree's breadth-first stream; the whole trinary map
(free / occupied / unknown) as a region quadtree with uniform children pruned. Also: the non-zero
share of the full log-odds grid (the thesis's < 5 % rule), the quadtree's
build time and node share of its 4^depth lattice, batched occupancy lookups of
10^6 uniform random points in the map's extent by the quadtree vs dense numpy
indexing (median of 5, the two alternated; same answers checked), the line map's
compact binary size (``LineMap.to_bytes``, round trip checked bit for bit) and
JSON size vs the dense grid and its symmetric Chamfer distance to the wall
cells (boundary cells of the occupied mask). A second table has the wall mesh of each line map, walls as boxes one
cell thick (no floor): open3d's ``is_watertight`` of each box and of the whole
mesh, vertex and triangle counts, and the Hausdorff distance (m) between the
walls' outline at z = 0 and the line map (both sampled every 5 mm; the larger
of the two directed distances, half a cell when the boxes sit on the lines),
also for the thesis's quads (thickness 0). A third table scores both line
extractors on the simulator office (true walls known).

    nice .venv/bin/python benchmarks/mapping_layers.py [MAP.yaml ...] [--points 1000000] [--repeat 5] [--mesh-only]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from slam2d.mapping.export import LOADED_LOG_ODDS
from slam2d.mapping.geometric import extract_line_map
from slam2d.mapping.grid import OccupancyGrid
from slam2d.mapping.line_map import LineMap
from slam2d.mapping.line_scores import chamfer, line_scores
from slam2d.mapping.maps import load_map
from slam2d.mapping.mesh import footprint_hausdorff, solids_watertight, wall_mesh
from slam2d.mapping.quadtree import QuadTree, decode_trinary, encode_trinary, trinary_values
from slam2d.mapping.sparse import HashedGrid, Triplets, sparsity

ROOMS = Path("/work/shared/datasets/rooms")
THESIS = "thesis (600 x 600 / depth 10)"


def timed(fn, repeat: int) -> tuple[float, object]:
    """Median wall time (s) of ``repeat`` calls and the last result."""
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), out


def interleaved(a, b, repeat: int):
    """((median s, result) of ``a``, (median s, result) of ``b``), the two called alternately (fair under load)."""
    runs = [(timed(a, 1), timed(b, 1)) for _ in range(repeat)]
    return [(statistics.median(r[k][0] for r in runs), runs[-1][k][1]) for k in (0, 1)]


def dense_lookup(mask: np.ndarray, grid: OccupancyGrid, xy: np.ndarray) -> np.ndarray:
    """Occupancy of points (M, 2) m by numpy indexing of the dense mask (outside: False)."""
    col = np.floor((xy[:, 0] - grid.origin[0]) / grid.resolution).astype(np.int64)
    row = np.floor((xy[:, 1] - grid.origin[1]) / grid.resolution).astype(np.int64)
    ok = (row >= 0) & (row < mask.shape[0]) & (col >= 0) & (col < mask.shape[1])
    return mask[np.where(ok, row, 0), np.where(ok, col, 0)] & ok


def measure(name: str, grid: OccupancyGrid, n_points: int, repeat: int, rng) -> dict:
    mask = grid.occupied_mask()
    occ = OccupancyGrid(np.where(mask, np.float32(LOADED_LOG_ODDS), np.float32(0)), grid.resolution, grid.origin)
    coo, hashed = Triplets.from_grid(occ), HashedGrid.from_grid(occ)
    for form in (coo, hashed):
        assert np.array_equal(form.to_grid().log_odds, occ.log_odds)
    build_s, tree = timed(lambda: QuadTree.from_mask(mask, grid.resolution, grid.origin), 3)
    stream = tree.to_bytes()
    assert np.array_equal(QuadTree.from_bytes(stream).to_mask(), mask)
    classes = trinary_values(grid)
    trinary = encode_trinary(classes)
    assert np.array_equal(decode_trinary(trinary), classes)
    x0, x1, y0, y1 = grid.extent
    xy = rng.uniform([x0, y0], [x1, y1], (n_points, 2))
    tree.occupied(xy[:10])  # compiled before timing
    (qt_s, qt), (np_s, dense) = interleaved(lambda: tree.occupied(xy), lambda: dense_lookup(mask, grid, xy), repeat)
    assert np.array_equal(qt, dense)
    line_s, lines = timed(lambda: extract_line_map(mask, grid.resolution, grid.origin), 1)
    packed = lines.to_bytes()
    assert all(np.array_equal(a, b) for a, b in zip(LineMap.from_bytes(packed).polylines, lines.polylines, strict=True))
    return dict(map=name, shape=f"{grid.shape[0]} x {grid.shape[1]}", occupied=100 * mask.mean(),
                nonzero=100 * sparsity(grid)["nonzero_share"], dense=mask.size, coo=coo.nbytes, hashed=hashed.nbytes,
                quadtree=len(stream), qt_share=100 * len(stream) / mask.size, trinary=100 * len(trinary) / mask.size,
                nodes=100 * tree.node_count / 4.0**tree.depth,
                depth=tree.depth, build_ms=1e3 * build_s, ratio=qt_s / np_s, qt_ms=1e3 * qt_s, np_ms=1e3 * np_s,
                lines=len(packed), line_ratio=mask.size / len(packed), lines_json=len(lines.to_json()), line_s=line_s,
                polylines=len(lines.polylines), chamfer=chamfer(lines.segments, mask, grid.resolution, grid.origin),
                mesh=mesh_measure(name, lines))


def mesh_measure(name: str, lines: LineMap) -> dict:
    """The wall mesh of a line map, walls one cell thick: watertight boxes, size, footprint Hausdorff (m)."""
    t0 = time.perf_counter()
    mesh = wall_mesh(lines.segments, thickness=lines.resolution)
    good, solids = solids_watertight(mesh)
    whole = mesh.is_watertight()
    h, ab, ba = footprint_hausdorff(mesh, lines)
    quads = footprint_hausdorff(wall_mesh(lines.segments), lines)[0]
    return dict(map=name, segments=len(lines.segments), watertight=f"{good} / {solids}", whole="yes" if whole else "no",
                v=len(mesh.vertices), t=len(mesh.triangles), hausdorff=f"{h:.4f} ({ab:.4f} / {ba:.4f})",
                quads=f"{quads:.4f}", s=time.perf_counter() - t0)


def mesh_table(rows: list[dict]) -> list[str]:
    """Markdown rows of the wall-mesh measurements."""
    head = ("| map | segments | boxes watertight | whole mesh watertight | vertices | triangles | "
            "Hausdorff m (outline -> lines / lines -> outline) | quads: Hausdorff m | s |")
    out = [head, "|" + "---|" * 9]
    keys = ("map", "segments", "watertight", "whole", "v", "t", "hausdorff", "quads")
    return out + ["| " + " | ".join(str(r[k]) for k in keys) + f" | {r['s']:.1f} |" for r in rows]


def office_scores() -> list[str]:
    """Line extractors on the simulator office rasterised at 0.05 m against its true walls."""
    from slam2d.sim.world import World

    world, res, origin = World.office(), 0.05, (-1.0, -1.0)
    w, h = int(round(22 / res)), int(round(14 / res))
    x, y = np.meshgrid(origin[0] + (np.arange(w) + 0.5) * res, origin[1] + (np.arange(h) + 0.5) * res)
    occ = world.occupied(np.column_stack([x.ravel(), y.ravel()])).reshape(h, w)
    rows = ["| extractor | precision | recall | segments | polylines | binary B | JSON B |", "|" + "---|" * 7]
    for method in ("contour", "hough"):
        lines = extract_line_map(occ, res, origin, method=method)
        s = line_scores(lines.segments, world.segments, tol=0.05, angle_tol_deg=1.0, occupied=world.occupied)
        rows.append(f"| {method} | {s['precision']:.3f} | {s['recall']:.3f} | {len(lines.segments)} | "
                    f"{len(lines.polylines)} | {len(lines.to_bytes())} | {len(lines.to_json())} |")
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("maps", nargs="*", type=Path, help="extra map.yaml files (e.g. Intel, ACES, FR079 runs)")
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--mesh-only", action="store_true", help="only the wall-mesh table")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    paths = [p for p in sorted(ROOMS.glob("*.png")) if not p.stem.endswith(("_furnitures", "_gt_segmentation"))]
    names = [p.stem for p in paths] + [f"{p.parent.name}/{p.name}" for p in args.maps]
    grids = [load_map(p) for p in paths + list(args.maps)]
    if args.mesh_only:
        masks = [g.occupied_mask() for g in grids]
        lines = [extract_line_map(m, g.resolution, g.origin) for m, g in zip(masks, grids, strict=True)]
        print("\n".join(mesh_table([mesh_measure(n, ln) for n, ln in zip(names, lines, strict=True)])))
        return
    rows = [measure(n, g, args.points, args.repeat, rng) for n, g in zip(names, grids, strict=True)]
    columns = ["map", "cells", "occupied %", "non-zero %", "dense B", "COO B", "hash B", "quadtree B",
               "quadtree / dense %", "trinary quadtree / dense %", "nodes / 4^d %", "depth", "build ms",
               "lookup 10^6 ms (quadtree / numpy)", "ratio", "lines B", "grid / lines", "lines JSON B", "polylines",
               "Chamfer m", "lines s"]
    print("| " + " | ".join(columns) + " |")
    print("|" + "---|" * len(columns))
    for r in rows:
        cells = [r["map"], r["shape"], f"{r['occupied']:.2f}", f"{r['nonzero']:.1f}", r["dense"], r["coo"], r["hashed"],
                 r["quadtree"], f"{r['qt_share']:.2f}", f"{r['trinary']:.2f}", f"{r['nodes']:.3f}", r["depth"],
                 f"{r['build_ms']:.1f}", f"{r['qt_ms']:.1f} / {r['np_ms']:.1f}", f"{r['ratio']:.2f}", r["lines"],
                 f"{r['line_ratio']:.0f}", r["lines_json"], r["polylines"], f"{r['chamfer']:.3f}",
                 f"{r['line_s']:.2f}"]
        print("| " + " | ".join(map(str, cells)) + " |")
    thesis = [THESIS, "600 x 600", "0.735", "-", "360000"] + ["-"] * 5 + ["0.26", "10"] + ["-"] * 9
    print("| " + " | ".join(thesis) + " |")
    print()
    print("\n".join(mesh_table([r["mesh"] for r in rows])))
    print()
    print("\n".join(office_scores()))


if __name__ == "__main__":
    main()
