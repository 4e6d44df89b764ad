"""Odometry models the frontends share.

The information of an odometry delta, a motion-dependent odometry noise, a test for
one-scan odometry outliers, and an online calibration of the odometry heading (a
curvature bias and a turn scale). Deltas are ``(x, y, theta)`` (m, m, rad) in the
previous base frame.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from slam2d import geometry
from slam2d.config import Section

__all__ = ["odometry_information", "MotionNoise", "odometry_spike", "HeadingCalibration"]


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
