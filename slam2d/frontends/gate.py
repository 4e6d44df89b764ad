"""Accept a scan match or keep odometry: the frame-to-frame similarity gate.

The patrol-robot thesis (Tian 2016, section 2.3.3) trusts a laser correction
only when consecutive scans are similar (a nearest-neighbour similarity that
dips when the robot passes a doorway, enters new ground or sees heavy noise)
and the matcher's own confidence is high; otherwise it keeps odometry.

:class:`SimilarityGate` implements that decision for any frontend. The
similarity is a normalised form of the thesis's nearest-neighbour measure:
the current points are moved into the previous base frame by the match's
delta (or the odometry delta), and the similarity is the mean of the two
directed fractions of points that have a neighbour in the other scan within
``radius + range_factor * range`` metres (1 for identical scans, symmetric,
in [0, 1]). A scan is "not continuous" when its similarity is below
``min_similarity`` or below ``min_relative`` times the running typical value
(the dip at a doorway).

The module also holds the small odometry helpers the feature frontends share:
an odometry information matrix, a motion-dependent odometry noise, a test for
one-scan odometry outliers, eigenvalue bounds on an information, and an online
calibration of the odometry heading (a curvature bias and a turn scale).
"""

from __future__ import annotations

import logging
from collections import Counter
from typing import Literal

import numpy as np
from pydantic import Field

from slam2d import geometry
from slam2d.config import Section
from slam2d.frontends.base import FrontendResult

log = logging.getLogger(__name__)

__all__ = [
    "SimilarityGate",
    "MotionNoise",
    "odometry_spike",
    "nn_similarity",
    "odometry_information",
    "bound_information",
    "HeadingCalibration",
]


def odometry_information(sigma_xy: float, sigma_theta_deg: float) -> np.ndarray:
    """Diagonal 3x3 information of an odometry delta with stds ``sigma_xy`` (m) and ``sigma_theta_deg``."""
    return np.diag(1.0 / np.array([sigma_xy, sigma_xy, np.deg2rad(sigma_theta_deg)]) ** 2)


class MotionNoise(Section):
    """Odometry noise of one step: a floor per step plus drift growing with the motion."""

    sigma_xy: float = Field(0.01, gt=0, description="m per step")
    sigma_theta_deg: float = Field(0.2, gt=0, description="per step")
    drift_xy: float = Field(0.05, ge=0, description="m per m travelled")
    drift_theta_deg: float = Field(2.0, ge=0, description="per m travelled")
    drift_rotation: float = Field(0.05, ge=0, description="rad per rad turned")

    def covariance(self, delta) -> np.ndarray:
        """Diagonal 3x3 covariance (m^2, m^2, rad^2) of an odometry delta (x, y, theta)."""
        d = geometry.as_pose(delta)
        trans = float(np.hypot(d[0], d[1]))
        s_xy = self.sigma_xy + self.drift_xy * trans
        s_th = np.deg2rad(self.sigma_theta_deg + self.drift_theta_deg * trans) + self.drift_rotation * abs(d[2])
        return np.diag([s_xy**2, s_xy**2, s_th**2])


def odometry_spike(previous, current, min_turn_deg: float = 5.0, ratio: float = 0.3) -> bool:
    """Whether the odometry delta ``current`` undoes a turn of ``previous`` larger than ``min_turn_deg``.

    Then the odometry pose of the scan between was an outlier (seen in the
    Intel log, where interleaved odometry messages give one-scan heading
    spikes of 5-15 degrees): both deltas should be replaced by their composition.
    """
    if previous is None:
        return False
    a, b = float(geometry.as_pose(previous)[2]), float(geometry.as_pose(current)[2])
    return abs(a) > np.deg2rad(min_turn_deg) and abs(a + b) < ratio * abs(a)


