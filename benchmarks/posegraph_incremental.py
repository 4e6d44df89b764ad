"""The SLAM back end's incremental path on a benchmark graph: iSAM2 cadence and relinearisation.

Replays a g2o graph into ``PoseGraph`` as a SLAM run would (vertices in order as keyframes,
the edge to the next vertex as odometry, every other edge as a loop when its later end is
added) with an iSAM2 update every ``--every`` keyframes, under each relinearisation setting
(threshold m / rad, check every ``skip`` updates), then the final batch optimisation
the SLAM back end runs at the end. Reports wall seconds and the GTSAM error
beside the batch solve (chordal start + LM, as ``slam2d optimize``) in the same run.

    nice .venv/bin/python benchmarks/posegraph_incremental.py [--graph M3500] [--every 1 10 100]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

DATA = Path(os.environ.get("SLAM2D_DATA", Path(__file__).resolve().parents[1] / ".." / "shared" / "datasets"))
SETTINGS = ((0.01, 1), (0.1, 10))  # (relinearise threshold, relinearise skip); the first is the default


def replay(graph, every: int, threshold: float, skip: int) -> tuple[float, float, float]:
    """(incremental s, final batch s, error after the final batch) of one replay."""
    import slam2d.backend.pose_graph as pgm
    from slam2d.config import BackendConfig

    saved = pgm.RELINEARIZE_THRESHOLD, pgm.RELINEARIZE_SKIP
    pgm.RELINEARIZE_THRESHOLD, pgm.RELINEARIZE_SKIP = threshold, skip
    try:
        t0 = time.perf_counter()
        pg = pgm.replay_g2o(graph, BackendConfig(name="pose_graph", robust="none"), every=every)
        t1 = time.perf_counter()
        pg.optimize_batch()
        t2 = time.perf_counter()
    finally:
        pgm.RELINEARIZE_THRESHOLD, pgm.RELINEARIZE_SKIP = saved
    return t1 - t0, t2 - t1, pgm.g2o_error(graph, pg.estimate())


def batch_seconds(graph) -> tuple[float, float]:
    """(wall s, error) of the batch solve from the chordal start."""
    from slam2d.backend.pose_graph import g2o_error, optimize_g2o

    t0 = time.perf_counter()
    poses = optimize_g2o(graph)
    return time.perf_counter() - t0, g2o_error(graph, poses)


def main() -> None:
    from slam2d.datasets.g2o import read_g2o

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--graph", default="M3500", help="name of a graph in SLAM2D_DATA/posegraphs")
    ap.add_argument("--every", type=int, nargs="+", default=[1, 10, 100], help="keyframes per iSAM2 update")
    args = ap.parse_args()
    graph = read_g2o(DATA / "posegraphs" / f"{args.graph}.g2o")
    batch_s, batch_err = batch_seconds(graph)
    print(f"{args.graph}: {len(graph.ids)} poses, {len(graph.i)} edges; batch (chordal + LM) {batch_s:.3f} s, "
          f"error {batch_err:.6f}\n")  # fmt: skip
    print("| keyframes per update | relinearise threshold / skip | incremental (s) | + final batch (s) "
          "| total × batch | error after the final batch |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    for every in args.every:
        for threshold, skip in SETTINGS:
            inc, fin, err = replay(graph, every, threshold, skip)
            print(f"| {every} | {threshold} / {skip} | {inc:.2f} | {fin:.2f} | {(inc + fin) / batch_s:.1f} | {err:.6f} |",
                  flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
