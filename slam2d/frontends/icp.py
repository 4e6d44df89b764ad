"""Scan-to-local-map ICP on kiss-icp's C++ building blocks, planar points (z = 0).

The frontend keeps the robot base pose in its own odometry-like local frame
and a kiss-icp ``VoxelHashMap`` of the last ``map_window`` scans in that frame
(points in the base frame, so the laser mounting pose is already applied).
Each scan is registered to the map starting from the wheel-odometry
prediction, not kiss-icp's constant-velocity model; the returned delta is the
base motion from the previous scan to this one. kiss-icp's
``AdaptiveThreshold`` (fed with the deviation of the result from odometry)
sets the correspondence distance and the robust kernel.

Two solvers share the map, the threshold and the checks:

- ``point_to_line`` (default): 2D Gauss-Newton over (x, y, theta). Each scan
  point is matched to its ``neighbours`` nearest map points (a bucketed grid
  searched in numba); where they form a line the residual is the distance
  across it, where they do not but the scan's own neighbouring beams do, the
  residual is across the scan's line, else it is point-to-point (isolated
  points are dropped). Geman-McClure weights with the adaptive scale to
  ``coarse_convergence``, then a refinement with the fixed ``refine_kernel``
  to ``convergence``; a weak prior on the odometry
  delta keeps directions the scan cannot see (corridors) at odometry.
- ``point_to_point``: kiss-icp's own 6-DoF ``Registration`` on (x, y, 0)
  points, projected to SE(2). With every point at z = 0 the z rows of the
  problem pin z, roll and pitch: the result is planar exactly (checked, and a
  non-planar result falls back to odometry).

The information matrix is J^T W J / sigma^2 of the final residuals in
(x, y, theta), sigma^2 estimated from them, plus the odometry prior, expressed
in the frame of the delta and bounded so every direction's std lies in
[min_sigma, max_sigma]. The confidence is the fraction of points whose
residual is within ``inlier_distance``. Too few points, a non-finite or
non-planar result, a correction beyond the divergence bound or too few
matches fall back to odometry with confidence 0, counted in ``events``.

Odometry that lies (frozen then jumping, a wild step, slip): when the match
from the odometry prediction diverges from it, the constant-velocity and the
no-motion predictions are tried as starts and priors of their own; a match
that agrees with one of them and matches well overrules odometry (counted
under ``ODOMETRY_OVERRULED_EVENT``) instead of falling back to it.

Motion filter: while odometry says the robot moved less than ``still_distance``
and ``still_angle_deg`` since the last registered scan, a scan is not
registered (nor added to the map); its delta is the odometry one with the
tightest information, counted in ``events`` under ``STILL_EVENT`` (a third
of ACES is such scans).
The filter applies only after a registration that agreed with odometry
(within ``STILL_TRUST_XY`` and ``STILL_TRUST_THETA``): after a large correction
the next scan is registered whatever odometry says.
"""

from __future__ import annotations

import logging
from collections import Counter, deque
from typing import Literal, NamedTuple

import numpy as np
from numba import njit
from pydantic import Field

from slam2d import geometry
from slam2d.config import Section
from slam2d.frontends.base import FrontendResult, register_frontend
from slam2d.frontends.common import (
    MaxCorrectionThetaDeg,
    MaxCorrectionXY,
    MaxRange,
    MaxSigmaThetaDeg,
    MaxSigmaXY,
    MinRange,
    MinSigmaThetaDeg,
    MinSigmaXY,
    OdomSigmaThetaDeg,
    OdomSigmaXY,
    bound_information,
    local_information,
    sigma_bounds,
)
from slam2d.frontends.odometry import odometry_information
from slam2d.types import Scan

log = logging.getLogger(__name__)

STILL_EVENT = "scans not registered (no motion)"  # key in ``events``
ODOMETRY_OVERRULED_EVENT = "odometry overruled by the scan match"  # key in ``events``
STILL_TRUST_XY = 0.02  # m; a registration corrected by less than this (and ...
STILL_TRUST_THETA = np.deg2rad(1.0)  # ... this) lets the motion filter skip the next still scans
GRID_CELLS_PER_POINT = 16  # the neighbour-search grid has at most this many cells per map point

__all__ = ["IcpFrontend"]