class HeadingCalibration:
    """Online calibration of the odometry heading: a curvature bias (rad/m) and a turn-scale error.

    The two systematic heading errors of a differential drive (Borenstein and
    Feng's UMBmark) are unequal wheel radii, which bend straight runs by a
    fixed angle per metre, and a wrong wheelbase, which scales every turn (the
    Intel log's odometry bends by about 2 degrees per metre against its scan
    matches). Between two accepted matches the heading error of the corrected
    odometry is ``curvature_error * forward_distance + scale_error * turn``;
    each accepted match measures it (its heading minus the predicted one) and
    recursive least squares with forgetting refines both parameters.
    :meth:`correct` turns every odometry delta by ``curvature * dx + scale *
    dtheta``, once a parameter is significant, so the heading drifts less
    while no match is found.
    """

    class Config(Section):
        """Calibration of the odometry heading from the matches' heading corrections."""

        enabled: bool = Field(True, description="False: odometry deltas are used as they are")
        forgetting: float = Field(0.995, gt=0, le=1, description="RLS forgetting factor per accepted match")
        sigma_curvature_deg_m: float = Field(3.0, ge=0, description="prior std of the curvature bias (0: none)")
        sigma_scale: float = Field(0.05, ge=0, description="prior std of the turn-scale error (0: none)")
        noise_deg: float = Field(0.5, gt=0, description="std of one match's heading correction")
        max_curvature_deg_m: float = Field(5.0, ge=0, description="the curvature estimate stays within +- this")
        max_scale: float = Field(0.1, ge=0, description="the turn-scale estimate stays within +- this")
        max_span: float = Field(2.0, gt=0, description="m; corrections after a longer run without a match are unused")
        min_updates: int = Field(20, ge=0, description="accepted matches before odometry is corrected")
        significance: float = Field(4.0, ge=0, description="a parameter corrects odometry only beyond this many "
                                    "of its standard errors")

    def __init__(self, config: Config | None = None):
        self.config = cfg = config or self.Config()
        self.params = np.zeros(2)  # curvature (rad/m), turn-scale error
        self.cov = np.diag([np.deg2rad(cfg.sigma_curvature_deg_m) ** 2, cfg.sigma_scale**2])
        self.updates = 0
        self._since = np.zeros(2)  # (forward distance m, odometry turn rad) since the last accepted match
        self._travel = 0.0  # path length since the last accepted match, m

    @property
    def applied(self) -> np.ndarray:
        """The parameters (curvature rad/m, scale) that correct odometry now: each estimate beyond
        ``significance`` standard errors (after ``min_updates`` matches), else 0."""
        if not self.config.enabled or self.updates < self.config.min_updates:
            return np.zeros(2)
        sd = np.sqrt(np.maximum(np.diag(self.cov), 0.0))
        return np.where(np.abs(self.params) > self.config.significance * sd, self.params, 0.0)

    def correct(self, delta) -> np.ndarray:
        """The odometry ``delta`` (3,) with its heading corrected; its motion is added to the current span."""
        delta = geometry.as_pose(delta).copy()
        phi = np.array([delta[0], delta[2]])
        self._since += phi
        self._travel += float(np.hypot(delta[0], delta[1]))
        delta[2] += float(self.applied @ phi)
        return delta

    def observe(self, matched, predicted) -> None:
        """An accepted match put the base at pose ``matched`` (3,) where odometry predicted ``predicted``:
        refine from their heading difference, restart the span."""
        heading_error = geometry.wrap_angle(float(matched[2]) - float(predicted[2]))
        cfg = self.config
        phi, travel = self._since, self._travel
        applied = self.applied
        self._since, self._travel = np.zeros(2), 0.0
        if not cfg.enabled or travel > cfg.max_span or not phi.any():
            return
        # raw odometry error = measured error of the corrected prediction + the correction applied
        innovation = float(heading_error) + float(phi @ applied) - float(phi @ self.params)
        noise = np.deg2rad(cfg.noise_deg) ** 2
        p_phi = self.cov @ phi
        gain = p_phi / (cfg.forgetting * noise + phi @ p_phi)
        self.params = self.params + gain * innovation
        self.cov = (self.cov - np.outer(gain, p_phi)) / cfg.forgetting
        limit = np.array([np.deg2rad(cfg.max_curvature_deg_m), cfg.max_scale])
        self.params = np.clip(self.params, -limit, limit)
        self.updates += 1


