"""SE-Sync's optimality certificate for 2D pose graphs (Rosen et al. 2019), numpy / scipy only.

SE-Sync's isotropic objective: every edge ``i -> j`` (rotation ``R~``, translation ``t~``)
costs ``kappa |R_j - R_i R~|_F^2 + tau |t_j - t_i - R_i t~|^2`` with SE-Sync's weights from
the g2o information ``L``: ``kappa = L_theta_theta`` (1/rad^2), ``tau = 2 / trace(inv(L_xy))``
(1/m^2). With ``X = [t_1 .. t_n | R_1 .. R_n]`` (2 x 3n) it is ``tr(X M X^T)``, ``M`` (3n x 3n)
sparse. At a critical point ``X`` on ``R^2n x SO(2)^n`` the Lagrange multipliers are
``Lambda_i = sym((M X^T X)_ii)`` on each rotation block (zero on translations), and ``X`` is a
global minimum when ``S = M - diag(0, Lambda)`` is positive semidefinite (SE-Sync's
certificate; sufficient, and exact unless the noise is large). ``S + eta I`` is tested by
an LDL^T factorisation: by Sylvester's law its pivots are all positive if and only if every
eigenvalue of ``S`` exceeds ``-eta``.

This certifies the isotropic objective, not GTSAM's (anisotropic information, SE(2) log):
``certify`` first polishes the given poses to a critical point of the isotropic objective by
Newton's method, so a certified result says that the GTSAM optimum lies in the basin of the
isotropic problem's global minimum.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slam2d.backend.consistency import id_ranks
from slam2d.backend.sparse import SymmetricFactor, held_first, unknowns
from slam2d.datasets import g2o

ETA_REL = 1e-7  # eigenvalue tolerance, relative to the largest diagonal entry of M
STATIONARY_REL = 1e-8  # a critical point: |S X^T| within this times max |M_kk| max |X| (largest entries)
POLISH_ITERATIONS = 50  # Newton steps at most
POLISH_TOL = 1e-10  # stop when the step's largest entry (m / rad) is below this
POLISH_CONTRACTION = 2.0  # a Hessian factorisation is reused while each step is at least this many times smaller
POLISH_STATIONARY = 0.1 * STATIONARY_REL  # the polish stops once this stationary (a tenth of the certificate's
# tolerance: M3500's optimum after 6 Newton steps, not 19)


@dataclass(frozen=True)
class Certificate:
    """``certified``: the polished poses (N, 3) ``poses`` are a critical point (``stationarity``,
    relative, within STATIONARY_REL) where S + eta I is positive definite; ``cost``: the isotropic
    objective there; ``moved``: largest position change (m) of the polish; ``negative_pivots``:
    pivots <= 0 of the LDL^T of S + eta I (-1: a zero pivot); ``eta``."""

    certified: bool
    cost: float
    poses: np.ndarray
    moved: float
    stationarity: float
    negative_pivots: int
    eta: float


def isotropic_weights(graph: g2o.PoseGraphFile) -> tuple[np.ndarray, np.ndarray]:
    """SE-Sync's (kappa, tau) (M,) of every edge."""
    kappa = graph.information[:, 2, 2]
    tau = 2.0 / np.trace(np.linalg.inv(graph.information[:, :2, :2]), axis1=1, axis2=2)
    return kappa, tau


def _rot(theta: np.ndarray) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def _residuals(graph, a, b, kappa, tau, poses):
    """Isotropic residuals (M, 3): rotation (2 sqrt(2 kappa) sin(d/2), whose square is the
    Frobenius term) and translation (2,), and the angle errors d (M,)."""
    d = poses[b, 2] - poses[a, 2] - graph.measurements[:, 2]
    rt = np.einsum("mij,mj->mi", _rot(poses[a, 2]), graph.measurements[:, :2])
    rot = 2.0 * np.sqrt(2.0 * kappa) * np.sin(0.5 * d)
    trans = np.sqrt(tau)[:, None] * (poses[b, :2] - poses[a, :2] - rt)
    return np.column_stack([rot, trans]), d


def _jacobian(graph, a, b, kappa, tau, poses, d, n):
    """Sparse (3M, 3N) Jacobian of the residuals; unknowns (x, y, theta) per vertex."""
    from scipy.sparse import csr_matrix

    m = len(a)
    e = np.arange(m)
    half = np.sqrt(2.0 * kappa) * np.cos(0.5 * d)
    c, s = np.cos(poses[a, 2]), np.sin(poses[a, 2])
    tx, ty = graph.measurements[:, 0], graph.measurements[:, 1]
    st = np.sqrt(tau)
    rows = [3 * e, 3 * e]
    cols = [3 * b + 2, 3 * a + 2]
    vals = [half, -half]
    dr = np.stack([-(-s * tx - c * ty), -(c * tx - s * ty)], 1)  # d(-R_i t~)/d theta_i
    for k in range(2):
        rows += [3 * e + 1 + k] * 3
        cols += [3 * b + k, 3 * a + k, 3 * a + 2]
        vals += [st, -st, st * dr[:, k]]
    return csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * m, 3 * n))


