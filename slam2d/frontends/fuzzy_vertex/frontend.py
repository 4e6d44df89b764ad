"""The fuzzy-vertex frontend: vertex self-localisation on a fuzzy geometric map (Chen & Zhang 2006).

The vertex fit, the wall headings and the odometry prediction are combined as independent
estimates by their information (3x3 over map-frame x, y, theta; 1/m^2, 1/rad^2).
"""

from __future__ import annotations

from collections import Counter
from typing import Literal

import numpy as np
from pydantic import Field

from slam2d import geometry
from slam2d.config import Section
from slam2d.frontends.base import FrontendResult, register_frontend
from slam2d.frontends.common import (
    MaxCorrectionThetaDeg,
    MaxCorrectionXY,
    MaxRange,
    MinRange,
    MinSigmaThetaDeg,
    MinSigmaXY,
    cap_information,
    local_information,
)
from slam2d.frontends.fuzzy_vertex.classification import twice_classification
from slam2d.frontends.fuzzy_vertex.extraction import (
    FUZZY_SCALE,
    Units,
    Vertices,
    extract_vertices,
    fit_units,
    scan_points,
)
from slam2d.frontends.fuzzy_vertex.map import UnitMap, VertexMap
from slam2d.frontends.fuzzy_vertex.matching import (
    arm_differences,
    fit_se2,
    match_vertices,
    rigid_matches,
    translation_offset,
)
from slam2d.frontends.odometry import HeadingCalibration
from slam2d.types import LandmarkObservation, Scan

__all__ = ["FuzzyVertexFrontend"]


