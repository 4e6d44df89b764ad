"""Greedy admission of rejected loops by their innovation against the kept graph.

A loop that the pairwise screen could not support (no partner loop nearby) and that lies far from a
solution of the kept loops is lost by DCS and the final gate, though it may agree with the kept graph
once that graph's uncertainty is counted: on MIT (20 loops, most of them alone) 12 of 20 true loops fail
the screen, and the screened solution is 27 m off where they would pull.

``admit_consistent`` linearises every edge at the least-squares solution of the kept edges (GTSAM's
whitened Jacobians) and, for each rejected loop, computes its innovation: the squared Mahalanobis
distance of its whitened residual under ``I + J H^-1 J^T`` (its own noise plus the covariance of the
relative pose the kept graph predicts, first order). The loop with the smallest innovation within the
gate enters, and so on: one loop at a time, so that a false loop that fits a loosely constrained graph
faces a sharper test once the true loops that agree better are in. Each entry updates the linearised
graph as a Kalman filter would (every other loop's residual and covariance, no new factorisation); once
the entries have turned some pose by ``LINEAR_HEADING``, least squares over the kept edges renews the
linearisation (MIT: one loop a round; manhattan's 13 rejected true loops: 6 rounds instead of 13).
Poses are ``(x, y, theta)`` (m, m, rad).
"""

from __future__ import annotations

import numpy as np

from slam2d.backend.consistency import edge_chi2
from slam2d.backend.factors import factor_graph, g2o_values, pose_key, prior_factor
from slam2d.backend.lm import in_worker
from slam2d.datasets import g2o

ADMIT_MAX_ROUNDS = 20  # admission rounds at most (each one factorisation and one least-squares solve; MIT
# needs 10-12; MIT with 1000 random false loops, most of them kept, spent 48 s in 50 rounds)
LINEAR_HEADING = 0.01  # rad: the most the loops admitted in one round may turn any pose in the linearised graph
# before a solve renews the linearisation (a turn of 0.01 rad is linear to 5 mm at 100 m)
ADMIT_BOUND_SLACK = 2.0  # a loop's lower bound on its innovation may exceed the gate this much and still take part
# (the bound is first order; a relinearised graph may predict a little more spread)
ADMIT_MAX_REJECTED = 300  # with more rejected edges the stage does not run: its cost grows with their number
# times the poses (M3500 with 1000 rejected false loops: 32 s a round on the shared machine, against a 1 s solve)


def _linear_system(graph: g2o.PoseGraphFile, plain: list, poses):
    """(A, b): whitened Jacobian (3M + 3, 3N) of every edge and of the anchor prior (last 3 rows) at
    ``poses`` (N, 3), sparse CSR, and the whitened residuals (3M + 3,), both in GTSAM's linearisation."""
    from scipy.sparse import csr_matrix

    values = g2o_values(graph.ids, poses)
    fg = factor_graph(plain)
    key = pose_key(graph.ids[0])
    fg.add(prior_factor(key, values.atPose2(key)))
    rows, cols, vals = fg.linearize(values).sparseJacobian_()
    n3, m3 = 3 * len(graph.ids), 3 * (len(plain) + 1)
    j = csr_matrix((vals, (rows.astype(int) - 1, cols.astype(int) - 1)), shape=(m3, n3 + 1))
    return j[:, :n3], j[:, n3].toarray().ravel()


