"""Degeneracy-aware fusion of a scan match with the motion prediction (solution remapping).

A scan constrains the motion only in some directions: in a corridor its walls fix the
heading and the position across, nothing fixes the position along. Following Zhang, Kaess
and Singh ("On degeneracy of optimization-based state estimation problems", ICRA 2016) and
Tuna et al. (X-ICP, T-RO 2023), the match's correction to the prediction is kept only in
the directions the scan constrains; in the others the prediction (wheel odometry, or the
prediction that overruled it) stands.

Which directions: the generalised eigenproblem ``H v = lambda Omega v`` of the scan's
information ``H`` (J^T W J / sigma^2, 1/m^2 and 1/rad^2) against the prediction's
information ``Omega`` (the odometry noise model). A direction with ``lambda`` below
``ratio`` carries less information from the scan than from odometry: it is degenerate and
left to the prediction. With ``Omega`` from the odometry's stds this needs no scale of its
own: metres and radians are weighed by the odometry noise. Deltas are ``(x, y, theta)`` in
the previous base frame (m, m, rad).
"""

from __future__ import annotations

import numpy as np

from slam2d import geometry

__all__ = ["constrained_projector", "remap"]


def constrained_projector(scan_information: np.ndarray, prior_information: np.ndarray,
                          ratio: float) -> tuple[np.ndarray, int]:
    """(P (3, 3), number of degenerate directions): ``P @ c`` is the part of a correction ``c`` (3,)
    in the directions where ``scan_information`` (3, 3) exceeds ``ratio`` x ``prior_information``
    (3, 3, positive definite); P is the identity when every direction is constrained."""
    lower = np.linalg.cholesky(prior_information)  # Omega = L L^T
    inv = np.linalg.inv(lower)
    normalised = inv @ (0.5 * (scan_information + scan_information.T)) @ inv.T
    vals, vecs = np.linalg.eigh(normalised)
    kept = vecs[:, vals >= ratio]
    free = 3 - kept.shape[1]
    if free == 0:
        return np.eye(3), 0
    return inv.T @ kept @ kept.T @ lower.T, free


def remap(base: np.ndarray, predicted: np.ndarray, matched: np.ndarray, scan_information: np.ndarray,
          prior_information: np.ndarray, ratio: float) -> tuple[np.ndarray, int]:
    """(pose (3,), degenerate directions): ``matched`` moved back to ``predicted`` along the directions
    the scan does not constrain (see :func:`constrained_projector`). Poses are in one frame; the
    informations are over the delta from ``base`` (perturbations in ``base``'s frame)."""
    if ratio <= 0:
        return matched, 0
    projector, free = constrained_projector(scan_information, prior_information, ratio)
    if free == 0:
        return matched, 0
    d_pred = geometry.between(base, predicted)
    correction = geometry.between(base, matched) - d_pred
    correction[2] = geometry.wrap_angle(correction[2])
    return geometry.compose(base, d_pred + projector @ correction), free
