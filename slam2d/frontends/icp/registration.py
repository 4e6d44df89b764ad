"""Registration of one scan to the local map: point-to-line Gauss-Newton or kiss-icp's point-to-point.

Both solvers start from a given pose and share the map, the threshold and the fit of the
result to the map (``Fit``), from which the frontend takes its information and confidence.
``point_to_line`` runs the numba kernels of ``point_to_line`` on a ``SearchGrid`` of the map's
points; ``point_to_point`` runs kiss-icp's 6-DoF ``Registration`` on (x, y, 0) points and
projects the result to SE(2) (a non-planar result fails). Poses are (x, y, theta) (m, m, rad).
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np

from slam2d.frontends.icp.config import IcpConfig
from slam2d.frontends.icp.grid import SearchGrid
from slam2d.frontends.icp.mapping import LocalMap, to3d
from slam2d.frontends.icp.point_to_line import fit, icp_line
from slam2d.frontends.odometry import odometry_information

log = logging.getLogger(__name__)

__all__ = ["Fit", "Registration", "get_registration", "pose_to_matrix", "matrix_to_pose", "planarity_error"]


def pose_to_matrix(pose: np.ndarray) -> np.ndarray:
    """4x4 homogeneous transform of an SE(2) pose (m, rad) in the z = 0 plane."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    m[:2, 3] = pose[:2]
    return m


def matrix_to_pose(m: np.ndarray) -> np.ndarray:
    """SE(2) pose (x, y, yaw) of a 4x4 transform (drops z, roll, pitch)."""
    return np.array([m[0, 3], m[1, 3], np.arctan2(m[1, 0], m[0, 0])])


def planarity_error(m: np.ndarray) -> float:
    """How far a 4x4 transform is from the z = 0 plane: max(|z| m, |tilt| rad)."""
    return float(max(abs(m[2, 3]), np.linalg.norm(m[2, :2]), np.linalg.norm(m[:2, 2])))


class Fit(NamedTuple):
    """A registered pose's fit to the map: the fraction of scan points matched within
    ``inlier_distance`` and the robust normal equations (H (3, 3), sum of w e^2 in m^2,
    sum of w) of its residuals, for the information."""

    matched: float
    h: np.ndarray
    weighted_sq: float
    weight_sum: float


class Registration:
    """The configured solver (``method``) and the fit of its result, with the odometry prior of
    ``point_to_line`` (``odom_prior``: the odometry information in the units of the unweighted
    point residuals, m^2)."""

    def __init__(self, config: IcpConfig):
        from kiss_icp.registration import Registration as KissRegistration

        self.config = cfg = config
        self._kiss = KissRegistration(cfg.max_iterations, cfg.convergence, cfg.threads)
        odometry = odometry_information(cfg.odom_sigma_xy, cfg.odom_sigma_theta_deg)
        self.prior = cfg.point_sigma**2 * odometry if cfg.odom_prior else np.zeros((3, 3))

    def match(self, source, start, guess, threshold: float, grid: SearchGrid, local_map: LocalMap):
        """Register ``source`` (M, 4: points and scan-line normals) from ``start`` (prior at ``guess``)
        with the correspondence scale ``threshold`` (m); (pose, its ``Fit``) or None."""
        cfg = self.config
        if cfg.method == "point_to_point":
            pose = self._register_kiss(source, start, threshold, local_map)
        else:
            pose = self._register_line(source, start, guess, threshold, grid)
        if pose is None:
            return None
        refined = cfg.method == "point_to_line" and cfg.refine_kernel > 0
        kernel = cfg.refine_kernel if refined else cfg.kernel_factor * threshold
        return pose, Fit(*fit(
            grid, source, pose, cfg.information_neighbours, cfg.correspondence_factor * threshold,
            cfg.along_weight, cfg.line_ratio, cfg.min_cluster, kernel, cfg.inlier_distance,
        ))

    def _register_kiss(self, source, start, threshold: float, local_map: LocalMap) -> np.ndarray | None:
        """kiss-icp's 6-DoF point-to-point ICP, checked planar and projected to SE(2)."""
        cfg = self.config
        m = self._kiss.align_points_to_map(
            to3d(source[:, :2]), local_map.voxels, pose_to_matrix(start),
            cfg.correspondence_factor * threshold, cfg.kernel_factor * threshold,
        )
        if not np.all(np.isfinite(m)):
            return None
        if planarity_error(m) > cfg.max_planarity_error:
            log.debug("kiss-icp result off the plane by %.2e", planarity_error(m))
            return None
        return matrix_to_pose(m)

    def _register_line(self, source, start, guess, threshold: float, grid: SearchGrid) -> np.ndarray | None:
        """Point-to-line ICP with the adaptive kernel, then refined with ``refine_kernel``; None if it failed."""
        cfg = self.config
        pose = start
        if cfg.refine_kernel > 0:
            passes = ((cfg.kernel_factor * threshold, cfg.coarse_convergence), (cfg.refine_kernel, cfg.convergence))
        else:
            passes = ((cfg.kernel_factor * threshold, cfg.convergence),)
        for kernel, convergence in passes:
            pose, ok = icp_line(
                grid, source, pose, guess, self.prior,
                cfg.correspondence_factor * threshold, kernel, cfg.neighbours, cfg.along_weight, cfg.line_ratio,
                cfg.min_cluster, cfg.max_iterations, cfg.inner_iterations, convergence,
            )
            if not ok:
                return None
        return pose


def get_registration(config: IcpConfig) -> Registration:
    """The registration of ``config``."""
    return Registration(config)
