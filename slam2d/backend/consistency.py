"""Loop-closure consistency through the odometry chain (numpy only, no GTSAM).

Two loops whose ends lie close together along the trajectory close a short
cycle with the odometry between their ends: loop 1 ``a -> b``, odometry
``b -> d``, loop 2 back ``d -> c``, odometry ``c -> a``. Its error, whitened by
the covariance of the four relative poses (first order, the odometry chain's
covariance from prefix sums), is chi-square with 3 degrees of freedom when both
loops are true (the pairwise consistency of PCM, Mangelson et al. 2018). A loop
that spans few vertices is checked against the odometry between its own ends.

``pairwise_support`` marks the loops consistent with at least one such short
cycle. A false loop between random places has no partner and fails; true loops
come in runs along revisited corridors and pass; a group of mutually consistent
false loops passes too and is left to the robust optimisation.

``edge_chi2`` is the squared whitened residual of every edge at given poses,
GTSAM's ``2 * BetweenFactorPose2.error`` (Pose2 logmap) in one vectorised pass.

Poses are ``(x, y, theta)`` (m, m, rad); covariances are in the tangent space
of the pose they belong to (GTSAM's right perturbation, order x, y, theta).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from slam2d import geometry
from slam2d.datasets import g2o
from slam2d.errors import InputError

SUPPORT_WINDOW = 10  # vertices: the most each end of a partner loop (or a loop's own ends) may lie apart
CHI2_3DOF_99 = 11.344866730144373  # chi-square 99 % quantile, 3 degrees of freedom
CHI2_3DOF_MEDIAN = 2.3659738843753377  # chi-square median, 3 degrees of freedom
CHI2_3DOF_QUARTILE = 1.2125329030456691  # chi-square lower quartile, 3 degrees of freedom


def _sandwich(a: np.ndarray, s: np.ndarray) -> np.ndarray:
    """a s a^T over leading dimensions."""
    return a @ s @ np.swapaxes(a, -1, -2)


def _mahalanobis2(r: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """(P,) r^T cov^-1 r for residuals (P, 3) and covariances (P, 3, 3)."""
    return np.einsum("pi,pi->p", r, np.linalg.solve(cov, r[..., None])[..., 0])


def edge_rows(graph: g2o.PoseGraphFile) -> tuple[np.ndarray, np.ndarray]:
    """Row numbers (into ``graph.ids``) of every edge's two ends; InputError for an unknown vertex."""
    order = np.argsort(graph.ids)
    a = np.searchsorted(graph.ids, graph.i, sorter=order).clip(0, len(order) - 1)
    b = np.searchsorted(graph.ids, graph.j, sorter=order).clip(0, len(order) - 1)
    a, b = order[a], order[b]
    if not (np.array_equal(graph.ids[a], graph.i) and np.array_equal(graph.ids[b], graph.j)):
        k = int(np.argmax((graph.ids[a] != graph.i) | (graph.ids[b] != graph.j)))
        raise InputError("g2o graph", f"edge {graph.i[k]} -> {graph.j[k]} to an unknown vertex")
    return a, b


def edge_chi2(graph: g2o.PoseGraphFile, poses) -> np.ndarray:
    """(M,) squared whitened residual of every edge at ``poses`` (N, 3), no robust kernel."""
    a, b = edge_rows(graph)
    poses = np.asarray(poses, dtype=np.float64)
    r = geometry.logmap(geometry.between(graph.measurements, geometry.between(poses[a], poses[b])))
    return np.einsum("mi,mij,mj->m", r, graph.information, r)


def id_ranks(graph: g2o.PoseGraphFile) -> tuple[np.ndarray, np.ndarray]:
    """Every edge's two ends as ranks in id order (0 = smallest id)."""
    a, b = edge_rows(graph)
    rank = np.empty(len(graph.ids), int)
    rank[np.argsort(graph.ids)] = np.arange(len(graph.ids))
    return rank[a], rank[b]