@register_frontend("fuzzy_vertex")
class FuzzyVertexFrontend:
    """Vertex self-localisation on a fuzzy geometric map (Chen & Zhang 2006).

    The frontend keeps the base pose in its own map frame, a global vertex
    map (stable ids) and a global unit map. Each scan's vertices are matched
    to the map from the odometry prediction, the pose is fitted, and the maps
    are updated at the fitted pose. The returned delta is the fitted motion
    since the previous scan; with no vertex matched it is the odometry delta
    (counted in ``events``).
    """

    class Config(Section):
        """Parameters; defaults suit 180-beam 1-degree SICK logs and the simulator."""

        min_range: MinRange = 0.1
        max_range: MaxRange = 30.0
        xi: float = Field(0.05, gt=0, description="m; collinearity tolerance (definition 1)")
        xi_range: float = Field(0.01, ge=0, description="xi added per metre of range (range-proportional noise)")
        max_gap: float | None = Field(0.5, gt=0, description="m; a farther point starts a new set (None: off)")
        max_gap_range: float = Field(0.1, ge=0, description="gap allowance added per metre of range")
        min_unit_points: int = Field(3, ge=2, description="points of a unit")
        min_unit_length: float = Field(0.15, ge=0, description="m; shorter units are dropped")
        sigma: float = Field(0.5, gt=0, description="m; end of G_i to start of G_i+1 for a vertex")
        min_vertex_angle_deg: float = Field(30.0, ge=0, lt=90, description="min angle between a vertex's two lines")
        max_arm_error_deg: float | None = Field(30.0, gt=0, description="matched vertices' walls differ less")
        dead_reckoning_error: float = Field(0.02, gt=0, description="m; delta_a of eq. 3 per scan, at rest")
        dead_reckoning_rel: float = Field(0.1, ge=0, description="delta_a added per metre travelled in the step")
        heading_error_deg: float = Field(0.5, gt=0, description="odometry heading std per scan, at rest")
        heading_rel: float = Field(0.1, ge=0, description="heading std added per radian turned in the step")
        heading_lever: bool = Field(True, description="add the heading error's displacement at each unit to delta_a")
        min_radius: float = Field(0.1, gt=0, description="m; floor of R (eq. 11) and of fused half-widths (eq. 20)")
        max_radius: float = Field(1.0, gt=0, description="m; cap of a new vertex's R")
        heading: Literal["se2", "translation"] = Field(
            "se2", description="se2: weighted Kabsch (>= 2 vertices); translation: eq. 9, heading from odometry/compass"
        )
        arm_heading: bool = Field(True, description="matched vertices' wall directions also measure the heading")
        wall_heading: bool = Field(True, description="units matched to the unit map (eqs. 13-15) measure the heading")
        min_arm_sd_deg: float = Field(1.5, gt=0, description="floor of a wall direction's std")
        odometry_prior: bool = Field(True, description="fuse the vertex fit with the odometry prediction")
        iterations: int = Field(2, ge=1, description="match-and-fit rounds per scan")
        min_matches: int = Field(1, ge=1, description="fewer matched vertices -> odometry fallback")
        rigid_check: bool = Field(True, description="drop matches whose mutual distances disagree between scan and map")
        max_mahalanobis: float | None = Field(
            4.0, gt=0, description="reject a vertex fit this many stds from the odometry prediction (None: off)"
        )
        max_correction_xy: MaxCorrectionXY = 1.0
        max_correction_theta_deg: MaxCorrectionThetaDeg = 15.0
        prune_after: int | None = Field(50, ge=1, description="scans after which a vertex seen once is dropped")
        unit_map: bool = Field(True, description="keep the fused global unit map (eqs. 13-21)")
        min_sigma_xy: MinSigmaXY = 0.005
        min_sigma_theta_deg: MinSigmaThetaDeg = 0.1
        calibration: HeadingCalibration.Config = HeadingCalibration.Config()

    def __init__(self, config: Config | None = None):
        self.config = cfg = config or self.Config()
        self.calibration = HeadingCalibration(cfg.calibration)
        self.pose = np.zeros(3)
        self.vertices = VertexMap()
        self.units = UnitMap(cfg.min_radius)
        self.events: Counter[str] = Counter()
        self.matched_counts: list[int] = []
        self._step = -1

    # ------------------------------------------------------------------ public

    def process(self, scan: Scan, odom_delta: np.ndarray) -> FrontendResult:
        """Localise ``scan`` on the vertex map; ``odom_delta`` (3,) is the base motion since the last scan."""
        cfg = self.config
        self._step += 1
        odom_delta = self.calibration.correct(odom_delta)
        pred = geometry.compose(self.pose, odom_delta)
        delta_a = cfg.dead_reckoning_error + cfg.dead_reckoning_rel * float(np.hypot(*odom_delta[:2]))
        sigma_theta = np.deg2rad(cfg.heading_error_deg) + cfg.heading_rel * abs(float(odom_delta[2]))
        prior = np.diag([delta_a**-2, delta_a**-2, sigma_theta**-2])
        units, local = self.extract(scan, delta_a, sigma_theta if cfg.heading_lever else 0.0)
        if self._step == 0:
            return self._accept(pred, odom_delta, units, local, None, prior)
        walls = self._wall_heading(units, pred) if cfg.wall_heading else None
        pose, info, pairs, gate = self._localise(pred, local, prior, walls)
        if pairs is None:
            self.events["too few vertices matched"] += 1
            if walls is not None:  # odometry translation, heading from the matched walls
                pose, info = _combine(pred, [walls, (pred, prior)])
                if self._diverged(pose, pred, _mahalanobis2(walls[0], pred, walls[1], prior)) is None:
                    return self._accept(pose, odom_delta, units, local, None, info)
            return self._accept(pred, odom_delta, units, local, None, prior)
        reason = self._diverged(pose, pred, gate)
        if reason:
            self.events[reason] += 1
            return self._accept(pred, odom_delta, units, local, None, prior)
        self.calibration.observe(pose, pred)
        return self._accept(pose, odom_delta, units, local, pairs, info)

    def extract(self, scan: Scan, delta_a: float = 0.0, heading_error: float = 0.0) -> tuple[Units, Vertices]:
        """Units and vertices of ``scan`` in the robot base frame (``delta_a`` m, ``heading_error`` rad)."""
        cfg = self.config
        points, ranges, circular = scan_points(scan, cfg.min_range, cfg.max_range)
        if len(points) < 2:
            return Units.empty(), Vertices.empty()
        gap = None if cfg.max_gap is None else cfg.max_gap + cfg.max_gap_range * ranges
        bounds, _ = twice_classification(points, cfg.xi + cfg.xi_range * ranges, gap)
        units = fit_units(points, bounds, delta_a, cfg.min_unit_points, cfg.min_unit_length, heading_error)
        v = extract_vertices(units, cfg.sigma, np.deg2rad(cfg.min_vertex_angle_deg), circular)
        arm_sd = np.maximum(v.arm_sd, np.deg2rad(cfg.min_arm_sd_deg))
        return units, Vertices(v.o, np.clip(v.R, cfg.min_radius, cfg.max_radius), v.m, v.arms, arm_sd)

    # ------------------------------------------------------------------ steps

    def _wall_heading(self, units: Units, pred):
        """Heading estimate (pose, information) from units matched to the unit map (eqs. 13-15), or None."""
        if len(units) == 0 or len(self.units) == 0:
            return None
        world = units.transformed(pred)
        li, gj = self.units.match(world, pred)
        if len(li) == 0:
            return None
        mapped = self.units.units.select(gj)
        turn = (mapped.phi - world.phi[li] + np.pi / 2) % np.pi - np.pi / 2
        floor = np.deg2rad(self.config.min_arm_sd_deg)
        w = 1.0 / (np.maximum(world.direction_sd[li], floor) ** 2 + np.maximum(mapped.direction_sd, floor) ** 2)
        heading = pred[2] + (w * turn).sum() / w.sum()
        return np.array([pred[0], pred[1], heading]), np.diag([0.0, 0.0, w.sum()])

    def _localise(self, pred, local: Vertices, prior, walls=None):
        """Match and fit ``iterations`` times.

        Returns the pose, its information, the pairs (local idx, map idx) or
        None, and the squared Mahalanobis distance of the vertex fit from the
        odometry prediction.
        """
        cfg = self.config
        if len(local) == 0 or len(self.vertices) == 0:
            return pred, prior, None, 0.0
        reach = float(np.linalg.norm(local.o, axis=1).max()) + cfg.max_radius + cfg.max_correction_xy
        near = self.vertices.near(pred[:2], reach)
        mapped = self.vertices.v.select(near)
        arm_tol = None if cfg.max_arm_error_deg is None else np.deg2rad(cfg.max_arm_error_deg)
        pose, info, pairs, gate = pred, prior, None, 0.0
        for _ in range(cfg.iterations):
            li, gj = match_vertices(local.transformed(pose), mapped, arm_tol)
            if cfg.rigid_check:
                keep = rigid_matches(local.o[li], mapped.o[gj], local.R[li], mapped.m[gj])
                li, gj = li[keep], gj[keep]
            if len(li) < cfg.min_matches:
                pairs = None
                break
            pairs = (li, near[gj])
            pose, info, gate = self._fit(pred, prior, local.select(li), mapped.select(gj), walls)
        return pose, info, pairs, gate

    def _fit(self, pred, prior, local: Vertices, mapped: Vertices, walls=None):
        """Map pose (3,) and its information (3, 3, map frame) from matched vertex pairs.

        The vertex fit (eq. 9, or weighted Kabsch) and, optionally, the wall
        directions and the odometry prior are combined as independent
        estimates, each weighted by its information.
        """
        cfg = self.config
        p, q, m = local.o, mapped.o, mapped.m
        sd = np.minimum(local.R, mapped.R) / FUZZY_SCALE
        w = 1.0 / (sd**2 * (1.0 + 1.0 / m))
        if cfg.heading == "se2" and len(p) >= 2 and np.ptp(p, axis=0).max() > 0:
            fit = fit_se2(p, q, m)
            info = _vertex_information(fit, p, w, rotation=True)
        else:
            v = translation_offset(q, geometry.transform_points(pred, p), m)
            fit = np.array([pred[0] + v[0], pred[1] + v[1], pred[2]])
            info = _vertex_information(fit, p, w, rotation=False)
        estimates = [(fit, info)]
        if cfg.arm_heading:
            turn = arm_differences(mapped.arms, local.arms + pred[2])  # (S, 2)
            w_arm = 1.0 / (local.arm_sd**2 * (1.0 + 1.0 / m))
            heading = pred[2] + (w_arm[:, None] * turn).sum() / (2.0 * w_arm.sum())
            estimates.append((np.array([pred[0], pred[1], heading]), np.diag([0.0, 0.0, 2.0 * w_arm.sum()])))
        if walls is not None:
            estimates.append(walls)
        fit, fit_info = _combine(pred, estimates)
        gate = _mahalanobis2(fit, pred, fit_info, prior)
        if cfg.odometry_prior:
            return *_combine(pred, [(fit, fit_info), (pred, prior)]), gate
        if fit_info[2, 2] == 0:  # translation only: the heading is the odometry's (or the compass')
            fit_info = fit_info + np.diag([0.0, 0.0, prior[2, 2]])
        return fit, fit_info, gate

    def _diverged(self, pose, pred, gate: float) -> str | None:
        cfg = self.config
        if cfg.max_mahalanobis is not None and gate > cfg.max_mahalanobis**2:
            return "vertex fit inconsistent with odometry"
        if np.hypot(*(pose[:2] - pred[:2])) > cfg.max_correction_xy:
            return "translation correction too large"
        if abs(geometry.wrap_angle(pose[2] - pred[2])) > np.deg2rad(cfg.max_correction_theta_deg):
            return "rotation correction too large"
        return None

    def _accept(self, pose, odom_delta, units: Units, local: Vertices, pairs, info_world) -> FrontendResult:
        """Update the maps at ``pose`` and return the delta from the previous pose."""
        cfg = self.config
        world = local.transformed(pose)
        li = np.zeros(0, int) if pairs is None else pairs[0]
        landmarks: tuple[LandmarkObservation, ...] = ()
        if pairs is not None:
            self.vertices.update(pairs[1], world.select(li), self._step, cfg.min_radius)
            landmarks = _observations(local.select(li), self.vertices.ids[pairs[1]])
        self.vertices.add(world.select(np.setdiff1d(np.arange(len(local)), li)), self._step)
        if cfg.prune_after is not None:
            self.vertices.prune(self._step, cfg.prune_after)
        if cfg.unit_map and len(units):
            self.units.integrate(units.transformed(pose), pose)
        delta = geometry.between(self.pose, pose) if self._step else np.asarray(odom_delta, float).copy()
        self.pose = pose
        matched = len(li)
        self.matched_counts.append(matched)
        info = cap_information(local_information(info_world, pose[2]), cfg.min_sigma_xy,
                               np.deg2rad(cfg.min_sigma_theta_deg))
        return FrontendResult(delta=delta, information=info, confidence=matched / (matched + 1.0), landmarks=landmarks)


