"""The online pose graph: keyframes, loops and landmarks under iSAM2, and a final batch.

Keyframe ``k`` is the gtsam key ``symbol('x', k)``, landmark ``n`` is
``symbol('l', n)`` (see ``factors``, which builds every factor). Keyframe 0 carries a
tight prior; each later keyframe a between factor from its predecessor (odometry or
scan matching, no robust kernel); loop closures are between factors with the configured
robust kernel; landmark observations are bearing-range factors. iSAM2 keeps the incremental estimate (at most one
update per keyframe, ``PoseGraph.update``); ``optimize_batch`` runs Levenberg-Marquardt (or GNC) over all factors in a
worker process that a signal ends at once (``lm.in_worker``; iSAM2's updates stay in this process).

Poses are numpy ``(x, y, theta)`` (m, m, rad); information matrices are 3x3
inverse covariances in the frame of the measurement (GTSAM's tangent space,
order x, y, theta). Errors follow GTSAM: 0.5 * sum of squared whitened residuals.

``replay.replay_g2o`` feeds a g2o file's graph into a ``PoseGraph`` as a SLAM run would; ``batch``
optimises one in a single batch.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from slam2d import geometry
from slam2d.backend import consistency
from slam2d.backend import robust as rb
from slam2d.backend.factors import (
    PRIOR_SIGMAS,
    bearing_range_factor,
    between_factor,
    gtsam_pose,
    landmark_key,
    lm_params,
    pose_key,
    prior_factor,
)
from slam2d.backend.lm import in_worker, levenberg_marquardt
from slam2d.backend.readmission import inconsistent_loops, second_chance
from slam2d.config import BackendConfig
from slam2d.datasets import g2o
from slam2d.errors import InputError

log = logging.getLogger(__name__)

RELINEARIZE_POSE = (0.1, 0.1, 0.01)  # m, m, rad: iSAM2 relinearises a pose whose delta exceeds one of these
# (a between factor is linear in the positions given the headings; 0.01 m too doubled the time on M3500 for
# estimates between batches within 2.5 cm of the optimum instead of 2 cm, docs/posegraphs.md)
RELINEARIZE_LANDMARK = 0.01  # m: the same for a landmark's position
RELINEARIZE_SKIP = 1  # iSAM2: check for relinearisation at every update
PARTIAL_RELINEARIZATION_CHECK = False  # iSAM2: check only the cliques an update touches (docs/posegraphs.md, "Latency
# per keyframe": M3500's p99 within 50 ms, city10000's not; off: it moves the online estimates, and Intel loses)
ISAM2_FACTORIZATION = "CHOLESKY"  # faster; an ill-conditioned update falls back to "QR" (see update)
DEFAULT_ODOMETRY_SIGMAS = np.array([0.05, 0.05, np.deg2rad(2.0)])  # m, m, rad, when no information is given
CHI2_3DOF_99 = consistency.CHI2_3DOF_99  # chi-square 99% quantile, 3 degrees of freedom: loop residual / consistency gate


def _pose3(p, where: str) -> np.ndarray:
    a = np.asarray(p, dtype=np.float64)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise InputError(where, f"expected a finite pose (x, y, theta), got {p!r}")
    return a


def _lm(graph, initial):
    """(gtsam.Values, iterations) of Levenberg-Marquardt (``lm_params``) over ``graph`` from ``initial``, in a
    worker process that a signal ends at once (``lm``: the same values as GTSAM's ``optimize()``)."""
    return levenberg_marquardt(graph, initial, lambda values, iterations: (values, iterations))


def _gnc(graph, initial, inliers):
    """(gtsam.Values, weights (M,)) of GTSAM's GNC (``robust.gnc_params``, ``inliers``: known inlier factors)."""
    import gtsam

    opt = gtsam.GncLMOptimizer(graph, initial, rb.gnc_params(inliers, lm_params=lm_params()))
    return opt.optimize(), np.asarray(opt.getWeights()).ravel()


@dataclass(frozen=True)
class _Factor:
    """One factor and what it measures (for g2o export and GNC bookkeeping)."""

    kind: str  # "prior" | "odometry" | "loop" | "landmark"
    factor: object
    i: int
    j: int
    measurement: np.ndarray | None = None
    information: np.ndarray | None = None


class PoseGraph:
    """Keyframe pose graph with iSAM2 updates and a final batch optimisation."""

    def __init__(self, cfg: BackendConfig | None = None):
        self.cfg = cfg if cfg is not None else BackendConfig(name="pose_graph")
        rb.m_estimator(self.cfg.robust, self.cfg.robust_param)  # fail early on a bad kernel
        self._default_odometry_info = np.diag(1.0 / DEFAULT_ODOMETRY_SIGMAS**2)
        self._default_odometry_model = rb.noise_model(self._default_odometry_info)
        self._factors: list[_Factor] = []
        self._active: list[bool] = []
        self._initial: list[np.ndarray] = []  # poses given to add_keyframe
        self._landmarks: set[int] = set()
        self._odometry: list = []  # (keyframe it starts at, gtsam.Pose2) odometry into keyframe k + 1
        self.rejected_inconsistent = 0  # loops removed after the batch optimisation
        self.isam_updates = 0  # iSAM2 updates run
        self.factorization = ISAM2_FACTORIZATION
        self._reset_isam()

    # ----------------------------------------------------------------- building

    def add_keyframe(self, pose, delta_from_previous=None, information=None, previous: int | None = None) -> int:
        """Add a keyframe with initial value ``pose`` (3,); return its key (0, 1, ...).

        The first keyframe gets a tight prior at ``pose``. Later ones get a between
        factor from the previous keyframe (or from keyframe ``previous``: a trajectory
        that starts where another session placed it): ``delta_from_previous`` (3,)
        (default: the relative pose between the poses given to this method) with
        ``information`` (3, 3) (default: ``DEFAULT_ODOMETRY_SIGMAS``).
        """
        import gtsam

        pose = _pose3(pose, "add_keyframe pose")
        k = len(self._initial)
        if k == 0:
            factor = prior_factor(pose_key(0), gtsam_pose(pose))
            self._add(_Factor("prior", factor, 0, 0, pose, np.diag(1.0 / PRIOR_SIGMAS**2)))
        else:
            i = k - 1 if previous is None else self._check_key(previous)
            if delta_from_previous is None:
                delta = geometry.between(self._initial[i], pose)
            else:
                delta = _pose3(delta_from_previous, "add_keyframe delta_from_previous")
            if information is None:
                info, model = self._default_odometry_info, self._default_odometry_model
            else:
                info = rb.check_information(information, f"odometry information {i} -> {k}")
                model = gtsam.noiseModel.Gaussian.Information(info)
            factor = between_factor(i, k, delta, model)
            self._add(_Factor("odometry", factor, i, k, delta, info))
            self._odometry.append((i, gtsam_pose(delta)))
        self._new_values.insert(pose_key(k), gtsam_pose(pose))
        self._initial.append(pose)
        return k

    def add_loop(self, i: int, j: int, delta, information) -> int:
        """Loop closure: pose of keyframe ``j`` seen from keyframe ``i`` is ``delta`` (3,)
        with ``information`` (3, 3), under the configured robust kernel. Returns its factor index."""
        i, j = self._check_key(i), self._check_key(j)
        if i == j:
            raise InputError("add_loop", f"a loop needs two different keyframes, got {i} twice")
        delta = _pose3(delta, f"loop {i} -> {j} delta")
        info = rb.check_information(information, f"loop {i} -> {j} information")
        model = rb.noise_model(info, self.cfg.robust, self.cfg.robust_param)
        factor = between_factor(i, j, delta, model)
        return self._add(_Factor("loop", factor, i, j, delta, info))

    def add_landmark_observation(self, key: int, landmark_id: int, bearing: float, range: float, covariance) -> int:
        """Bearing (rad, sensor = keyframe frame) and range (m) of landmark ``landmark_id``
        from keyframe ``key`` with 2x2 ``covariance`` (rad^2, m^2), under the loops' robust kernel:
        re-observing a landmark mapped long ago closes a loop, and a frontend's wrong association
        must not pull the graph apart. A new landmark is initialised from this observation.
        Returns the factor index."""
        import gtsam

        key = self._check_key(key)
        if not (np.isfinite(bearing) and np.isfinite(range) and range > 0):
            raise InputError("add_landmark_observation", f"need a finite bearing and range > 0, got {bearing}, {range}")
        cov = rb.check_information(covariance, f"landmark {landmark_id} observation", kind="covariance")
        lkey = landmark_key(landmark_id)
        if landmark_id not in self._landmarks:
            local = np.array([range * np.cos(bearing), range * np.sin(bearing)])
            self._new_values.insert(lkey, self._pose_value(key).transformFrom(local))
            self._landmarks.add(int(landmark_id))
        kernel = rb.m_estimator(self.cfg.robust, self.cfg.robust_param)
        model = rb.wrap(gtsam.noiseModel.Gaussian.Covariance(cov), kernel)
        factor = bearing_range_factor(key, landmark_id, bearing, range, model)
        return self._add(_Factor("landmark", factor, key, int(landmark_id)))

    # -------------------------------------------------------------- optimising

    def update(self) -> None:
        """Bring the estimate up to date with the factors added since the last call.

        Keyframes added with odometry alone do not reach iSAM2 while its estimate has settled (no delta
        above a relinearisation threshold, so an update would only add them): a chain of odometry leaves
        the optimum of the rest unchanged, so each such keyframe is estimated at its predecessor's estimate
        composed with its odometry (which replaces its initial value, also when it enters iSAM2 at once).
        When iSAM2 has not settled, the relinearisation waits for the next call, so it goes with the
        keyframe's loops if they come before any read: a keyframe costs at most one iSAM2 update
        (docs/posegraphs.md, "Latency per keyframe"); a read runs it first, so gives what it gave before.
        With any other factor (loop, landmark, the first keyframe's prior), one iSAM2 update with everything
        pending; so too a call with nothing new (one more iteration). Reads needing iSAM2
        (``marginal_covariance``, ``loop_consistency``) hand the waiting keyframes over first."""
        nothing_new = self._n_updated == len(self._initial)
        for k in range(max(self._n_updated, 1), len(self._initial)):
            i, delta = self._odometry[k - 1]
            self._new_values.update(pose_key(k), self._pose_value(i).compose(delta))
        self._n_updated = len(self._initial)
        if self._pending_other or nothing_new or self._relinearisation_due:
            self._flush()
        else:
            self._relinearisation_due = not self._is_settled()

    def _flush(self) -> None:
        """One iSAM2 update with every factor and value pending. If Cholesky finds the system indeterminate
        (very anisotropic information matrices, as in MIT.g2o, square the condition number), iSAM2 restarts
        with QR factorisation from its last linearisation point and stays with QR."""
        import gtsam

        self.isam_updates += 1
        try:
            self._isam.update(self._new_graph, self._new_values)
        except RuntimeError as err:
            if self.factorization == "QR" or "Indeterminate" not in str(err):
                raise
            values = gtsam.Values(self._new_values)
            values.insert_or_assign(self._isam.getLinearizationPoint())
            self._reset_isam()
            try:  # a fresh start from the last linearisation point usually factors again
                self._isam.update(self._batch_graph()[0], values)
                log.info("iSAM2 Cholesky update failed (ill-conditioned system); restarted")
            except RuntimeError:
                log.warning("iSAM2 Cholesky update failed twice (ill-conditioned system); continuing with QR")
                self.factorization = "QR"
                self._reset_isam()
                self._isam.update(self._batch_graph()[0], values)
        self._new_graph, self._new_values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        self._n_in_isam = self._n_updated = len(self._initial)
        self._pending_other = self._relinearisation_due = False
        self._isam_poses = None
        self._settled = None  # unknown until asked (``_is_settled``)

    def _is_settled(self) -> bool:
        """Whether iSAM2's next update would relinearise nothing, asked once per iSAM2 update: its full check
        (any delta component above its threshold; a partial check may find less) on the delta as one vector,
        landmarks (2 each) before poses (3 each): ``predictUpdateInfo`` without its up to 50 ms of marking."""
        if self._settled is None:
            delta = self._isam.getDelta().vector()
            n = delta.size - 3 * self._n_in_isam  # landmark components
            self._settled = not (np.any(np.abs(delta[n:]).reshape(-1, 3) > RELINEARIZE_POSE)
                                 or np.any(np.abs(delta[:n]) > RELINEARIZE_LANDMARK))
        return self._settled

    def estimate(self) -> np.ndarray:
        """Current poses (K, 3) in key order: keyframes waiting outside iSAM2 at their predecessor's
        estimate composed with their odometry (see ``update``), keyframes not yet updated at their
        initial value."""
        import gtsam

        self._relinearise_if_due()
        if self._isam_poses is None:
            self._isam_poses = gtsam.utilities.extractPose2(self._isam.calculateEstimate()).reshape(-1, 3)
        tail = gtsam.utilities.extractPose2(self._new_values).reshape(-1, 3)  # the keyframes not in iSAM2, in key order
        return np.vstack([self._isam_poses, tail])

    def pose(self, key: int) -> np.ndarray:
        """Current pose (3,) of keyframe ``key`` alone (cheaper than the whole estimate)."""
        self._relinearise_if_due()
        p = self._pose_value(self._check_key(key))
        return np.array([p.x(), p.y(), p.theta()])

    def landmarks(self) -> tuple[np.ndarray, np.ndarray]:
        """Landmark ids (L,) and their current positions (L, 2), m."""
        self._relinearise_if_due()
        ids = np.array(sorted(self._landmarks), dtype=int)
        pts = [self._point_value(landmark_key(n)) for n in ids]
        return ids, np.array(pts).reshape(-1, 2)

    def marginal_covariance(self, key: int) -> np.ndarray:
        """3x3 marginal covariance of keyframe ``key`` (m^2, rad^2) in its own frame."""
        key = self._check_updated(key)
        return np.asarray(self._isam.marginalCovariance(pose_key(key)))

    def loop_consistency(self, i: int, j: int, delta, information) -> float:
        """Squared Mahalanobis distance of a loop measurement ``delta`` (j seen from i) from the current
        estimate; compare with ``CHI2_3DOF_99``. The covariance is the measurement's plus that of the
        estimated relative pose, propagated from the iSAM2 joint marginal of keyframes i and j."""
        import gtsam

        i, j = self._check_updated(i), self._check_updated(j)
        meas_cov = np.linalg.inv(rb.check_information(information, f"loop {i} -> {j} information"))
        ki, kj = pose_key(i), pose_key(j)
        rel = self._isam.calculateEstimatePose2(ki).between(self._isam.calculateEstimatePose2(kj))
        err = gtsam.Pose2.Logmap(gtsam_pose(_pose3(delta, f"loop {i} -> {j} delta")).between(rel))
        joint = self._isam.jointMarginalCovariance([ki, kj])
        a = -rel.inverse().AdjointMap()  # d(between)/d(x_i); d/d(x_j) is the identity
        sij = joint.at(ki, kj)
        rel_cov = a @ joint.at(ki, ki) @ a.T + a @ sij + sij.T @ a.T + joint.at(kj, kj)
        return float(err @ np.linalg.solve(rel_cov + meas_cov, err))

    def optimize_batch(self) -> np.ndarray:
        """Levenberg-Marquardt over all factors from the current estimate; loops whose
        residual then fails the chi-square test (``CHI2_3DOF_99``) are removed, the clusters
        of them the graph accommodates readmitted (``readmission``), and LM runs once more.
        With ``cfg.gnc``, GNC instead, rejecting loops it weighs as outliers. The result
        replaces the estimate and restarts iSAM2 from it. Returns the poses (K, 3)."""
        graph, index = self._batch_graph()
        initial = self._values()
        t0 = time.perf_counter()
        if self.cfg.gnc:
            inliers = [g for g, f in enumerate(index) if self._factors[f].kind != "loop"]
            result, weights = in_worker(_gnc, graph, initial, inliers)
            self._reject_outliers(index, weights)
        else:
            result, iterations = _lm(graph, initial)
            log.info("batch LM: %d iterations", iterations)
            removed = self._reject_inconsistent(result)
            if removed:
                result = self._second_chance(result, removed)
                graph, index = self._batch_graph()
        log.info(
            "batch %s: error %.6g -> %.6g in %.3f s",
            "GNC" if self.cfg.gnc else "LM",
            graph.error(initial),
            graph.error(result),
            time.perf_counter() - t0,
        )
        return self._restart_at(result)

    def solve_with(self, pairs, deltas, informations) -> np.ndarray:
        """Levenberg-Marquardt over the active factors plus one between factor per row of ``pairs``
        (P, 2) (keyframes i, j; ``deltas`` (P, 3) j's pose in i's frame, ``informations`` (P, 3, 3)),
        each under the loops' kernel, from the current estimate. The extra factors are not kept: the
        solution replaces the estimate and iSAM2 restarts from it over the graph's own factors.
        Returns the poses (K, 3)."""
        import gtsam

        graph, _ = self._batch_graph()
        kernel = rb.m_estimator(self.cfg.robust, self.cfg.robust_param)
        infos = rb.check_information_stack(informations, lambda k: f"dense pair {pairs[k]}")
        for (i, j), d, info in zip(np.asarray(pairs).tolist(), np.asarray(deltas, float), infos):
            model = rb.wrap(gtsam.noiseModel.Gaussian.Information(info), kernel)
            graph.add(between_factor(self._check_key(i), self._check_key(j), d, model))
        initial = self._values()
        return self._restart_at(_lm(graph, initial)[0])

    def _restart_at(self, values) -> np.ndarray:
        """Restart iSAM2 at gtsam.Values ``values`` (a batch solution) over the active factors
        (rejected loops left out); returns the poses (K, 3)."""
        import gtsam

        self._reset_isam()
        self._new_graph, self._new_values = self._batch_graph()[0], values
        self._flush()
        self._isam_poses = gtsam.utilities.extractPose2(values).reshape(-1, 3)
        return self.estimate()

    # ---------------------------------------------------------------- exporting

    def to_g2o(self) -> g2o.PoseGraphFile:
        """Keyframes at their current estimate with all odometry and loop edges."""
        _, i, j, measurements, information = zip(*edges) if (edges := self.edges()) else ((),) * 5
        return g2o.PoseGraphFile(ids=np.arange(len(self._initial)), poses=self.estimate(), i=np.array(i, dtype=int),
                                 j=np.array(j, dtype=int), measurements=np.array(measurements).reshape(-1, 3),
                                 information=np.array(information).reshape(-1, 3, 3))

    def edges(self) -> list[tuple[str, int, int, np.ndarray, np.ndarray]]:
        """The odometry and loop factors in the graph (removed loops left out), in the order added:
        (kind, i, j, measurement (3,), information (3, 3)), the measurement the pose of ``j`` in ``i``'s frame."""
        return [(f.kind, f.i, f.j, f.measurement, f.information)
                for f, a in zip(self._factors, self._active) if a and f.kind in ("odometry", "loop")]

    def loop_edges(self) -> np.ndarray:
        """Every loop added, in order, as rows (i, j, kept): keyframe keys and 1 if still in the graph."""
        rows = [(f.i, f.j, int(a)) for f, a in zip(self._factors, self._active) if f.kind == "loop"]
        return np.array(rows, dtype=int).reshape(-1, 3)

    def write_g2o(self, path) -> None:
        """Write ``to_g2o()`` to ``path``."""
        g2o.write_g2o(path, self.to_g2o())

    # ----------------------------------------------------------------- counters

    @property
    def num_keyframes(self) -> int:
        return len(self._initial)

    @property
    def num_odometry(self) -> int:
        """Odometry (consecutive keyframe) factors."""
        return self._count("odometry")

    @property
    def num_loops(self) -> int:
        """Loop-closure factors in the graph (GNC-rejected ones excluded)."""
        return self._count("loop")

    @property
    def num_landmark_observations(self) -> int:
        return self._count("landmark")

    def __len__(self) -> int:
        return len(self._initial)

    # ----------------------------------------------------------------- internals

    def _reset_isam(self) -> None:
        import gtsam

        thresholds = gtsam.ISAM2ThresholdMap()
        thresholds.insert(("x", np.asarray(RELINEARIZE_POSE, dtype=np.float64)))
        thresholds.insert(("l", np.full(2, RELINEARIZE_LANDMARK)))
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(thresholds)
        params.relinearizeSkip = RELINEARIZE_SKIP
        params.enablePartialRelinearizationCheck = PARTIAL_RELINEARIZATION_CHECK
        params.setFactorization(self.factorization)
        self._isam = gtsam.ISAM2(params)
        self._new_graph, self._new_values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        self._n_in_isam = self._n_updated = 0  # keyframes in iSAM2; keyframes update() has seen
        self._pending_other = self._relinearisation_due = False  # pending: a non-odometry factor; a relinearisation
        self._settled = None  # iSAM2's next update would relinearise nothing (None: not asked)
        self._isam_poses = None

    def _add(self, f: _Factor) -> int:
        self._factors.append(f)
        self._active.append(True)
        self._new_graph.add(f.factor)
        self._pending_other |= f.kind != "odometry"
        return len(self._factors) - 1

    def _count(self, kind: str) -> int:
        return sum(a and f.kind == kind for f, a in zip(self._factors, self._active))

    def _batch_graph(self):
        """All active factors as one graph, and each graph position's factor index."""
        import gtsam

        graph, index = gtsam.NonlinearFactorGraph(), []
        for n, (f, a) in enumerate(zip(self._factors, self._active)):
            if a:
                graph.add(f.factor)
                index.append(n)
        return graph, index

    def _reject_inconsistent(self, values) -> list[int]:
        """Deactivate loops whose squared Mahalanobis residual at ``values`` exceeds
        ``CHI2_3DOF_99`` (the graph could not accommodate them); their factor indices."""
        removed = inconsistent_loops(self._factors, self._active, values)
        for n in removed:
            self._active[n] = False
        if removed:
            log.info("%d loop closures inconsistent with the optimised graph removed", len(removed))
        self.rejected_inconsistent += len(removed)
        return removed

    def _second_chance(self, values, removed: list[int]):
        """The ``removed`` loops readmitted where the graph accommodates them (``readmission``); the solution."""
        result, out = second_chance(self._factors, self._active, lambda: self._batch_graph()[0], removed, values, _lm)
        self.rejected_inconsistent += len(set(out) - set(removed)) - sum(self._active[n] for n in removed)
        return result

    def _reject_outliers(self, index, weights) -> None:
        """Deactivate the loops GNC weighs as outliers (counted in ``rejected_inconsistent``)."""
        for g, n in enumerate(index):
            f = self._factors[n]
            if f.kind == "loop" and weights[g] < rb.GNC_OUTLIER_WEIGHT:
                self._active[n] = False
                self.rejected_inconsistent += 1
                log.info("GNC rejected loop %d -> %d (weight %.3g)", f.i, f.j, weights[g])

    def _check_key(self, key) -> int:
        k = int(key)
        if not 0 <= k < len(self._initial):
            raise InputError("pose graph", f"no keyframe {key} (have {len(self._initial)})")
        return k

    def _check_updated(self, key) -> int:
        """``key`` checked to be updated; keyframes waiting outside iSAM2 are handed over."""
        k = self._check_key(key)
        if k >= self._n_updated:
            raise InputError("pose graph", f"keyframe {k} is not optimised yet; call update() first")
        if k >= self._n_in_isam or self._relinearisation_due:
            self._flush()
        return k

    def _relinearise_if_due(self) -> None:
        """Run the relinearisation ``update`` left for its next call before a read."""
        if self._relinearisation_due:
            self._flush()

    def _values(self):
        """gtsam.Values of every variable at its current estimate (a waiting relinearisation run first)."""
        self._relinearise_if_due()
        values = self._isam.calculateEstimate()
        values.insert(self._new_values)
        return values

    def _pose_value(self, k: int):
        """Best current gtsam.Pose2 of keyframe ``k``."""
        if k < self._n_in_isam:
            return self._isam.calculateEstimatePose2(pose_key(k))
        return self._new_values.atPose2(pose_key(k))

    def _point_value(self, lkey: int) -> np.ndarray:
        if self._isam.valueExists(lkey):
            return np.asarray(self._isam.calculateEstimatePoint2(lkey)).ravel()
        return np.asarray(self._new_values.atPoint2(lkey)).ravel()