@dataclass(frozen=True)
class OdometryChain:
    """Dead reckoning along the odometry edges, indexed by id rank: poses ``dead`` (N, 3),
    prefix sums ``prefix`` (N, 3, 3) of the step covariances moved to the world frame, and
    ``segment`` (N,) numbering the runs of vertices linked by odometry."""

    dead: np.ndarray
    prefix: np.ndarray
    segment: np.ndarray

    def relative(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Relative poses (P, 3) of ranks ``y`` seen from ranks ``x`` along the odometry and their
        covariances (P, 3, 3) in the frame of ``y`` (ranks of one segment)."""
        rel = geometry.between(self.dead[x], self.dead[y])
        world = np.where((y >= x)[:, None, None], self.prefix[y] - self.prefix[x], self.prefix[x] - self.prefix[y])
        return rel, _sandwich(np.linalg.inv(geometry.adjoint(self.dead[y])), world)


def odometry_chain(graph: g2o.PoseGraphFile) -> OdometryChain:
    """The ``OdometryChain`` of ``graph`` (odometry: ``g2o.odometry_mask``; an edge from id k
    to id k + 1 links consecutive ranks)."""
    steps = max(len(graph.ids) - 1, 0)
    odo = np.flatnonzero(g2o.odometry_mask(graph))
    first = id_ranks(graph)[0][odo]
    step, cov, linked = np.zeros((steps, 3)), np.zeros((steps, 3, 3)), np.zeros(steps, bool)
    step[first], cov[first], linked[first] = graph.measurements[odo], np.linalg.inv(graph.information[odo]), True
    theta = np.r_[0.0, np.cumsum(step[:, 2])]
    c, s = np.cos(theta[:-1]), np.sin(theta[:-1])
    moves = np.column_stack([c * step[:, 0] - s * step[:, 1], s * step[:, 0] + c * step[:, 1]])
    dead = np.column_stack([np.vstack([[0.0, 0.0], np.cumsum(moves, 0)]), theta])
    world = _sandwich(geometry.adjoint(dead[1:]), cov)
    prefix = np.concatenate([np.zeros((1, 3, 3)), np.cumsum(world, 0)])
    return OdometryChain(dead, prefix, np.r_[0, np.cumsum(~linked)])


def _loops_forward(graph: g2o.PoseGraphFile):
    """Loop edges (indices), their ends as id ranks (first < second), measurements and
    covariances turned to match."""
    loops = np.flatnonzero(~g2o.odometry_mask(graph))
    ra, rb = id_ranks(graph)
    a, b = ra[loops], rb[loops]
    z, cov = graph.measurements[loops].copy(), np.linalg.inv(graph.information[loops])
    flip = a > b
    cov[flip] = _sandwich(geometry.adjoint(z[flip]), cov[flip])  # covariance of the inverse measurement
    z[flip] = geometry.inverse(z[flip])
    a[flip], b[flip] = b[flip], a[flip]
    return loops, a, b, z, cov


def pairwise_support(graph: g2o.PoseGraphFile, window: int = SUPPORT_WINDOW,
                     gate: float = CHI2_3DOF_99) -> np.ndarray:
    """(M,) bool: odometry edges, and every loop that closes a consistent short cycle (squared
    Mahalanobis error within ``gate``) with another loop whose ends each lie within ``window``
    vertices of its own, or with the odometry between its own ends when they are within ``window``."""
    from scipy.spatial import cKDTree

    chain = odometry_chain(graph)
    loops, a, b, z, cov = _loops_forward(graph)
    seg = chain.segment
    support = np.zeros(len(loops), bool)
    if len(loops) > 1:
        pairs = cKDTree(np.column_stack([a, b])).query_pairs(window, p=np.inf, output_type="ndarray")
        k, m = pairs[:, 0], pairs[:, 1]
        same = (seg[a[k]] == seg[a[m]]) & (seg[b[k]] == seg[b[m]])
        k, m = k[same], m[same]
        o_ac, c_ac = chain.relative(a[k], a[m])
        o_bd, c_bd = chain.relative(b[k], b[m])
        r = geometry.logmap(geometry.between(geometry.compose(z[k], o_bd), geometry.compose(o_ac, z[m])))
        s = (_sandwich(geometry.adjoint(geometry.inverse(o_bd)), cov[k]) + c_bd
             + _sandwich(geometry.adjoint(geometry.inverse(z[m])), c_ac) + cov[m])
        good = _mahalanobis2(r, s) <= gate
        support[k[good]] = support[m[good]] = True
    short = np.flatnonzero((b - a <= window) & (seg[a] == seg[b]))
    o, c = chain.relative(a[short], b[short])
    support[short[_mahalanobis2(geometry.logmap(geometry.between(z[short], o)), cov[short] + c) <= gate]] = True
    out = np.ones(len(graph.i), bool)
    out[loops] = support
    return out


def residual_ratio(chi2: np.ndarray) -> float:
    """How much larger squared whitened residuals ``chi2`` (K,) are than the information matrices predict:
    their median over the chi-square median (3 dof); 1 when there is none. Above 1 the lower quartile over
    the chi-square's speaks for the true loops when it is lower (false loops among them)."""
    if not len(chi2):
        return 1.0
    ratio = float(np.median(chi2)) / CHI2_3DOF_MEDIAN
    return min(ratio, float(np.quantile(chi2, 0.25)) / CHI2_3DOF_QUARTILE) if ratio > 1 else ratio


REFUTE_P = 0.01  # a noise ratio above 1 is refuted when so many loops lie within the nominal gate that it
# leaves them less than this chance (the 1 % of the gates' 99 % quantile)


def chi2_3dof_cdf(x: float) -> float:
    """P(chi-square with 3 degrees of freedom <= ``x``)."""
    x = max(float(x), 0.0)
    return max(0.0, math.erf(math.sqrt(x / 2)) - math.sqrt(2 * x / math.pi) * math.exp(-x / 2))


LOOP_FAMILY_P = 0.01  # a graph's loop gate: the chance that one of its true loops, calibrated, lies beyond it


def loop_gate(loops: int) -> float:
    """The chi-square gate (3 dof) that all of ``loops`` true loops with calibrated information pass with
    probability 1 - ``LOOP_FAMILY_P`` (Sidak: each at (1 - p)^(1/loops)); 11.34, the 99 % quantile, for one
    loop, 27.3 for 1954 (M3500). One gate per loop at 99 % drops 1 % of a calibrated graph's true loops, and
    each that carries weight moves the solution off the plain optimum (manhattan: one true loop at 13.2,
    9.7 cm RMS)."""
    each = (1.0 - LOOP_FAMILY_P) ** (1.0 / max(int(loops), 1))
    lo, hi = 0.0, 200.0
    for _ in range(60):  # bisection on the cdf: no scipy.stats import (0.8 s)
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if chi2_3dof_cdf(mid) < each else (lo, mid)
    return hi


def binomial_tail(k: int, n: int, p: float) -> float:
    """P(K >= ``k``) for K binomial with ``n`` trials of probability ``p`` (log-space sum, no scipy.stats:
    its import costs the command 0.8 s)."""
    if k <= 0 or p >= 1.0:
        return 1.0
    if k > n or p <= 0.0:
        return 0.0
    log_fact = np.r_[0.0, np.cumsum(np.log(np.arange(1, n + 1)))]
    j = np.arange(k, n + 1)
    log_pmf = log_fact[n] - log_fact[j] - log_fact[n - j] + j * math.log(p) + (n - j) * math.log1p(-p)
    return float(np.exp(log_pmf).sum())


def noise_ratio(chi2: np.ndarray) -> float:
    """The noise of loops with squared whitened residuals ``chi2`` (K,) (``edge_chi2``) relative to what the
    graph's information matrices predict (``residual_ratio`` of their squared whitened residuals). Below 1: the information
    understates the precision (M3500: 0.010); about 1: calibrated; above 1: the information overstates it, or
    false loops are among them (intel with 1000 grouped false loops among its 760 screened true
    ones: 2535 by the median, 0.017 by the quartile, 0.007 at the outlier-free optimum). A ratio above 1 is
    refuted when more loops lie within the nominal chi-square gate than a noise that large leaves a
    ``REFUTE_P`` chance of (binomial tail): the solution fits those loops as their information states, the
    rest are false, and the ratio is theirs (CSAIL with 1000 grouped false loops among its 128 true ones:
    27 160 by the quartile, which leaves a loop a chance of 2e-6 to lie within the gate, where 126 true loops
    lie; 0.027 from them, 0.038 at the outlier-free optimum)."""
    chi2 = np.asarray(chi2, dtype=np.float64)
    ratio = residual_ratio(chi2)
    fitted = chi2 <= CHI2_3DOF_99
    if ratio <= 1 or not fitted.any():
        return ratio
    chance = chi2_3dof_cdf(CHI2_3DOF_99 / ratio)  # of one loop at this noise to lie within the gate
    refuted = binomial_tail(int(fitted.sum()), len(chi2), chance) < REFUTE_P
    return residual_ratio(chi2[fitted]) if refuted else ratio


GATE_NOISE_MAX = 30.0  # a gate is at most this times its quantile of the measured noise (the noise ratio times it)


def gate_scale(ratio: float, loops: int = 1) -> float:
    """What a graph's loop gate (``loop_gate`` of its ``loops``) is multiplied by, given the ``noise_ratio``:
    at least 1, so a graph whose information overstates its precision keeps its true loops and a calibrated
    one the gate of all its loops, but the gate at most ``GATE_NOISE_MAX`` times the 99 % quantile of one
    loop's measured noise, so the gates of a graph whose information understates its precision follow its
    noise (M3500: 0.126 of its 27.3 at its own information, 340 noise units, the same with its information
    × 0.1; without the cap, false loops 400-1000 times the noise passed there, and at 30 times the gate of
    all its loops (820 noise units) a group of 10 false loops)."""
    if ratio <= 0:
        return 1.0
    return min(max(1.0, ratio), GATE_NOISE_MAX * ratio * CHI2_3DOF_99 / loop_gate(loops))


def subgraph(graph: g2o.PoseGraphFile, keep) -> g2o.PoseGraphFile:
    """``graph`` with the edges where ``keep`` (M,) bool is set; every vertex stays."""
    keep = np.asarray(keep, bool)
    return g2o.PoseGraphFile(graph.ids, graph.poses, graph.i[keep], graph.j[keep], graph.measurements[keep],
                             graph.information[keep])
