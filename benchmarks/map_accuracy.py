"""Map accuracy as wall-to-wall distances (the 2018 thesis' Table 5-1) on the simulator's office.

Usage: .venv/bin/python benchmarks/map_accuracy.py [--seeds 0 1 2 3] [--explore-seeds 0] [--out FILE.md]

For each seed, `slam2d run` on the office (its default: ICP frontend, pose graph, noisy odometry)
and, for ``--explore-seeds``, `slam2d explore` from nothing (its default strategy). The office's
eleven named spans (:data:`slam2d.sim.spans.OFFICE_SPANS`) are measured in each map
(:mod:`slam2d.evaluation.map_accuracy`): at the registered scan endpoints, in the run's 5 cm grid
and in a 2 cm grid built from the same poses; an exploration keeps its 5 cm grid only. One row per
map: spans seen, mean / median / largest absolute error (cm), mean signed error (cm).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

from slam2d import config, geometry
from slam2d.datasets.registry import open_dataset
from slam2d.evaluation.map_accuracy import measure_spans, span_summary
from slam2d.evaluation.trajectory import align_se2
from slam2d.exploration.config import ExploreConfig
from slam2d.exploration.loop import explore, resolved
from slam2d.mapping.occupancy import build_grid
from slam2d.pipeline import SlamPipeline
from slam2d.runs.slam_outputs import grid_points, scan_points
from slam2d.sim.spans import world_spans
from slam2d.sim.world import World

THESIS = "2.4–7.5 cm, mean 4.78 cm (real robot, Kinect-free 2D laser, ~80 m², six spans)"


def _measure(spans, to_truth, points_views) -> dict:
    points, views = (geometry.transform_points(to_truth, a) for a in points_views)
    return span_summary(spans, measure_spans(points, spans, views))


def run_rows(seed: int, spans) -> list[dict]:
    cfg = config.load(None, [f"seed={seed}"])
    result = SlamPipeline(cfg).run(open_dataset(cfg.dataset, seed=seed))
    to_truth = align_se2(result.poses, result.ground_truth)
    fine = cfg.mapping.model_copy(update={"resolution": 0.02})
    maps = {"scan endpoints": scan_points(result.scans, result.poses),
            f"grid {100 * cfg.mapping.resolution:g} cm": grid_points(build_grid(result.poses, result.scans, cfg.mapping)),
            "grid 2 cm": grid_points(build_grid(result.poses, result.scans, fine))}  # fmt: skip
    return [{"map": f"run seed {seed}, {name}", **_measure(spans, to_truth, pv)} for name, pv in maps.items()]


def explore_row(seed: int, spans) -> dict:
    cfg = resolved(ExploreConfig(seed=seed, exploration={"animation": False}))
    run = explore(cfg)
    summary = _measure(spans, align_se2(run.estimate, run.truth), grid_points(run.grid))
    return {"map": f"explore seed {seed}, grid {100 * cfg.mapping.resolution:g} cm", **summary}


def _cm(row: dict, key: str) -> str:
    return f"{100 * row[key]:.2f}" if key in row else "–"


def table(rows: list[dict]) -> str:
    lines = ["| map | spans seen | mean abs (cm) | median abs (cm) | max abs (cm) | mean signed (cm) |",
             "|---|---|---|---|---|---|"]  # fmt: skip
    for r in rows:
        lines.append(f"| {r['map']} | {r['seen']}/{r['spans']} | {_cm(r, 'mean_abs_error_m')} | "
                     f"{_cm(r, 'median_abs_error_m')} | {_cm(r, 'max_abs_error_m')} | {_cm(r, 'mean_error_m')} |")
    return "\n".join(lines) + f"\n\nthesis Table 5-1: {THESIS}\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="*", default=[0, 1, 2, 3])
    ap.add_argument("--explore-seeds", type=int, nargs="*", default=[0])
    ap.add_argument("--out", type=Path, help="also write the table to this Markdown file")
    args = ap.parse_args(argv)
    spans = world_spans(World.office())
    rows = []
    for seed in args.seeds:
        t0 = time.perf_counter()
        rows += run_rows(seed, spans)
        print(f"run seed {seed}: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    for seed in args.explore_seeds:
        t0 = time.perf_counter()
        rows.append(explore_row(seed, spans))
        print(f"explore seed {seed}: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    text = table(rows)
    for kind in ("scan endpoints", "grid 5 cm", "grid 2 cm"):
        means = [r["mean_abs_error_m"] for r in rows if r["map"].endswith(kind) and "mean_abs_error_m" in r]
        if means:
            text += (f"\n{kind}: mean abs error over the maps, median {100 * statistics.median(means):.2f} cm "
                     f"(range {100 * min(means):.2f}–{100 * max(means):.2f} cm)")
    print(text)
    if args.out:
        args.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
