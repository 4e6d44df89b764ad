"""Sampling steps of Monte Carlo localisation: the odometry motion model, systematic
resampling and the particle count KLD sampling asks for."""

from __future__ import annotations

import math

import numpy as np

from slam2d import geometry
from slam2d.localization.config import MclConfig

__all__ = ["kld_limit", "low_variance_indices", "sample_motion"]

_MIN_TRANS = 0.01  # m: below this a motion has no heading of its own (rot1 = 0), as in amcl


def kld_limit(k, err: float, z: float, n_min: int, n_max: int, single_bin: str = "min") -> np.ndarray:
    """Particles KLD sampling asks for ``k`` occupied bins (Fox 2003, eq. 12), clipped to [n_min, n_max]:
    n = (k - 1) / (2 err) (1 - 2 / (9 (k - 1)) + sqrt(2 / (9 (k - 1))) z)^3; one bin gives n_min or n_max."""
    k = np.asarray(k, dtype=np.float64)
    km1 = np.maximum(k - 1.0, 1.0)
    a = 2.0 / (9.0 * km1)
    n = np.ceil(km1 / (2.0 * err) * (1.0 - a + np.sqrt(a) * z) ** 3)
    n = np.where(k <= 1, n_min if single_bin == "min" else n_max, n)
    return np.clip(n, n_min, n_max).astype(np.int64)


def sample_motion(particles: np.ndarray, before, after, cfg: MclConfig, rng: np.random.Generator) -> np.ndarray:
    """Particles (P, 3) moved by the odometry ``before`` -> ``after`` (3,) with the four-alpha noise
    (sample_motion_model_odometry; a backward step's turns count without their half turn, as amcl)."""
    d = geometry.between(before, after)
    trans = math.hypot(d[0], d[1])
    rot1 = math.atan2(after[1] - before[1], after[0] - before[0]) - before[2] if trans >= _MIN_TRANS else 0.0
    rot1 = float(geometry.wrap_angle(rot1))
    rot2 = float(geometry.wrap_angle(d[2] - rot1))
    turn1, turn2 = min(abs(rot1), math.pi - abs(rot1)), min(abs(rot2), math.pi - abs(rot2))
    sd = np.sqrt([cfg.alpha1 * turn1**2 + cfg.alpha2 * trans**2,
                  cfg.alpha3 * trans**2 + cfg.alpha4 * (turn1**2 + turn2**2),
                  cfg.alpha1 * turn2**2 + cfg.alpha2 * trans**2])  # fmt: skip
    e = rng.standard_normal((len(particles), 3)) * sd
    r1, t, r2 = rot1 - e[:, 0], trans - e[:, 1], rot2 - e[:, 2]
    heading = particles[:, 2] + r1
    out = np.empty_like(particles)
    out[:, 0] = particles[:, 0] + t * np.cos(heading)
    out[:, 1] = particles[:, 1] + t * np.sin(heading)
    out[:, 2] = geometry.wrap_angle(heading + r2)
    return out


def low_variance_indices(weights: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` indices drawn with probability ``weights`` (normalised) by one random offset (systematic)."""
    cdf = np.cumsum(weights)
    cdf[-1] = 1.0
    return np.minimum(np.searchsorted(cdf, (rng.random() + np.arange(count)) / count), len(weights) - 1)
