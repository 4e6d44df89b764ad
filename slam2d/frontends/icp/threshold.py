"""The correspondence scale of ICP: kiss-icp's adaptive threshold, clipped."""

from __future__ import annotations

import numpy as np

from slam2d.frontends.icp.config import IcpConfig
from slam2d.frontends.icp.registration import pose_to_matrix

__all__ = ["AdaptiveThreshold", "get_threshold_estimator"]


class AdaptiveThreshold:
    """kiss-icp's ``AdaptiveThreshold``: a correspondence scale (m) from the deviations of the
    accepted results from their predictions, starting at ``initial_threshold`` m (deviations below
    ``min_motion`` m are not counted; ``max_range`` m turns rotation into m), clipped to
    [``min_threshold``, ``max_threshold``] m."""

    def __init__(self, initial_threshold: float, min_motion: float, max_range: float, min_threshold: float,
                 max_threshold: float):
        from kiss_icp.pybind import kiss_icp_pybind

        self._estimator = kiss_icp_pybind._AdaptiveThreshold(
            initial_threshold=initial_threshold, min_motion_th=min_motion, max_range=max_range
        )
        self.min_threshold, self.max_threshold = min_threshold, max_threshold

    @property
    def value(self) -> float:
        """Current correspondence scale (m)."""
        sigma = self._estimator._compute_threshold()
        return float(np.clip(sigma, self.min_threshold, self.max_threshold))

    def update(self, correction) -> None:
        """Count the deviation ``correction`` (3,) of an accepted result from its prediction."""
        self._estimator._update_model_deviation(pose_to_matrix(correction))


def get_threshold_estimator(config: IcpConfig) -> AdaptiveThreshold:
    """The adaptive threshold of ``config`` (``initial_threshold``, ``min_motion``, ``threshold_range``,
    ``min_threshold``, ``max_threshold``)."""
    return AdaptiveThreshold(config.initial_threshold, config.min_motion, config.threshold_range,
                             config.min_threshold, config.max_threshold)
