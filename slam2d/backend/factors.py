"""GTSAM keys, values and factors of a 2D pose graph: the only module that builds GTSAM factors.

Keyframe (or g2o vertex) ``k`` is the gtsam key ``symbol('x', k)``, landmark ``n`` is
``symbol('l', n)``. Poses are numpy ``(x, y, theta)`` (m, m, rad); information matrices are
3x3 inverse covariances in the frame of the measurement (GTSAM's tangent space, order x, y,
theta). The online graph (``pose_graph``) and the batch solver (``batch``) both build their
factors here.
"""

from __future__ import annotations

import numpy as np

from slam2d.backend import consistency
from slam2d.backend import robust as rb
from slam2d.datasets import g2o
from slam2d.errors import InputError

PRIOR_SIGMAS = np.array([1e-6, 1e-6, 1e-6])  # m, m, rad: anchors the first keyframe / vertex


POSE_KEY_BASE = ord("x") << 56  # gtsam.symbol("x", 0): a gtsam Symbol is its character above a 56-bit index


def pose_key(k: int) -> int:
    """GTSAM key of keyframe ``k`` (``gtsam.symbol("x", k)``, without a call into gtsam)."""
    return POSE_KEY_BASE + int(k)


def landmark_key(n: int) -> int:
    """GTSAM key of landmark ``n``."""
    import gtsam

    return gtsam.symbol("l", int(n))


def gtsam_pose(p):
    """gtsam.Pose2 of a pose ``p`` (3,) (m, m, rad)."""
    import gtsam

    return gtsam.Pose2(float(p[0]), float(p[1]), float(p[2]))


def lm_params():
    """Levenberg-Marquardt parameters: GTSAM's defaults."""
    import gtsam

    return gtsam.LevenbergMarquardtParams()


def prior_factor(key: int, pose):
    """Tight prior (``PRIOR_SIGMAS``) holding gtsam key ``key`` at the gtsam.Pose2 ``pose``."""
    import gtsam

    return gtsam.PriorFactorPose2(key, pose, gtsam.noiseModel.Diagonal.Sigmas(PRIOR_SIGMAS))


def between_factor(i: int, j: int, delta, model):
    """Between factor: pose of keyframe ``j`` seen from keyframe ``i`` is ``delta`` (3,), under the
    gtsam noise model ``model``."""
    import gtsam

    return gtsam.BetweenFactorPose2(pose_key(i), pose_key(j), gtsam_pose(delta), model)


def bearing_range_factor(key: int, landmark_id: int, bearing: float, range: float, model):
    """Bearing (rad, keyframe frame) and range (m) of landmark ``landmark_id`` from keyframe ``key``,
    under the gtsam noise model ``model`` (2-dimensional: bearing, range)."""
    import gtsam

    return gtsam.BearingRangeFactor2D(pose_key(key), landmark_key(landmark_id), gtsam.Rot2(float(bearing)),
                                      float(range), model)


def factor_graph(factors, keep=None):
    """gtsam.NonlinearFactorGraph of ``factors`` (those where ``keep`` (bool) is set)."""
    import gtsam

    fg = gtsam.NonlinearFactorGraph()
    for f in factors if keep is None else (f for f, k in zip(factors, keep) if k):
        fg.add(f)
    return fg


def elimination_order(ids, fg) -> np.ndarray | None:
    """The ranks (in sorted order) of the vertices ``ids`` (N,) in GTSAM's COLAMD elimination order of ``fg``, a
    graph over exactly those vertices: a fill-reducing order for sparse factorisations outside GTSAM
    (``certificate.certify``); None when ``fg`` leaves out a vertex."""
    import gtsam

    ordering = gtsam.Ordering.ColamdNonlinearFactorGraph(fg)
    keyed = np.array([gtsam.Symbol(ordering.at(i)).index() for i in range(ordering.size())], dtype=np.int64)
    ranked = np.sort(np.asarray(ids, dtype=np.int64))
    return np.searchsorted(ranked, keyed) if len(keyed) == len(ranked) else None


def g2o_values(ids, poses):
    """gtsam.Values with vertex ``ids[n]`` at ``poses[n]`` (N, 3)."""
    import gtsam

    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    if len(poses) != len(ids):
        raise InputError("g2o graph", f"{len(ids)} vertices but {len(poses)} poses")
    values = gtsam.Values()
    for k, (x, y, t) in zip(np.asarray(ids).tolist(), poses.tolist()):
        values.insert(pose_key(k), gtsam.Pose2(x, y, t))
    return values


def g2o_factor_list(graph: g2o.PoseGraphFile, robust: str = "none", robust_param: float = 1.0,
                    plain_odometry: bool = False) -> list:
    """One gtsam between factor per edge of a g2o graph, under the ``robust`` kernel (odometry
    edges without it when ``plain_odometry``)."""
    import gtsam

    consistency.edge_rows(graph)  # InputError for an edge to an unknown vertex
    info = rb.check_information_stack(graph.information, lambda k: f"g2o edge {k} ({graph.i[k]} -> {graph.j[k]})")
    kernel = rb.m_estimator(robust, robust_param)
    plain = g2o.odometry_mask(graph) if plain_odometry else np.zeros(len(graph.i), bool)
    factors, models = [], {}  # one noise model per distinct information and kernel: most graphs have one
    for a, b, m, inf, p in zip(graph.i.tolist(), graph.j.tolist(), graph.measurements.tolist(), info, plain.tolist()):
        model = models.get(key := (inf.tobytes(), p))
        if model is None:
            model = models[key] = rb.wrap(gtsam.noiseModel.Gaussian.Information(inf), None if p else kernel)
        factors.append(between_factor(a, b, m, model))
    return factors


def g2o_factors(graph: g2o.PoseGraphFile, robust: str = "none", robust_param: float = 1.0,
                plain_odometry: bool = False):
    """gtsam graph of a g2o file's edges (no prior); see ``g2o_factor_list``."""
    return factor_graph(g2o_factor_list(graph, robust, robust_param, plain_odometry))


def g2o_weighted_factors(graph: g2o.PoseGraphFile, weights, plain: list | None = None) -> list:
    """Between factors of the edges whose weight (M,) is positive, each information matrix scaled by
    its weight (GNC's weighted least squares); an edge of weight 1 reuses its factor from ``plain``
    (``g2o_factor_list(graph)``) when given. Information matrices are taken as checked."""
    import gtsam

    w = np.asarray(weights, dtype=np.float64)
    out = []
    for k in np.flatnonzero(w > 0).tolist():
        if plain is not None and w[k] == 1.0:
            out.append(plain[k])
        else:
            model = gtsam.noiseModel.Gaussian.Information(w[k] * graph.information[k])
            out.append(between_factor(int(graph.i[k]), int(graph.j[k]), graph.measurements[k], model))
    return out
