"""Two exploration runs of the same world side by side: coverage against distance, and a run's final map
with its frontier cells, those the depth rule keeps and those in which it finds no opening.

Usage: .venv/bin/python benchmarks/exploration_faces.py BEFORE_RUN AFTER_RUN [--map RUN]
       [--out docs/img/explore_faces.png]

BEFORE_RUN and AFTER_RUN are results folders of ``slam2d explore`` (``coverage.csv``, ``map.yaml``,
``metrics.json``, ``ground_truth.tum``), e.g. the same world and seed on the code before the rule (a
worktree of an older commit) and on the current code. The frontier cells are those of ``frontier_mask``
on the map of ``--map`` (default BEFORE_RUN; e.g. the run before, stopped when it reached 99 %): with ``depth`` 0 (every free cell with an unknown 4-neighbour and no occupied cell
within 2 cells) and with the robot's width (the explorer's).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def main() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from slam2d.config import MappingConfig
    from slam2d.exploration.frontiers import depth_cells, frontier_mask
    from slam2d.exploration.gridops import GridView
    from slam2d.mapping.export import load_map_server
    from slam2d.sim.robot import ROBOT_RADIUS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before", type=Path)
    ap.add_argument("after", type=Path)
    ap.add_argument("--map", type=Path, help="the results folder whose map is drawn (default: BEFORE_RUN)")
    ap.add_argument("--out", default="docs/img/explore_faces.png")
    args = ap.parse_args()
    runs = [(folder, json.loads((folder / "metrics.json").read_text())) for folder in (args.before, args.after)]
    fig, (ax_map, ax_cov) = plt.subplots(1, 2, figsize=(15, 4.6), gridspec_kw={"width_ratios": [2.2, 1]})

    shown = args.map or args.before
    grid = load_map_server(shown / "map.yaml")
    m = MappingConfig()
    view = GridView.of(grid, m.free_thresh, m.occupied_thresh)
    plain = frontier_mask(view.state)
    deep = frontier_mask(view.state, depth=depth_cells(2 * ROBOT_RADIUS, view.resolution))
    x0, x1, y0, y1 = grid.extent
    img = np.full(view.shape + (3,), 0.8)
    img[view.state == 0] = 1.0
    img[view.state == 1] = 0.0
    ax_map.imshow(img, origin="lower", extent=(x0, x1, y0, y1), interpolation="nearest")
    path = np.loadtxt(shown / "ground_truth.tum")
    ax_map.plot(path[:, 1], path[:, 2], lw=0.3, c="tab:blue", alpha=0.6, label="path")
    for mask, colour, label in ((plain & ~deep, "red", "frontier cells with no opening (dropped)"),
                                (deep, "lime", "frontier cells kept")):  # fmt: skip
        xy = view.to_world(np.argwhere(mask))
        ax_map.scatter(xy[:, 0], xy[:, 1], s=2, c=colour, marker="s", linewidths=0, label=f"{label}: {len(xy)}")
    ax_map.set_aspect("equal")
    ax_map.legend(loc="upper right", fontsize=7, markerscale=4)
    shown_m = json.loads((shown / "metrics.json").read_text())
    ax_map.set_title(f"{shown_m['world']} · {shown_m['strategy']}, seed {shown_m['seed']}: the map after "
                     f"{shown_m['distance']:.0f} m ({100 * shown_m['coverage']:.2f} %)", fontsize=9)  # fmt: skip

    for (folder, metrics), name in zip(runs, ("before", "after")):
        curve = np.loadtxt(folder / "coverage.csv", delimiter=",", skiprows=1)
        ax_cov.plot(curve[:, 1], 100 * curve[:, 2], label=f"{name}: {metrics['stop_reason']} at "
                    f"{metrics['distance']:.0f} m, 99 % at {metrics['distance_to_99']:.0f} m")  # fmt: skip
    ax_cov.axhline(99, c="grey", lw=0.6, ls="--")
    ax_cov.set_xlabel("distance driven (m)")
    ax_cov.set_ylabel("coverage (%)")
    ax_cov.set_ylim(80, 100.5)
    ax_cov.legend(fontsize=8, loc="lower right")
    ax_cov.set_title("coverage against distance", fontsize=9)
    fig.savefig(args.out, dpi=110, bbox_inches="tight")
    print(f"wrote {args.out}: {int(plain.sum())} frontier cells, {int(deep.sum())} with an opening")


if __name__ == "__main__":
    main()
