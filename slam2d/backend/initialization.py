"""Initial estimates for batch optimisation of a 2D pose graph (no GTSAM needed).

- ``chordal``: rotation synchronisation by the chordal relaxation (Carlone et al.
  2015): each rotation as (cos, sin), every edge a linear constraint
  ``R_j = R_i R_ij`` weighted by its heading information, solved in sparse least
  squares and projected back to angles; then translations from the linear system
  ``t_j - t_i = R_i t_ij`` weighted by the translation information.
- ``spanning_tree``: measurements composed along a spanning tree that prefers
  odometry edges (``j == i + 1``), breadth first from the first vertex.
- ``file``: the graph's own poses.

Every start holds the first vertex at the file's pose. Poses are ``(N, 3)``
``(x, y, theta)`` in m, m, rad, ordered like ``graph.ids``.
"""

from __future__ import annotations

import numpy as np

from slam2d import geometry
from slam2d.backend.sparse import SymmetricFactor, held_first, unknowns
from slam2d.datasets import g2o
from slam2d.errors import InputError

INITS = ("chordal", "spanning_tree", "file")


def _edge_index(graph: g2o.PoseGraphFile) -> tuple[np.ndarray, np.ndarray]:
    """Row numbers (into ``graph.ids``) of every edge's two ends."""
    order = np.argsort(graph.ids)
    a = order[np.searchsorted(graph.ids, graph.i, sorter=order)]
    b = order[np.searchsorted(graph.ids, graph.j, sorter=order)]
    if not (np.array_equal(graph.ids[a], graph.i) and np.array_equal(graph.ids[b], graph.j)):
        raise InputError("g2o graph", "an edge refers to an unknown vertex")
    return a, b


def _solve_anchored(rows, cols, vals, rhs, n_vars, fixed, perm=None):
    """Least squares ``A x ~ rhs`` (A sparse from triplets) with ``x[k] = v`` for (k, v) in ``fixed``; the normal
    equations factorised with the free unknowns in the order ``perm`` (None: scipy's ``spsolve``)."""
    from scipy.sparse import csc_matrix
    from scipy.sparse.linalg import spsolve

    a = csc_matrix((vals, (rows, cols)), shape=(len(rhs), n_vars))
    keep = np.ones(n_vars, bool)
    x = np.zeros(n_vars)
    for k, v in fixed:
        keep[k], x[k] = False, v
    rhs = rhs - a @ x
    a_free = a[:, keep]
    normal, projected = a_free.T @ a_free, a_free.T @ rhs
    x[keep] = spsolve(normal.tocsc(), projected) if perm is None else SymmetricFactor(normal, perm).solve(projected)
    return x


def _free_order(graph: g2o.PoseGraphFile, elimination) -> np.ndarray | None:
    """The order of the free unknowns (two a vertex, the first vertex's held) of the vertices' id ranks
    ``elimination`` (None: None)."""
    rows = None if elimination is None else np.argsort(graph.ids)[np.asarray(elimination)]
    return unknowns(held_first(rows), lambda k: 2 * k[:, None] + np.arange(2))


def chordal_rotations(graph: g2o.PoseGraphFile, weighted: bool = True, elimination=None) -> np.ndarray:
    """Headings (N,) in rad by the chordal relaxation, vertex 0 at the file's heading;
    each edge weighted by the square root of its heading information (1 unless ``weighted``). ``elimination``:
    the vertices' id ranks in a fill-reducing order (``factors.elimination_order``; None: scipy's own)."""
    a, b = _edge_index(graph)
    m, n = len(a), len(graph.ids)
    c, s = np.cos(graph.measurements[:, 2]), np.sin(graph.measurements[:, 2])
    w = np.sqrt(graph.information[:, 2, 2]) if weighted else np.ones(m)
    e = np.arange(m)
    # unknowns: cos at 2k, sin at 2k + 1; rows: cos_j - (c cos_i - s sin_i), sin_j - (s cos_i + c sin_i)
    rows = np.r_[2 * e, 2 * e, 2 * e, 2 * e + 1, 2 * e + 1, 2 * e + 1]
    cols = np.r_[2 * b, 2 * a, 2 * a + 1, 2 * b + 1, 2 * a, 2 * a + 1]
    vals = np.r_[w, -w * c, w * s, w, -w * s, -w * c]
    t0 = graph.poses[0, 2]
    x = _solve_anchored(rows, cols, vals, np.zeros(2 * m), 2 * n, [(0, np.cos(t0)), (1, np.sin(t0))],
                        _free_order(graph, elimination))
    return np.arctan2(x[1::2], x[0::2])