def bound_information(info: np.ndarray, min_sigma: np.ndarray, max_sigma: np.ndarray) -> np.ndarray:
    """Symmetric ``info`` (3, 3) with every direction's std within [min_sigma, max_sigma] (per axis, m, m, rad).

    The bounds apply to the information scaled by the per-axis sigmas, so the
    result stays positive definite in degenerate scenes and never claims a
    smaller std than ``min_sigma``.
    """
    info = 0.5 * (info + info.T)
    for scale, floor in ((np.asarray(max_sigma, float), True), (np.asarray(min_sigma, float), False)):
        normalised = scale[:, None] * info * scale[None, :]
        vals, vecs = np.linalg.eigh(normalised)
        vals = np.maximum(vals, 1.0) if floor else np.minimum(vals, 1.0)
        info = (vecs * vals) @ vecs.T / scale[:, None] / scale[None, :]
        info = 0.5 * (info + info.T)
    return info


def _tree(points: np.ndarray):
    from scipy.spatial import cKDTree

    return cKDTree(points, balanced_tree=False, compact_nodes=False)


def _shared_fraction(query: np.ndarray, limit: np.ndarray, tree) -> float:
    """Fraction of ``query`` points (M, 2) with a tree point within ``limit`` (M,) m."""
    dist, _ = tree.query(query, k=1, distance_upper_bound=float(limit.max()) + 1e-9)
    return float(np.mean(dist <= limit))


def nn_similarity(a: np.ndarray, b: np.ndarray, radius: float = 0.1, range_factor: float = 0.0) -> float:
    """Symmetric nearest-neighbour similarity in [0, 1] of point sets ``a`` (N, 2) and ``b`` (M, 2), metres.

    A point counts as shared when the other set has a point within
    ``radius + range_factor * |point|`` m (``|point|``: distance from the
    frame origin, which absorbs the wider beam spacing far away). The result is
    the mean of the shared fractions of ``a`` and of ``b``; 0 if either is empty.
    """
    a, b = np.asarray(a, float).reshape(-1, 2), np.asarray(b, float).reshape(-1, 2)
    if len(a) == 0 or len(b) == 0:
        return 0.0
    limit_a = radius + range_factor * np.hypot(a[:, 0], a[:, 1])
    limit_b = radius + range_factor * np.hypot(b[:, 0], b[:, 1])
    return 0.5 * (_shared_fraction(a, limit_a, _tree(b)) + _shared_fraction(b, limit_b, _tree(a)))


