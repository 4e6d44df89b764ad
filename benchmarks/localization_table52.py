"""The 2018 thesis's navigation accuracy test (Table 5-2) repeated in the simulator, on the MCL pose.

Usage: nice .venv/bin/python benchmarks/localization_table52.py [--trials 10] [--pose mcl truth]

The map frame's origin is a point of the office corridor, x along it: F = (5.5, 4.2, 0).
Each trial starts the robot at a random pose within 0.5 m and 30 deg of F; the filter
starts from F with the thesis's rough initial pose (amcl's initial covariance:
0.5 m, 15 deg). The robot is sent to (0, 0, 0), then to (1, 0, 0) (map frame), and
the true pose where it stops gives the X, Y and heading deviations. The same trials
run on the true pose for contrast. Navigator defaults (goal tolerance 3 cm, 2 deg).
"""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np

FRAME = np.array([5.5, 4.2, 0.0])
THESIS = [(-0.10, -0.06, 6.0), (0.04, -0.04, 12.4), (0.05, -0.02, 10.6), (-0.05, 0.02, 7.7), (-0.05, 0.05, 7.3),
          (0.06, -0.03, 12.3), (0.03, -0.04, 4.5), (0.06, 0.07, 7.9), (-0.07, 0.03, 6.3), (-0.06, 0.02, 5.6)]


def trial(seed: int, pose: str) -> tuple[float, float, float, bool]:
    """(X m, Y m, heading deg) deviation of the true stop from (1, 0, 0), and whether both legs succeeded."""
    from slam2d import geometry
    from slam2d.localization import KnownMap, MclPoseSource
    from slam2d.navigation import run_navigation, world_grid
    from slam2d.sim import Robot, World

    rng = np.random.default_rng(seed)
    world = World.office()
    start = geometry.compose(FRAME, [*rng.uniform(-0.5, 0.5, 2), rng.uniform(-0.5, 0.5)])
    robot = Robot(world, start, seed=seed)
    source = MclPoseSource(KnownMap.from_world(world), FRAME, seed=seed) if pose == "mcl" else None
    grid = world_grid(world)
    ok = True
    for goal in ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0]):
        result = run_navigation(world, robot, grid, geometry.compose(FRAME, goal), "dwa", pose_source=source)
        ok &= result.success
    d = geometry.between(geometry.compose(FRAME, [1.0, 0.0, 0.0]), robot.pose)
    return float(d[0]), float(d[1]), float(np.degrees(d[2])), ok


def summary(rows) -> dict:
    a = np.array([r[:3] for r in rows])
    e = np.hypot(a[:, 0], a[:, 1])
    return {"mean_pos": e.mean(), "max_pos": e.max(), "mean_abs_heading": np.abs(a[:, 2]).mean(),
            "max_abs_heading": np.abs(a[:, 2]).max()}  # fmt: skip


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=10)
    ap.add_argument("--pose", nargs="+", default=["mcl", "truth"])
    args = ap.parse_args(argv)
    runs = {p: [trial(seed, p) for seed in range(args.trials)] for p in args.pose}
    head = " | ".join(f"{p}: X (m) | {p}: Y (m) | {p}: heading (°)" for p in runs)
    print(f"| No. | thesis X (m) | thesis Y (m) | thesis heading (°) | {head} |")
    print("|---|" + "---|" * (3 + 3 * len(runs)))
    for i in range(args.trials):
        th = THESIS[i] if i < len(THESIS) else (math.nan,) * 3
        cells = " | ".join(f"{r[i][0]:+.3f} | {r[i][1]:+.3f} | {r[i][2]:+.2f}" + ("" if r[i][3] else " (failed)")
                           for r in runs.values())  # fmt: skip
        print(f"| {i + 1} | {th[0]:+.2f} | {th[1]:+.2f} | {th[2]:.1f} | {cells} |")
    print()
    print("| | mean position error (m) | max (m) | mean abs heading (°) | max (°) |")
    print("|---|---|---|---|---|")
    for name, rows in [("thesis", [(*t, True) for t in THESIS]), *runs.items()]:
        s = summary(rows)
        print(f"| {name} | {s['mean_pos']:.3f} | {s['max_pos']:.3f} | {s['mean_abs_heading']:.2f} | "
              f"{s['max_abs_heading']:.2f} |")  # fmt: skip


if __name__ == "__main__":
    main(sys.argv[1:])
