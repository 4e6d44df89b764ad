"""A g2o graph fed into a :class:`~slam2d.backend.pose_graph.PoseGraph` as a SLAM run feeds it (the
incremental path's benchmarks and tests)."""

from __future__ import annotations

import logging

import numpy as np

from slam2d.backend.pose_graph import PoseGraph
from slam2d.config import BackendConfig
from slam2d.datasets import g2o
from slam2d.errors import InputError

__all__ = ["replay_g2o"]

log = logging.getLogger(__name__)


def replay_g2o(graph: g2o.PoseGraphFile, cfg: BackendConfig | None = None, gate: float | None = None,
               every: int = 1) -> PoseGraph:
    """Feed a g2o graph into a PoseGraph as a SLAM run would: vertices 0..N-1 in order as
    keyframes (edge k -> k+1 as odometry, the file's pose as initial value) with an iSAM2
    update each; then every other edge ending there as a loop, skipped when ``gate`` is
    set and its ``loop_consistency`` exceeds it, and one more update if any was added.
    With ``every`` > 1 (no gate), one update per ``every`` keyframes and their loops."""
    if every > 1 and gate is not None:
        raise InputError("replay_g2o", "the consistency gate needs an update per keyframe (every = 1)")
    n = len(graph.ids)
    if not np.array_equal(graph.ids, np.arange(n)):
        raise InputError("replay_g2o", "vertex ids must be 0..N-1")
    odometry = {int(a): k for k, (a, b) in enumerate(zip(graph.i, graph.j)) if b == a + 1}
    missing = sorted(set(range(n - 1)) - set(odometry))
    if missing:
        raise InputError("replay_g2o", f"no edge {missing[0]} -> {missing[0] + 1} to use as odometry")
    loops: dict[int, list[int]] = {}
    for k, (a, b) in enumerate(zip(graph.i.tolist(), graph.j.tolist())):
        if k != odometry.get(a, -1):
            loops.setdefault(max(a, b), []).append(k)
    pg = PoseGraph(cfg)
    for v in range(n):
        if v == 0:
            pg.add_keyframe(graph.poses[0])
        else:
            e = odometry[v - 1]
            pg.add_keyframe(graph.poses[v], graph.measurements[e], graph.information[e])
        if every == 1:
            pg.update()
        added = 0
        for k in loops.get(v, []):
            a, b, m, info = graph.i[k], graph.j[k], graph.measurements[k], graph.information[k]
            if gate is not None and pg.loop_consistency(a, b, m, info) > gate:
                log.info("replay: loop %d -> %d fails the consistency gate", a, b)
                continue
            pg.add_loop(a, b, m, info)
            added += 1
        if (every == 1 and added) or (every > 1 and ((v + 1) % every == 0 or v == n - 1)):
            pg.update()
    return pg
