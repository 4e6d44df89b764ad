"""3D obstacles: DWA with the laser alone against DWA with the depth camera's obstacle layer.

Usage: .venv/bin/python benchmarks/obstacles_3d.py [--worlds office rooms] [--pairs N] [--seed S]
       [--objects boxes=6 tables=1 chairs=2 shelves=1] [--slam off] [--workers N] [--experiments]

Navigation runs: ``slam2d navigate`` without the results folder (``slam2d.runs.navigate.simulate``)
from random start/goal pairs (as ``benchmarks/navigation.py``: at least 4 m apart, seeded) with
objects with heights scattered by the run's seed near the shortest path (low boxes 3-5 cm,
tables, chairs, shelves whose board is at 0.30-0.34 m; each at least 0.7 m from walls and from
each other). The same runs with ``navigation.options.depth_camera.enabled`` false and true. A
collision is a contact of the robot's disc with an object part whose height range overlaps the
body's (0.01-0.45 m): the robot stops there.

``--experiments``: the 2018 thesis's test (two boxes 3.5 cm and 4.0 cm high, 0.8 m apart, the
robot driving between them) and the smallest box height the depth layer marks (boxes 1-4 cm high
approached from 3.5 m, the camera at its default mount), plus the floor-only false marks.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import statistics
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from navigation import pairs, worlds

from slam2d import config
from slam2d.config import ObjectSpec
from slam2d.navigation import NavigatorConfig, run_navigation, world_grid
from slam2d.navigation.depth_layer import ObstacleLayer
from slam2d.runs.navigate import simulate
from slam2d.sim import Robot, World
from slam2d.sim.depth import DepthCamera, DepthCameraConfig
from slam2d.sim.objects3d import Objects3D, furnish

BOX = 0.3  # m, side of the thesis experiment's boxes


def _run(overrides: dict) -> dict:
    run = simulate(config.load(None, overrides))
    return run.metrics | {"objects": len(run.world.objects) if run.world.objects is not None else 0}


def navigation_rows(specs, n, seed, objects: dict, slam: bool, pool=None, name="") -> None:
    rng = np.random.default_rng(seed)
    jobs = []
    for spec in specs:
        for k, (start, goal) in enumerate(pairs(spec, n, rng)):
            base = {"seed": seed + k, "dataset.simulator.world": spec, "navigation.start": start.tolist(),
                    "navigation.goal": goal.tolist(), "navigation.slam": slam, "output.figures": False,
                    **{f"dataset.simulator.objects.{key}": v for key, v in objects.items()}}  # fmt: skip
            jobs += [base | {"navigation.options.depth_camera.enabled": cam} for cam in (False, True)]
    results = list(pool.map(_run, jobs) if pool else map(_run, jobs))
    for job, m in zip(jobs, results):
        cam = job["navigation.options.depth_camera.enabled"]
        print(f"  {Path(job['dataset.simulator.world']).stem} seed {job['seed']} camera {cam}: {m['status']} "
              f"{m['time']:.1f} s, objects {m['objects']}, object collisions {m['object_collisions']}"
              + ("" if m["success"] else f" ({m['reason']})"), file=sys.stderr, flush=True)
    for cam in (False, True):
        runs = [m for job, m in zip(jobs, results) if job["navigation.options.depth_camera.enabled"] == cam]
        ok = [r for r in runs if r["success"]]
        med = lambda key, rs=runs: statistics.median(r[key] for r in rs) if rs else float("nan")
        print(f"| {name} | {'laser + depth camera' if cam else 'laser alone'} | {len(runs)} "
              f"| {med('objects'):.0f} | {100 * len(ok) / len(runs):.0f} % "
              f"| {sum(r['object_collisions'] > 0 for r in runs)} | {sum(r['object_collisions'] for r in runs)} "
              f"| {sum(r['collisions'] > r['object_collisions'] for r in runs)} "
              f"| {med('time', ok):.1f} | {float(np.nanmedian([r['planner_hz'] for r in runs])):.0f} "
              f"| {med('real_time_factor'):.1f} |", flush=True)


def two_boxes(camera: bool, seed: int, layout: str, heights=(0.035, 0.040), apart: float = 0.8):
    """The thesis's test in a 8 m x 4 m room, the robot driving from one end to the other: two boxes
    ``heights`` high, ``apart`` m between them, ``across`` the way (the robot passes between them) or
    ``along`` it (centres on the straight line; the robot goes round both). The pair is shifted across
    the way by up to 5 cm with the seed. (result, min clearance m of the robot's disc to the boxes)."""
    room = World.from_polygons([[[0, 0], [8, 0], [8, 4], [0, 4]]], name="room")
    y0 = 2.0 + np.random.default_rng(seed).uniform(-0.05, 0.05)
    if layout == "across":
        at = [(4.0, y0 - (apart + BOX) / 2), (4.0, y0 + (apart + BOX) / 2)]
    else:
        at = [(3.6, y0), (3.6 + apart, y0)]
    specs = [ObjectSpec(kind="box", at=a, size=(BOX, BOX), z=(0.0, h)) for a, h in zip(at, heights)]
    world = furnish(room, Objects3D.from_specs(specs), 0.25)
    cfg = NavigatorConfig.model_validate({"depth_camera": {"enabled": camera}})
    robot = Robot(world, [1.0, 2.0, 0.0], seed=seed)
    result = run_navigation(world, robot, world_grid(world), [7.0, 2.0], "dwa", cfg, seed=seed)
    parts = world.objects.parts
    xy = result.trajectory[:, :2]
    dx = np.maximum(np.maximum(parts[None, :, 0] - xy[:, :1], xy[:, :1] - parts[None, :, 3]), 0)
    dy = np.maximum(np.maximum(parts[None, :, 1] - xy[:, 1:], xy[:, 1:] - parts[None, :, 4]), 0)
    return result, float(np.hypot(dx, dy).min() - robot.cfg.radius)


def detected(height: float, seed: int, cfg: DepthCameraConfig | None = None, distance: float = 3.5) -> bool:
    """Whether the obstacle layer marks a box ``height`` m high (0.3 m square) at some point while the
    robot drives straight at it from ``distance`` m to 0.3 m (the camera at its mount, noise seeded)."""
    cfg = cfg or DepthCameraConfig(enabled=True)
    room = World.from_polygons([[[0, 0], [8, 0], [8, 4], [0, 4]]], name="room")
    box = ObjectSpec(kind="box", at=(6.0, 2.0), size=(BOX, BOX), z=(0.0, height))
    world = furnish(room, Objects3D.from_specs([box]), 0.25)
    camera, layer = DepthCamera(cfg, seed), ObstacleLayer(cfg)
    for x in np.arange(6.0 - distance, 6.0 - BOX / 2 - 0.3, 0.1):
        pose = np.array([x, 2.0, 0.0])
        layer.update(pose, camera.render(world, pose), x)
        near_box = np.all(np.abs(layer.points() - box.at) <= BOX / 2 + 0.05, axis=1)
        if near_box.any():
            return True
    return False


def false_marks(seed: int, steps: int = 100, cfg: DepthCameraConfig | None = None) -> int:
    """Obstacle points the layer holds after ``steps`` frames of an empty floor (robot turning in place)."""
    cfg = cfg or DepthCameraConfig(enabled=True)
    room = World.from_polygons([[[0, 0], [10, 0], [10, 10], [0, 10]]], name="room")
    camera, layer = DepthCamera(cfg, seed), ObstacleLayer(cfg)
    marks = 0
    for k in range(steps):
        pose = np.array([5.0, 5.0, 0.1 * k])
        layer.update(pose, camera.render(room, pose), 0.1 * k)
        marks = max(marks, len(layer))
    return marks


def experiments(seeds: int) -> None:
    print("| test | sensors | runs | reached | runs with a contact | min clearance to the boxes (cm) | median time (s) |")
    print("|---|---|---|---|---|---|---|")
    for layout, camera in ((a, c) for a in ("across", "along") for c in (False, True)):
        runs = [two_boxes(camera, s, layout) for s in range(seeds)]
        print(f"| two boxes 3.5 + 4.0 cm, 0.8 m apart {layout} the way "
              f"| {'laser + depth camera' if camera else 'laser alone'} "
              f"| {seeds} | {sum(r.success for r, _ in runs)} | {sum(r.object_collisions > 0 for r, _ in runs)} "
              f"| {100 * min(c for _, c in runs):.1f} | {statistics.median(r.time for r, _ in runs):.1f} |",
              flush=True)  # fmt: skip
    print("\n| box height (cm) | " + " | ".join(f"{h:.1f}" for h in np.arange(1.0, 4.01, 0.5)) + " |")
    print("|---|" + "---|" * 7)
    rates = [np.mean([detected(h / 100, s) for s in range(seeds)]) for h in np.arange(1.0, 4.01, 0.5)]
    print(f"| marked (of {seeds} approaches) | " + " | ".join(f"{100 * r:.0f} %" for r in rates) + " |")
    marks = [false_marks(s) for s in range(seeds)]
    print(f"\nfloor only, {seeds} x 100 frames turning in place: at most {max(marks)} points marked")


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worlds", nargs="+", default=["rooms"], help="office, rooms, or PNG paths")
    ap.add_argument("--pairs", type=int, default=2, help="start/goal pairs per world")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--objects", nargs="*", default=["boxes=6", "tables=1", "chairs=2", "shelves=1"])
    ap.add_argument("--slam", default="off", choices=["on", "off"])
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--experiments", action="store_true", help="the two-box test and the smallest height only")
    ap.add_argument("--seeds", type=int, default=10, help="seeds of the experiments")
    args = ap.parse_args(argv)
    if args.experiments:
        experiments(args.seeds)
        return
    objects = {k: int(v) for k, v in (o.split("=") for o in args.objects)}
    pool = ProcessPoolExecutor(args.workers, mp_context=multiprocessing.get_context("forkserver")) if (
        args.workers > 1) else None  # fmt: skip
    print("| worlds | sensors | runs | objects per run | success | runs with an object collision | object collisions "
          "| runs with another collision | median time (s) | local planner (Hz) | real-time factor |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    navigation_rows(worlds(args.worlds), args.pairs, args.seed, objects, args.slam == "on", pool,
                    " ".join(args.worlds) + ("" if args.slam == "off" else ", SLAM"))  # fmt: skip


if __name__ == "__main__":
    main(sys.argv[1:])