def _curvature(graph, a, b, kappa, tau, poses, r, d, n):
    """Sparse (3N, 3N) second-order part of the Hessian of 0.5 |r|^2 (sum r_k d2 r_k), headings only."""
    from scipy.sparse import coo_matrix

    w = -r[:, 0] * 0.5 * np.sqrt(2.0 * kappa) * np.sin(0.5 * d)  # rotation residual: d2/d(theta_a, theta_b)
    rt = np.einsum("mij,mj->mi", _rot(poses[a, 2]), graph.measurements[:, :2])
    u = np.sqrt(tau) * np.sum(r[:, 1:] * rt, 1)  # translation residual: d2/d theta_a^2 = sqrt(tau) R_a t~
    ta, tb = 3 * a + 2, 3 * b + 2
    rows = np.concatenate([ta, tb, ta, tb, ta])
    cols = np.concatenate([ta, tb, tb, ta, ta])
    return coo_matrix((np.concatenate([w, w, -w, -w, u]), (rows, cols)), shape=(3 * n, 3 * n)).tocsc()


def _newton_factor(graph, a, b, kappa, tau, x, r, d, n, free, perm=None):
    """Factorisation of Newton's Hessian at ``x`` (free unknowns, taken in the order ``perm``), or of
    Gauss-Newton's when Newton's is singular."""
    j = _jacobian(graph, a, b, kappa, tau, x, d, n)
    gauss = j.T @ j
    try:
        return SymmetricFactor((gauss + _curvature(graph, a, b, kappa, tau, x, r, d, n))[free][:, free], perm)
    except RuntimeError:
        return SymmetricFactor(gauss[free][:, free], perm)


def polish(graph: g2o.PoseGraphFile, poses, mat=None, elimination=None) -> np.ndarray:
    """Poses (N, 3) at a critical point of the isotropic objective, reached from ``poses`` by
    Newton steps that reuse one factorisation of the Hessian while the steps shrink at least
    ``POLISH_CONTRACTION``-fold (chord method: two factorisations on M3500's optimum instead of five), a
    fresh one otherwise; first vertex held; a step that raises the cost is halved. Stops once the poses
    are ``POLISH_STATIONARY`` (``stationarity``; ``mat``: the graph's ``data_matrix``) or the step is below
    ``POLISH_TOL``. ``elimination``: the vertices' id ranks in a fill-reducing order (``certify``)."""
    a, b = id_ranks(graph)
    order = np.argsort(graph.ids)
    x = np.asarray(poses, dtype=np.float64)[order].copy()
    kappa, tau = isotropic_weights(graph)
    n = len(x)
    free = np.arange(3, 3 * n)
    perm = unknowns(held_first(elimination), lambda k: 3 * k[:, None] + np.arange(3))  # the first vertex held
    mat = data_matrix(graph) if mat is None else mat
    r, d = _residuals(graph, a, b, kappa, tau, x)
    lu, last = None, np.inf
    for _ in range(POLISH_ITERATIONS):
        if stationarity(mat, _variables(x)) <= POLISH_STATIONARY:
            break
        gradient = (_jacobian(graph, a, b, kappa, tau, x, d, n).T @ r.ravel())[free]
        step = None if lu is None else -lu.solve(gradient)
        if step is None or not (np.isfinite(step).all() and step @ gradient < 0):
            lu = _newton_factor(graph, a, b, kappa, tau, x, r, d, n, free, perm)  # fresh Hessian
            step = -lu.solve(gradient)
        size = float(np.abs(step).max())
        if size > last / POLISH_CONTRACTION:
            lu = None  # too slow a contraction: a fresh Hessian next time
        last = size
        for _ in range(30):
            trial = x.copy()
            trial[1:] += step.reshape(-1, 3)
            r_new, d_new = _residuals(graph, a, b, kappa, tau, trial)
            if np.sum(r_new**2) <= np.sum(r**2) * (1 + 1e-12):
                break
            step *= 0.5
        x, r, d = trial, r_new, d_new
        if np.abs(step).max() < POLISH_TOL:
            break
    out = np.empty_like(x)
    out[order] = x
    return out


