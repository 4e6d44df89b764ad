"""The SLAM pose graph's final check of its loops, and a second chance for the loops it removes.

After the batch optimisation a loop whose squared Mahalanobis residual exceeds ``CHI2_3DOF_99`` is removed:
the optimised graph could not accommodate it (``inconsistent_loops``). A true loop that closes a long drift
(a return to the start after minutes without a loop) can be removed too: under the robust kernel it enters
where the kernel has saturated it, pulls nothing, and fails the check at the solution that ignored it.

``second_chance`` tries the removed loops again, one cluster at a time (loops whose later keyframes lie within
``CLUSTER_KEYFRAMES`` of each other: the loops of one return): least squares with the cluster as plain Gaussian
factors beside the graph's active factors. When every loop passes the check there, the kept ones and the
cluster's, the loops agree with each other: the cluster is readmitted, and the graph with its robust factors is
solved from there. The chain between keyframes is not asked to pass: a frontend's chain states its certainty
scan by scan and says nothing of a stretch that turned too far (the clinic's return, docs/benchmarks.md). A
false loop rarely passes: it must fit without pushing any other loop out of the gate. At the end the check runs
once more, without a second chance: a readmitted loop that the robust solution lets go again is removed.
"""

from __future__ import annotations

import logging

from slam2d.backend.consistency import CHI2_3DOF_99
from slam2d.backend.factors import gtsam_pose, pose_key

log = logging.getLogger(__name__)

CLUSTER_KEYFRAMES = 100  # removed loops whose later keyframes are this close (keyframes) are tried together


def loop_chi2(values, f) -> float:
    """Squared Mahalanobis residual of the loop factor record ``f`` (i, j, measurement, information) at
    gtsam.Values ``values``."""
    import gtsam

    rel = values.atPose2(pose_key(f.i)).between(values.atPose2(pose_key(f.j)))
    err = gtsam.Pose2.Logmap(gtsam_pose(f.measurement).between(rel))
    return float(err @ f.information @ err)


def inconsistent_loops(factors, active, values) -> list[int]:
    """Indices of the active loops (``factors``: records with kind, i, j, measurement, information; ``active``
    bool per factor) whose squared Mahalanobis residual at ``values`` exceeds ``CHI2_3DOF_99``."""
    return [n for n, (f, a) in enumerate(zip(factors, active))
            if a and f.kind == "loop" and loop_chi2(values, f) > CHI2_3DOF_99]


def clusters(factors, removed) -> list[list[int]]:
    """The ``removed`` loop indices grouped by their later keyframe (the larger of ``i``, ``j``): a loop joins the
    cluster of the one before it, in that order, when their later keyframes differ by at most ``CLUSTER_KEYFRAMES``."""
    later = {n: max(factors[n].i, factors[n].j) for n in removed}
    out: list[list[int]] = []
    for n in sorted(removed, key=later.get):
        if out and later[n] - later[out[-1][-1]] <= CLUSTER_KEYFRAMES:
            out[-1].append(n)
        else:
            out.append([n])
    return out


def second_chance(factors, active, batch_graph, removed, values, lm):
    """Readmit (``active[n] = True``) the clusters of the ``removed`` loops that the graph accommodates (see the
    module), from gtsam.Values ``values``; then deactivate the loops that fail the check at the solution (without a
    second chance). ``factors`` and ``active`` as in :func:`inconsistent_loops`, ``batch_graph()`` the gtsam graph
    of the active factors, ``lm(graph, initial) -> (values, iterations)``. Returns the solution over the active
    factors and the loops deactivated at the end."""
    import gtsam

    current = lm(batch_graph(), values)[0]
    for cluster in clusters(factors, removed):
        trial = batch_graph()
        for n in cluster:
            f = factors[n]
            trial.add(gtsam.BetweenFactorPose2(pose_key(f.i), pose_key(f.j), gtsam_pose(f.measurement),
                                               gtsam.noiseModel.Gaussian.Information(f.information)))
        fitted = lm(trial, current)[0]  # least squares with the cluster: where it fits, if anywhere
        pairs = [(factors[n].i, factors[n].j) for n in cluster]
        for n in cluster:
            active[n] = True
        worst = max(loop_chi2(fitted, f) for f, a in zip(factors, active) if a and f.kind == "loop")
        if worst > CHI2_3DOF_99:
            for n in cluster:
                active[n] = False
            log.info("loops %s left out: with them a loop's residual reaches %.3g", pairs, worst)
            continue
        log.info("loops %s readmitted: with them every loop's residual is within %.3g", pairs, CHI2_3DOF_99)
        current = lm(batch_graph(), fitted)[0]
    out = inconsistent_loops(factors, active, current)
    for n in out:
        active[n] = False
    return (lm(batch_graph(), current)[0] if out else current), out
