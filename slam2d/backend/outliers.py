"""Batch rejection of false loop closures: ``pc_dcs`` and warm-started GNC.

``pc_dcs`` screens the loops by pairwise consistency through the odometry
(``consistency.pairwise_support``), solves DCS over the screened loops, brings back the
loops that agree with that solution and ends with least squares over the loops within the
chi-square gate, where a kept loop beyond one loop's gate must fit a solution it did not shape
(``contest``). ``gnc`` is graduated non-convexity (Yang et al. 2020; TLS or
Geman-McClure, odometry known inliers) written as a Python loop of weighted least-squares
solves: it starts from ``pc_dcs``'s solution (or a given start), leaves loops of weight 0
out of the linear system (no fill-in from false loops between random places) and
graduates in at most ``GNC_MAX_STEPS`` steps.

Thresholds are in whitened units (sigmas, chi-square) times ``consistency.gate_scale`` of the
noise ratio measured at the first DCS solution: when the loops' residuals are larger than the
information matrices predict (information scaled up), the gates and DCS's Phi widen with them;
when they are more than 30-fold smaller, the gates narrow with them. The readmission gate is in
noise units throughout. Every method ends with least squares
over the loops it keeps, so its result is that inlier set's optimum, which ``batch``
verifies and certifies on that set alone. Poses are ``(x, y, theta)`` (m, m, rad).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from slam2d.backend import admission, consistency
from slam2d.backend import initialization as ini
from slam2d.backend.consistency import (
    CHI2_3DOF_99,
    edge_chi2,
    noise_ratio,
    residual_ratio,
    subgraph,
)
from slam2d.backend.factors import (
    factor_graph,
    g2o_factor_list,
    g2o_values,
    g2o_weighted_factors,
    pose_key,
    prior_factor,
)
from slam2d.backend.lm import in_worker, levenberg_marquardt
from slam2d.datasets import g2o

READMIT_NOISE_CHI2 = 1000 * CHI2_3DOF_99  # pc_dcs: loops whose squared whitened residual after the screened
# DCS is within this times the noise ratio measured there enter its second DCS. In the graph's own noise units, so
# the same loops enter at any scale of the information: a solution without a detour's loops is off by far more
# than the noise (M3500: its two detour loops at 1350 and 2590 noise units there, the 1000 random false loops at
# 6700 and more, intel's at 28 000 and more); DCS and the final gate judge the loops that enter
DCS_CALIBRATED_PHI = 100.0  # pc_dcs: DCS's Phi at least this times the noise ratio measured at the first DCS.
# With calibrated information Phi = 1 drops true loops (a simulated grid: 8-15 %, the test's laps: 8 of 41); 30
# dropped 11 of intel's heavy-tailed loops with its information x 10 (99 % of them within 45 noise units at the
# optimum, the largest at 90), 100 none
PC_DCS_START = "spanning_tree"  # pc_dcs's start: the odometry, which grouped false loops that pass the screen do
# not bend (the chordal start of the screened graph, the second start before, cost M3500 with 1000 grouped false
# loops 42 LM iterations through their fill-in and changed no result once Phi and the readmission gate follow
# the measured noise); init="chordal_screened" names it
SECOND_START = "chordal_screened"  # pc_dcs: the chordal start of the screened graph, also run when the screened
# loops' residuals at the first DCS solution exceed what the information predicts (``residual_ratio`` above 1: DCS
# from the odometry stopped short, or the information overstates the precision) and the loops the start did not fit
# do not refute that (``noise_ratio``; CSAIL with 1000 grouped false loops: they do, the unfitted loops are false);
# the lower DCS cost is kept
FINAL_ROUNDS = 4  # least-squares solves at most in the final judgement of the loops
GNC_MAX_STEPS = 20  # graduation steps at most (each one warm-started weighted least squares)
GNC_MU_STEP = 1.4  # GTSAM's factor between steps; larger when the schedule would need more steps
GNC_TLS_WARM_MU = 10.0  # TLS from a robust start: weight 1 below 0.91 x the gate, 0 beyond 1.1 x
GNC_TLS_END_MU = 100.0  # TLS's weights are binary within 1 % of the gate from here
GNC_GM_WARM_MU = 16.0  # Geman-McClure from a robust start: starts this much wider than its kernel
GNC_MIN_WEIGHT = 1e-4  # loops below this weight stay out of the solve (no pull, no fill-in)
GNC_OUTLIER_WEIGHT = 0.5  # a loop whose final weight is below this is rejected


@dataclass
class Solution:
    """A method's result: poses (N, 3) in vertex order, ``inlier`` (M,) bool (odometry always; the
    loops of its final least squares), LM iterations, GNC graduation steps (0 for pc_dcs), the
    noise scale its gates used, the start's name, per-step wall times (s) and the Phi of pc_dcs's
    DCS (whitened units)."""

    poses: np.ndarray
    inlier: np.ndarray
    iterations: int
    steps: int
    scale: float
    init: str
    seconds: dict = field(default_factory=dict)
    phi: float = float("nan")


def _poses(values, ids) -> np.ndarray:
    import gtsam

    return gtsam.utilities.extractPose2(values).reshape(-1, 3)[np.searchsorted(np.sort(ids), ids)]


def _solve(graph: g2o.PoseGraphFile, factors, poses):
    """LM (in a worker process) over ``factors`` and a tight prior holding the first vertex at
    ``poses[0]``, from ``poses`` (N, 3); returns (poses, iterations)."""
    values = g2o_values(graph.ids, poses)
    fg = factor_graph(factors)
    key = pose_key(graph.ids[0])
    fg.add(prior_factor(key, values.atPose2(key)))
    return levenberg_marquardt(fg, values, lambda out, iterations: (_poses(out, graph.ids), iterations))


def _pick(factors, keep) -> list:
    return [f for f, k in zip(factors, keep) if k]


def inlier_gate(graph: g2o.PoseGraphFile, scale: float = 1.0) -> float:
    """A loop's final gate (chi-square): ``consistency.loop_gate`` of the graph's loops times the noise
    ``scale``; residuals at the optimum are smaller than the noise (the laps of the tests: 0.62 of it)."""
    return consistency.loop_gate(int((~g2o.odometry_mask(graph)).sum())) * scale


def pc_dcs(graph: g2o.PoseGraphFile, plain: list, phi: float = 1.0, init: str | None = None) -> Solution:
    """The ``pc_dcs`` method (``plain``: ``g2o_factor_list(graph)``; ``phi``: DCS's Phi, whitened
    units, times the noise scale):

    1. DCS over the odometry and the loops of ``pairwise_support`` from ``PC_DCS_START``, and from
       ``SECOND_START`` when the screened loops' ``residual_ratio`` there exceeds 1 and the loops the start
       did not fit do not refute it (``noise_ratio``: DCS may have stopped short), the lower DCS cost kept
       (``init``: the starts, comma-separated, all run; "chordal_screened" the chordal start of the screened
       graph);
    2. the noise ratio measured on the screened loops there (``consistency.noise_ratio``); when it
       asks for a wider Phi (at least ``DCS_CALIBRATED_PHI`` times the ratio, ``phi`` times the ratio
       when above 1), DCS over the screened loops again from there;
    3. DCS from that solution over the odometry and every loop within ``READMIT_NOISE_CHI2`` times the
       noise ratio (the graph's noise units: the same loops at any scale of the information);
    4. least squares over the odometry and the loops within ``inlier_gate`` (``gate_scale``), judged
       again at its solution (``least_squares_kept``); the kept loops beyond one loop's gate re-enter only
       by their innovation against the others (``contest``);
    5. the loops left out enter one by one while their innovation against the kept graph is within that
       gate (``admission.admit_consistent``: the loops the screen could not support, as on MIT)."""
    t0 = time.perf_counter()
    odometry = g2o.odometry_mask(graph)
    screened = in_worker(consistency.pairwise_support, graph)
    seconds = {"screen": time.perf_counter() - t0}
    t0 = time.perf_counter()
    robust = g2o_factor_list(graph, "dcs", phi, plain_odometry=True)
    starts = {"chordal_screened": lambda: in_worker(ini.chordal, subgraph(graph, screened))}
    names = init.split(",") if init else [PC_DCS_START, SECOND_START]
    best, iterations = None, 0
    for name in names:
        if best is not None and not init and best[3] <= 1.0:
            break  # residuals within the information's noise, or refuted by the loops DCS came to fit
        start = starts[name]() if name in starts else in_worker(ini.initial_poses, graph, name)
        poses, n = _solve(graph, _pick(robust, screened), start)
        iterations += n
        cost = factor_graph(robust, screened).error(g2o_values(graph.ids, poses))
        if best is None or cost < best[0]:
            loops, chi2 = screened & ~odometry, edge_chi2(graph, poses)
            moved = loops & (edge_chi2(graph, start) > CHI2_3DOF_99)  # loops the start did not fit
            short = min(residual_ratio(chi2[loops]), noise_ratio(chi2[moved]))
            best = (cost, poses, name, short, noise_ratio(chi2[loops]))
    _, poses, name, _, ratio = best
    scale = consistency.gate_scale(ratio, int((~odometry).sum()))
    phi_used = max(phi * max(1.0, ratio), DCS_CALIBRATED_PHI * ratio)
    if phi_used != phi:  # DCS again from there with Phi in the graph's own noise units
        robust = g2o_factor_list(graph, "dcs", phi_used, plain_odometry=True)
        poses, n = _solve(graph, _pick(robust, screened), poses)
        iterations += n
    keep = odometry | (edge_chi2(graph, poses) <= READMIT_NOISE_CHI2 * ratio)
    poses, n = _solve(graph, _pick(robust, keep), poses)
    iterations += n
    gate = inlier_gate(graph, scale)
    keep, poses, n = least_squares_kept(graph, plain, poses, gate)
    keep, poses, more = contest(graph, plain, keep, poses, gate, scale)
    iterations += more
    seconds["solve"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    keep, poses, more, _ = admission.admit_consistent(graph, plain, keep, poses, gate,
                                                      lambda k, p: _solve(graph, _pick(plain, k), p))
    seconds["admit"] = time.perf_counter() - t0
    return Solution(poses, keep, iterations + n + more, 0, scale, name, seconds, phi_used)


def least_squares_kept(graph: g2o.PoseGraphFile, plain: list, poses, gate: float, rounds: int = FINAL_ROUNDS):
    """Least squares over the odometry and the loops within ``gate`` (chi-square) at ``poses`` (N, 3),
    the loops judged again at its solution until the set stays (at most ``rounds`` solves): a robust
    solution biases the residuals of true loops, the least-squares one over the true loops does not.
    Returns (kept (M,) bool, poses, LM iterations)."""
    odometry = g2o.odometry_mask(graph)
    keep, iterations = odometry | (edge_chi2(graph, poses) <= gate), 0
    for _ in range(rounds):
        poses, n = _solve(graph, _pick(plain, keep), poses)
        iterations += n
        again = odometry | (edge_chi2(graph, poses) <= gate)
        if np.array_equal(again, keep):
            break
        keep = again
    else:
        poses, n = _solve(graph, _pick(plain, keep), poses)
        iterations += n
    return keep, poses, iterations


def contest(graph: g2o.PoseGraphFile, plain: list, keep, poses, gate: float, scale: float = 1.0):
    """The kept loops beyond one loop's 99 % gate (``CHI2_3DOF_99 * scale``) at ``poses`` (N, 3), the
    least-squares solution of ``keep`` (M,), are contested: each re-enters only by its innovation against
    the least-squares solution of the other kept edges (``admission.admit_consistent``), as a rejected
    loop would. A false loop that bent the solution until it fitted within ``gate`` does not (manhattan
    with 1000 local false loops: two at 20 and 24 there, 89 and 137 at the true optimum); a true loop in
    the tail of the noise does. Returns (keep, poses, LM iterations)."""
    contested = np.asarray(keep, bool) & ~g2o.odometry_mask(graph) & (edge_chi2(graph, poses) > CHI2_3DOF_99 * scale)
    if not contested.any():
        return keep, poses, 0
    solve = lambda k, p: _solve(graph, _pick(plain, k), p)
    poses, n = solve(keep & ~contested, poses)
    keep, poses, more, _ = admission.admit_consistent(graph, plain, keep & ~contested, poses, gate, solve, contested)
    return keep, poses, n + more


def _weights(chi2: np.ndarray, mu: float, gate: float, loss: str) -> np.ndarray:
    """GNC weights (Yang et al. 2020, eq. 14 for TLS, eq. 12 for Geman-McClure) of squared whitened
    residuals ``chi2`` at control parameter ``mu`` with the inlier gate ``gate`` (chi-square)."""
    if loss == "gm":
        return (mu * gate / (chi2 + mu * gate)) ** 2
    with np.errstate(divide="ignore"):
        w = np.sqrt(gate * mu * (mu + 1) / chi2) - mu
    w[chi2 >= (mu + 1) / mu * gate] = 0.0
    w[chi2 <= mu / (mu + 1) * gate] = 1.0
    return np.clip(w, 0.0, 1.0)


def gnc(graph: g2o.PoseGraphFile, plain: list, start, loss: str = "tls", scale: float = 1.0,
        warm: bool = True, init: str = "pc_dcs", max_steps: int = GNC_MAX_STEPS) -> Solution:
    """GNC from ``start`` (N, 3) with the odometry as known inliers, the gate ``inlier_gate(graph, scale)``,
    then least squares over the loops of weight >= ``GNC_OUTLIER_WEIGHT`` (unless the last weighted solve was
    that one: binary weights). ``warm``: ``start`` is a
    robust solution, so the graduation begins near the target kernel (TLS: mu = ``GNC_TLS_WARM_MU``,
    Geman-McClure: ``GNC_GM_WARM_MU``) instead of at GTSAM's convex end; the steps' factor grows from
    ``GNC_MU_STEP`` so that at most ``max_steps`` weighted solves run. Stops early once TLS's weights
    are binary and either unchanged or the solve left the poses as they were (from pc_dcs's solution: one
    step)."""
    t0 = time.perf_counter()
    odometry = g2o.odometry_mask(graph)
    gate = inlier_gate(graph, scale)
    poses, iterations, steps = np.asarray(start, dtype=np.float64), 0, 0
    chi2 = edge_chi2(graph, poses)
    top = float(chi2[~odometry].max(initial=0.0))
    weights = np.ones(len(chi2))
    if top > gate:
        if loss == "tls":
            mu = gate / (2 * top - gate)  # GTSAM's start: the worst residual just within the convex regime
            mu = max(mu, GNC_TLS_WARM_MU) if warm else mu
            step = max(GNC_MU_STEP, (GNC_TLS_END_MU / mu) ** (1.0 / max_steps))
        else:
            mu = 2 * top / gate
            mu = min(mu, GNC_GM_WARM_MU) if warm else mu
            step = max(GNC_MU_STEP, mu ** (1.0 / max_steps))
        previous = None
        while steps < max_steps:
            weights = _weights(chi2, mu, gate, loss)
            weights[odometry] = 1.0
            weights[weights < GNC_MIN_WEIGHT] = 0.0
            poses, n = _solve(graph, g2o_weighted_factors(graph, weights, plain), poses)
            iterations, steps = iterations + n, steps + 1
            chi2 = edge_chi2(graph, poses)
            binary = np.all((weights == 0) | (weights == 1))
            if loss == "tls" and binary and (n == 0 or previous is not None and np.array_equal(weights, previous)):
                break  # unchanged poses (or weights): TLS's binary weights stay as mu grows
            if loss == "gm" and mu <= 1.0:
                break
            previous = weights
            mu = mu * step if loss == "tls" else max(1.0, mu / step)
    keep = odometry | (weights >= GNC_OUTLIER_WEIGHT)
    if steps == 0 or not np.array_equal(weights, keep.astype(float)):  # else the last solve was this one
        poses, n = _solve(graph, _pick(plain, keep), poses)
        iterations += n
    return Solution(poses, keep, iterations, steps, scale, init, {"gnc": time.perf_counter() - t0})


def robust_cost(graph: g2o.PoseGraphFile, poses, method: str, phi: float, scale: float) -> float:
    """The cost a method minimises, at ``poses`` (N, 3), over every edge (odometry plain): for
    ``pc_dcs`` GTSAM's error under DCS with Phi ``phi``; for GNC 0.5 * the sum of squared
    whitened residuals, each loop's truncated at ``inlier_gate`` (TLS) or under
    Geman-McClure of that width."""
    if method == "pc_dcs":
        robust = g2o_factor_list(graph, "dcs", phi, plain_odometry=True)
        return float(factor_graph(robust).error(g2o_values(graph.ids, poses)))
    chi2 = edge_chi2(graph, poses)
    loops = ~g2o.odometry_mask(graph)
    gate = inlier_gate(graph, scale)
    rho = chi2.copy()
    rho[loops] = (np.minimum(chi2, gate) if method == "tls" else gate * chi2 / (gate + chi2))[loops]
    return 0.5 * float(rho.sum())
