"""Closed-loop navigation benchmark: random start/goal pairs per world, with and without people.

Usage: .venv/bin/python benchmarks/navigation.py [--worlds office rooms] [--pairs N] [--planners dwa fsm]
       [--people 0 5] [--slam on off] [--seed S] [--set KEY=VALUE ...] [--only WORLD:SEED ...] [--workers N]
       [--save RUNS.json]

Each run is `slam2d navigate` without the results folder (``slam2d.runs.navigate.simulate``):
the simulated robot drives from a random free start to a random free goal at least
4 m away (seeded), on online SLAM's pose and grid (``--slam on``) or on the true pose
and the world's map (``off``). Worlds: the office, and the ten room maps of
``$SLAM2D_DATA/rooms/`` with furniture as floor plans (0.05 m/px). One row per
(worlds, planner, people, slam): success rate, runs with a collision, median time,
median length / optimal grid path, median goal error (true pose at the stop),
median pose error of the pose driven on, and the real-time factor.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import statistics
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from scipy import ndimage

from slam2d import config
from slam2d.navigation import world_grid
from slam2d.runs.navigate import simulate
from slam2d.planning.grid import inflate
from slam2d.sim.robot import RobotConfig
from slam2d.sim.world import load_world

MIN_DISTANCE = 4.0  # m between start and goal
CLEARANCE = 0.45  # m from walls for a start or goal


def worlds(names: list[str]) -> list[str]:
    """World specs: 'office' and the furnished room plans."""
    out = []
    for name in names:
        if name == "rooms":
            data = Path(os.environ.get("SLAM2D_DATA", "../shared/datasets")) / "rooms"
            out += sorted(str(p) for p in data.glob("*_furnitures.png"))
        else:
            out.append(name)
    return out


def pairs(world_spec: str, n: int, rng: np.random.Generator) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n`` (start pose, goal xy) pairs in the world's free space, at least MIN_DISTANCE apart and
    connected for the robot (a floor plan's free space outside the building is not)."""
    world = load_world(world_spec, 0.05)
    region = reachable_regions(world)
    lo, hi = np.asarray(world.bounds[0]), np.asarray(world.bounds[1])
    out = []
    while len(out) < n:
        pts = rng.uniform(lo, hi, (200, 2))
        pts = pts[world.free(pts, CLEARANCE)]
        for a, b in zip(pts[0::2], pts[1::2]):
            if np.linalg.norm(a - b) >= MIN_DISTANCE and len(out) < n and region(a) == region(b) > 0:
                out.append((np.array([*a, rng.uniform(-np.pi, np.pi)]), b))
    return out


def reachable_regions(world):
    """``region(xy)``: the label of the connected free region of the world's map, inflated by the
    robot's radius, that holds ``xy``; 0 for none, and for the space around a floor plan's
    building (regions reaching the world's bounds, when others do not)."""
    grid = world_grid(world)
    labels, _ = ndimage.label(inflate(grid.free, RobotConfig().radius / grid.resolution), np.ones((3, 3)))
    band = int(np.ceil(2 * RobotConfig().radius / grid.resolution)) + 1  # the world's bounds are walls
    outside = np.unique(np.concatenate([labels[:band].ravel(), labels[-band:].ravel(),
                                        labels[:, :band].ravel(), labels[:, -band:].ravel()]))
    if np.setdiff1d(np.unique(labels), np.append(outside, 0)).size:  # a building inside: not its surroundings
        labels[np.isin(labels, outside)] = 0

    def region(xy) -> int:
        cell = grid.world_to_cell(np.asarray(xy, dtype=np.float64))
        return int(labels[cell[0], cell[1]]) if grid.in_bounds(cell) else 0

    return region


def _run(overrides: dict) -> dict:
    """One closed-loop run's metrics (in a worker process)."""
    return simulate(config.load(None, overrides)).metrics


