"""Where the active moves of a global run went, and what each told apart (office_c's late runs).

Usage: nice .venv/bin/python benchmarks/localization_active_trace.py --world PLAN.png --seeds 2 4 8

Drives the benchmark's `active` scenario (same start, noise and seed as benchmarks/localization.py) and
prints, per move (the goals the Looker chose, those less than 1 s apart merged): the travel it took, its
goal's way and predicted evidence a scan, the contenders (compact hypotheses within the evidence threshold)
before and after, the evidence of the best over the runner-up and the true pose's weight. At the start of
each move, per contender: its offset from the best, its weight and the nearest way (m) from the estimate
to a place where one scan would add 0.1 / 0.3 / 1.0 nat against it (every 8th free cell within 15 m of
way, as slam2d.localization.active predicts it), and the longest of those over the contenders above 1 %
(no route shorter separates them all).
"""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np

THRESHOLDS = (0.1, 0.3, 1.0)  # log evidence a scan


def _truth_weight(hyps, truth) -> float:
    return next((h.weight for h in hyps if math.hypot(*(h.pose[:2] - truth[:2])) < 0.5), 0.0)


def nearest_separating(pf, angles) -> list[tuple]:
    """Per other contender: (offset (dx, dy) m from the best, weight, nearest way (m) to a place worth each
    of THRESHOLDS a scan against it)."""
    from slam2d.localization.active import contenders, gains, way_length

    hyps, known = contenders(pf), pf.map
    cells = known.free_cells(0.5)
    way = way_length(known, hyps[0].pose).ravel()[cells]
    cells, way = cells[way <= 15.0][::8], way[way <= 15.0][::8]
    row, col = np.divmod(cells, known.shape[1])
    xy = np.column_stack([known.origin[0] + (col + 0.5) * known.resolution,
                          known.origin[1] + (row + 0.5) * known.resolution])  # fmt: skip
    goals = np.column_stack([xy, np.arctan2(xy[:, 1] - hyps[0].pose[1], xy[:, 0] - hyps[0].pose[0])])
    gain, weights, free = gains(pf, goals, angles, 0.5)
    out = []
    for k, h in enumerate(hyps[1:]):
        g = np.where(free, gain[k], 0.0)
        near = [float(way[g >= t].min()) if np.any(g >= t) else math.inf for t in THRESHOLDS]
        out.append((h.pose[:2] - hyps[0].pose[:2], float(weights[k]), near))
    return out


def trace(spec: str, seed: int, seconds: float = 40.0) -> None:
    from slam2d import geometry
    from slam2d.localization import KnownMap, ParticleFilter, preset
    from slam2d.localization import scenario as sc
    from slam2d.localization.active import Looker, contenders
    from slam2d.sim import Robot
    from slam2d.sim.world import load_world

    world, known = load_world(spec), KnownMap.load(spec)
    rng = np.random.default_rng(seed)
    robot = Robot(world, sc.random_free_pose(world, known, rng), seed=seed)
    step = robot.step(0.0, 0.0, 0.0)
    pf = ParticleFilter(known, preset("slam2d"), step.scan.range_max, seed=seed)
    pf.init_global()
    looker, rec = Looker(pf), sc._Recorder()
    pose, turning, travel, moves, tracked = rec.add(pf, step.scan), 0.0, 0.0, [], None
    for k in range(1, round(seconds / sc.PERIOD) + 1):
        chosen = len(looker.goals)
        heading = looker.heading(pose, step.scan)
        if len(looker.goals) > chosen:
            state = (travel, len(contenders(pf)), pf.estimate.evidence,
                     _truth_weight(pf.estimate.hypotheses, step.pose))  # fmt: skip
            if not moves or k * sc.PERIOD - moves[-1]["t"] >= 1.0:
                moves.append({"t": k * sc.PERIOD, "start": state, "near": nearest_separating(pf, step.scan.angles)})
            moves[-1].update(t=k * sc.PERIOD, goal=looker.goals[-1])
        toward = None if heading is None else sc._towards(step.scan, float(geometry.wrap_angle(heading - pose[2])))
        if toward is not None:
            (v, w), turning = toward, 0.0
        else:
            v, w, turning = sc.wander_command(step.scan, turning)
        before = step.pose
        step = robot.step(v, w, sc.PERIOD)
        travel += math.hypot(*(step.pose[:2] - before[:2]))
        pose = rec.add(pf, step.scan)
        if moves:
            moves[-1]["end"] = (travel, len(contenders(pf)), pf.estimate.evidence,
                                _truth_weight(pf.estimate.hypotheses, step.pose))
        if tracked is None and pf.state == "tracking":
            tracked = travel
    print(f"seed {seed}: tracking from {tracked if tracked is None else round(tracked, 1)} m of travel")
    for m in moves:
        (t0, c0, e0, w0), (t1, c1, e1, w1), g = m["start"], m.get("end", m["start"]), m["goal"]
        print(f"  move at {m['t']:.1f} s: travel {t0:.1f} -> {t1:.1f} m, goal {g.distance:.1f} m of way worth "
              f"{g.separation:.2f} a scan; contenders {c0} -> {c1}, evidence {e0:.2f} -> {e1:.2f}, "
              f"truth's weight {w0:.3f} -> {w1:.3f}")
        for off, w, near in m["near"]:
            print(f"    contender ({off[0]:+.1f}, {off[1]:+.1f}) m, {w:.3f}: " + " / ".join(f"{d:.1f}" for d in near))
        worst = [max([n[i] for _, w, n in m["near"] if w > 0.01], default=0.0) for i in range(len(THRESHOLDS))]
        print("    no shorter route separates every contender above 1 %: " + " / ".join(f"{d:.1f}" for d in worst))


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--world", required=True)
    ap.add_argument("--seeds", type=int, nargs="+", default=[2, 4, 8])
    args = ap.parse_args(argv)
    for seed in args.seeds:
        trace(args.world, seed)


if __name__ == "__main__":
    main(sys.argv[1:])
