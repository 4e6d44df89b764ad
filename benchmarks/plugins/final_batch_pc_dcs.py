"""Plugin for benchmarks/slam_final_batch.py: the SLAM back end's final batch by ``pc_dcs``.

Importing it replaces ``PoseGraph.optimize_batch`` (Cauchy LM + the chi-square check) with
``solve_g2o(robust="pc_dcs")`` from the current estimate over the keyframes' odometry and loop
edges; the loops it classifies as outliers are deactivated and counted like the default's.
DCS's Phi is read from ``SLAM2D_PC_DCS_PHI`` (default 1). Landmark factors are not supported.
"""

from __future__ import annotations

import os

from slam2d.backend import batch, factors
from slam2d.backend import pose_graph as pg


def optimize_batch(self):
    """``pc_dcs`` over the pose graph; returns the poses (K, 3) as ``PoseGraph.optimize_batch``."""
    edges = [n for n, (f, a) in enumerate(zip(self._factors, self._active)) if a and f.kind in ("odometry", "loop")]
    if len(edges) != sum(self._active) - 1:  # all but the first keyframe's prior
        raise NotImplementedError("the pc_dcs final batch handles odometry and loop factors only")
    graph = self.to_g2o()  # the same edges in the same order, the poses at the current estimate
    result = batch.solve_g2o(graph, robust="pc_dcs", robust_param=float(os.environ.get("SLAM2D_PC_DCS_PHI", "1")),
                             init="file")  # fmt: skip
    for n, inlier in zip(edges, result.inlier):
        if self._factors[n].kind == "loop" and not inlier:
            self._active[n] = False
            self.rejected_inconsistent += 1
    return self._restart_at(factors.g2o_values(graph.ids, result.poses))


pg.PoseGraph.optimize_batch = optimize_batch
