"""Map export of a large grid: map_server PGM + YAML and the PNG figure.

Builds a synthetic 60 M-cell grid (6000 rows x 10000 columns at 0.05 m, rooms
of free space behind 2-cell walls with doors, unknown outside) and times
``save_map_server`` + ``save_map_png`` (wall clock, median of ``--repeat``
runs), then measures the peak memory allocated while writing (tracemalloc,
numpy's allocations included; the grid itself excluded). Prints a Markdown line.

    nice .venv/bin/python benchmarks/map_export.py [--rows 6000] [--cols 10000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

from slam2d.config import MappingConfig
from slam2d.mapping.export import save_map_png, save_map_server
from slam2d.mapping.grid import OccupancyGrid


def synthetic_grid(rows: int, cols: int, room: int = 200, seed: int = 0) -> OccupancyGrid:
    """Rooms of ``room`` cells with 2-cell walls and doors, a 5 % unknown border; log-odds float32."""
    rng = np.random.default_rng(seed)
    lo = np.zeros((rows, cols), np.float32)
    b = rows // 20
    lo[b:-b, b:-b] = rng.uniform(-4.0, -1.5, (rows - 2 * b, cols - 2 * b)).astype(np.float32)
    for k in range(b, rows - b, room):
        lo[k : k + 2, b:-b] = 3.5
    for k in range(b, cols - b, room):
        lo[b:-b, k : k + 2] = 3.5
    for k in range(b + room // 2, rows - b, room):  # doors in the vertical walls
        lo[k : k + 16, b + 2 : -b : room] = -3.0
    return OccupancyGrid(lo, 0.05, (-10.0, -20.0))


def write(grid: OccupancyGrid, out: Path, cfg: MappingConfig) -> None:
    """What a run writes: the map_server map and the figure with one trajectory."""
    traj = np.column_stack([np.linspace(0.0, 400.0, 5000), np.linspace(0.0, 200.0, 5000), np.zeros(5000)])
    save_map_server(grid, out / "map", cfg)
    save_map_png(grid, out / "map.png", {"estimate": traj}, title="synthetic")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=6000)
    ap.add_argument("--cols", type=int, default=10000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    grid, cfg = synthetic_grid(args.rows, args.cols), MappingConfig()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        times = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            write(grid, out, cfg)
            times.append(time.perf_counter() - t0)
        tracemalloc.start()
        write(grid, out, cfg)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        pgm_mb = (out / "map.pgm").stat().st_size / 1e6
    cells = args.rows * args.cols / 1e6
    print(f"| {args.rows} x {args.cols} ({cells:.0f} M cells) | {statistics.median(times):.2f} s "
          f"(median of {args.repeat}) | {peak / 1e6:.0f} MB peak | PGM {pgm_mb:.0f} MB |")  # fmt: skip


if __name__ == "__main__":
    main()
