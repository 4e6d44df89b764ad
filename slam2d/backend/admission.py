"""Greedy admission of rejected loops by their innovation against the kept graph.

A loop that the pairwise screen could not support (no partner loop nearby) and that lies far from a
solution of the kept loops is lost by DCS and the final gate, though it may agree with the kept graph
once that graph's uncertainty is counted: on MIT (20 loops, most of them alone) 12 of 20 true loops fail
the screen, and the screened solution is 27 m off where they would pull.

``admit_consistent`` linearises every edge at the least-squares solution of the kept edges (GTSAM's
whitened Jacobians) and, for each rejected loop, computes its innovation: the squared Mahalanobis
distance of its whitened residual under ``I + J H^-1 J^T`` (its own noise plus the covariance of the
relative pose the kept graph predicts, first order). The loop with the smallest innovation within the
gate enters, least squares over the kept edges runs again, and so on. One loop per round: a false loop
that fits a loosely constrained graph faces a sharper test once the true loops that agree better are
in. Poses are ``(x, y, theta)`` (m, m, rad).
"""

from __future__ import annotations

import numpy as np

from slam2d.backend.factors import factor_graph, g2o_values, pose_key, prior_factor
from slam2d.backend.lm import in_worker
from slam2d.datasets import g2o

ADMIT_MAX_ROUNDS = 20  # loops admitted at most (each round one factorisation and one least-squares solve; MIT
# needs 10-12; MIT with 1000 random false loops, most of them kept, spent 48 s in 50 rounds)
BLOCK = 300  # rejected loops whose innovations are solved for together (3 right-hand sides each)
ADMIT_MAX_REJECTED = BLOCK  # with more rejected edges the stage does not run: its cost grows with their number
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


def innovations(graph: g2o.PoseGraphFile, plain: list, keep, poses, edges) -> np.ndarray:
    """(K,) squared innovation of each of ``edges`` (K,) against the edges where ``keep`` (M,) is set,
    linearised at ``poses`` (N, 3), their least-squares solution (see module)."""
    from scipy.sparse.linalg import splu

    a, b = _linear_system(graph, plain, poses)
    kept = a[np.r_[np.repeat(np.asarray(keep, bool), 3), [True] * 3]]
    lu = splu((kept.T @ kept).tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
              options={"SymmetricMode": True})
    out = np.empty(len(edges))
    for s in range(0, len(edges), BLOCK):
        rows = (3 * np.asarray(edges[s:s + BLOCK])[:, None] + np.arange(3)).ravel()
        jc = a[rows]
        cross = (jc @ lu.solve(jc.T.toarray())).reshape(len(rows) // 3, 3, len(rows) // 3, 3)
        k = np.arange(len(rows) // 3)
        s_mat = np.eye(3) + cross[k, :, k, :]  # (K, 3, 3)
        r = b[rows].reshape(-1, 3)
        out[s:s + len(k)] = np.einsum("ki,ki->k", r, np.linalg.solve(s_mat, r[..., None])[..., 0])
    return out


def admit_consistent(graph: g2o.PoseGraphFile, plain: list, keep, poses, gate: float, solve):
    """Greedy admission (see module) of the loops outside ``keep`` (M,) bool, starting from ``poses`` (N, 3),
    the least-squares solution of the kept edges: while some loop's innovation is within ``gate``
    (chi-square), fewer than ``ADMIT_MAX_ROUNDS`` entered and at most ``ADMIT_MAX_REJECTED`` are out,
    the smallest enters and ``solve(keep, poses)`` (least squares over the kept edges; returns (poses,
    LM iterations)) runs. Returns (keep, poses, LM iterations, loops admitted)."""
    keep, iterations, admitted = np.array(keep, bool), 0, 0
    while admitted < ADMIT_MAX_ROUNDS:
        rejected = np.flatnonzero(~keep)
        if not len(rejected) or len(rejected) > ADMIT_MAX_REJECTED:
            break
        d2 = in_worker(innovations, graph, plain, keep, poses, rejected)
        best = int(np.argmin(d2))
        if not d2[best] <= gate:
            break
        keep[rejected[best]] = True
        poses, n = solve(keep, poses)
        iterations, admitted = iterations + n, admitted + 1
    return keep, poses, iterations, admitted