def _vertex_information(pose, p, w, rotation: bool) -> np.ndarray:
    """Information (3, 3) of a map-frame pose (x, y, theta) from vertices p (S, 2) in the base frame.

    Each vertex gives the residual pose * p - map vertex with isotropic weight w (1/m^2).
    """
    info = np.zeros((3, 3))
    info[0, 0] = info[1, 1] = w.sum()
    if rotation:
        rp = p @ geometry.rotation(pose[2]).T
        lever = np.column_stack([-rp[:, 1], rp[:, 0]])  # d(R p)/d theta
        info[:2, 2] = info[2, :2] = (w[:, None] * lever).sum(0)
        info[2, 2] = (w * (lever**2).sum(1)).sum()
    return info


def _combine(pred, estimates) -> tuple[np.ndarray, np.ndarray]:
    """Information-weighted mean of pose estimates [(pose, info)] in the tangent space at ``pred``."""
    total = sum(info for _, info in estimates)
    rhs = sum(info @ _difference(x, pred) for x, info in estimates)
    step = np.linalg.lstsq(total, rhs, rcond=None)[0]
    return np.array([pred[0] + step[0], pred[1] + step[1], geometry.wrap_angle(pred[2] + step[2])]), total


def _difference(a, b) -> np.ndarray:
    """a - b for poses (3,), the angle wrapped."""
    return np.array([a[0] - b[0], a[1] - b[1], geometry.wrap_angle(a[2] - b[2])])


def _mahalanobis2(fit, pred, fit_info, prior) -> float:
    """Squared Mahalanobis distance of ``fit`` from ``pred``: e^T (I_f^-1 + I_p^-1)^-1 e, I_f may be singular."""
    e = _difference(fit, pred)
    s_inv = fit_info @ np.linalg.solve(fit_info + prior, prior)
    return float(e @ s_inv @ e)


def _observations(local: Vertices, ids) -> tuple[LandmarkObservation, ...]:
    """Range-bearing observations (base frame) of matched vertices; covariance from R, isotropic
    in the plane, in (bearing, range) order (rad^2, m^2)."""
    o = local.o
    rng = np.linalg.norm(o, axis=1)
    bearing = np.arctan2(o[:, 1], o[:, 0])
    sd = local.R / FUZZY_SCALE
    return tuple(
        LandmarkObservation(int(i), float(r), float(b), np.diag([(s / max(r, 1e-3)) ** 2, s**2]))
        for i, r, b, s in zip(ids, rng, bearing, sd)
        if r > 1e-3
    )