def translations(graph: g2o.PoseGraphFile, theta, weighted: bool = True, elimination=None) -> np.ndarray:
    """Positions (N, 2) in m minimising the translation residuals for fixed headings ``theta`` (N,),
    whitened by each edge's translation information (identity unless ``weighted``); ``elimination`` as in
    ``chordal_rotations``."""
    a, b = _edge_index(graph)
    m, n = len(a), len(graph.ids)
    # whiten in the frame of vertex i: L^T R_i^T (t_j - t_i - R_i t_ij), Lambda_xy = L L^T
    lam = graph.information[:, :2, :2] if weighted else np.broadcast_to(np.eye(2), (m, 2, 2))
    chol = np.linalg.cholesky(lam)  # lower, (M, 2, 2)
    rot = geometry.rotation(theta[a])  # (M, 2, 2)
    wmat = np.einsum("mji,mkj->mik", chol, rot)  # L^T R^T
    rhs = np.einsum("mij,mj->mi", chol.transpose(0, 2, 1), graph.measurements[:, :2]).ravel()
    rows, cols, vals = [], [], []
    for r in range(2):
        for k in range(2):
            rows += [2 * np.arange(m) + r] * 2
            cols += [2 * b + k, 2 * a + k]
            vals += [wmat[:, r, k], -wmat[:, r, k]]
    x = _solve_anchored(np.concatenate(rows), np.concatenate(cols), np.concatenate(vals), rhs, 2 * n,
                        [(0, graph.poses[0, 0]), (1, graph.poses[0, 1])], _free_order(graph, elimination))
    return x.reshape(n, 2)


def chordal(graph: g2o.PoseGraphFile, weighted: bool = True, elimination=None) -> np.ndarray:
    """Chordal start (N, 3): rotations by synchronisation, then linear translations
    (isotropic unit weights unless ``weighted``; ``elimination`` as in ``chordal_rotations``)."""
    theta = chordal_rotations(graph, weighted, elimination)
    return np.column_stack([translations(graph, theta, weighted, elimination), theta])


def spanning_tree(graph: g2o.PoseGraphFile) -> np.ndarray:
    """Poses (N, 3) composed along a minimum spanning tree that prefers odometry edges."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order, minimum_spanning_tree

    a, b = _edge_index(graph)
    n = len(graph.ids)
    cost = np.where(np.abs(graph.j - graph.i) == 1, 1.0, 2.0)
    tree = minimum_spanning_tree(coo_matrix((cost, (a, b)), shape=(n, n)).tocsr())
    order, pred = breadth_first_order(tree, 0, directed=False)
    edge = {}
    for k, (x, y) in enumerate(zip(a.tolist(), b.tolist())):
        edge.setdefault((x, y), k)
    poses = np.tile(graph.poses[0], (n, 1))
    for v in order[1:].tolist():
        p = int(pred[v])
        if (p, v) in edge:
            poses[v] = geometry.compose(poses[p], graph.measurements[edge[p, v]])
        else:
            poses[v] = geometry.compose(poses[p], geometry.inverse(graph.measurements[edge[v, p]]))
    if len(order) < n:
        raise InputError("g2o graph", f"{n - len(order)} vertices not connected to vertex {graph.ids[0]}")
    return poses


def initial_poses(graph: g2o.PoseGraphFile, init: str = "chordal", elimination=None) -> np.ndarray:
    """Start (N, 3) named ``init``: "chordal", "spanning_tree" or "file" (``elimination``: as in ``chordal``)."""
    name = str(init).lower()
    if name not in INITS:
        raise InputError("init", f"unknown initialisation {init!r} (choose from {', '.join(INITS)})")
    if name == "file":
        return np.array(graph.poses, dtype=np.float64)
    return chordal(graph, elimination=elimination) if name == "chordal" else spanning_tree(graph)