class SimilarityGate:
    """Accept a match when frame-to-frame similarity is normal and confidence high; else odometry.

    ``check(previous, current, result, odom_delta)`` returns ``result`` or an
    odometry fallback (odometry delta and information, confidence 0). Each
    fallback is counted in ``events`` under ``gate: <reason>``.

    The two scans are aligned by the match's own delta (``align = "match"``:
    a doorway, new ground or a wrong match all lower the overlap) or by the
    odometry delta (``"odometry"``, closer to the thesis, which then also
    rejects matches exactly where odometry slipped).
    """

    class Config(Section):
        """Gate thresholds; the thesis gives none, these suit 1-degree scans at 5-10 Hz."""

        enabled: bool = Field(True, description="False: every result passes")
        align: Literal["match", "odometry"] = Field("match", description="delta that aligns the two scans")
        radius: float = Field(0.1, gt=0, description="m; a point within this of the other scan is shared")
        range_factor: float = Field(0.02, ge=0, description="m per m of range added to radius (beam spacing)")
        min_similarity: float = Field(0.5, ge=0, le=1, description="below this the scans are not continuous")
        min_relative: float = Field(
            0.7, ge=0, le=1, description="below this fraction of the recent typical similarity is a dip"
        )
        history: int = Field(20, gt=0, description="scans in the running typical similarity (EMA span)")
        min_confidence: float = Field(0.3, ge=0, le=1, description="matches with a lower confidence are dropped")
        odom_sigma_xy: float = Field(0.05, gt=0, description="m; std of the odometry fallback delta")
        odom_sigma_theta_deg: float = Field(2.0, gt=0, description="std of the odometry fallback delta")

    def __init__(self, config: Config | None = None):
        self.config = config or self.Config()
        self.events: Counter[str] = Counter()
        self.odometry_information = odometry_information(self.config.odom_sigma_xy, self.config.odom_sigma_theta_deg)
        self.typical: dict[str, float] = {}  # per source: EMA of recent similarities
        self.last_similarity: float | None = None
        self._trees: list[tuple[np.ndarray, object]] = []  # KD-trees of the last two scans

    def _tree_of(self, points: np.ndarray):
        """KD-tree of ``points`` (built once per array; the last two are kept)."""
        for pts, tree in self._trees:
            if pts is points:
                return tree
        tree = _tree(points)
        self._trees = [*self._trees[-1:], (points, tree)]
        return tree

    def similarity(self, previous: np.ndarray | None, current: np.ndarray, delta) -> float | None:
        """:func:`nn_similarity` of ``current`` and ``previous`` (each in its own base frame), aligned by ``delta``.

        ``delta`` (3,) is the current base pose in the previous base frame. None
        without a previous scan, 0 if either scan is empty.
        """
        if previous is None:
            return None
        if len(previous) == 0 or len(current) == 0:
            return 0.0
        cfg, delta = self.config, geometry.as_pose(delta)
        limit_cur = cfg.radius + cfg.range_factor * np.hypot(current[:, 0], current[:, 1])
        limit_prev = cfg.radius + cfg.range_factor * np.hypot(previous[:, 0], previous[:, 1])
        forward = _shared_fraction(geometry.transform_points(delta, current), limit_cur, self._tree_of(previous))
        backward = _shared_fraction(geometry.transform_points(geometry.inverse(delta), previous), limit_prev,
                                    self._tree_of(current))
        return 0.5 * (forward + backward)

    def continuity(self, similarity: float | None, source: str = "") -> str | None:
        """Why scans with this ``similarity`` are not continuous (too low, or a dip), else None.

        Call once per scan and ``source``: it also updates that source's running
        typical similarity (``None``, no previous scan, is continuous and changes nothing).
        """
        if similarity is None:
            return None
        cfg = self.config
        typical = self.typical.get(source)
        alpha = 2.0 / (cfg.history + 1.0)
        self.typical[source] = similarity if typical is None else (1 - alpha) * typical + alpha * similarity
        self.last_similarity = similarity
        if similarity < cfg.min_similarity:
            return "similarity below min_similarity"
        if typical is not None and similarity < cfg.min_relative * typical:
            return "similarity dip"
        return None

    def decide(self, discontinuity: str | None, result: FrontendResult, odom_delta,
               min_confidence: float | None = None, source: str = "") -> FrontendResult:
        """``result``, or the odometry fallback (counted) if the scans are discontinuous or confidence low.

        ``discontinuity`` is what :meth:`continuity` returned for this scan.
        """
        if not self.config.enabled:
            return result
        threshold = self.config.min_confidence if min_confidence is None else min_confidence
        reason = discontinuity
        if reason is None and result.confidence < threshold:
            reason = "confidence below min_confidence"
        return result if reason is None else self.fallback(reason, odom_delta, source)

    def check(self, previous: np.ndarray | None, current: np.ndarray, result: FrontendResult, odom_delta,
              min_confidence: float | None = None, source: str = "") -> FrontendResult:
        """Gate ``result`` of the scan ``current`` (base frame, (M, 2)) after ``previous`` (or None)."""
        if not self.config.enabled:
            return result
        align = result.delta if self.config.align == "match" else odom_delta
        discontinuity = self.continuity(self.similarity(previous, current, align), source)
        return self.decide(discontinuity, result, odom_delta, min_confidence, source)

    def fallback(self, reason: str, odom_delta, source: str = "") -> FrontendResult:
        """Odometry delta with the odometry information and confidence 0, counted under ``reason``."""
        key = f"gate{' ' + source if source else ''}: {reason}"
        self.events[key] += 1
        log.debug("%s", key)
        return FrontendResult(
            delta=geometry.as_pose(odom_delta).copy(), information=self.odometry_information.copy(), confidence=0.0
        )
