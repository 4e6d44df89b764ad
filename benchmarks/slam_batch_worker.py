"""What the worker process costs ``slam2d run``'s batch solves, on a real log.

Runs ``slam2d run EXPERIMENT`` in this process with every batch solve of the SLAM back end
(``PoseGraph.optimize_batch`` and ``solve_with``: the final batch and the refinement rounds) timed
as it runs in its worker process, then run again here on the same graph and start for comparison;
prints per solve the two wall times, whether the values are bit-identical, the factors and the
process's peak resident memory (the fork copies its page tables). The run's own result is the worker's.

    SLAM2D_DATA=... nice .venv/bin/python benchmarks/slam_batch_worker.py experiments/intel.yaml -q [--out DIR]
"""

from __future__ import annotations

import resource
import sys
import time

import gtsam
import numpy as np

from slam2d.backend import lm
from slam2d.backend import pose_graph as pg

_worker_lm = pg._lm


def _timed(graph, initial):
    t0 = time.perf_counter()
    out = _worker_lm(graph, initial)
    t1 = time.perf_counter()
    here = lm._solve(graph, initial, lambda values, n: (values, n), None)
    t2 = time.perf_counter()
    same = np.array_equal(gtsam.utilities.extractPose2(out[0]), gtsam.utilities.extractPose2(here[0]))
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"| {t1 - t0:.3f} | {t2 - t1:.3f} | {'yes' if same else 'NO'} | {graph.size()} | {rss:.0f} |",
          file=sys.stderr, flush=True)
    return out


def main() -> None:
    from slam2d.cli import main as cli

    pg._lm = _timed
    print("| solve in the worker (s) | the same solve here (s) | identical | factors | peak RSS (MB) |\n"
          "|---:|---:|---|---:|---:|", file=sys.stderr, flush=True)
    sys.argv = ["slam2d", "run", *sys.argv[1:]]
    cli()


if __name__ == "__main__":
    main()