def _pose_to_matrix(pose: np.ndarray) -> np.ndarray:
    """4x4 homogeneous transform of an SE(2) pose (m, rad) in the z = 0 plane."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    m[:2, 3] = pose[:2]
    return m


def _matrix_to_pose(m: np.ndarray) -> np.ndarray:
    """SE(2) pose (x, y, yaw) of a 4x4 transform (drops z, roll, pitch)."""
    return np.array([m[0, 3], m[1, 3], np.arctan2(m[1, 0], m[0, 0])])


def _planarity_error(m: np.ndarray) -> float:
    """How far a 4x4 transform is from the z = 0 plane: max(|z| m, |tilt| rad)."""
    return float(max(abs(m[2, 3]), np.linalg.norm(m[2, :2]), np.linalg.norm(m[:2, 2])))


def _to3d(points: np.ndarray) -> np.ndarray:
    """(M, 2) planar points -> (M, 3) with z = 0."""
    return np.column_stack([points, np.zeros(len(points))])


class _Fit(NamedTuple):
    """A registered pose's fit to the map: the fraction of scan points matched within
    ``inlier_distance`` and the robust normal equations (H (3, 3), sum of w e^2 in m^2,
    sum of w) of its residuals, for the information."""

    matched: float
    h: np.ndarray
    weighted_sq: float
    weight_sum: float


class _Grid(NamedTuple):
    """The local map's points bucketed on a dense grid for neighbour search.

    ``points`` (N, 2) are sorted by cell; those of cell (ix, iy) are
    ``points[start[ix * ny + iy]:start[ix * ny + iy + 1]]``. Cell (0, 0) has
    its lower corner at (x0, y0); cells are ``cell`` m wide.
    """

    points: np.ndarray
    start: np.ndarray
    nx: int
    ny: int
    x0: float
    y0: float
    cell: float

    @classmethod
    def build(cls, points: np.ndarray, cell: float) -> _Grid:
        """Bucket ``points`` (N >= 1, 2) in cells of at least ``cell`` m (wider over sparse maps)."""
        lo = points.min(axis=0)
        extent = points.max(axis=0) - lo
        cell = max(cell, float(np.sqrt(extent[0] * extent[1] / (GRID_CELLS_PER_POINT * len(points)))))
        nx, ny = (extent // cell).astype(np.int64) + 1
        ordered, start = _bucket(points, lo[0], lo[1], cell, nx, ny)
        return cls(ordered, start, int(nx), int(ny), float(lo[0]), float(lo[1]), cell)


@register_frontend("icp")
class IcpFrontend:
    """Scan-to-local-map ICP with the odometry delta as the initial guess.

    ``pose`` is the base pose (3,) of the last scan in the frontend's local
    frame, ``map`` the kiss-icp voxel map in that frame, ``events`` counts
    the scans answered with odometry, by reason.
    """

    class Config(Section):
        """ICP frontend parameters; defaults suit 180-beam SICK logs (5-10 Hz) and the 360-beam simulator."""

        method: Literal["point_to_line", "point_to_point"] = Field(
            "point_to_line", description="2D point-to-line Gauss-Newton, or kiss-icp's 3D point-to-point"
        )
        min_range: MinRange = 0.1
        max_range: MaxRange = 30.0
        voxel_size: float = Field(0.0, ge=0, description="m; downsampling of the registered points (0: none)")
        map_voxel_size: float = Field(0.2, gt=0, description="m; voxel of the local map")
        map_max_points_per_voxel: int = Field(20, gt=0, description="points kept per map voxel")
        map_window: int = Field(30, ge=0, description="scans kept in the local map (0: all within map_radius)")
        map_radius: float = Field(30.0, gt=0, description="m; map voxels farther than this from the robot are dropped")
        initial_threshold: float = Field(0.5, gt=0, description="m; correspondence scale before any motion statistics")
        min_motion: float = Field(0.02, ge=0, description="m; odometry deviation that updates the adaptive threshold")
        threshold_range: float = Field(10.0, gt=0, description="m; lever arm turning rotation deviation into m")
        min_threshold: float = Field(0.05, gt=0, description="m; floor of the adaptive threshold")
        max_threshold: float = Field(1.0, gt=0, description="m; cap of the adaptive threshold")
        correspondence_factor: float = Field(3.0, gt=0, description="max correspondence distance / threshold")
        kernel_factor: float = Field(1.0, gt=0, description="Geman-McClure scale / threshold")
        refine_kernel: float = Field(0.05, ge=0, description="m; Geman-McClure scale of a final refinement (0: none)")
        neighbours: int = Field(5, ge=2, description="map points per correspondence (point_to_line)")
        information_neighbours: int = Field(
            15, ge=2, description="map points per line fit for the information and confidence (steadier normals)"
        )
        along_weight: float = Field(0.0, ge=0, le=1, description="weight of the along-line residual (point_to_line)")
        line_ratio: float = Field(0.2, gt=0, le=1, description="max eigenvalue ratio of a line neighbourhood")
        scan_line_gap: float = Field(1.0, gt=0, description="m; max gap between beams fitted to one scan line")
        min_cluster: int = Field(3, ge=1, description="map points near a point on no line for a point-to-point match")
        max_iterations: int = Field(20, gt=0, description="correspondence searches per scan")
        inner_iterations: int = Field(3, gt=0, description="Gauss-Newton steps per correspondence search")
        convergence: float = Field(1e-4, gt=0, description="stop when the update is below this (m and rad)")
        coarse_convergence: float = Field(
            3e-3, gt=0, description="... in the adaptive-kernel pass before a refinement (m and rad)"
        )
        odom_prior: bool = Field(True, description="regularise the match with the odometry delta (point_to_line)")
        point_sigma: float = Field(0.03, gt=0, description="m; std of one point residual: prior weight vs points")
        inlier_distance: float = Field(0.1, gt=0, description="m; residual of a point counted as matched")
        retry_below: float = Field(0.6, ge=0, le=1, description="matched fraction below which other guesses are tried")
        min_points: int = Field(20, ge=3, description="fewer valid points than this -> odometry fallback")
        min_inlier_fraction: float = Field(0.2, ge=0, le=1, description="fewer matched points -> fallback")
        max_correction_xy: MaxCorrectionXY = 0.5
        max_correction_theta_deg: MaxCorrectionThetaDeg = 30.0
        max_planarity_error: float = Field(1e-3, gt=0, description="point_to_point: tolerated z (m) / tilt (rad)")
        odom_sigma_xy: OdomSigmaXY = 0.05  # the prior and the fallback
        odom_sigma_theta_deg: OdomSigmaThetaDeg = 2.0
        min_sigma_xy: MinSigmaXY = 0.002
        min_sigma_theta_deg: MinSigmaThetaDeg = 0.05
        max_sigma_xy: MaxSigmaXY = 1.0
        max_sigma_theta_deg: MaxSigmaThetaDeg = 20.0
        threads: int = Field(1, ge=0, description="kiss-icp registration threads (0: all cores)")
        still_distance: float = Field(
            0.01, ge=0, description="m; odometry motion since the last registered scan below which a scan is skipped"
        )
        still_angle_deg: float = Field(0.5, ge=0, description="... and rotation below which (0 and 0: never skip)")

    def __init__(self, config: Config | None = None):
        from kiss_icp.mapping import VoxelHashMap
        from kiss_icp.pybind import kiss_icp_pybind
        from kiss_icp.registration import Registration

        self.config = cfg = config or self.Config()
        self.map = VoxelHashMap(cfg.map_voxel_size, cfg.map_radius, cfg.map_max_points_per_voxel)
        self._threshold = kiss_icp_pybind._AdaptiveThreshold(
            initial_threshold=cfg.initial_threshold, min_motion_th=cfg.min_motion, max_range=cfg.threshold_range
        )
        self._registration = Registration(cfg.max_iterations, cfg.convergence, cfg.threads)
        self._odom_information = odometry_information(cfg.odom_sigma_xy, cfg.odom_sigma_theta_deg)
        self._sigma_bounds = sigma_bounds(cfg)
        self._still_information = np.diag(1.0 / self._sigma_bounds[0] ** 2)  # the tightest
        # the odometry prior in the units of the unweighted point residuals (m^2)
        self._prior = cfg.point_sigma**2 * self._odom_information if cfg.odom_prior else np.zeros((3, 3))
        self.pose = np.zeros(3)
        self.events: Counter[str] = Counter()
        self._unregistered = np.zeros(3)  # odometry since the last registered scan
        self._trust_still = False  # the last registration agreed with odometry (see STILL_TRUST_*)
        self._last_delta = np.zeros(3)
        self._started = False
        self._recent: deque[np.ndarray] = deque(maxlen=cfg.map_window or None)
        self._since_rebuild = 0

    # ------------------------------------------------------------------ public

    def process(self, scan: Scan, odom_delta: np.ndarray) -> FrontendResult:
        """Register ``scan`` to the local map; ``odom_delta`` (3,) is the base motion since the last scan."""
        cfg = self.config
        odom_delta = geometry.as_pose(odom_delta)
        known = bool(np.all(np.isfinite(odom_delta)))
        if not known:
            log.debug("non-finite odometry delta %s; registering from no motion", odom_delta)
            odom_delta = np.zeros(3)
        guess = geometry.compose(self.pose, odom_delta)
        points = scan.points_in_base(cfg.min_range, cfg.max_range)
        if not self._started:
            return self._first(points, guess, odom_delta)
        self._unregistered = geometry.compose(self._unregistered, odom_delta)
        if known and self._trust_still and self._is_still(self._unregistered):
            self.events[STILL_EVENT] += 1
            self.pose = guess
            return FrontendResult(delta=odom_delta.copy(), information=self._still_information.copy(), confidence=1.0)
        self._unregistered = np.zeros(3)
        if len(points) < cfg.min_points:
            return self._fallback(f"fewer than {cfg.min_points} valid points", guess, odom_delta, points)
        if self.map.empty():
            return self._fallback("empty local map", guess, odom_delta, points)
        source = self._source(points)
        threshold = self.threshold
        grid = self._map_grid(threshold)
        found = self._best_match(source, guess, threshold, grid)
        if found is None:
            return self._fallback("registration failed (non-finite, non-planar or < 3 matches)", guess, odom_delta,
                                  points)
        pose, fit, start = found
        reason = self._diverged(pose, start)
        if reason:
            return self._fallback(reason, guess, odom_delta, points)
        if fit.matched < cfg.min_inlier_fraction:
            return self._fallback(f"matched fraction below {cfg.min_inlier_fraction}", guess, odom_delta, points)
        if start is not guess:
            self.events[ODOMETRY_OVERRULED_EVENT] += 1
            log.debug("odometry delta %s overruled by the scan match", np.round(odom_delta, 3))
        information = self._information(fit)
        correction = geometry.between(start, pose)
        self._threshold._update_model_deviation(_pose_to_matrix(correction))
        self._trust_still = bool(
            start is guess
            and np.hypot(correction[0], correction[1]) < STILL_TRUST_XY
            and abs(correction[2]) < STILL_TRUST_THETA
        )
        return self._accept(pose, points, information, fit.matched)

    def _is_still(self, motion: np.ndarray) -> bool:
        cfg = self.config
        return bool(
            np.hypot(motion[0], motion[1]) < cfg.still_distance
            and abs(motion[2]) < np.deg2rad(cfg.still_angle_deg)
        )

    @property
    def threshold(self) -> float:
        """Current correspondence scale (m) from kiss-icp's adaptive threshold, clipped."""
        sigma = self._threshold._compute_threshold()
        return float(np.clip(sigma, self.config.min_threshold, self.config.max_threshold))

    # ------------------------------------------------------------------ steps

    def _source(self, points: np.ndarray) -> np.ndarray:
        """Registered points with their scan-line normals (M, 4): x, y, nx, ny (normal 0: none).

        Normals come from the neighbouring beams before downsampling; with
        ``voxel_size`` > 0 the first point of each voxel is kept (as kiss-icp's
        voxel_down_sample, which cannot carry the normals along).
        """
        cfg = self.config
        source = np.column_stack([points, _scan_normals(points, cfg.line_ratio, cfg.scan_line_gap)])
        if cfg.voxel_size > 0:
            keys = np.floor(points / cfg.voxel_size).astype(np.int64)
            source = source[np.sort(np.unique(keys, axis=0, return_index=True)[1])]
        return source

    def _map_grid(self, threshold: float) -> _Grid:
        """The local map's points (x, y) on a search grid; a third of the search radius per cell."""
        points = np.ascontiguousarray(self.map.point_cloud()[:, :2])
        cfg = self.config
        return _Grid.build(points, max(cfg.correspondence_factor * threshold / 3, 0.5 * cfg.map_voxel_size))

    def _best_match(self, source, guess, threshold, grid):
        """(pose, fit, start) of the best start, or None if all failed.

        Starts from the odometry ``guess``; if under ``retry_below`` of the
        points match, also from the constant-velocity and the no-motion
        predictions (prior still at ``guess``), keeping the result matching
        most points. If that result diverges from ``guess``, odometry may be
        lying (frozen then jumping, a wild step, slip): each of the two
        predictions is tried as its own start and prior, and one whose match
        stays within the divergence bound of it and matches at least
        ``retry_below`` of the points overrules odometry. ``start`` is the
        prediction the result is judged against (``guess`` when odometry held).
        """
        cfg = self.config
        best = self._match(source, guess, guess, threshold, grid)
        predictions = (geometry.compose(self.pose, self._last_delta), self.pose)
        if best is None or best[1].matched < cfg.retry_below:
            for start in predictions:
                other = self._match(source, start, guess, threshold, grid)
                if other is not None and (best is None or other[1].matched > best[1].matched):
                    best = other
        if best is not None and not self._diverged(best[0], guess):
            return (*best, guess)
        overruling = []
        for start in predictions:
            other = self._match(source, start, start, threshold, grid)
            if other is not None and other[1].matched >= cfg.retry_below and not self._diverged(other[0], start):
                overruling.append((*other, start))
        if overruling:
            return max(overruling, key=lambda r: r[1].matched)
        return None if best is None else (*best, guess)

    def _match(self, source, start, guess, threshold, grid):
        """Register from ``start`` (prior at ``guess``); (pose, its _Fit) or None."""
        cfg = self.config
        if cfg.method == "point_to_point":
            pose = self._register_kiss(source, start, threshold)
        else:
            pose = self._register_line(source, start, guess, threshold, grid)
        if pose is None:
            return None
        refined = cfg.method == "point_to_line" and cfg.refine_kernel > 0
        kernel = cfg.refine_kernel if refined else cfg.kernel_factor * threshold
        return pose, _Fit(*_fit(
            grid, source, pose, cfg.information_neighbours, cfg.correspondence_factor * threshold,
            cfg.along_weight, cfg.line_ratio, cfg.min_cluster, kernel, cfg.inlier_distance,
        ))

    def _register_kiss(self, source, start, threshold) -> np.ndarray | None:
        """kiss-icp's 6-DoF point-to-point ICP, checked planar and projected to SE(2)."""
        cfg = self.config
        m = self._registration.align_points_to_map(
            _to3d(source[:, :2]), self.map, _pose_to_matrix(start),
            cfg.correspondence_factor * threshold, cfg.kernel_factor * threshold,
        )
        if not np.all(np.isfinite(m)):
            return None
        if _planarity_error(m) > cfg.max_planarity_error:
            log.debug("kiss-icp result off the plane by %.2e", _planarity_error(m))
            return None
        return _matrix_to_pose(m)

    def _register_line(self, source, start, guess, threshold, grid) -> np.ndarray | None:
        """Point-to-line ICP with the adaptive kernel, then refined with ``refine_kernel``; None if it failed."""
        cfg = self.config
        pose = start
        if cfg.refine_kernel > 0:
            passes = ((cfg.kernel_factor * threshold, cfg.coarse_convergence), (cfg.refine_kernel, cfg.convergence))
        else:
            passes = ((cfg.kernel_factor * threshold, cfg.convergence),)
        for kernel, convergence in passes:
            pose, ok = _icp_line(
                grid, source, pose, guess, self._prior,
                cfg.correspondence_factor * threshold, kernel, cfg.neighbours, cfg.along_weight, cfg.line_ratio,
                cfg.min_cluster, cfg.max_iterations, cfg.inner_iterations, convergence,
            )
            if not ok:
                return None
        return pose

    def _information(self, fit: _Fit) -> np.ndarray:
        """Information (3, 3) of the delta: J^T W J / sigma^2 (+ odometry prior), bounded.

        Computed for the pose in the local frame, then expressed in the
        previous base frame (the frame of the delta).
        """
        cfg = self.config
        sigma2 = max(fit.weighted_sq / max(fit.weight_sum - 3, 1.0), cfg.min_sigma_xy**2)
        info = fit.h / sigma2 + (self._odom_information if cfg.odom_prior and cfg.method == "point_to_line" else 0.0)
        return bound_information(local_information(info, self.pose[2]), *self._sigma_bounds)

    def _diverged(self, pose, guess) -> str | None:
        """Reason the result is implausibly far from the odometry prediction, else None."""
        d = geometry.between(guess, pose)
        if np.hypot(d[0], d[1]) > self.config.max_correction_xy:
            return "correction beyond max_correction_xy"
        if abs(d[2]) > np.deg2rad(self.config.max_correction_theta_deg):
            return "correction beyond max_correction_theta_deg"
        return None

    # ------------------------------------------------------------------ results

    def _add_to_map(self, pose: np.ndarray, points: np.ndarray) -> None:
        """Insert ``points`` (base frame) at ``pose``; forget old scans and voxels beyond map_radius.

        With ``map_window`` > 0 the map is rebuilt, newest scan first, from the
        last ``map_window`` scans whenever a quarter window has been added since
        the last rebuild, so it always holds between 1 and 1.25 windows of scans.
        """
        world = _to3d(geometry.transform_points(pose, points))
        window = self.config.map_window
        if window:
            self._recent.append(world)
            self._since_rebuild += 1
            if self._since_rebuild >= max(1, window // 4):
                self.map.clear()
                self.map.add_points(np.concatenate(list(self._recent)[::-1]))
                self._since_rebuild = 0
                return
        if len(world):
            self.map.add_points(world)
        self.map.remove_far_away_points(np.array([pose[0], pose[1], 0.0]))

    def _step(self, pose, points) -> np.ndarray:
        """Move to ``pose``, add the scan to the map; the delta from the previous pose."""
        delta = geometry.between(self.pose, pose)
        self.pose, self._last_delta = pose, delta
        self._add_to_map(pose, points)
        return delta

    def _accept(self, pose, points, information, confidence) -> FrontendResult:
        delta = self._step(pose, points)
        return FrontendResult(delta=delta, information=information, confidence=confidence)

    def _first(self, points, guess, odom_delta) -> FrontendResult:
        """The first scan starts the map; its delta is the odometry one (zeros by protocol)."""
        self._started = True
        self._step(guess, points)
        return FrontendResult(delta=odom_delta.copy(), information=self._odom_information.copy(), confidence=0.0)

    def _fallback(self, reason: str, guess, odom_delta, points) -> FrontendResult:
        """Odometry delta, odometry information, confidence 0; counted by reason."""
        self.events[reason] += 1
        self._trust_still = False
        log.debug("icp fallback to odometry: %s", reason)
        self._step(guess, points)
        return FrontendResult(delta=odom_delta.copy(), information=self._odom_information.copy(), confidence=0.0)


# ---------------------------------------------------------------------- maths
# numba kernels: each loops over the 100-400 points of one scan, several times
# per scan; numpy's per-call overhead on arrays this small would dominate.


@njit(cache=True, nogil=True)
def _scan_normals(points, line_ratio, max_gap, half_window=2):
    """Unit normals (M, 2) of the scan's local lines; zeros where the beams around a point are no line.

    ``points`` (M, 2) are in beam order. Each point's window is the
    ``2 * half_window + 1`` beams around it (clipped at the ends); it is a line
    when its scatter's eigenvalue ratio is <= ``line_ratio`` and no two
    consecutive beams in it are more than ``max_gap`` m apart (a depth jump).
    """
    m = len(points)
    out = np.zeros((m, 2))
    for i in range(m):
        lo, hi = max(0, i - half_window), min(m, i + half_window + 1)
        if hi - lo < 3:
            continue
        mx, my, gap = 0.0, 0.0, 0.0
        for j in range(lo, hi):
            mx += points[j, 0]
            my += points[j, 1]
            if j > lo:
                gap = max(gap, np.hypot(points[j, 0] - points[j - 1, 0], points[j, 1] - points[j - 1, 1]))
        if gap > max_gap:
            continue
        mx, my = mx / (hi - lo), my / (hi - lo)
        cxx, cyy, cxy = 0.0, 0.0, 0.0
        for j in range(lo, hi):
            dx, dy = points[j, 0] - mx, points[j, 1] - my
            cxx += dx * dx
            cyy += dy * dy
            cxy += dx * dy
        ok, tx, ty = _line_direction(cxx, cyy, cxy, line_ratio)
        if ok:
            out[i, 0], out[i, 1] = -ty, tx
    return out


@njit(cache=True, nogil=True)
def _bucket(points, x0, y0, cell, nx, ny):
    """``points`` (N, 2) sorted by grid cell and the cells' start offsets (nx * ny + 1,); see ``_Grid``."""
    n = len(points)
    cells = np.empty(n, np.int64)
    start = np.zeros(nx * ny + 1, np.int64)
    for i in range(n):
        ix = min(int((points[i, 0] - x0) / cell), nx - 1)
        iy = min(int((points[i, 1] - y0) / cell), ny - 1)
        cells[i] = ix * ny + iy
        start[cells[i] + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    ordered = np.empty((n, 2))
    for i in range(n):
        ordered[fill[cells[i]]] = points[i]
        fill[cells[i]] += 1
    return ordered, start


@njit(cache=True, nogil=True)
def _knn(grid, x, y, radius, idx, d2):
    """The up to ``len(idx)`` map points nearest to (x, y) within ``radius``; returns their count.

    Rings of cells of ``grid`` (a ``_Grid``) are searched outwards until the
    next ring cannot hold a closer point. Fills ``idx`` (rows of
    ``grid.points``) and ``d2`` (squared m) in increasing distance.
    """
    pts, start, nx, ny, cell = grid.points, grid.start, grid.nx, grid.ny, grid.cell
    k, n = len(idx), 0
    cx, cy = int(np.floor((x - grid.x0) / cell)), int(np.floor((y - grid.y0) / cell))
    r2 = radius * radius
    ring = 0
    while (ring - 1) * cell <= radius and (n < k or ((ring - 1) * cell) ** 2 <= d2[n - 1]):
        for ix in range(max(cx - ring, 0), min(cx + ring + 1, nx)):
            edge = ix == cx - ring or ix == cx + ring
            for iy in range(cy - ring, cy + ring + 1, 1 if edge else 2 * ring):  # a ring's cells only
                if iy < 0 or iy >= ny:
                    continue
                c = ix * ny + iy
                for p in range(start[c], start[c + 1]):
                    dd = (pts[p, 0] - x) ** 2 + (pts[p, 1] - y) ** 2
                    if dd <= r2 and (n < k or dd < d2[n - 1]):
                        m = min(n, k - 1)
                        while m > 0 and d2[m - 1] > dd:
                            d2[m], idx[m] = d2[m - 1], idx[m - 1]
                            m -= 1
                        d2[m], idx[m] = dd, p
                        n = min(n + 1, k)
        ring += 1
    return n


@njit(cache=True, nogil=True)
def _line_direction(cxx, cyy, cxy, line_ratio):
    """(is a line, tx, ty): unit direction of the largest eigenvector of [[cxx, cxy], [cxy, cyy]].

    A line when the smaller eigenvalue is at most ``line_ratio`` times the larger.
    """
    half = 0.5 * (cxx + cyy)
    disc = np.sqrt(max(half * half - (cxx * cyy - cxy * cxy), 0.0))
    hi, lo = half + disc, half - disc
    if not (hi > 0 and lo <= line_ratio * hi):
        return False, 1.0, 0.0
    ax, ay, bx, by = hi - cyy, cxy, cxy, hi - cxx
    tx, ty = (ax, ay) if ax * ax + ay * ay >= bx * bx + by * by else (bx, by)
    norm = np.sqrt(tx * tx + ty * ty)
    return True, tx / norm, ty / norm


@njit(cache=True, nogil=True)
def _line_fit(map_xy, idx, n, along, line_ratio, out_target, out_omega):
    """Target and weight of one correspondence from its ``n`` nearest map points ``idx``.

    A neighbourhood whose scatter is a line (eigenvalue ratio <= line_ratio, at
    least 3 points) gives target = its mean and weight n n^T + along t t^T;
    otherwise target = the nearest point and weight = identity (point-to-point).
    Returns whether the neighbourhood is a line.
    """
    mx, my = 0.0, 0.0
    for j in range(n):
        mx += map_xy[idx[j], 0]
        my += map_xy[idx[j], 1]
    mx, my = mx / n, my / n
    cxx, cyy, cxy = 0.0, 0.0, 0.0
    for j in range(n):
        dx, dy = map_xy[idx[j], 0] - mx, map_xy[idx[j], 1] - my
        cxx += dx * dx
        cyy += dy * dy
        cxy += dx * dy
    ok, tx, ty = _line_direction(cxx, cyy, cxy, line_ratio)
    if n >= 3 and ok:
        out_omega[0, 0] = ty * ty + along * tx * tx
        out_omega[1, 1] = tx * tx + along * ty * ty
        out_omega[0, 1] = out_omega[1, 0] = (along - 1.0) * tx * ty
        out_target[0], out_target[1] = mx, my
        return True
    out_omega[0, 0], out_omega[1, 1], out_omega[0, 1], out_omega[1, 0] = 1.0, 1.0, 0.0, 0.0
    out_target[0], out_target[1] = map_xy[idx[0], 0], map_xy[idx[0], 1]
    return False


@njit(cache=True, nogil=True)
def _correspond(grid, source, pose, k, radius, along, line_ratio, min_cluster):
    """Correspondences (valid (M,), target (M, 2), omega (M, 2, 2)) of ``source`` moved to ``pose``.

    ``source`` (M, 4) holds points and scan-line normals. The residual is
    across the map's local line where the map neighbourhood is one, else
    across the scan's own line (to the nearest map point) where the scan has
    one there, else point-to-point.
    """
    m = len(source)
    valid = np.zeros(m, np.bool_)
    target = np.zeros((m, 2))
    omega = np.zeros((m, 2, 2))
    idx, d2 = np.empty(k, np.int64), np.empty(k)
    c, s = np.cos(pose[2]), np.sin(pose[2])
    for i in range(m):
        x = pose[0] + c * source[i, 0] - s * source[i, 1]
        y = pose[1] + s * source[i, 0] + c * source[i, 1]
        n = _knn(grid, x, y, radius, idx, d2)
        if n == 0:
            continue
        valid[i] = True
        if _line_fit(grid.points, idx, n, along, line_ratio, target[i], omega[i]):
            continue
        if source[i, 2] != 0.0:
            nx = c * source[i, 2] - s * source[i, 3]  # the scan's own line, in the local frame
            ny = s * source[i, 2] + c * source[i, 3]
            omega[i, 0, 0], omega[i, 0, 1], omega[i, 1, 0], omega[i, 1, 1] = nx * nx, nx * ny, nx * ny, ny * ny
        elif n < min_cluster:
            valid[i] = False  # an isolated point: its nearest map point is likely another surface point
    return valid, target, omega


@njit(cache=True, nogil=True)
def _normal_equations(source, pose, valid, target, omega, kernel, inlier_distance=0.0):
    """Robust normal equations of the residuals T(pose) source - target over (x, y, theta).

    Geman-McClure weights w = (kernel^2 / (kernel^2 + e^2))^2, e^2 = r^T omega r.
    Returns H (3, 3), g (3,), sum of w e^2 (m^2), sum of w, and the number of
    residuals with e <= ``inlier_distance`` (m).
    """
    c, s = np.cos(pose[2]), np.sin(pose[2])
    h = np.zeros((3, 3))
    g = np.zeros(3)
    k2, wsq, wsum, inliers = kernel * kernel, 0.0, 0.0, 0
    for i in range(len(source)):
        if not valid[i]:
            continue
        px, py = source[i, 0], source[i, 1]
        jx, jy = -s * px - c * py, c * px - s * py  # d(R p)/d theta
        rx, ry = c * px - s * py + pose[0] - target[i, 0], s * px + c * py + pose[1] - target[i, 1]
        o00, o01, o11 = omega[i, 0, 0], omega[i, 0, 1], omega[i, 1, 1]
        ox, oy = o00 * rx + o01 * ry, o01 * rx + o11 * ry
        e2 = rx * ox + ry * oy
        w = (k2 / (k2 + e2)) ** 2
        qx, qy = o00 * jx + o01 * jy, o01 * jx + o11 * jy
        h[0, 0] += w * o00
        h[0, 1] += w * o01
        h[1, 1] += w * o11
        h[0, 2] += w * qx
        h[1, 2] += w * qy
        h[2, 2] += w * (jx * qx + jy * qy)
        g[0] += w * ox
        g[1] += w * oy
        g[2] += w * (jx * ox + jy * oy)
        wsq += w * e2
        wsum += w
        inliers += e2 <= inlier_distance * inlier_distance
    h[1, 0], h[2, 0], h[2, 1] = h[0, 1], h[0, 2], h[1, 2]
    return h, g, wsq, wsum, inliers


@njit(cache=True, nogil=True)
def _fit(grid, source, pose, k, radius, along, line_ratio, min_cluster, kernel, inlier_distance):
    """(matched fraction, H, sum w e^2, sum w) of ``source`` at ``pose``: see ``_Fit``."""
    valid, target, omega = _correspond(grid, source, pose, k, radius, along, line_ratio, min_cluster)
    h, _, weighted_sq, weight_sum, inliers = _normal_equations(source, pose, valid, target, omega, kernel,
                                                               inlier_distance)
    return inliers / max(len(source), 1), h, weighted_sq, weight_sum


@njit(cache=True, nogil=True)
def _abs_max(v):
    """max |v_i| of a 3-vector."""
    return max(abs(v[0]), abs(v[1]), abs(v[2]))


@njit(cache=True, nogil=True)
def _solve3(a, b):
    """Solution of the 3x3 system a x = b by the adjugate (a symmetric positive semi-definite)."""
    c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
    c01 = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
    c02 = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
    det = a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02 + 1e-300
    c11 = a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]
    c12 = a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]
    c22 = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    x = np.empty(3)
    x[0] = (c00 * b[0] + c01 * b[1] + c02 * b[2]) / det
    x[1] = (c01 * b[0] + c11 * b[1] + c12 * b[2]) / det
    x[2] = (c02 * b[0] + c12 * b[1] + c22 * b[2]) / det
    return x


