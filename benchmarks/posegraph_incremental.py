"""The SLAM back end's incremental path on a benchmark graph: iSAM2 cadence and relinearisation.

Replays a g2o graph into ``PoseGraph`` as a SLAM run would (vertices in order as keyframes,
the edge to the next vertex as odometry, every other edge as a loop when its later end is
added) with ``PoseGraph.update`` every ``--every`` keyframes, under each relinearisation setting
(pose thresholds x, y m / theta rad, check every ``skip`` updates), then the final batch
optimisation the SLAM back end runs at the end. Reports the median wall seconds of ``--repeat``
runs, the iSAM2 updates run and the GTSAM error before and after the final batch, beside the
batch solve (chordal start + LM, as ``slam2d optimize``; median of as many runs, after one to warm up).

With ``--latency`` it reports instead, for each graph, the wall time a SLAM run waits per keyframe
at one update per keyframe under the default thresholds (adding the keyframe, its loops and the
updates: the time from one keyframe's arrival to the next's), its median, p90, p99 and max over
all keyframes and ``--repeat`` runs, the same for this thread's CPU time (the machine is shared), and the final
estimate's error against the batch optimum's. The replay adds a keyframe's loops before it reads anything, so a
relinearisation waiting in ``PoseGraph.update`` goes with them; the SLAM back end's loop search reads in between.

    nice .venv/bin/python benchmarks/posegraph_incremental.py [--graph M3500] [--every 1 10] [--repeat 3]
    nice .venv/bin/python benchmarks/posegraph_incremental.py --latency --graph M3500 intel MIT CSAIL [--partial-check]
"""

from __future__ import annotations

import argparse
import itertools
import os
import statistics
import time
from pathlib import Path

DATA = Path(os.environ.get("SLAM2D_DATA", Path(__file__).resolve().parents[1] / ".." / "shared" / "datasets"))
SETTINGS = (((0.1, 0.1, 0.01), 1), ((0.01, 0.01, 0.01), 1))  # (pose thresholds, skip); the first is the default


def replay(graph, every: int, threshold, skip: int) -> tuple[float, float, int, float, float]:
    """(incremental s, final batch s, iSAM2 updates, error before and after the final batch) of one replay."""
    from slam2d.backend import batch
    from slam2d.backend import pose_graph as pgm
    from slam2d.backend.replay import replay_g2o
    from slam2d.config import BackendConfig

    saved = pgm.RELINEARIZE_POSE, pgm.RELINEARIZE_SKIP
    pgm.RELINEARIZE_POSE, pgm.RELINEARIZE_SKIP = threshold, skip
    try:
        t0 = time.perf_counter()
        pg = replay_g2o(graph, BackendConfig(name="pose_graph", robust="none"), every=every)
        t1 = time.perf_counter()
        before = batch.g2o_error(graph, pg.estimate())
        t2 = time.perf_counter()
        pg.optimize_batch()
        t3 = time.perf_counter()
    finally:
        pgm.RELINEARIZE_POSE, pgm.RELINEARIZE_SKIP = saved
    return t1 - t0, t3 - t2, pg.isam_updates, before, batch.g2o_error(graph, pg.estimate())


def keyframe_latencies(graph) -> tuple[list[float], list[float], float]:
    """(wall s per keyframe: its arrival to the next's, the last one's to the end; this thread's CPU s over the
    same spans; error after the final batch) of one replay at one update per keyframe, default relinearisation."""
    from slam2d.backend import batch
    from slam2d.backend import pose_graph as pgm
    from slam2d.backend.replay import replay_g2o
    from slam2d.config import BackendConfig

    arrivals = []
    add_keyframe = pgm.PoseGraph.add_keyframe

    def timed(self, *args, **kwargs):
        arrivals.append((time.perf_counter(), time.thread_time()))
        return add_keyframe(self, *args, **kwargs)

    pgm.PoseGraph.add_keyframe = timed
    try:
        pg = replay_g2o(graph, BackendConfig(name="pose_graph", robust="none"), every=1)
        arrivals.append((time.perf_counter(), time.thread_time()))
    finally:
        pgm.PoseGraph.add_keyframe = add_keyframe
    pg.optimize_batch()
    wall, cpu = ([b[n] - a[n] for a, b in itertools.pairwise(arrivals)] for n in (0, 1))
    return wall, cpu, batch.g2o_error(graph, pg.estimate())


