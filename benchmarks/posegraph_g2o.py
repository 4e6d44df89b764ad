"""Batch pose-graph optimisation of the real g2o files: slam2d beside GTSAM's own reader.

For each file: GTSAM's ``readG2o`` + Levenberg-Marquardt, and slam2d's
``read_g2o`` + ``solve_g2o`` (same LM defaults, first vertex held by a tight
prior); they should agree, which checks the reader and the factor building.
Then (unless ``--no-replay``) the graph is fed to ``PoseGraph`` keyframe by
keyframe with one iSAM2 update each, as a SLAM run would, and finished with
``optimize_batch``. Errors are GTSAM's: 0.5 * sum of squared whitened residuals
over all edges (the prior excluded).

    .venv/bin/python benchmarks/posegraph_g2o.py [--data DIR] [--datasets intel MIT CSAIL M3500] [--no-replay]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import gtsam
import numpy as np

from slam2d import geometry
from slam2d.backend.pose_graph import PRIOR_SIGMAS, g2o_error, replay_g2o, solve_g2o
from slam2d.config import BackendConfig
from slam2d.datasets.g2o import read_g2o

DEFAULT_DATA = Path(os.environ.get("SLAM2D_DATA", Path(__file__).resolve().parents[1] / ".." / "shared" / "datasets"))
DATASETS = ("intel", "MIT", "CSAIL", "M3500")


def gtsam_direct(path: Path):
    """GTSAM alone: readG2o, a prior on vertex 0, LM with default parameters."""
    t0 = time.perf_counter()
    graph, initial = gtsam.readG2o(str(path), False)
    read_s = time.perf_counter() - t0
    error0 = graph.error(initial)
    graph.add(gtsam.PriorFactorPose2(0, initial.atPose2(0), gtsam.noiseModel.Diagonal.Sigmas(PRIOR_SIGMAS)))
    t0 = time.perf_counter()
    opt = gtsam.LevenbergMarquardtOptimizer(graph, initial, gtsam.LevenbergMarquardtParams())
    result = opt.optimize()
    seconds = time.perf_counter() - t0
    graph.remove(graph.size() - 1)  # the error without the prior
    return gtsam.utilities.extractPose2(result), error0, graph.error(result), opt.iterations(), read_s, seconds


def max_pose_difference(a, b) -> tuple[float, float]:
    """Largest translation (m) and heading (rad) difference between two (N, 3) trajectories."""
    d = np.asarray(a) - np.asarray(b)
    return float(np.hypot(d[:, 0], d[:, 1]).max()), float(np.abs(geometry.wrap_angle(d[:, 2])).max())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="dataset root holding posegraphs/")
    ap.add_argument("--datasets", nargs="+", default=list(DATASETS))
    ap.add_argument("--no-replay", action="store_true", help="skip the incremental iSAM2 replay")
    args = ap.parse_args()

    header = (f"{'dataset':8} {'N':>5} {'M':>5}  {'method':22} {'initial':>12} {'final':>10} {'iters':>5} "
              f"{'read s':>7} {'opt s':>7}")
    print(header)
    print("-" * len(header))
    for name in args.datasets:
        path = args.data / "posegraphs" / f"{name}.g2o"
        ref_poses, e0, e1, iters, read_s, opt_s = gtsam_direct(path)
        t0 = time.perf_counter()
        g = read_g2o(path)
        ours_read_s = time.perf_counter() - t0
        ours = solve_g2o(g)
        n, m = len(g.ids), len(g.i)
        print(f"{name:8} {n:5d} {m:5d}  {'gtsam readG2o + LM':22} {e0:12.6g} {e1:10.6f} {iters:5d} "
              f"{read_s:7.3f} {opt_s:7.3f}")
        print(f"{'':20}  {'slam2d optimize_g2o':22} {ours.initial_error:12.6g} {ours.final_error:10.6f} "
              f"{ours.iterations:5d} {ours_read_s:7.3f} {ours.seconds:7.3f}")
        dxy, dth = max_pose_difference(ours.poses, ref_poses)
        print(f"{'':20}  max |difference|: {dxy:.2e} m, {dth:.2e} rad")
        if not args.no_replay:
            t0 = time.perf_counter()
            pg = replay_g2o(g, BackendConfig(name="pose_graph", robust="none"))
            replay_s = time.perf_counter() - t0
            inc = g2o_error(g, pg.estimate())
            t0 = time.perf_counter()
            final = g2o_error(g, pg.optimize_batch())
            batch_s = time.perf_counter() - t0
            print(f"{'':20}  {'PoseGraph iSAM2 replay':22} {ours.initial_error:12.6g} {inc:10.6f} {'-':>5} "
                  f"{'':7} {replay_s:7.3f}   ({n} keyframes, {pg.num_loops} loops, {pg.factorization})")
            print(f"{'':20}  {'  + optimize_batch':22} {'':12} {final:10.6f} {'':5} {'':7} {batch_s:7.3f}")


if __name__ == "__main__":
    main()
