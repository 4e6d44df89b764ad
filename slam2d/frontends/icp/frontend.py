"""The ICP frontend: each scan registered to the local map from the odometry prediction (see the package docstring)."""

from __future__ import annotations

import logging
from collections import Counter

import numpy as np

from slam2d import geometry
from slam2d.frontends.base import FrontendResult, register_frontend
from slam2d.frontends.common import bound_information, local_information, sigma_bounds
from slam2d.frontends.icp.config import IcpConfig
from slam2d.frontends.icp.degeneracy import remap
from slam2d.frontends.icp.grid import SearchGrid
from slam2d.frontends.icp.mapping import get_local_map
from slam2d.frontends.icp.moving import Views
from slam2d.frontends.icp.point_to_line import scan_normals
from slam2d.frontends.icp.registration import Fit, get_registration
from slam2d.frontends.icp.threshold import get_threshold_estimator
from slam2d.frontends.odometry import odometry_information
from slam2d.types import Scan

log = logging.getLogger(__name__)

STILL_EVENT = "scans not registered (no motion)"  # key in ``events``
ODOMETRY_OVERRULED_EVENT = "odometry overruled by the scan match"  # key in ``events``
STILL_TRUST_XY = 0.02  # m; a registration corrected by less than this (and ...
STILL_TRUST_THETA = np.deg2rad(1.0)  # ... this) lets the motion filter skip the next still scans
STILL_RANGE_CHANGE = 2.0  # a scan whose median range change exceeds this x still_distance is registered
STILL_SCAN_MOVED_EVENT = "scans registered though odometry said still (the scan changed)"  # key in ``events``
DEGENERATE_EVENT = "scans with directions left to odometry (degenerate)"  # key in ``events``
MOVING_EVENT = "scans matched again without moving points (seen through before)"  # key in ``events``
VIEWS = 30  # earlier scans the see-through test looks at when the local map keeps every scan (map_window 0)

__all__ = ["DEGENERATE_EVENT", "MOVING_EVENT", "ODOMETRY_OVERRULED_EVENT", "STILL_EVENT", "STILL_SCAN_MOVED_EVENT", "IcpFrontend"]


