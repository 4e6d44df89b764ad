"""Why global localisation runs fail: how well the look-alike the filter keeps explains the scans.

Usage: nice .venv/bin/python benchmarks/localization_lookalike.py [--world PNG|office] [--seeds 0 1 ...]
       [--travel 10] [--out results/bench-localization-lookalike]

Each seeded global run (the stream of benchmarks/localization.py's global scenario) is replayed
through slam2d's filter. A run that does not converge within ``--travel`` m is examined at that
travel: the heaviest cluster more than 1 m from the truth is the look-alike, and the rigid
transform T that takes the true pose onto it gives a look-alike trajectory T x truth over the
scans so far. Summed over the filter updates up to that travel, each field's log-likelihood of the
scans (what the filter weighs with: 60 beams, each raised to 0.2) is compared at the truth and
- at T x truth, T as the cluster's mean gives it ("filter");
- at the look-alike moved by the constant rigid offset that fits it best ("best offset": a
  coarse-to-fine grid search, up to 0.5 m and 7 deg, turning about its last pose): a room plan's
  copies need not be drawn on the same grid cells, and a filter can hold a look-alike wherever
  it fits best.
A look-alike within a few units of the truth ("best offset" > -3, a likelihood ratio below 20)
cannot be told from it by any filter weighing these scans; the run is a look-alike failure.
Rows go to runs.jsonl and a markdown table to table.md.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

SECONDS = 40.0  # s, as the benchmark's global scenario
SEARCH = [(0.08, math.radians(1.0)), (0.015, math.radians(0.2)), (0.003, math.radians(0.04))]  # steps, coarse to fine
TOLD_APART = -3.0  # best-offset difference below which the truth is clearly better


def _grid(step_xy: float, step_theta: float, half: int = 6) -> np.ndarray:
    """Offsets (n, 3) on a (2 half + 1)^3 grid of the given steps."""
    k = np.arange(-half, half + 1)
    return np.stack(np.meshgrid(k * step_xy, k * step_xy, k * step_theta, indexing="ij"), -1).reshape(-1, 3)


def _moved(transform, centre, offset, t) -> np.ndarray:
    """The look-alike pose (3,) of true pose ``t``: transform x t, then the rigid offset about ``centre``."""
    from slam2d import geometry

    h = geometry.compose(transform, t)
    c, s = math.cos(offset[2]), math.sin(offset[2])
    r = h[:2] - centre
    return np.array([centre[0] + c * r[0] - s * r[1] + offset[0], centre[1] + s * r[0] + c * r[1] + offset[1],
                     h[2] + offset[2]])  # fmt: skip


def _sum_over(scans, transform, centre, offsets, fields) -> dict:
    """Per field, the log-likelihood summed over ``scans`` [(scan, true pose)] of the look-alike
    trajectory transform x truth moved by each rigid offset (n, 3) (dx, dy, turn about ``centre``)."""
    from slam2d import geometry

    ca, sa = np.cos(offsets[:, 2]), np.sin(offsets[:, 2])
    out = {name: np.zeros(len(offsets)) for name in fields}
    for scan, t in scans:
        h = geometry.compose(transform, t)
        r = h[:2] - centre
        poses = np.column_stack([centre[0] + ca * r[0] - sa * r[1] + offsets[:, 0],
                                 centre[1] + sa * r[0] + ca * r[1] + offsets[:, 1], h[2] + offsets[:, 2]])
        for name, field in fields.items():
            out[name] += field.log_likelihood(poses, scan)[0]
    return out


def examine(spec: str, seed: int, travel: float) -> dict:
    """One seeded global run: converged or not, and for a failure the look-alike's fit against the truth."""
    from slam2d import geometry
    from slam2d.localization import KnownMap, ParticleFilter, preset
    from slam2d.localization.clusters import cluster_means
    from slam2d.localization.scenario import converged_at, replay, wander
    from slam2d.sim.world import load_world

    world = load_world(spec)
    known = KnownMap.from_world(world) if spec == "office" else KnownMap.load(spec)
    stream = wander(world, known, SECONDS, seed)
    row = {"world": Path(spec).stem.replace("_furnitures", ""), "seed": seed}
    pf = ParticleFilter(known, preset("slam2d"), stream.scans[0].range_max, seed=seed)
    pf.init_global()
    track = replay(pf, stream)
    c = converged_at(track)
    row["converged"] = bool(c is not None and stream.travelled[c] <= travel)
    row["travel"] = None if c is None else round(float(stream.travelled[c]), 2)
    if row["converged"]:
        return row
    # the same run again, stopped at the travel limit, scoring truth and look-alike at every update
    pf = ParticleFilter(known, preset("slam2d"), stream.scans[0].range_max, seed=seed)
    pf.init_global()
    updates = []
    end = int(np.searchsorted(stream.travelled, travel, side="right")) - 1
    for i, scan in enumerate(stream.scans[: end + 1]):
        if pf.add(scan):
            updates.append(i)
    lab = pf._labels
    means, log_w = cluster_means(pf.particles, pf.log_w, lab, int(lab.max()) + 1)
    truth = stream.truth[end]
    far = np.hypot(*(means[:, :2] - truth[:2]).T) > 1.0
    if not far.any():
        row["lookalike"] = None
        return row
    j = int(np.flatnonzero(far)[np.argmax(log_w[far])])
    share = float(np.exp(log_w[j] - np.logaddexp.reduce(log_w)))
    transform = geometry.compose(means[j], geometry.inverse(truth))
    fields = {"sharp": pf.sensor, "smooth": pf.coarse}
    scans = [(stream.scans[i], stream.truth[i]) for i in updates]
    true = {name: sum(float(f.log_likelihood(t[None], scan)[0][0]) for scan, t in scans) for name, f in fields.items()}
    centre = geometry.compose(transform, truth)[:2]  # offsets turn about the look-alike's last pose
    at_filter = _sum_over(scans, transform, centre, np.zeros((1, 3)), fields)
    best, look = np.zeros(3), None
    for step_xy, step_theta in SEARCH:
        grid = best + _grid(step_xy, step_theta)
        look = _sum_over(scans, transform, centre, grid, fields)
        best = grid[int(np.argmax(look["sharp"]))]
    k = int(np.argmax(look["sharp"]))
    gap = np.cumsum([float(pf.sensor.log_likelihood(_moved(transform, centre, best, t)[None], scan)[0][0]
                           - pf.sensor.log_likelihood(t[None], scan)[0][0]) for scan, t in scans])  # fmt: skip
    apart = np.flatnonzero(gap < TOLD_APART)
    row.update(lookalike=[round(float(v), 3) for v in means[j]], share=round(share, 3),
               transform=[round(float(transform[0]), 2), round(float(transform[1]), 2),
                          round(math.degrees(float(transform[2])), 2)],
               sharp_filter=round(float(at_filter["sharp"][0] - true["sharp"]), 1),
               sharp_best=round(float(look["sharp"][k] - true["sharp"]), 1),
               smooth_filter=round(float(at_filter["smooth"][0] - true["smooth"]), 1),
               smooth_best=round(float(look["smooth"][k] - true["smooth"]), 1),
               offset=[round(float(best[0]), 3), round(float(best[1]), 3), round(math.degrees(float(best[2])), 2)],
               told_apart=bool(look["sharp"][k] - true["sharp"] < TOLD_APART),
               apart_at=round(float(stream.travelled[updates[apart[0]]]), 1) if len(apart) else None)  # fmt: skip
    return row


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--world", default="office")
    ap.add_argument("--seeds", type=int, nargs="+", default=list(range(10)))
    ap.add_argument("--travel", type=float, default=10.0, help="m, the benchmark's limit")
    ap.add_argument("--out", default="results/bench-localization-lookalike")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    lines = [("| seed | converged ≤ 10 m | look-alike (x, y, θ°) | its share | transform (dx, dy, θ°) | sharp at filter's "
              "| sharp best offset | offset (m, m, °) | smooth at filter's | smooth best offset | sharp gap < -3 from (m) |"),
             "|---|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    with open(out / "runs.jsonl", "w") as f:
        for seed in args.seeds:
            r = examine(args.world, seed, args.travel)
            f.write(json.dumps(r) + "\n")
            print(json.dumps(r), flush=True)
            if r.get("lookalike"):
                lx, ly, lt = r["lookalike"]
                lines.append(f"| {seed} | no | ({lx:.1f}, {ly:.1f}, {math.degrees(lt):.0f}) | {r['share']:.2f} | "
                             f"({r['transform'][0]}, {r['transform'][1]}, {r['transform'][2]}) | "
                             f"{r['sharp_filter']} | {r['sharp_best']} | {tuple(r['offset'])} | "
                             f"{r['smooth_filter']} | {r['smooth_best']} | {r['apart_at'] if r['apart_at'] is not None else '-'} |")
            else:
                lines.append(f"| {seed} | {'yes' if r['converged'] else 'no'} | - | - | - | - | - | - | - | - | - |")
    text = "\n".join(lines) + "\n"
    (out / "table.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main(sys.argv[1:])
