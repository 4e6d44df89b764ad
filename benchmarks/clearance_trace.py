"""Where an exploration run came closest to a wall, measured in the simulator's true world (not the SLAM map).

Usage: .venv/bin/python benchmarks/clearance_trace.py RESULTS_FOLDER [--radius 0.2] [--margin 0.05]

RESULTS_FOLDER is one of ``slam2d explore`` (its config.yaml, ground_truth.tum, goals.json, metrics.json). Printed:
the smallest clearance between the robot's disc and the plan's walls (m, from the true poses), when and where;
the stretches below the margin; the tight goals; for the stretch of route through a 2.4 m box round the smallest
clearance, the bottleneck of the true free space between where it enters and leaves the box (the widest gap a
route between those two places can have: twice the largest wall distance it can keep throughout) and so the best
clearance possible there; the largest wall distance within 15 cm of the place; and the area the robot can reach
with its disc against with its disc grown by the margin (what lies only behind gaps narrower than that).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import yaml
from scipy import ndimage

from slam2d.exploration.coverage import reachable_free, truth_map
from slam2d.sim.world import load_world

STEP = 0.005  # m, the true wall distance's sampling
HALF = 1.2  # m, half the box round the smallest clearance


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("folder", type=Path)
    ap.add_argument("--radius", type=float, default=0.2, help="m, the robot's")
    ap.add_argument("--margin", type=float, default=0.05, help="m, the safety margin")
    a = ap.parse_args()
    cfg = yaml.safe_load((a.folder / "config.yaml").read_text())
    world = load_world(cfg["dataset"]["simulator"]["world"], cfg["dataset"]["simulator"]["resolution"])
    rows = np.loadtxt(a.folder / "ground_truth.tum")
    t, xy = rows[:, 0] - rows[0, 0], rows[:, 1:3]
    clear = world.distance(xy) - a.radius
    k = int(np.argmin(clear))
    print(f"smallest clearance {100 * clear[k]:.1f} cm at {t[k]:.1f} s, ({xy[k, 0]:.2f}, {xy[k, 1]:.2f})")
    low = np.flatnonzero(clear < a.margin)
    for run in np.split(low, np.flatnonzero(np.diff(low) > 1) + 1) if len(low) else []:
        j = run[np.argmin(clear[run])]
        print(f"  below {100 * a.margin:g} cm {t[run[0]]:.1f}-{t[run[-1]]:.1f} s, least {100 * clear[j]:.1f} cm "
              f"at ({xy[j, 0]:.2f}, {xy[j, 1]:.2f})")  # fmt: skip
    for g in json.loads((a.folder / "goals.json").read_text()):
        if g.get("tight"):
            x, y = g["position"]
            print(f"tight goal at {g['time']:.1f} s, ({x:.2f}, {y:.2f}): {g['outcome']} {g.get('reason', '')}")
    bottleneck(world, t, xy, clear, k, a.radius)
    free, frame = truth_map(world)
    area = [reachable_free(free, frame, xy[0], r, 12.0).sum() * frame.resolution**2
            for r in (a.radius, a.radius + a.margin)]  # fmt: skip
    print(f"reachable area: disc {area[0]:.1f} m², disc + margin {area[1]:.1f} m², only with the disc "
          f"{area[0] - area[1]:.2f} m²")  # fmt: skip


def bottleneck(world, t, xy, clear, k: int, radius: float) -> None:
    """The true free space's bottleneck on the route's stretch through the box round pose ``k``."""
    c = xy[k]
    gx, gy = np.arange(c[0] - HALF, c[0] + HALF, STEP), np.arange(c[1] - HALF, c[1] + HALF, STEP)
    pts = np.stack(np.meshgrid(gx, gy), axis=-1).reshape(-1, 2)
    wall = np.where(world.occupied(pts), 0.0, world.distance(pts)).reshape(len(gy), len(gx))
    inside = np.flatnonzero((np.abs(xy - c) < HALF - 0.05).all(axis=1))
    stretch = next(s for s in np.split(inside, np.flatnonzero(np.diff(inside) > 1) + 1) if k in s)
    cell = lambda p: (round((p[1] - gy[0]) / STEP), round((p[0] - gx[0]) / STEP))
    a, b = cell(xy[stretch[0]]), cell(xy[stretch[-1]])
    lo, hi = 0.0, float(min(wall[a], wall[b]))
    for _ in range(30):  # the largest wall distance keeping a and b connected
        mid = (lo + hi) / 2
        labels, _ = ndimage.label(wall > mid)
        lo, hi = (mid, hi) if labels[a] and labels[a] == labels[b] else (lo, mid)
    p = cell(c)
    near = wall[p[0] - 30:p[0] + 31, p[1] - 30:p[1] + 31].max()
    print(f"route {t[stretch[0]]:.1f}-{t[stretch[-1]]:.1f} s through the box: true bottleneck {200 * lo:.1f} cm wide, "
          f"best clearance {100 * (lo - radius):.1f} cm, the robot's least {100 * clear[stretch].min():.1f} cm; "
          f"largest wall distance within 15 cm of the place {100 * near:.1f} cm")  # fmt: skip


if __name__ == "__main__":
    main()