@njit(cache=True, nogil=True)
def _gauss_newton(source, pose, valid, target, omega, kernel, guess, prior, iterations, convergence):
    """Gauss-Newton steps with fixed correspondences and the prior ``prior`` (3, 3) on ``pose - guess``.

    Returns the new pose and the size of its total change (max over m and rad).
    """
    out = pose.copy()
    for _ in range(iterations):
        h, g, _, _, _ = _normal_equations(source, out, valid, target, omega, kernel)
        off = out - guess
        off[2] = (off[2] + np.pi) % (2.0 * np.pi) - np.pi
        for i in range(3):
            g[i] += prior[i, 0] * off[0] + prior[i, 1] * off[1] + prior[i, 2] * off[2]
            h[i, i] += 1e-9
        step = _solve3(h + prior, -g)
        out += step
        if _abs_max(step) < convergence:
            break
    return out, _abs_max(out - pose)


@njit(cache=True, nogil=True)
def _icp_line(grid, source, start, guess, prior, radius, kernel, k, along, line_ratio,
              min_cluster, iterations, inner, convergence):
    """Point-to-line ICP from ``start``: correspondences re-found each outer iteration.

    Stops when an outer iteration moves the pose less than ``convergence`` or
    returns to where it was two iterations before (cycling between two
    correspondence sets). Returns the pose and whether it is usable.
    """
    pose, before = start.copy(), np.full(3, np.inf)
    for _ in range(iterations):
        valid, target, omega = _correspond(grid, source, pose, k, radius, along, line_ratio,
                                           min_cluster)
        if valid.sum() < 3:
            return pose, False
        new, step = _gauss_newton(source, pose, valid, target, omega, kernel, guess, prior, inner, convergence)
        if not (np.isfinite(new[0]) and np.isfinite(new[1]) and np.isfinite(new[2])):
            return pose, False
        cycling = _abs_max(new - before) < convergence
        before, pose = pose, new
        if step < convergence or cycling:
            break
    pose[2] = (pose[2] + np.pi) % (2.0 * np.pi) - np.pi
    return pose, True


