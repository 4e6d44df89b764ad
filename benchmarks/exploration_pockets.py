"""What an office exploration leaves unexplored, with the views of pockets off and on.

Usage: nice .venv/bin/python benchmarks/exploration_pockets.py [--strategy nearest_frontier] [--seed 0]
       [--out docs/img/explore_pockets.png]

Runs ``slam2d explore`` on the office twice (``exploration.pockets`` false, then true; same seed), and
for each final SLAM grid prints the unexplored part of the reachable area in two kinds: seen from
places where the navigator plans (the robot's centre farther than radius + inflation margin from
walls), and seen only from places nearer the walls than that (farther than the radius alone: the
disc less than the margin from a wall). Also the frontier cells left at the end, with and without the
rule that drops those within 2 cells of an obstacle. Draws both maps with these cells.
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy import ndimage


def unexplored(run, cfg, margin: float):
    """(missing within the navigator's reach, missing only within the disc's reach) (H, W) bool on the
    world's cells, the two coverages, and the frontier cell counts (with / without the wall rule)."""
    from slam2d.exploration.frontiers import frontier_mask
    from slam2d.exploration.gridops import GridView
    from slam2d.exploration.coverage import reachable_free, truth_map
    from slam2d.sim.robot import RobotConfig

    free, frame = truth_map(run.world)
    start, range_max = run.truth[0, :2], cfg.dataset.simulator.laser.range_max
    radius = RobotConfig().radius
    disc = reachable_free(free, frame, start, radius, range_max)
    nav = reachable_free(free, frame, start, radius + margin, range_max)
    grid, m = run.grid, cfg.mapping
    known = ndimage.binary_dilation(grid.free_mask(m.free_thresh) | grid.occupied_mask(m.occupied_thresh),
                                    np.ones((3, 3), bool))  # fmt: skip
    rows, cols = np.indices(free.shape)
    cells = grid.world_to_cell(frame.cell_to_world(np.column_stack([rows.ravel(), cols.ravel()])))
    ok = grid.in_bounds(cells)
    seen = np.zeros(len(cells), dtype=bool)
    seen[ok] = known[cells[ok, 0], cells[ok, 1]]
    seen = seen.reshape(free.shape)
    state = GridView.of(grid, m.free_thresh, m.occupied_thresh).state
    fronts = int(frontier_mask(state).sum()), int(frontier_mask(state, 0).sum())
    cover = (disc & seen).sum() / disc.sum(), (nav & seen).sum() / nav.sum()
    return nav & ~seen, disc & ~nav & ~seen, cover, fronts, frame, (disc.sum(), nav.sum())


def main() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from slam2d.exploration import config
    from slam2d.exploration.loop import explore, resolved
    from slam2d.navigation import NavigatorConfig

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--strategy", default="nearest_frontier")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="docs/img/explore_pockets.png")
    args = ap.parse_args()
    fig, axes = plt.subplots(1, 2, figsize=(15, 4.9))
    for ax, pockets in zip(axes, (False, True)):
        cfg = resolved(config.load(None, {"exploration.strategy": args.strategy, "seed": args.seed,
                                          "exploration.pockets": pockets, "exploration.animation": False}))  # fmt: skip
        run = explore(cfg)
        margin = cfg.exploration.options.get("inflation_margin", NavigatorConfig().inflation_margin)
        near, only_disc, (c_disc, c_nav), fronts, frame, areas = unexplored(run, cfg, margin)
        res2 = frame.resolution**2
        mt = run.metrics
        print(f"pockets {pockets}: {mt['stop_reason']}, {mt['distance']:.1f} m, {mt['collisions']} collisions, "
              f"{mt['pocket_goals']} pocket goals; reachable {areas[0] * res2:.2f} m² (disc) / "
              f"{areas[1] * res2:.2f} m² (navigator); coverage {100 * c_disc:.2f} % / {100 * c_nav:.2f} %; "
              f"unexplored {near.sum() * res2:.2f} m² seen from where the navigator drives, "
              f"{only_disc.sum() * res2:.2f} m² seen only nearer the walls; frontier cells left {fronts[0]} "
              f"({fronts[1]} without the wall rule)")  # fmt: skip
        grid = run.grid
        x0, x1, y0, y1 = grid.extent
        img = np.full(grid.shape + (3,), 0.8)
        img[grid.free_mask(cfg.mapping.free_thresh)] = 1.0
        img[grid.occupied_mask(cfg.mapping.occupied_thresh)] = 0.0
        ax.imshow(img, origin="lower", extent=(x0, x1, y0, y1), interpolation="nearest")
        for mask, colour, label in ((near, "red", "unexplored, seen from where the navigator drives"),
                                    (only_disc, "orange", "unexplored, seen only with < 5 cm beside the disc")):
            xy = frame.cell_to_world(np.column_stack(np.nonzero(mask)))
            ax.scatter(xy[:, 0], xy[:, 1], s=1.2, c=colour, marker="s", linewidths=0, label=label)
        ax.plot(*run.truth[:, :2].T, lw=0.5, c="tab:blue", label="path")
        ax.set_xlim(-0.3, 20.3)
        ax.set_ylim(-0.3, 12.3)
        ax.set_aspect("equal")
        ax.set_title(f"pockets {'on' if pockets else 'off'}: {args.strategy}, seed {args.seed}, stops at "
                     f"{100 * c_disc:.1f} % / {100 * c_nav:.1f} % (disc / navigator reach), {mt['distance']:.0f} m",
                     fontsize=9)  # fmt: skip
    axes[0].legend(loc="lower center", bbox_to_anchor=(1.05, -0.22), ncol=3, fontsize=8, markerscale=6)
    fig.savefig(args.out, dpi=100, bbox_inches="tight")
    print("wrote", args.out)


if __name__ == "__main__":
    main()
