"""The stop at the goal on the true pose: goals just round the corner of an L-shaped corridor.

Usage: .venv/bin/python benchmarks/goal_stop.py [--planners dwa teb]

The corridor runs along x (1.2 m wide) and turns up at its end (x 4.8-6 m); 12 goals round the corner
(x 5.25-5.55 m, y 0.9-1.5 m) are driven to from three starts (down the corridor, halfway along it, from
the far leg) on the world's map and the true pose, so that what is measured is the navigator's stop
alone: per planner the goal error (median, max), how far the robot went beyond the goal along its last
0.3 m (max; negative: it never passed it) and the total time of the 36 runs.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from slam2d.navigation import run_navigation, world_grid
from slam2d.sim import Robot, World

STARTS = ([0.6, 0.6, 0.0], [3.0, 0.4, 0.0], [5.4, 3.5, -1.57])
GOALS = [(x, y) for x in (5.25, 5.4, 5.55) for y in (0.9, 1.1, 1.3, 1.5)]


def beyond(trajectory: np.ndarray, goal: np.ndarray) -> float:
    """m the robot went past ``goal`` along the way it came in over its last 0.3 m (negative: short of it)."""
    d = np.hypot(*(trajectory[:, :2] - goal).T)
    i = int(np.argmax(d < 0.3))
    way = (goal - trajectory[i, :2]) / max(d[i], 1e-9)
    return float(((trajectory[i:, :2] - goal) @ way).max())


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--planners", nargs="+", default=["dwa", "teb"])
    args = ap.parse_args(argv)
    world = World.from_polygons([[(0, 0), (6, 0), (6, 5), (4.8, 5), (4.8, 1.2), (0, 1.2)]], name="L")
    grid = world_grid(world)
    print("| planner | runs | reached | goal error median / max (cm) | beyond the goal, max (cm) | total time (s) |")
    print("|---|---|---|---|---|---|")
    for planner in args.planners:
        runs = [run_navigation(world, Robot(world, start, seed=0), grid, np.array(goal), planner)
                for goal in GOALS for start in STARTS]  # fmt: skip
        err = 100 * np.array([r.goal_error for r in runs])
        past = 100 * max(beyond(r.trajectory, np.array(g)) for r, g in zip(runs, [g for g in GOALS for _ in STARTS]))
        print(f"| {planner} | {len(runs)} | {sum(r.success for r in runs)} | {np.median(err):.2f} / {err.max():.2f} "
              f"| {past:.1f} | {sum(r.time for r in runs):.1f} |", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