def run_row(specs, n, planner, people, slam, seed, overrides=(), pool=None, only=()) -> dict:
    """One row's metrics; ``only`` ("world:seed", the world a prefix of the file's name, e.g.
    "lab_d:1002") keeps just those runs (the pairs are drawn as for the whole row: a run is the same alone)."""
    rng = np.random.default_rng(seed)
    jobs = []
    for spec in specs:
        for k, (start, goal) in enumerate(pairs(spec, n, rng)):
            if only and not any(Path(spec).stem.startswith(w) and int(s) == seed + k
                                for w, s in (o.rsplit(":", 1) for o in only)):
                continue
            jobs.append({
                "seed": seed + k, "dataset.simulator.world": spec, "navigation.start": start.tolist(),
                "navigation.goal": goal.tolist(), "navigation.planner": planner, "navigation.people": people,
                "navigation.slam": slam, **dict(map(config.parse_override, overrides)),
            })  # fmt: skip
    runs = []
    for job, m in zip(jobs, pool.map(_run, jobs) if pool else map(_run, jobs)):
        runs.append({**m, "world": Path(job["dataset.simulator.world"]).stem, "seed": job["seed"]})
        print(f"  {Path(job['dataset.simulator.world']).stem} seed {job['seed']}: {m['status']} {m['time']:.1f} s, "
              f"collisions {m['collisions']}, goal error {m['goal_error'] * 100:.1f} cm (estimate to goal "
              f"{m['stop_control_error'] * 100:.1f} cm, estimate off {m['stop_pose_error'] * 100:.1f} cm), "
              f"heading {np.degrees(m['heading_error']):.1f} deg"
              + ("" if m["success"] else f" ({m['reason']})"), file=sys.stderr, flush=True)
    med = lambda key: statistics.median(r[key] for r in runs)  # noqa: E731
    return {
        "runs": len(runs),
        "success": sum(r["success"] for r in runs) / len(runs),
        "collided": sum(r["collisions"] > 0 for r in runs),
        "time": med("time"),
        "ratio": statistics.median(r["length_ratio"] for r in runs if r["success"]) if any(
            r["success"] for r in runs) else float("nan"),  # fmt: skip
        "goal_cm": 100 * med("goal_error"),
        "pose_cm": 100 * med("pose_rmse"),
        "rtf": med("real_time_factor"),
        "hz": float(np.nanmedian([r["planner_hz"] for r in runs])),  # nan: a run that never planned
        "ms": [float(np.nanmedian([r[f"planner_ms_{k}"] for r in runs])) for k in ("median", "p95")],
        "runs_metrics": runs,
    }


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worlds", nargs="+", default=["office"], help="office, rooms, or PNG paths")
    ap.add_argument("--pairs", type=int, default=20, help="start/goal pairs per world")
    ap.add_argument("--planners", nargs="+", default=["dwa", "fsm"])
    ap.add_argument("--people", nargs="+", type=int, default=[0, 5])
    ap.add_argument("--slam", nargs="+", default=["on"], choices=["on", "off"])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="config overrides for every run")
    ap.add_argument("--only", nargs="*", default=[], metavar="WORLD:SEED", help="only these runs, e.g. lab_d:1002")
    ap.add_argument("--workers", type=int, default=1, help="runs in parallel (processes)")
    ap.add_argument("--save", metavar="JSON", help="write every run's metrics (with world, seed, planner) there")
    args = ap.parse_args(argv)
    # forkserver: a worker forked after numba's parallel kernels ran would abort (GNU OpenMP)
    pool = ProcessPoolExecutor(args.workers, mp_context=multiprocessing.get_context("forkserver")) if (
        args.workers > 1) else None  # fmt: skip
    specs = worlds(args.worlds)
    print("| worlds | planner | people | pose from | runs | success | runs with a collision | median time (s) "
          "| median length / optimal | median goal error (cm) | median pose RMSE (cm) | real-time factor "
          "| local planner (Hz) | call ms, median / p95 (wall) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    rows = {}
    for slam in args.slam:
        for planner in args.planners:
            for people in args.people:
                r = run_row(specs, args.pairs, planner, people, slam == "on", args.seed, args.set, pool, set(args.only))
                rows[slam, planner, people] = r["runs_metrics"]
                print(f"| {' '.join(args.worlds)} | {planner} | {people} | {'SLAM' if slam == 'on' else 'truth'} "
                      f"| {r['runs']} | {100 * r['success']:.0f} % | {r['collided']} | {r['time']:.1f} "
                      f"| {r['ratio']:.2f} | {r['goal_cm']:.1f} | {r['pose_cm']:.1f} | {r['rtf']:.1f} "
                      f"| {r['hz']:.0f} | {r['ms'][0]:.1f} / {r['ms'][1]:.1f} |", flush=True)
    paired(rows)
    if args.save:
        runs = [{**m, "planner": planner, "people_row": people, "slam_row": slam}
                for (slam, planner, people), ms in rows.items() for m in ms]
        Path(args.save).write_text(json.dumps(runs, indent=1, default=float))


def paired(rows: dict) -> None:
    """Each planner against the DWA on the same runs: the median of the per-run ratios of time to goal and of
    length / optimal (runs both planners reached)."""
    for (slam, planner, people), runs in rows.items():
        base = rows.get((slam, "dwa", people))
        if planner == "dwa" or base is None:
            continue
        both = [(a, b) for a, b in zip(runs, base) if a["success"] and b["success"]]
        if both:
            time = statistics.median(a["time"] / b["time"] for a, b in both)
            length = statistics.median(a["length_ratio"] / b["length_ratio"] for a, b in both)
            print(f"{planner} / dwa, {people} people, {slam}: median over {len(both)} paired runs: time {time:.2f}, "
                  f"length / optimal {length:.2f}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
