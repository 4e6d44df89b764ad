"""The corner frontend: scan corners matched to the global corner list, landmark observations of matched
corners, a pose covariance grown by odometry between matches."""

from __future__ import annotations

import logging
from collections import Counter

import numpy as np
from pydantic import Field

from slam2d import geometry
from slam2d.config import Section
from slam2d.frontends.base import FrontendResult, register_frontend
from slam2d.frontends.common import (
    MaxCorrectionThetaDeg,
    MaxCorrectionXY,
    MaxSigmaThetaDeg,
    MaxSigmaXY,
    MinSigmaThetaDeg,
    MinSigmaXY,
    beyond_correction,
    bound_information,
    sigma_bounds,
)
from slam2d.frontends.corners.extraction import (
    CornerExtraction,
    CornerExtractionConfig,
    extract_corners,
)
from slam2d.frontends.corners.map import CornerMap
from slam2d.frontends.corners.matching import (
    corner_confidence,
    match_corners,
    unique_matches,
)
from slam2d.frontends.gate import SimilarityGate
from slam2d.frontends.odometry import HeadingCalibration, MotionNoise, odometry_spike
from slam2d.types import LandmarkObservation, Scan

log = logging.getLogger(__name__)

__all__ = ["CornerFrontend"]


class CornerFrontend:
    """Scan corners matched to the global corner list; landmark observations of matched corners."""

    class Config(Section):
        """Corner frontend options: extraction, corner list, matching, information, gate."""

        extraction: CornerExtractionConfig = CornerExtractionConfig()
        merge_radius: float = Field(0.25, gt=0, description="m; a corner this close to a listed one is that one")
        match_radius: float = Field(0.4, gt=0, description="m; association radius at the odometry guess")
        min_observations: int = Field(2, ge=1, description="sightings before a listed corner is matched")
        tentative_scans: int = Field(30, ge=1, description="scans a corner with fewer sightings is kept")
        rebuild_every: int = Field(16, gt=0, description="appends before the KD-tree is rebuilt")
        max_count: int = Field(50, gt=0, description="sightings weighting a corner's running mean at most")
        max_angle_deg: float = Field(30.0, gt=0, description="bisectors of one corner differ by less than this")
        use_direction: bool = Field(False, description="the corners' bisectors also constrain the heading")
        sigma_corner: float = Field(0.05, gt=0, description="m; std of an observed corner against its listed one")
        sigma_direction_deg: float = Field(1.0, gt=0, description="std added to a bisector's own (arm fit) std")
        max_correction_xy: MaxCorrectionXY = 0.5
        max_correction_theta_deg: MaxCorrectionThetaDeg = 15.0
        motion: MotionNoise = MotionNoise()
        max_pose_sigma_xy: float = Field(0.5, gt=0, description="m; the pose uncertainty between matches stops here")
        max_pose_sigma_theta_deg: float = Field(10.0, gt=0, description="... and here")
        min_sigma_xy: MinSigmaXY = 0.005
        min_sigma_theta_deg: MinSigmaThetaDeg = 0.1
        max_sigma_xy: MaxSigmaXY = 1.0
        max_sigma_theta_deg: MaxSigmaThetaDeg = 20.0
        landmarks: bool = Field(True, description="return matched corners as landmark observations")
        landmark_sigma: float = Field(0.2, gt=0, description="m; std of a landmark observation (range, and across)")
        gate: SimilarityGate.Config = SimilarityGate.Config(min_confidence=0.66)
        calibration: HeadingCalibration.Config = HeadingCalibration.Config()

    def __init__(self, config: Config | None = None):
        self.config = cfg = config or self.Config()
        self.map = CornerMap(cfg.merge_radius, cfg.rebuild_every, cfg.max_count, cfg.max_angle_deg)
        self.pose = np.zeros(3)
        self.events: Counter[str] = Counter()
        self.gate = SimilarityGate(cfg.gate)
        self.gate.events = self.events
        self.cov = np.zeros((3, 3))  # uncertainty of self.pose against the corner list, local frame
        self._before = (self.pose, self.cov)  # pose and covariance before the last scan
        self._last_delta: np.ndarray | None = None
        self._cov_cap = np.array([cfg.max_pose_sigma_xy, cfg.max_pose_sigma_xy,
                                  np.deg2rad(cfg.max_pose_sigma_theta_deg)])
        self._min_sigma, self._max_sigma = sigma_bounds(cfg)
        self._previous: np.ndarray | None = None
        self._index = 0
        self.calibration = HeadingCalibration(cfg.calibration)

    def process(self, scan: Scan, odom_delta) -> FrontendResult:
        """Match the scan's corners to the corner list, starting from the odometry guess.

        The pose against the corner list carries a covariance: odometry grows
        it (``motion``), a match shrinks it; the predicted covariance is the
        prior of the match, so noisy corners move a well-known pose little.
        """
        odom_delta = self.calibration.correct(odom_delta)
        base, base_cov, motion = self.pose, self.cov, odom_delta
        if odometry_spike(self._last_delta, odom_delta):  # bridge the outlier odometry of the last scan
            self.events["odometry spike bridged"] += 1
            base, base_cov = self._before
            motion = geometry.compose(self._last_delta, odom_delta)
        self._before, self._last_delta = (self.pose, self.cov), odom_delta
        guess = geometry.compose(base, motion)
        step = self.config.motion.covariance(motion)
        predicted = _capped(geometry.compose_covariance(base_cov, motion, step), self._cov_cap)
        odom_delta = geometry.between(self.pose, guess)  # the odometry estimate of this scan's delta
        ext = self.extract(scan)
        points = scan.points_in_base()
        result, pose, cov = self._odometry(odom_delta, step), guess, predicted
        if self._index > 0:
            matched, match_pose, match_cov = self._match(ext, guess, predicted, step, odom_delta)
            if matched is not None and self.gate.check(self._previous, points, matched, odom_delta) is matched:
                result, pose, cov = matched, match_pose, match_cov
                self.calibration.observe(pose, guess)
        self._commit(pose, cov, ext)
        self._previous = points
        return result

    def extract(self, scan: Scan) -> CornerExtraction:
        """Corners of ``scan`` with points (C, 2) and bisector directions (C,) in the base frame."""
        ext = extract_corners(scan.ranges, scan.angles, scan.range_min, scan.range_max, self.config.extraction)
        mount = geometry.as_pose(scan.sensor_pose)
        return CornerExtraction(ext.index, geometry.transform_points(mount, ext.points), ext.turn,
                                geometry.wrap_angle(ext.direction + mount[2]), ext.direction_var, ext.candidates)

    # ------------------------------------------------------------------ steps

    def _match(self, ext: CornerExtraction, guess, predicted, step, odom_delta):
        """(result, pose, covariance) of a corner match from ``guess``, or (None, ...) after counting why not."""
        cfg = self.config
        corners = ext.points
        if not len(corners):
            return self._fallback("no corners")
        idx, dist = self.map.nearest(geometry.transform_points(guess, corners), cfg.match_radius,
                                     cfg.min_observations, geometry.wrap_angle(ext.direction + guess[2]))
        idx = unique_matches(idx, dist)
        sel = np.flatnonzero(idx >= 0)
        if not len(sel):
            return self._fallback("no matched corners")
        dirs = {}
        if cfg.use_direction:
            dirs = dict(obs_dir=ext.direction[sel], ref_dir=self.map.direction[idx[sel]],
                        dir_var=ext.direction_var[sel] + np.deg2rad(cfg.sigma_direction_deg) ** 2)
        prior = np.linalg.inv(predicted + 1e-12 * np.eye(3))
        match = match_corners(corners[sel], self.map.xy[idx[sel]], guess, prior, cfg.sigma_corner, **dirs)
        if beyond_correction(guess, match.pose, cfg.max_correction_xy, cfg.max_correction_theta_deg):
            return self._fallback("correction beyond max_correction")
        used = sel[match.inliers]
        if not len(used):
            return self._fallback("no consistent corners")
        odometry = np.linalg.inv(step)
        info = bound_information(match.information + odometry, self._min_sigma, self._max_sigma)
        landmarks = self._landmarks(corners[used], self.map.ids[idx[used]]) if cfg.landmarks else ()
        result = FrontendResult(delta=geometry.between(self.pose, match.pose), information=info,
                                confidence=corner_confidence(len(used)), landmarks=landmarks)
        return result, match.pose, np.linalg.inv(match.information + prior)

    def _landmarks(self, corners: np.ndarray, ids: np.ndarray) -> tuple[LandmarkObservation, ...]:
        """Range-bearing observations of corners (base frame); covariance in (bearing, range) order."""
        s = self.config.landmark_sigma
        rng = np.hypot(corners[:, 0], corners[:, 1])
        bearing = np.arctan2(corners[:, 1], corners[:, 0])
        return tuple(
            LandmarkObservation(int(i), float(r), float(b), np.diag([(s / max(r, s)) ** 2, s**2]))
            for i, r, b in zip(ids, rng, bearing)
        )

    def _commit(self, pose, cov, ext: CornerExtraction) -> None:
        cfg = self.config
        self.pose, self.cov = pose, 0.5 * (cov + cov.T)
        if len(ext.points):
            self.map.update(geometry.transform_points(pose, ext.points), self._index,
                            geometry.wrap_angle(ext.direction + pose[2]))
        if self._index % 25 == 0:
            self.map.prune(self._index, cfg.min_observations, cfg.tentative_scans)
        self._index += 1

    @staticmethod
    def _odometry(odom_delta, step_cov) -> FrontendResult:
        """The odometry delta is the estimate: information of one odometry step, confidence 0."""
        return FrontendResult(delta=odom_delta.copy(), information=np.linalg.inv(step_cov), confidence=0.0)

    def _fallback(self, reason: str):
        self.events[reason] += 1
        log.debug("corners fallback to odometry: %s", reason)
        return None, None, None


def _capped(cov: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """``cov`` with every direction's std at most ``sigma`` (per axis, scaled)."""
    normalised = cov / sigma[:, None] / sigma[None, :]
    vals, vecs = np.linalg.eigh(0.5 * (normalised + normalised.T))
    return (vecs * np.minimum(vals, 1.0)) @ vecs.T * sigma[:, None] * sigma[None, :]


register_frontend("corners")(CornerFrontend)
