"""Batch optimisation of g2o pose graphs and the tools around it.

``solve_g2o`` optimises a g2o file's graph in one batch (Levenberg-Marquardt under an
M-estimator, or the false-loop methods of ``outliers``: pc_dcs, GNC), from one or several global starts, the first
vertex held by a tight prior; ``g2o_metrics`` turns its result into metrics.json content,
``reference_poses`` picks a reference graph's poses for the RMSE. The factors come from
``factors``. Poses are ``(x, y, theta)`` (m, m, rad); errors follow GTSAM: 0.5 * sum of
squared whitened residuals.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from slam2d.backend import certificate, consistency, outliers
from slam2d.backend import initialization as ini
from slam2d.backend import robust as rb
from slam2d.backend.factors import (
    elimination_order,
    factor_graph,
    g2o_factor_list,
    g2o_factors,
    g2o_values,
    pose_key,
    prior_factor,
)
from slam2d.backend.lm import in_worker, levenberg_marquardt, sparse_worker
from slam2d.datasets import g2o
from slam2d.errors import InputError
from slam2d.evaluation.trajectory import ate

log = logging.getLogger(__name__)

G2O_INIT = "chordal"  # batch start without outliers: reaches the best-known minimum on every benchmark graph
G2O_ROBUST_INIT = "spanning_tree"  # start under an M-estimator: false loops do not bend odometry
VERIFY_REL = 1e-6  # relative error difference under which two optima agree
VERIFY_STARTS = ("chordal_isotropic", "spanning_tree", "chordal")  # verification's starts, in this order, until
# one agrees with the kept run (the isotropic chordal start, the cheapest, agrees on intel, MIT, CSAIL and M3500;
# the spanning tree ends in MIT's local minimum)


@dataclass(frozen=True)
class BatchResult:
    """Result of a batch optimisation: poses (N, 3) in the graph's vertex order; errors (0.5 * sum
    of squared whitened residuals): ``initial_error`` at the file's poses and ``start_error`` at the
    start, both under the method's cost, ``final_error`` the method's own cost at the end (plain
    least squares over every edge for "none", the robust cost otherwise: ``robust_cost``),
    ``kept_error`` the plain error over the edges kept as inliers (comparable between methods);
    LM iterations (all solves of the method), GNC graduation steps, wall time (s) of the
    optimisation (the start excluded), the start's name; ``verified`` when the certificate holds on
    the kept edges or else a second start reached the same error (None: not checked); ``inlier`` (M,) bool per edge (odometry always; for pc_dcs
    and GNC the loops of their final least squares, else a loop within ``outliers.inlier_gate``);
    ``certified``: SE-Sync's certificate holds next to the result (``certificate.certify`` on the
    kept edges: every edge of an outlier-free least-squares solve; None when not checked);
    ``scale``: the noise scale of the gates (``consistency.gate_scale``); ``timings``: wall time (s)
    of each step."""

    poses: np.ndarray
    initial_error: float
    final_error: float
    iterations: int
    seconds: float
    init: str = "file"
    start_error: float = float("nan")
    verified: bool | None = None
    inlier: np.ndarray | None = None
    certified: bool | None = None
    kept_error: float = float("nan")
    steps: int = 0
    scale: float = 1.0
    timings: dict = field(default_factory=dict)


def _poses_in_vertex_order(values, ids) -> np.ndarray:
    """(N, 3) poses of ``values`` ordered like ``ids`` (extractPose2 sorts by key)."""
    import gtsam

    sorted_poses = gtsam.utilities.extractPose2(values).reshape(-1, 3)
    return sorted_poses[np.searchsorted(np.sort(ids), ids)]


def g2o_error(graph: g2o.PoseGraphFile, poses=None) -> float:
    """0.5 * sum of squared whitened edge residuals at ``poses`` (N, 3) (default: the file's): GTSAM's
    error of the graph's between factors, in numpy (``consistency.edge_chi2``)."""
    return 0.5 * float(consistency.edge_chi2(graph, graph.poses if poses is None else poses).sum())


def _anchor_prior(graph: g2o.PoseGraphFile, values):
    """Tight prior holding the first vertex at its value in ``values``."""
    anchor = pose_key(graph.ids[0])
    return prior_factor(anchor, values.atPose2(anchor))


def _lm(graph: g2o.PoseGraphFile, fg, initial) -> tuple[np.ndarray, int, float]:
    """Levenberg-Marquardt (GTSAM defaults, in a worker process: ``lm``) over ``fg`` and the anchor prior from
    gtsam.Values ``initial``; returns (poses (N, 3) in vertex order, iterations, ``fg``'s error there)."""
    import gtsam

    anchored = gtsam.NonlinearFactorGraph(fg)
    anchored.add(_anchor_prior(graph, initial))
    return levenberg_marquardt(anchored, initial,
                               lambda values, n: (_poses_in_vertex_order(values, graph.ids), n, float(fg.error(values))))


def _classify(graph: g2o.PoseGraphFile, poses) -> np.ndarray:
    """(M,) bool inlier flags (see ``BatchResult.inlier``)."""
    return (consistency.edge_chi2(graph, poses) <= outliers.inlier_gate(graph)) | g2o.odometry_mask(graph)


@dataclass(frozen=True)
class _Run:
    """One optimisation from one start: wall times (s) of the start and of LM."""

    init: str
    start: np.ndarray
    poses: np.ndarray
    iterations: int
    seconds: float
    cost: float
    start_seconds: float = 0.0


def _start(graph: g2o.PoseGraphFile, name: str, call=in_worker, elimination=None) -> np.ndarray:
    """The start ``name`` ("chordal_isotropic": chordal with unit weights), computed in a worker process
    (``call``: ``lm.in_worker`` or a ``lm.sparse_worker``'s ``call``; ``elimination``: as in ``ini.chordal``)."""
    return call(_start_here, graph, name, elimination)


def _start_here(graph: g2o.PoseGraphFile, name: str, elimination=None) -> np.ndarray:
    if name == "chordal_isotropic":
        return ini.chordal(graph, weighted=False, elimination=elimination)
    return ini.initial_poses(graph, name, elimination)


def _certified(graph: g2o.PoseGraphFile, poses, call=in_worker, elimination=None) -> bool:
    """Whether SE-Sync's certificate holds at ``poses`` (``certificate.certify`` in the ``elimination`` order, in
    a worker process: ``call`` as in ``_start``)."""
    return call(_certified_here, graph, poses, elimination)


def _certified_here(graph: g2o.PoseGraphFile, poses, elimination=None) -> bool:
    return certificate.certify(graph, poses, elimination).certified


def _run(graph: g2o.PoseGraphFile, fg, name: str, call=in_worker, elimination=None) -> _Run:
    """LM over ``fg`` from the start ``name`` (computed by ``call`` in the ``elimination`` order, as in
    ``_start``)."""
    t0 = time.perf_counter()
    start = _start(graph, name, call, elimination)
    t1 = time.perf_counter()
    poses, iterations, cost = _lm(graph, fg, g2o_values(graph.ids, start))
    return _Run(name, start, poses, iterations, time.perf_counter() - t1, cost, t1 - t0)


def _agree(a: float, b: float) -> bool:
    return abs(a - b) <= VERIFY_REL * max(a, b, 1e-12)


def _verify_kept(graph: g2o.PoseGraphFile, poses, kept) -> tuple[bool, bool, dict]:
    """(verified, certified, timings) of a least-squares optimum ``poses`` (N, 3) over the ``kept``
    edges (M,) bool: SE-Sync's certificate on those edges; when it does not hold, plain LM over them from
    the starts of ``VERIFY_STARTS`` in turn until one reaches the same error (verified) or a lower one
    (not verified). A certified optimum is verified (the stronger check: no start reaches a lower cost of
    the isotropic problem), and no second start runs."""
    sub = consistency.subgraph(graph, kept)
    t0 = time.perf_counter()
    certified = _certified(sub, poses)
    timings = {"certify": time.perf_counter() - t0}
    if certified:
        return True, True, timings
    t0 = time.perf_counter()
    fg = g2o_factors(sub)
    error, verified = g2o_error(sub, poses), False
    for name in VERIFY_STARTS:
        cost = _run(sub, fg, name).cost
        if _agree(cost, error) or cost < error:
            verified = _agree(cost, error)
            break
    return verified, certified, {**timings, "verify": time.perf_counter() - t0}


def _solve_outliers(graph: g2o.PoseGraphFile, robust: str, robust_param: float, init: str | None,
                    verify: bool) -> BatchResult:
    """``pc_dcs`` or GNC (``outliers``); verification and certificate on the kept edges."""
    t0 = time.perf_counter()
    plain = g2o_factor_list(graph)
    loss = rb.gnc_loss(robust)
    init = None if init is None or str(init).lower() == "pc_dcs" else str(init).lower()  # "pc_dcs": GNC's default
    sol = outliers.pc_dcs(graph, plain, robust_param, None if loss else init)
    timings = dict(sol.seconds)
    method = "pc_dcs"
    if loss:
        method = loss
        if init:
            start = _start(graph, init)  # a start's residuals say nothing of the noise: nominal gate
            sol = outliers.gnc(graph, plain, start, loss, 1.0, warm=False, init=init)
        else:
            first = sol.iterations
            sol = outliers.gnc(graph, plain, sol.poses, loss, sol.scale)
            sol.iterations += first
        timings.update(sol.seconds)
    seconds = time.perf_counter() - t0
    verified = certified = None
    if verify:
        verified, certified, more = _verify_kept(graph, sol.poses, sol.inlier)
        timings.update(more)
    phi = sol.phi if method == "pc_dcs" else robust_param
    cost = lambda p: outliers.robust_cost(graph, p, method, phi, sol.scale)
    start = _start(graph, "spanning_tree" if sol.init in ("pc_dcs", "chordal_screened") else sol.init)
    kept_error = g2o_error(consistency.subgraph(graph, sol.inlier), sol.poses)
    out = BatchResult(sol.poses, cost(graph.poses), cost(sol.poses), sol.iterations, seconds, sol.init, cost(start),
                      verified, sol.inlier, certified, kept_error, sol.steps, sol.scale, timings)
    log.info("g2o %s from %s: robust cost %.9g, kept edges error %.9g, %d iterations, %d steps, %.3f s",
             robust, sol.init, out.final_error, kept_error, sol.iterations, sol.steps, seconds)
    return out


def solve_g2o(graph: g2o.PoseGraphFile, robust: str = "none", robust_param: float = 1.0,
              init: str | None = None, verify: bool = False, meanwhile=None) -> BatchResult:
    """Batch optimisation of a g2o graph, the first vertex held at its start pose by a
    tight prior; errors exclude the prior.

    ``robust``: "none" (least squares), an M-estimator of ``robust.ROBUST_KERNELS`` on every edge
    (width ``robust_param``, whitened units) under Levenberg-Marquardt (GTSAM defaults), "pc_dcs"
    (``outliers.pc_dcs``: pairwise screen, DCS with Phi = ``robust_param``, least squares over the
    loops kept) or GNC ("gnc" = TLS, "gnc_gm"; ``outliers.gnc``: warm-started from pc_dcs's
    solution unless ``init`` names a start). ``init``: "chordal", "spanning_tree" or "file";
    default ``G2O_INIT``, ``G2O_ROBUST_INIT`` under an M-estimator. ``verify``: plain least squares
    is first checked by SE-Sync's certificate (``BatchResult.certified``) on the edges within the gate;
    certified on every edge, it is verified. Otherwise (and under M-estimators) the other starts of
    ``VERIFY_STARTS`` run, in order, until one agrees with the kept run (verified; False when none
    does); of several runs the first is kept unless another reaches a lower cost beyond VERIFY_REL.
    pc_dcs and GNC are certified and verified on the edges they keep (``_verify_kept``). ``meanwhile(result)``,
    when given, runs while plain least squares is certified, with the result as it stands (``certified`` and
    ``verified`` None): the result returned has the same poses, inliers and start unless the certificate
    failed and another start reached a lower cost."""
    loss, screened = rb.gnc_loss(robust), rb.screened_kernel(robust)
    if loss or screened:
        return _solve_outliers(graph, robust, robust_param, init, verify)
    with sparse_worker() as worker:  # scipy imported there while gtsam is imported here
        return _least_squares(graph, robust, robust_param, init, verify, worker, meanwhile)


def _least_squares(graph: g2o.PoseGraphFile, robust: str, robust_param: float, init: str | None, verify: bool,
                   worker, meanwhile) -> BatchResult:
    """``solve_g2o`` without false-loop methods: plain least squares or an M-estimator; the starts and the
    certificate computed by ``worker`` (a ``lm.sparse_worker``), ``meanwhile`` run while it certifies."""
    call = worker.call
    plain = robust == "none"
    first = str(init).lower() if init else (G2O_INIT if plain else G2O_ROBUST_INIT)
    fg = factor_graph(g2o_factor_list(graph, robust, robust_param))
    elimination = elimination_order(graph.ids, fg)  # the starts' and the certificate's (city10000: 0.6 s less)
    runs = [_run(graph, fg, first, call, elimination)]
    best, verified, certified = runs[0], None, None  # the first start's run unless another is clearly lower
    timings = {"start": best.start_seconds, "solve": best.seconds}
    poses = best.poses
    inlier = _classify(graph, poses)
    if verify and plain:  # on the edges within the gate: a solution bent by false loops is not worth a
        t0 = time.perf_counter()  # certificate of the whole graph's (M3500 + 1000 false loops: 450 s)
        pending = worker.submit(_certified_here, consistency.subgraph(graph, inlier), poses, elimination)
        t1 = time.perf_counter()
        if meanwhile is not None:
            meanwhile(_result(graph, fg, plain, best, poses, inlier, None, None, dict(timings)))
        t2 = time.perf_counter()
        certified = pending()
        timings["certify"] = time.perf_counter() - t2 + t1 - t0  # the wait beyond ``meanwhile``
        verified = True if certified and inlier.all() else None  # the optimum of every edge: no second start
    t0 = time.perf_counter()
    for name in [n for n in VERIFY_STARTS if n != first] if verify and verified is None else []:
        runs.append(_run(graph, fg, name, call, elimination))
        if runs[-1].cost < best.cost and not _agree(runs[-1].cost, best.cost):
            best = runs[-1]
        verified = any(_agree(r.cost, best.cost) for r in runs if r is not best)
        if verified:
            break
    if len(runs) > 1:
        timings["verify"] = time.perf_counter() - t0
    for r in runs:
        log.info("g2o %s from %s: cost %.9g%s", robust, r.init, r.cost, " (kept)" if r is best else "")
    if best is not runs[0]:
        poses = best.poses
        inlier = _classify(graph, poses)
        if certified is not None:
            certified = _certified(consistency.subgraph(graph, inlier), poses, call, elimination)
    out = _result(graph, fg, plain, best, poses, inlier, verified, certified, timings)
    log.info("g2o %s from %s: error %.6g -> %.6g, %d iterations, %.3f s",
             robust, best.init, out.start_error, out.final_error, out.iterations, best.seconds)
    return out


def _result(graph: g2o.PoseGraphFile, fg, plain: bool, best: _Run, poses, inlier, verified, certified,
            timings) -> BatchResult:
    """The BatchResult of the run ``best`` (``poses``, ``inlier``) of least squares (``plain``) or of the
    M-estimator graph ``fg``."""
    cost = (lambda p: g2o_error(graph, p)) if plain else (lambda p: float(fg.error(g2o_values(graph.ids, p))))
    return BatchResult(poses, cost(graph.poses), best.cost, best.iterations, best.seconds,
                       best.init, cost(best.start), verified, inlier, certified,
                       g2o_error(consistency.subgraph(graph, inlier), poses), timings=timings)


def optimize_g2o(graph: g2o.PoseGraphFile, robust: str = "none", robust_param: float = 1.0,
                 init: str | None = None) -> np.ndarray:
    """Optimised poses (N, 3) of a g2o graph (see ``solve_g2o``)."""
    return solve_g2o(graph, robust, robust_param, init).poses


def loop_metrics(inlier, injected) -> dict:
    """Counts and rates of rejected loops against the injected false loops (both (M,) bool;
    odometry edges count as kept inliers). Precision / recall are of the rejections."""
    inlier, injected = np.asarray(inlier, bool), np.asarray(injected, bool)
    rejected = ~inlier
    hit = int(np.sum(rejected & injected))
    true_loops = ~injected
    return {
        "loops_rejected": int(rejected.sum()),
        "outliers_injected": int(injected.sum()),
        "outliers_rejected": hit,
        "true_rejected": int(np.sum(rejected & true_loops)),
        "precision": hit / rejected.sum() if rejected.any() else 1.0,
        "recall": hit / injected.sum() if injected.any() else 1.0,
    }


def g2o_metrics(graph: g2o.PoseGraphFile, result: BatchResult, injected=None, reference=None) -> dict:
    """metrics.json content of a batch solve: errors (``kept_edges_error``: plain error over the
    edges kept as inliers, comparable between methods; ``robust_cost``: the method's own cost;
    ``all_edges_error``: plain error over every edge, rejected ones included), iterations, GNC steps,
    time (s) and each step's time (``timings``), verification, loops kept / rejected, precision /
    recall against ``injected`` (M,) bool, and the position RMSE (m, after SE(2) alignment) against
    ``reference`` poses (N, 3)."""
    loops = ~g2o.odometry_mask(graph)
    out = {
        "vertices": len(graph.ids), "edges": len(graph.i), "loops": int(loops.sum()),
        "init": result.init, "initial_error": result.initial_error, "start_error": result.start_error,
        "kept_edges_error": result.kept_error, "robust_cost": result.final_error,
        "all_edges_error": g2o_error(graph, result.poses), "iterations": result.iterations,
        "gnc_steps": result.steps, "noise_scale": result.scale, "seconds": result.seconds,
        "timings": {k: round(v, 6) for k, v in result.timings.items()},
        "verified": result.verified, "certified": result.certified,
        "loops_rejected": int(np.sum(~result.inlier & loops)),
    }
    if injected is not None and np.any(injected):
        out.update(loop_metrics(result.inlier, injected))
        kept = result.inlier & ~np.asarray(injected, bool)
        out["true_loops_kept"] = float(np.sum(kept & loops) / max(1, np.sum(loops & ~injected)))
    if reference is not None:
        out["rmse_to_reference"] = ate(result.poses, reference)["rmse"]
    return out


def reference_poses(graph: g2o.PoseGraphFile, reference: g2o.PoseGraphFile) -> np.ndarray:
    """The ``reference`` graph's poses (N, 3) for ``graph``'s vertex ids; InputError if any is missing."""
    rows = np.searchsorted(reference.ids, graph.ids)
    rows = np.minimum(rows, len(reference.ids) - 1)
    if not np.array_equal(reference.ids[rows], graph.ids):
        raise InputError("--reference", "the reference lacks some of the graph's vertices")
    return reference.poses[rows]