def admit_linearised(graph: g2o.PoseGraphFile, plain: list, keep, poses, edges, gate: float):
    """Positions in ``edges`` (K,) of the loops admitted, in order, against the edges where ``keep`` (M,) is
    set, in the graph linearised at ``poses`` (N, 3), their least-squares solution (see module): while the
    smallest innovation is within ``gate``, that loop enters as a Kalman update of the linear system (the
    others' residuals and covariances follow, no new factorisation), until the headings have moved by
    ``LINEAR_HEADING`` in all (the linearisation is then renewed by a solve). Returns (positions, (K,) the
    largest eigenvalue of each loop's innovation covariance before any entered)."""
    from scipy.sparse.linalg import splu

    a, b = _linear_system(graph, plain, poses)
    kept = a[np.r_[np.repeat(np.asarray(keep, bool), 3), [True] * 3]]
    lu = splu((kept.T @ kept).tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
              options={"SymmetricMode": True})
    rows = (3 * np.asarray(edges)[:, None] + np.arange(3)).ravel()
    jc = a[rows]
    gain = lu.solve(jc.T.toarray())  # (3N, 3K): H^-1 J^T
    cross = jc @ gain  # (3K, 3K): J H^-1 J^T
    r = b[rows].copy()
    heading = np.zeros(a.shape[1] // 3)
    left, order = np.ones(len(edges), bool), []
    covariance = lambda k: np.eye(3) + cross.reshape(len(edges), 3, len(edges), 3)[k, :, k, :]
    spread = np.linalg.eigvalsh(covariance(np.arange(len(edges))))[:, -1]
    while left.any():
        k = np.flatnonzero(left)
        s_mat = covariance(k)  # (k, 3, 3): each loop's innovation covariance
        res = r.reshape(-1, 3)[k]
        d2 = np.einsum("ki,ki->k", res, np.linalg.solve(s_mat, res[..., None])[..., 0])
        best = int(np.argmin(d2))
        if not d2[best] <= gate:
            break
        e = k[best]
        cols = slice(3 * e, 3 * e + 3)
        step = np.linalg.solve(s_mat[best], r[cols])
        heading += (gain[:, cols] @ step)[2::3]
        update = np.linalg.solve(s_mat[best], cross[cols, :])  # (3, 3K)
        r -= cross[:, cols] @ step
        gain -= gain[:, cols] @ update
        cross -= cross[:, cols] @ update
        left[e] = False
        order.append(e)
        if np.abs(heading).max() > LINEAR_HEADING:
            break
    return np.array(order, dtype=int), spread


def admit_consistent(graph: g2o.PoseGraphFile, plain: list, keep, poses, gate: float, solve, candidates=None):
    """Greedy admission (see module) of the loops outside ``keep`` (M,) bool, starting from ``poses`` (N, 3),
    the least-squares solution of the kept edges: rounds of ``admit_linearised`` (in a worker), each followed
    by ``solve(keep, poses)`` (least squares over the kept edges; returns (poses, LM iterations)), at most
    ``ADMIT_MAX_ROUNDS`` of them and only while at most ``ADMIT_MAX_REJECTED`` may enter (``candidates`` (M,)
    bool: only these loops may; default every loop out). A loop takes part
    in a later round only while its squared whitened residual over the largest eigenvalue of its innovation
    covariance in an earlier round, a lower bound of its innovation (entries only shrink that covariance),
    is within ``ADMIT_BOUND_SLACK`` times the gate (manhattan with 100 random false loops: 17 loops take
    part in the second round instead of 112). Returns (keep, poses, LM iterations, loops admitted)."""
    keep, iterations, admitted = np.array(keep, bool), 0, 0
    spread = np.full(len(keep), np.inf)
    for _ in range(ADMIT_MAX_ROUNDS):
        rejected = np.flatnonzero(~keep if candidates is None else ~keep & candidates)
        if not len(rejected) or len(rejected) > ADMIT_MAX_REJECTED:
            break
        rejected = rejected[edge_chi2(graph, poses)[rejected] <= ADMIT_BOUND_SLACK * gate * spread[rejected]]
        if not len(rejected):
            break
        order, first = in_worker(admit_linearised, graph, plain, keep, poses, rejected, gate)
        spread[rejected] = np.minimum(spread[rejected], first)
        if not len(order):
            break
        keep[rejected[order]] = True
        poses, n = solve(keep, poses)
        iterations, admitted = iterations + n, admitted + len(order)
    return keep, poses, iterations, admitted
