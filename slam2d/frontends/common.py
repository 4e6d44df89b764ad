"""What the frontends share: common config fields, the correction bound, information matrices.

Config fields that several frontends' ``Config`` declare, each with its own default, are
typed here once with their bounds and description (``min_sigma_xy: MinSigmaXY = 0.005``).
Information matrices are 3x3 inverse covariances over (x, y, theta) (1/m^2, 1/m^2, 1/rad^2).
A frontend's range window on a scan is ``Scan.hit_mask`` / ``Scan.points_in_base`` with
``min_range`` and ``max_range``.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np
from pydantic import Field

from slam2d import geometry

__all__ = [
    "MinRange",
    "MaxRange",
    "OdomSigmaXY",
    "OdomSigmaThetaDeg",
    "MinSigmaXY",
    "MinSigmaThetaDeg",
    "MaxSigmaXY",
    "MaxSigmaThetaDeg",
    "MaxCorrectionXY",
    "MaxCorrectionThetaDeg",
    "sigma_bounds",
    "beyond_correction",
    "bound_information",
    "cap_information",
    "local_information",
]

# --------------------------------------------------------------------------- config fields

MinRange = Annotated[float, Field(ge=0, description="m; hits closer to the sensor are ignored")]
MaxRange = Annotated[float, Field(gt=0, description="m; hits farther from the sensor are ignored")]
OdomSigmaXY = Annotated[float, Field(gt=0, description="m; std of the odometry delta")]
OdomSigmaThetaDeg = Annotated[float, Field(gt=0, description="std of the odometry delta")]
MinSigmaXY = Annotated[float, Field(gt=0, description="m; the information never claims a smaller std")]
MinSigmaThetaDeg = Annotated[float, Field(gt=0, description="the information never claims a smaller std")]
MaxSigmaXY = Annotated[float, Field(gt=0, description="m; largest std of a direction (degenerate ones get it)")]
MaxSigmaThetaDeg = Annotated[float, Field(gt=0, description="largest std of a direction (degenerate ones get it)")]
MaxCorrectionXY = Annotated[float, Field(gt=0, description="m; a match farther from the odometry guess diverged")]
MaxCorrectionThetaDeg = Annotated[float, Field(gt=0, description="a match turned more from the odometry guess "
                                                                  "diverged")]


def sigma_bounds(cfg) -> tuple[np.ndarray, np.ndarray]:
    """(min_sigma, max_sigma), each (3,) (m, m, rad), of a config's ``min_sigma_xy``,
    ``min_sigma_theta_deg``, ``max_sigma_xy`` and ``max_sigma_theta_deg``."""
    lo = np.array([cfg.min_sigma_xy, cfg.min_sigma_xy, np.deg2rad(cfg.min_sigma_theta_deg)])
    hi = np.array([cfg.max_sigma_xy, cfg.max_sigma_xy, np.deg2rad(cfg.max_sigma_theta_deg)])
    return lo, hi


def beyond_correction(guess, pose, max_xy: float, max_theta_deg: float) -> bool:
    """Whether ``pose`` (3,) lies more than ``max_xy`` m or ``max_theta_deg`` degrees from ``guess`` (3,),
    measured in the frame of ``guess``."""
    corr = geometry.between(guess, pose)
    return bool(np.hypot(corr[0], corr[1]) > max_xy or abs(corr[2]) > np.deg2rad(max_theta_deg))


# --------------------------------------------------------------------------- information matrices


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


def cap_information(info: np.ndarray, min_sigma_xy: float, min_sigma_theta: float) -> np.ndarray:
    """``info`` (3, 3) symmetrised, with no direction claiming a std below ``min_sigma_xy`` (m) and
    ``min_sigma_theta`` (rad) and every scaled eigenvalue at least 1e-12 (no upper std bound)."""
    s = np.diag([min_sigma_xy, min_sigma_xy, min_sigma_theta])
    scaled = s @ (0.5 * (info + info.T)) @ s
    vals, vecs = np.linalg.eigh(scaled)
    vals = np.clip(vals, 1e-12, 1.0)
    inv = np.diag(1.0 / np.diag(s))
    return inv @ (vecs * vals) @ vecs.T @ inv


def local_information(info_world: np.ndarray, theta: float) -> np.ndarray:
    """Information (3, 3) of a pose at heading ``theta`` (rad) perturbed in its own frame, from its
    information over map-frame (x, y, theta) perturbations."""
    a = np.eye(3)
    a[:2, :2] = geometry.rotation(theta)
    return a.T @ info_world @ a