def data_matrix(graph: g2o.PoseGraphFile):
    """Sparse symmetric M (3n x 3n): translations in columns 0..n-1 (id order), rotation block of
    vertex k in columns n + 2k, n + 2k + 1; the isotropic objective is tr(X M X^T)."""
    from scipy.sparse import coo_matrix

    a, b = id_ranks(graph)
    n, m = len(graph.ids), len(a)
    kappa, tau = isotropic_weights(graph)
    rt = _rot(graph.measurements[:, 2])  # (M, 2, 2)
    # rotation term: kappa |X A|_F^2, A (3n x 2): I at block b, -R~ at block a
    # translation term: tau |X B|^2, B (3n,): +1 at t_b, -1 at t_a, -t~ at block a
    cols_a = n + 2 * a[:, None] + np.arange(2)  # (M, 2)
    cols_b = n + 2 * b[:, None] + np.arange(2)
    rows, cols, vals = [], [], []

    def add(ri, ci, v):
        rows.append(np.broadcast_to(ri, v.shape).ravel())
        cols.append(np.broadcast_to(ci, v.shape).ravel())
        vals.append(v.ravel())

    k = kappa[:, None, None]
    add(cols_b[:, :, None], cols_b[:, None, :], k * np.eye(2)[None])
    add(cols_a[:, :, None], cols_a[:, None, :], k * np.einsum("mij,mkj->mik", rt, rt))
    add(cols_b[:, :, None], cols_a[:, None, :], -k * rt.transpose(0, 2, 1))  # I (-R~)^T
    add(cols_a[:, :, None], cols_b[:, None, :], -k * rt)
    vec = np.zeros((m, 4))  # B restricted to its 4 nonzero rows: t_b, t_a, block a (2)
    vec[:, 0], vec[:, 1], vec[:, 2:] = 1.0, -1.0, -graph.measurements[:, :2]
    idx = np.column_stack([b, a, cols_a])
    add(idx[:, :, None], idx[:, None, :], tau[:, None, None] * vec[:, :, None] * vec[:, None, :])
    return coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * n, 3 * n)).tocsc()


def _variables(poses_sorted: np.ndarray) -> np.ndarray:
    """X (2, 3n) of poses (n, 3) in id order."""
    n = len(poses_sorted)
    x = np.empty((2, 3 * n))
    x[:, :n] = poses_sorted[:, :2].T
    x[:, n:] = _rot(poses_sorted[:, 2]).transpose(1, 0, 2).reshape(2, 2 * n)
    return x


def _multipliers(mat, x: np.ndarray) -> tuple[np.ndarray, float]:
    """Lagrange multipliers Lambda (n, 2, 2) at X (2, 3n) and the stationarity |S X^T| there (largest entry,
    relative to max |M_kk| max |X|; S = M - diag(0, Lambda))."""
    n = x.shape[1] // 3
    y = mat @ x.T  # (3n, 2)
    xr = x[:, n:].reshape(2, n, 2).transpose(1, 0, 2)  # (n, 2, 2): row k of X^T's rotation block k is xr[k].T
    blocks = np.einsum("kij,kjl->kil", y[n:].reshape(n, 2, 2), xr)
    lam = 0.5 * (blocks + blocks.transpose(0, 2, 1))
    slack = np.abs(y[:n]).max(initial=0.0)  # S X^T = M X^T - diag(0, Lambda) X^T
    slack = max(slack, float(np.abs(y[n:].reshape(n, 2, 2) - lam @ xr.transpose(0, 2, 1)).max()))
    return lam, slack / float(np.abs(mat.diagonal()).max() * np.abs(x).max())


def stationarity(mat, x: np.ndarray) -> float:
    """|S X^T| at X (2, 3n), relative (see ``_multipliers``): 0 at a critical point."""
    return _multipliers(mat, x)[1]


def certify(graph: g2o.PoseGraphFile, poses, elimination=None) -> Certificate:
    """SE-Sync's certificate at the isotropic critical point nearest ``poses`` (N, 3) (see module). ``elimination``:
    the vertices' id ranks (N,) in a fill-reducing order (``factors.elimination_order``), which
    every factorisation follows; None: SuperLU's minimum degree. The order changes the rounding, not the
    outcome."""
    from scipy.sparse import coo_matrix, identity

    mat = data_matrix(graph)
    polished = polish(graph, poses, mat, elimination)
    order = np.argsort(graph.ids)
    n = len(order)
    x = _variables(polished[order])
    lam, stationary = _multipliers(mat, x)
    rows = n + 2 * np.arange(n)[:, None, None] + np.arange(2)[None, :, None]
    big = coo_matrix((lam.ravel(), (np.broadcast_to(rows, lam.shape).ravel(),
                                    np.broadcast_to(rows.transpose(0, 2, 1), lam.shape).ravel())), shape=(3 * n, 3 * n))
    eta = ETA_REL * float(np.abs(mat.diagonal()).max())
    s = (mat - big + eta * identity(3 * n, format="csc")).tocsc()
    try:
        lu = SymmetricFactor(s, unknowns(elimination, lambda k: np.column_stack([k, n + 2 * k, n + 2 * k + 1])))
        negative = int(np.sum(lu.pivots() <= 0))
    except RuntimeError:  # an exactly singular pivot: S + eta I is not positive definite
        negative = -1
    return Certificate(negative == 0 and stationary <= STATIONARY_REL, float(np.trace(x @ (mat @ x.T))), polished,
                       float(np.abs(polished[:, :2] - np.asarray(poses)[:, :2]).max()), stationary, negative, eta)