def latency_table(names: list[str], repeat: int) -> None:
    """Print the per-keyframe latency table of each graph (module docstring): wall and this thread's CPU
    time per keyframe, the replays' CPU seconds and the load average (1 min) at their start."""
    import numpy as np

    from slam2d.datasets.g2o import read_g2o

    print("| graph | keyframes | loops | median (ms) | p90 (ms) | p99 (ms) | max (ms) | CPU median / p90 / p99 / max (ms) "
          "| CPU (s) | load | final error / batch optimum |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name in names:
        graph = read_g2o(DATA / "posegraphs" / f"{name}.g2o")
        _, optimum = batch_seconds(graph)
        load = os.getloadavg()[0]
        runs = [keyframe_latencies(graph) for _ in range(repeat)]
        ms, cpu = (1e3 * np.concatenate([r[k] for r in runs]) for k in (0, 1))
        p50, p90, p99 = np.percentile(ms, [50, 90, 99])
        c = "/".join(f"{x:.1f}" for x in [*np.percentile(cpu, [50, 90, 99]), cpu.max()])
        loops = len(graph.i) - (len(graph.ids) - 1)
        print(f"| {name} | {len(graph.ids)} | {loops} | {p50:.2f} | {p90:.2f} | {p99:.1f} | {ms.max():.0f} | {c} "
              f"| {cpu.sum() / 1e3 / repeat:.1f} | {load:.1f} | {runs[-1][2]:.6f} / {optimum:.6f} |", flush=True)  # fmt: skip


def batch_seconds(graph) -> tuple[float, float]:
    """(wall s, error) of the batch solve from the chordal start."""
    from slam2d.backend.batch import g2o_error, optimize_g2o

    t0 = time.perf_counter()
    poses = optimize_g2o(graph)
    return time.perf_counter() - t0, g2o_error(graph, poses)


def median_runs(fn, repeat: int) -> tuple:
    """``fn()`` ``repeat`` times; each field's median."""
    runs = [fn() for _ in range(repeat)]
    return tuple(statistics.median(r[k] for r in runs) for k in range(len(runs[0])))


def main() -> None:
    from slam2d.datasets.g2o import read_g2o

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--graph", nargs="+", default=["M3500"], help="names of graphs in SLAM2D_DATA/posegraphs")
    ap.add_argument("--latency", action="store_true", help="per-keyframe latency table instead")
    ap.add_argument("--every", type=int, nargs="+", default=[1, 10], help="keyframes per PoseGraph.update")
    ap.add_argument("--repeat", type=int, default=3, help="runs of each, medians reported")
    ap.add_argument("--partial-check", action="store_true",
                    help="iSAM2 checks only the cliques an update touches for relinearisation")
    args = ap.parse_args()
    if args.partial_check:
        from slam2d.backend import pose_graph as pgm

        pgm.PARTIAL_RELINEARIZATION_CHECK = True
    if args.latency:
        return latency_table(args.graph, args.repeat)
    if len(args.graph) > 1:
        ap.error("--graph: one graph without --latency")
    args.graph = args.graph[0]
    graph = read_g2o(DATA / "posegraphs" / f"{args.graph}.g2o")
    batch_seconds(graph)  # warm up (imports, first allocations)
    batch_s, batch_err = median_runs(lambda: batch_seconds(graph), args.repeat)
    print(f"{args.graph}: {len(graph.ids)} poses, {len(graph.i)} edges; batch (chordal + LM) {batch_s:.3f} s, "
          f"error {batch_err:.6f}; medians of {args.repeat}\n")  # fmt: skip
    print("| keyframes per update | pose relinearise thresholds / skip | iSAM2 updates | incremental (s) "
          "| + final batch (s) | total × batch | error before / after the final batch |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for every in args.every:
        for threshold, skip in SETTINGS:
            inc, fin, n, before, after = median_runs(lambda: replay(graph, every, threshold, skip), args.repeat)
            print(f"| {every} | {'/'.join(map(str, threshold))} / {skip} | {n:.0f} | {inc:.2f} | {fin:.2f} "
                  f"| {(inc + fin) / batch_s:.1f} | {before:.4f} / {after:.6f} |", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
