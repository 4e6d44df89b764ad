"""The ICP frontend's heading drift and the order a scan's points go into its local map.

Usage: .venv/bin/python benchmarks/icp_beam_order.py [--worlds PNG ...] [--pairs 3] [--seed 1000] [--planner dwa]

Drives the navigation benchmark's pairs (SLAM in the loop, no people, ``benchmarks/navigation.py``'s
start / goal draw), records every scan, then replays the ICP frontend alone over the recorded scans
and odometry: as recorded, mirrored (y -> -y), with each scan's beams in reverse order, with a local
map that keeps every point (``map_max_points_per_voxel`` 1000) and with ``map_order: random``. Per
variant: the heading drift a registered scan (mdeg) and the position error at the end (cm), per run
and median. Then a wall 1 m ahead seen through bearings 10-60 deg (1 cm range noise): where the map's
kept points sit across it, in beam order, reversed and random order.
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import navigation as bench  # the benchmark's pairs

from slam2d import config, geometry
from slam2d.frontends import create_frontend
from slam2d.frontends.icp import STILL_EVENT
from slam2d.frontends.icp.mapping import LocalMap
from slam2d.runs import navigate

MIRROR = np.diag([1.0, -1.0, -1.0])  # (x, y, theta) -> (x, -y, -theta)
VARIANTS = {
    "as recorded": ({}, None),
    "mirrored": ({}, "mirror"),
    "beams reversed": ({}, "reverse"),
    "every point kept": ({"map_max_points_per_voxel": 1000}, None),
    "map_order random": ({"map_order": "random"}, None),
}


def record(spec: str, start, goal, seed: int, planner: str) -> list:
    """(scan, odometry pose, true pose) of every step of one closed-loop run."""
    steps = []
    wrap = navigate._Recorder.wrap

    def recording(self, online, fixed=None):
        inner = wrap(self, online, fixed)
        return lambda step: (steps.append((step.scan, step.odom.copy(), step.pose.copy())), inner(step))[1]

    navigate._Recorder.wrap = recording
    try:
        navigate.simulate(config.load(None, {
            "seed": seed, "dataset.simulator.world": spec, "navigation.start": list(start),
            "navigation.goal": list(goal), "navigation.planner": planner, "navigation.people": 0,
        }))  # fmt: skip
    finally:
        navigate._Recorder.wrap = wrap
    return steps


def replay(steps, options: dict, change: str | None) -> tuple[float, float]:
    """(heading drift a registered scan in mdeg, end position error in m) of the frontend alone."""
    fe = create_frontend("icp", options)
    registered, previous = 0, None
    for scan, odom, truth in steps:
        if change == "mirror":
            scan = replace(scan, ranges=scan.ranges[::-1].copy(), angles=-scan.angles[::-1])
            odom, truth = odom @ MIRROR, truth @ MIRROR
        elif change == "reverse":
            scan = replace(scan, ranges=scan.ranges[::-1].copy(), angles=scan.angles[::-1].copy())
        still = fe.events[STILL_EVENT]
        fe.process(scan, np.zeros(3) if previous is None else geometry.between(previous, odom))
        registered += fe.events[STILL_EVENT] == still
        previous = odom
    first = steps[0][2] @ MIRROR if change == "mirror" else steps[0][2]
    end = geometry.compose(first, fe.pose)
    error = geometry.between(truth, end)
    return float(np.degrees(error[2]) * 1e3 / registered), float(np.hypot(error[0], error[1]))


def wall_offsets(trials: int = 2000, seed: int = 0) -> dict[str, float]:
    """Mean distance (mm) behind a wall x = 1 m of the points a map keeps of it (bearings 10-60 deg,
    receding with the bearing, beams 1 deg apart, 1 cm range noise), per insertion order."""
    rng = np.random.default_rng(seed)
    bearings = np.deg2rad(np.arange(10.0, 60.0, 1.0))
    out = {}
    for order in ("beam", "reversed", "random"):
        offsets = []
        for _ in range(trials):
            r = 1.0 / np.cos(bearings) + rng.normal(0.0, 0.01, len(bearings))
            points = np.column_stack([r * np.cos(bearings), r * np.sin(bearings)])
            local_map = LocalMap(0.2, 30.0, 20, 30, "random" if order == "random" else "beam")
            local_map.add(np.zeros(3), points[::-1] if order == "reversed" else points)
            offsets.append(local_map.voxels.point_cloud()[:, 0].mean() - 1.0)
        out[order] = 1e3 * float(np.mean(offsets))
    return out


def main(argv: list[str]) -> None:
    data = Path(os.environ.get("SLAM2D_DATA", "../shared/datasets")) / "rooms"
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worlds", nargs="+", default=[str(data / "lab_d_scan_furnitures.png"),
                                                    str(data / "office_a_furnitures.png")])  # fmt: skip
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--planner", default="dwa")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    runs = {}
    for spec in args.worlds:
        for k, (start, goal) in enumerate(bench.pairs(spec, args.pairs, rng)):
            runs[f"{Path(spec).stem} seed {args.seed + k}"] = record(spec, start, goal, args.seed + k, args.planner)
    print("| replay | " + " | ".join(runs) + " | median drift (mdeg a scan) | median end error (cm) |")
    print("|---" * (len(runs) + 3) + "|")
    for name, (options, change) in VARIANTS.items():
        results = [replay(steps, options, change) for steps in runs.values()]
        cells = " | ".join(f"{d:+.2f} / {100 * e:.2f}" for d, e in results)
        drift, end = np.median([d for d, _ in results]), 100 * np.median([e for _, e in results])
        print(f"| {name} | {cells} | {drift:+.2f} | {end:.2f} |", flush=True)
    offsets = wall_offsets()
    print("kept points behind the wall (mm): " + ", ".join(f"{k} {v:+.2f}" for k, v in offsets.items()))


if __name__ == "__main__":
    main(sys.argv[1:])