@register_frontend("icp")
class IcpFrontend:
    """Scan-to-local-map ICP with the odometry delta as the initial guess.

    ``pose`` is the base pose (3,) of the last scan in the frontend's local
    frame, ``map`` the local map in that frame (``mapping.LocalMap``), ``registration``
    the solver (``registration.Registration``), ``events`` counts the scans answered
    with odometry, by reason.
    """

    Config = IcpConfig

    def __init__(self, config: IcpConfig | None = None):
        self.config = cfg = config or self.Config()
        self.map = get_local_map(cfg)
        self.views = Views(cfg.map_window or VIEWS) if cfg.moving_margin > 0 else None  # the see-through test's scans
        self._threshold = get_threshold_estimator(cfg)
        self.registration = get_registration(cfg)
        self._odom_information = odometry_information(cfg.odom_sigma_xy, cfg.odom_sigma_theta_deg)
        self._sigma_bounds = sigma_bounds(cfg)
        self._still_information = np.diag(1.0 / self._sigma_bounds[0] ** 2)  # the tightest
        self.pose = np.zeros(3)
        self.events: Counter[str] = Counter()
        self._unregistered = np.zeros(3)  # odometry since the last registered scan
        self._trust_still = False  # the last registration agreed with odometry (see STILL_TRUST_*)
        self._reference_ranges: np.ndarray | None = None  # ranges (n,) m of the last registered scan
        self._last_delta = np.zeros(3)
        self._scan: Scan | None = None  # the scan being processed
        self._started = False

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
        self._scan = scan  # the views keep it once registered (``_step``)
        if not self._started:
            self._reference_ranges = scan.ranges
            return self._first(points, guess, odom_delta)
        self._unregistered = geometry.compose(self._unregistered, odom_delta)
        if known and self._trust_still and self._is_still(self._unregistered):
            if self._scan_unchanged(scan):
                self.events[STILL_EVENT] += 1
                self.pose = guess
                return FrontendResult(delta=odom_delta.copy(), information=self._still_information.copy(),
                                      confidence=1.0)
            self.events[STILL_SCAN_MOVED_EVENT] += 1
        self._unregistered = np.zeros(3)
        self._reference_ranges = scan.ranges
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
        pose, fit, points = self._without_moving(points, pose, fit, start, threshold, grid)
        reason = self._diverged(pose, start)
        if reason:
            return self._fallback(reason, guess, odom_delta, points)
        if fit.matched < cfg.min_inlier_fraction:
            return self._fallback(f"matched fraction below {cfg.min_inlier_fraction}", guess, odom_delta, points)
        if start is not guess:
            self.events[ODOMETRY_OVERRULED_EVENT] += 1
            log.debug("odometry delta %s overruled by the scan match", np.round(odom_delta, 3))
        pose = self._remap(pose, start, fit)
        information = self._information(fit)
        correction = geometry.between(start, pose)
        self._threshold.update(correction)
        self._trust_still = bool(
            start is guess
            and np.hypot(correction[0], correction[1]) < STILL_TRUST_XY
            and abs(correction[2]) < STILL_TRUST_THETA
        )
        return self._accept(pose, points, information, fit.matched)

    def _scan_unchanged(self, scan: Scan) -> bool:
        """Whether ``scan``'s ranges agree with the last registered scan's: their median change is
        below STILL_RANGE_CHANGE × ``still_distance`` (odometry that freezes while the robot moves
        says "still", the scan does not)."""
        reference = self._reference_ranges
        if reference is None or reference.shape != scan.ranges.shape:
            return False
        change = np.abs(scan.ranges - reference)
        change = change[np.isfinite(change)]
        return change.size > 0 and float(np.median(change)) < STILL_RANGE_CHANGE * self.config.still_distance

    def _is_still(self, motion: np.ndarray) -> bool:
        cfg = self.config
        return bool(
            np.hypot(motion[0], motion[1]) < cfg.still_distance
            and abs(motion[2]) < np.deg2rad(cfg.still_angle_deg)
        )

    @property
    def threshold(self) -> float:
        """Current correspondence scale (m) from kiss-icp's adaptive threshold, clipped."""
        return self._threshold.value

    # ------------------------------------------------------------------ steps

    def _source(self, points: np.ndarray) -> np.ndarray:
        """Registered points with their scan-line normals (M, 4): x, y, nx, ny (normal 0: none).

        Normals come from the neighbouring beams before downsampling; with
        ``voxel_size`` > 0 the first point of each voxel is kept (as kiss-icp's
        voxel_down_sample, which cannot carry the normals along).
        """
        cfg = self.config
        source = np.column_stack([points, scan_normals(points, cfg.line_ratio, cfg.scan_line_gap)])
        if cfg.voxel_size > 0:
            keys = np.floor(points / cfg.voxel_size).astype(np.int64)
            source = source[np.sort(np.unique(keys, axis=0, return_index=True)[1])]
        return source

    def _map_grid(self, threshold: float) -> SearchGrid:
        """The local map's points (x, y) on a search grid; a third of the search radius per cell."""
        cfg = self.config
        return self.map.search_grid(max(cfg.correspondence_factor * threshold / 3, 0.5 * cfg.map_voxel_size))

    def _best_match(self, source, guess, threshold, grid):
        """(pose, fit, start) of the best start, or None if all failed.

        Starts from the odometry ``guess``; if under ``retry_below`` of the
        points match, or with ``retry_beyond_reach`` either prediction lies beyond
        the ICP's reach from ``guess`` (``_beyond_reach``), also from the constant-velocity and the
        no-motion predictions (prior still at ``guess``), keeping the result
        matching most points. If that result diverges from ``guess``, odometry may be
        lying (frozen then jumping, a wild step, slip): each of the two
        predictions is tried as its own start and prior, and one whose match
        stays within the divergence bound of it and matches at least
        ``retry_below`` of the points overrules odometry. ``start`` is the
        prediction the result is judged against (``guess`` when odometry held).
        """
        cfg = self.config
        best = self.registration.match(source, guess, guess, threshold, grid, self.map)
        predictions = (geometry.compose(self.pose, self._last_delta), self.pose)
        beyond = cfg.retry_beyond_reach and self._beyond_reach(guess, predictions, threshold)
        if best is None or best[1].matched < cfg.retry_below or beyond:
            for start in predictions:
                other = self.registration.match(source, start, guess, threshold, grid, self.map)
                if other is not None and (best is None or other[1].matched > best[1].matched):
                    best = other
        if best is not None and not self._diverged(best[0], guess):
            return (*best, guess)
        overruling = []
        for start in predictions:
            other = self.registration.match(source, start, start, threshold, grid, self.map)
            if other is not None and other[1].matched >= cfg.retry_below and not self._diverged(other[0], start):
                overruling.append((*other, start))
        if overruling:
            return max(overruling, key=lambda r: r[1].matched)
        return None if best is None else (*best, guess)

    def _beyond_reach(self, guess, predictions, threshold: float) -> bool:
        """Whether a prediction lies beyond the ICP's reach from ``guess``: their translation apart plus the
        chord of their turn at ``threshold_range`` (kiss-icp's model deviation, m) above ``threshold``."""
        deltas = np.array([geometry.between(guess, p) for p in predictions])
        chords = 2 * self.config.threshold_range * np.abs(np.sin(deltas[:, 2] / 2))
        return bool(np.any(np.hypot(deltas[:, 0], deltas[:, 1]) + chords > threshold))

    def _without_moving(self, points, pose, fit: Fit, start, threshold, grid):
        """(pose, fit, points) matched again from ``pose`` without the points earlier scans saw
        through there (``moving``, ``moving_margin``), when there are such points and enough others;
        else as given."""
        cfg = self.config
        if self.views is None:
            return pose, fit, points
        moving = self.views.moving(geometry.transform_points(pose, points), cfg.moving_margin)
        static = points[~moving]
        if not moving.any() or len(static) < cfg.min_points:
            return pose, fit, points
        again = self.registration.match(self._source(static), pose, start, threshold, grid, self.map)
        if again is None:
            return pose, fit, points
        self.events[MOVING_EVENT] += 1
        return again[0], again[1], static

    def _scan_information(self, fit: Fit) -> np.ndarray:
        """The scan's information (3, 3) over the pose in the local frame: J^T W J / sigma^2 of the
        match, sigma^2 from its residuals."""
        sigma2 = max(fit.weighted_sq / max(fit.weight_sum - 3, 1.0), self.config.min_sigma_xy**2)
        return fit.h / sigma2

    def _information(self, fit: Fit) -> np.ndarray:
        """Information (3, 3) of the delta: the scan's (+ odometry prior), bounded; expressed in the
        previous base frame (the frame of the delta)."""
        cfg = self.config
        prior = self._odom_information if cfg.odom_prior and cfg.method == "point_to_line" else 0.0
        return bound_information(local_information(self._scan_information(fit) + prior, self.pose[2]),
                                 *self._sigma_bounds)

    def _remap(self, pose, start, fit: Fit) -> np.ndarray:
        """``pose`` with the directions the scan does not constrain taken from ``start`` (see
        ``degeneracy``); counted under DEGENERATE_EVENT."""
        ratio = self.config.degeneracy_ratio
        if ratio <= 0:
            return pose
        information = local_information(self._scan_information(fit), self.pose[2])
        pose, free = remap(self.pose, start, pose, information, self._odom_information, ratio)
        if free:
            self.events[DEGENERATE_EVENT] += 1
        return pose

    def _diverged(self, pose, guess) -> str | None:
        """Reason the result is implausibly far from the odometry prediction, else None."""
        d = geometry.between(guess, pose)
        if np.hypot(d[0], d[1]) > self.config.max_correction_xy:
            return "correction beyond max_correction_xy"
        if abs(d[2]) > np.deg2rad(self.config.max_correction_theta_deg):
            return "correction beyond max_correction_theta_deg"
        return None

    # ------------------------------------------------------------------ results

    def _step(self, pose, points) -> np.ndarray:
        """Move to ``pose``, add ``points`` to the map and the scan to the views; the delta from the previous pose."""
        delta = geometry.between(self.pose, pose)
        self.pose, self._last_delta = pose, delta
        self.map.add(pose, points)
        if self.views is not None:
            self.views.add(pose, self._scan)
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
